"""Absurd scenes (issue 13): the cost is estimated before any work and refused above
``[limits]``; seeds, nesting, string lengths and override values are bounded."""

from __future__ import annotations

import re

import pytest

import sim
from formats.errors import SceneError
from formats.strike_log import StrikeLog
from sim.defaults import MAX_SEED


def test_cost_of_a_preset_is_what_the_run_does(tmp_path):
    scene = sim.load_scene("asteroid-cross", ["time.duration=600"])
    assert (scene.cost.shots, scene.cost.beams, scene.cost.rays) == (60, 5, 300)
    summary = sim.simulate(scene, tmp_path / "x.h5", seed=0)
    assert summary["rays_cast"] == scene.cost.rays
    # The disk estimate is an upper bound (every pulse a strike), in whole chunks as written.
    assert (tmp_path / "x.h5").stat().st_size <= scene.cost.disk_bytes * 1.05


@pytest.mark.parametrize("overrides, limit", [
    (["errors.dilation_alpha=0.1", "errors.dilation_subrays=10000", "time.rotations=1000"],
     "limits.rays"),
    (["sensor.pattern=grid", "sensor.resolution=[100000, 100000]"], "limits.rays"),
    (["time.step=1e-6", "time.duration=1e6"], "limits.rays"),
    (["sensor.pattern=grid", "sensor.resolution=[5000, 5000]", "time.duration=10",
      "limits.rays=1e12"], "limits.memory_mb"),
    (["sensor.pattern=grid", "sensor.resolution=[64, 64]", "limits.rays=1e12"],
     "limits.disk_mb"),
])
def test_costly_scenes_are_refused_before_any_work(overrides, limit):
    with pytest.raises(SceneError, match=rf"{limit} = .*: this scene needs .* rays, .* MiB of "
                                         rf"memory, up to .* MB of log\); reduce it or raise "
                                         rf"{limit} in the scene file or an override$"):
        sim.load_scene("asteroid-lrf", overrides)


def test_a_limit_can_be_raised():
    overrides = ["time.step=0.1", "time.duration=1e7"]
    with pytest.raises(SceneError, match=r"limits.disk_mb = 20000: this scene needs 2.36e\+04"):
        sim.load_scene("asteroid-lrf", overrides)
    with pytest.raises(SceneError, match=r"limits.rays = 1e\+07"):
        sim.load_scene("asteroid-lrf", [*overrides, "limits.rays=1e7"])
    scene = sim.load_scene("asteroid-lrf", [*overrides, "limits.disk_mb=1e5"])
    assert scene.cost.rays == 10**8


def test_unbounded_shot_count_is_one_line():
    with pytest.raises(SceneError, match=r"time.step must lie within 1e-15 to 1e\+15 s in "
                                         r"magnitude, got 1e-300"):
        sim.load_scene("asteroid-lrf", ["time.duration=1e300", "time.step=1e-300"])
    with pytest.raises(SceneError, match=r"limits.rays = 1e\+10: this scene needs 1e\+30"):
        sim.load_scene("asteroid-lrf", ["time.duration=1e15", "time.step=1e-15"])


@pytest.mark.parametrize("override, key", [
    ("orbit.radius=1e300", "orbit.radius"), ("orbit.period=1e-300", "orbit.period"),
    ("target.semi_axes=[1e100, 1, 1]", "target.semi_axes"), ("orbit.density=1e300",
                                                               "orbit.density")])
def test_values_that_would_overflow_are_refused_naming_the_key(override, key):
    with pytest.raises(SceneError, match=rf"^{re.escape(key)} must lie within 1e-15 to "
                                         r"1e\+15 .*in magnitude, got"):
        sim.load_scene("asteroid-lrf", [override])


def test_seed_above_int64_is_refused(tmp_path):
    scene = sim.load_scene("asteroid-lrf", ["time.duration=100"])
    with pytest.raises(SceneError, match=r"seed must be a non-negative integer of at most "
                                         rf"{MAX_SEED}, got {MAX_SEED + 1}"):
        sim.simulate(scene, tmp_path / "x.h5", seed=MAX_SEED + 1)
    sim.simulate(scene, tmp_path / "x.h5", seed=MAX_SEED)
    with StrikeLog(tmp_path / "x.h5") as log:
        assert log.attrs["seed"] == MAX_SEED


def test_deep_nesting_is_one_line(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text("[time]\nstep = " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(SceneError, match=r"deep\.toml: arrays or tables nested too deeply"):
        sim.load_scene(path)


def test_long_strings_and_files_are_refused_and_not_echoed(tmp_path):
    with pytest.raises(SceneError, match=r"target.path must be a string of at most 4096 "
                                         r"printable characters, got 5,000,000 characters") as e:
        sim.load_scene("asteroid-lrf", ["target.kind=mesh", "target.path=" + "a" * 5_000_000])
    assert len(str(e.value)) < 300
    big = tmp_path / "big.toml"
    big.write_text('[target]\nkind = "mesh"\npath = "' + "a" * 2_000_000 + '"\n')
    with pytest.raises(SceneError, match=r"big\.toml: 2,000,0\d\d bytes, larger than any scene"):
        sim.load_scene(big)


def test_newline_in_set_cannot_inject_toml(tmp_path):
    with pytest.raises(SceneError, match=r"control characters \(newlines, tabs\) are not "
                                         r"allowed"):
        sim.load_scene("asteroid-lrf", ['slew.phase_deg=1\n[errors]\nrange_sigma3 = 5'])
    # What is stored in a log parses back to the same scene.
    scene = sim.load_scene("asteroid-lrf", ["time.duration=100", 'slew.phase_deg=1 # [x]'])
    stored = tmp_path / "stored.toml"
    stored.write_text(scene.to_toml())
    assert sim.load_scene(stored).values == scene.values
