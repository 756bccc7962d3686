"""Scenes: defaults, presets, overrides, and one clear error per bad key."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest
import trimesh

import sim
from formats.errors import ReconError, SceneError
from sim.defaults import SCHEMA
from tests.sim.conftest import write_obj

PAPER_PRESETS = ["asteroid-lrf", "asteroid-lrf-slew", "asteroid-cross", "asteroid-zigzag",
                 "asteroid-lidar", "rso-a-lrf", "rso-b-lrf", "rso-a-cross"]


def test_default_scene_is_the_papers_asteroid_run():
    scene = sim.load_scene("asteroid-lrf")
    assert scene["orbit.radius"] == 750.0 and scene["orbit.inclination_deg"] == 85.0
    assert scene["time.step"] == 10.0 and scene["target.spin_period"] == 15480.0
    assert scene.n_shots == 77_400   # 50 rotations of 4.3 h every 10 s
    assert scene["target.kind"] == "ellipsoid" and scene["sensor.pattern"] == "single"
    # Period from mu = G * 2000 kg/m^3 * volume, the volume measured by trimesh.
    volume = trimesh.Trimesh(scene.vertices, scene.faces, process=False).volume
    mu = 6.67430e-11 * 2000.0 * volume
    assert scene.mu == pytest.approx(mu, rel=1e-12)
    assert scene.orbit_period == pytest.approx(2 * math.pi * math.sqrt(750.0 ** 3 / mu))


def test_all_paper_presets_exist_with_descriptions():
    presets = dict(sim.list_presets())
    assert set(PAPER_PRESETS) <= set(presets)
    assert all(d and "\n" not in d for d in presets.values())


@pytest.mark.parametrize("name", [n for n, _ in sim.list_presets()])
def test_presets_load_and_state_only_what_differs(name):
    scene = sim.load_scene(name)
    assert scene.n_shots >= 1
    text = (sim.scene._preset_dir() / f"{name}.toml").read_text()
    for section, keys in tomllib.loads(text).items():
        for key, value in keys.items():
            assert value != SCHEMA[section][key].default, f"{name}: {section}.{key} is default"


def test_paper_preset_parameters():
    assert sim.load_scene("asteroid-lrf-slew")["slew.amplitude_deg"] == 2.0
    for name in ("asteroid-cross", "asteroid-zigzag"):
        assert sim.load_scene(name)["sensor.field_of_view_deg"] == [10.0, 10.0]
    assert sim.load_scene("asteroid-lidar")["time.rotations"] == 15.0
    for name in ("rso-a-lrf", "rso-b-lrf", "rso-a-cross"):
        assert sim.load_scene(name)["orbit.radius"] == 250.0
    assert sim.load_scene("rso-a-cross")["sensor.field_of_view_deg"] == [1.2, 1.2]


def test_overrides_replace_keys_and_alternatives():
    scene = sim.load_scene("asteroid-lidar", ["time.duration=600", "sensor.pattern=cross",
                                              "sensor.field_of_view_deg=[1.2, 2.4]",
                                              "target.subdivisions=2"])
    assert scene.n_shots == 60 and "rotations" not in scene.values["time"]
    assert scene["sensor.pattern"] == "cross" and scene["sensor.field_of_view_deg"] == [1.2, 2.4]
    assert "resolution" not in scene.values["sensor"]   # means nothing for a cross
    assert len(scene.faces) == 320
    scene = sim.load_scene("rso-a-lrf", ["orbit.period=3600"])
    assert scene.orbit_period == pytest.approx(3600.0) and "mu" not in scene.values["orbit"]
    assert sim.load_scene("asteroid-lrf", ["time.rotations=0.5"]).n_shots == 774


def test_scene_file_with_relative_mesh_path(tmp_path, box_obj):
    (tmp_path / "scenes").mkdir()
    scene_file = tmp_path / "scenes" / "box.toml"
    scene_file.write_text('[target]\nkind = "mesh"\npath = "../box.obj"\nscale = 10.0\n'
                          "[orbit]\nradius = 100.0\n[time]\nduration = 100.0\n")
    scene = sim.load_scene(scene_file)
    assert scene.target == "mesh:box.obj" and np.ptp(scene.vertices, axis=0)[2] == 60.0


def test_resolved_toml_reloads_to_the_same_scene(tmp_path):
    scene = sim.load_scene("rso-a-inclination-change", ["slew.amplitude_deg=3",
                                                        "errors.range_sigma3=0.3"])
    path = tmp_path / "resolved.toml"
    path.write_text(scene.to_toml())
    again = sim.load_scene(path)
    assert again.values == scene.values and again.n_shots == scene.n_shots


@pytest.mark.parametrize(("overrides", "match"), [
    (["orbit.radious=800"], r"unknown scene key orbit\.radious \(did you mean orbit\.radius"),
    (["orbits.radius=800"], r"unknown scene section \[orbits\]"),
    (["orbit.radius=far"], r"orbit\.radius must be a number \[m\], got string 'far'"),
    (["orbit.radius=true"], r"orbit\.radius must be a number"),
    (["target.subdivisions=2.5"], r"target\.subdivisions must be an integer"),
    (["target.spin_axis=[0, 1]"], r"target\.spin_axis must be an array of 3 numbers"),
    (["sensor.resolution=[4, 4.5]"], r"sensor\.resolution must be an array of 2 integers"),
    (["orbit.radius=-750"], r"orbit\.radius must be a positive finite number"),
    (["orbit.radius=200"], r"orbit\.radius = 200 m puts the orbit inside the target"),
    (["orbit.inclination_deg=190"], r"orbit\.inclination_deg must be between 0 and 180"),
    (["orbit.mu=0"], r"orbit\.mu must be a positive"),
    (["orbit.change_time=3600"], r"orbit\.change_inclination_deg is needed with "
                                 r"orbit\.change_time"),
    (["time.step=0"], r"time\.step must be a positive"),
    (["time.duration=5"], r"time\.duration gives 5 s, shorter than one time\.step"),
    (["target.spin_period=inf"], r"time\.rotations needs a spinning target"),
    (["target.spin_period=-10"], r"target\.spin_period must be a positive"),
    (["target.spin_axis=[0, 0, 0]"], r"target\.spin_axis must be a non-zero vector"),
    (["target.attitude=[0, 0, 0, 0]"], r"target\.attitude must be a non-zero vector"),
    (["target.subdivisions=9"], r"target\.subdivisions must be between 0 and 8"),
    (["target.kind=comet"], r"target\.kind must be one of ellipsoid, rso-a, rso-b, mesh"),
    (["target.kind=mesh"], r'target\.path is needed when target\.kind is "mesh"'),
    (["target.path=x.obj"], r'target\.path is only used when target\.kind is "mesh"'),
    (["sensor.beams=7"], r'sensor\.beams is only used when sensor\.pattern is "zigzag"'),
    (["sensor.pattern=fan"], r"sensor\.pattern must be one of single, cross, zigzag, grid"),
    (["sensor.pattern=cross", "sensor.resolution=[4, 4]"],
     r'sensor\.resolution is only used when sensor\.pattern is "grid", not "cross"'),
    (["sensor.pattern=grid", "sensor.field_of_view_deg=[180, 10]"],
     r"sensor\.field_of_view_deg azimuth extent of 180 deg is impossible"),
    (["sensor.pattern=grid", "sensor.field_of_view_deg=[-100, 85, -5, 5]"],
     r"sensor\.field_of_view_deg azimuth extent of 185 deg is impossible"),
    (["sensor.pattern=grid", "sensor.field_of_view_deg=[5, -5, -5, 5]"],
     r"sensor\.field_of_view_deg azimuth minimum 5 deg exceeds its maximum -5 deg"),
    (["sensor.pattern=grid", "sensor.field_of_view_deg=[0, 95, -5, 5]"],
     r"sensor\.field_of_view_deg azimuth limits must lie within 90 deg"),
    (["sensor.pattern=grid", "sensor.field_of_view_deg=[10, 10, 10]"],
     r"sensor\.field_of_view_deg must be an array of 2 or 4 numbers"),
    (["sensor.pattern=zigzag", "sensor.beams=1"], r"sensor\.beams must be at least 2"),
    (["sensor.pattern=grid", "sensor.resolution=[0, 4]"], r"sensor\.resolution must be at "
                                                           r"least 1 x 1"),
    (["sensor.range_max=0.5"], r"sensor\.range_max = 0\.5 m must exceed sensor\.range_min"),
    (["sensor.range_min=-1"], r"sensor\.range_min must be a finite number >= 0"),
    (["errors.range_sigma3=-0.3"], r"errors\.range_sigma3 must be a finite number >= 0"),
    (["errors.dilation_subrays=0"], r"errors\.dilation_subrays must be between 1 and 10000"),
    (["slew.amplitude_deg=90"], r"slew\.amplitude_deg must be at least 0 and below 90"),
    (["slew.period=0"], r"slew\.period must be a positive"),
    (["orbit.radius"], r"^overrides 'orbit\.radius': expected section\.key=value"),
])
def test_bad_values_name_the_key(overrides, match):
    with pytest.raises(SceneError, match=match) as info:
        sim.load_scene("asteroid-lrf", overrides)
    assert "\n" not in str(info.value)
    assert isinstance(info.value, ReconError) and isinstance(info.value, ValueError)


def test_unknown_preset_and_bad_files(tmp_path):
    with pytest.raises(SceneError, match=r"scene 'asteroid-lfr' is neither a preset nor a "
                                         r"\.toml file \(did you mean asteroid-lrf\?\)"):
        sim.load_scene("asteroid-lfr")
    with pytest.raises(SceneError, match=r"scene file .*missing\.toml: no such file"):
        sim.load_scene(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[orbit\nradius = 3\n")
    with pytest.raises(SceneError, match=r"bad\.toml: invalid TOML"):
        sim.load_scene(bad)
    both = tmp_path / "both.toml"
    both.write_text("[time]\nrotations = 2\nduration = 600\n")
    with pytest.raises(SceneError, match=r"give only one of time\.rotations, time\.duration"):
        sim.load_scene(both)
    flat = tmp_path / "flat.toml"
    flat.write_text("radius = 3\n")
    with pytest.raises(SceneError, match=r"unknown scene section \[radius\]"):
        sim.load_scene(flat)


def test_mesh_target_errors(tmp_path, box_obj):
    with pytest.raises(SceneError, match=r"target\.path: .*nothing\.obj: no such file"):
        sim.load_scene("asteroid-lrf", ["target.kind=mesh", "target.path=nothing.obj"])
    v, f = sim.targets.box([-1, -1, -1], [1, 1, 1])
    open_obj = write_obj(tmp_path / "open.obj", v, f[:-2])
    with pytest.raises(SceneError, match=r"orbit\.density cannot give a mass: the target mesh "
                                         r"is not closed"):
        sim.load_scene("asteroid-lrf", ["target.kind=mesh", f"target.path={open_obj}"])
    scene = sim.load_scene("asteroid-lrf", ["target.kind=mesh", f"target.path={open_obj}",
                                            "orbit.mu=1.0"])
    assert scene.mu == 1.0
    with pytest.raises(SceneError, match=r"target\.scale must be a positive"):
        sim.load_scene("asteroid-lrf", ["target.kind=mesh", f"target.path={box_obj}",
                                        "target.scale=0"])


def test_negative_seed_is_refused(tmp_path):
    with pytest.raises(SceneError, match="seed must be a non-negative integer"):
        sim.simulate(sim.load_scene("asteroid-lrf", ["time.duration=100"]), tmp_path / "x.h5",
                     seed=-1)
    with pytest.raises(SceneError, match="backend must be one of embree, open3d"):
        sim.simulate(sim.load_scene("asteroid-lrf", ["time.duration=100"]), tmp_path / "x.h5",
                     seed=0, backend="optix")


def test_scenes_do_not_share_mutable_defaults():
    a = sim.load_scene("asteroid-lrf")
    a.values["target"]["semi_axes"][0] = 1.0
    assert sim.load_scene("asteroid-lrf")["target.semi_axes"][0] == 143.75
    assert SCHEMA["target"]["semi_axes"].default[0] == 143.75
