"""Stability sweeps: degraded cells, failure maps and accuracy heatmaps per method."""

from __future__ import annotations

import json

import numpy as np
import pytest
import recon_fake_methods  # noqa: F401  (registers the test-only methods)

from formats.errors import ParameterError
from recon.experiments.stability import degrade, simulate_levels, stability
from tests.recon.conftest import FAST_SCORE, sphere_mesh, sphere_points


def test_degrade_adds_noise_along_the_line_of_sight_subsamples_and_adds_outliers():
    points, view, _ = sphere_points(4000)
    seq = np.random.SeedSequence((7, 1, 1, 1))
    noisy, noisy_view = degrade(points, view, noise_sigma3=0.03, density=0.5, outliers=0.1,
                                seed_sequence=seq)
    again, _ = degrade(points, view, noise_sigma3=0.03, density=0.5, outliers=0.1,
                       seed_sequence=np.random.SeedSequence((7, 1, 1, 1)))
    assert noisy.tobytes() == again.tobytes()  # same seed, same bytes
    assert len(noisy) == 2000 + 200 and noisy_view.shape == noisy.shape
    # View points sit on the normal, so range noise is radial: sigma 0.01 along the radius.
    radial = np.linalg.norm(noisy[:2000], axis=1) - 1
    assert np.std(radial) == pytest.approx(0.01, rel=0.1)
    low, high = noisy[:2000].min(axis=0), noisy[:2000].max(axis=0)  # the kept points' box
    assert np.all((noisy[2000:] >= low) & (noisy[2000:] <= high))


def test_stability_maps_failures_and_accuracy_per_method(tmp_path):
    points, view, _ = sphere_points(3000)
    report = stability(tmp_path, clouds={"base": (points, view, False)}, truth=sphere_mesh(4),
                       names=["convex-hull", "test-abort"], noise=(0.0, 0.03),
                       density=(1.0,), outliers=(0.0, 0.05), seed=1, timeout_s=60,
                       scheduler="threads", score_options=FAST_SCORE)
    records = report["records"]
    assert len(records) == 2 * 2 * 1 * 2
    abort = [r for r in records if r["method"] == "test-abort"]
    hull = [r for r in records if r["method"] == "convex-hull"]
    assert all(r["failure"] == "crash" for r in abort)
    assert all(r["status"] == "ok" for r in hull)
    # The hull wraps outliers and noise: its error grows with both.
    clean = next(r for r in hull if r["noise_sigma3_m"] == 0 and r["outliers"] == 0
                 and r["density"] == 1)
    dirty = next(r for r in hull if r["noise_sigma3_m"] == 0.03 and r["outliers"] == 0.05
                 and r["density"] == 1)
    assert dirty["chamfer_m"] > 3 * clean["chamfer_m"]
    # ... far beyond what the noise explains: an accuracy collapse, its own kind of failure,
    # with its scores kept. Noise alone (sigma 0.01 on the hull's clean error) is no collapse.
    limit = 3 * clean["chamfer_m"] + 0.01
    for r in hull:
        assert (r["failure"] == "collapse") == (r["chamfer_m"] > limit), r
    assert dirty["failure"] == "collapse" and "accuracy collapse" in dirty["reason"]
    noisy = next(r for r in hull if r["noise_sigma3_m"] == 0.03 and r["outliers"] == 0)
    assert noisy["failure"] is None
    summary = json.loads((tmp_path / "stability.json").read_text())
    collapsed = sum(r["failure"] == "collapse" for r in hull) / len(hull)
    assert summary["failure_rate"] == {"convex-hull": collapsed, "test-abort": 1.0}
    assert len((tmp_path / "stability.csv").read_text().splitlines()) == 9
    for method in ("convex-hull", "test-abort"):
        for kind in ("failures", "accuracy"):
            assert (tmp_path / f"{method}_{kind}.png").stat().st_size > 10_000


def test_stability_resumes_without_rerunning(tmp_path):
    points, view, _ = sphere_points(1000)
    common = {"clouds": {"base": (points, view, False)}, "truth": sphere_mesh(3),
              "names": ["convex-hull"], "noise": (0.0,), "density": (1.0, 0.5),
              "outliers": (0.0,), "scheduler": "serial", "score_options": FAST_SCORE}
    first = stability(tmp_path, **common)["records"]
    second = stability(tmp_path, resume=True, **common)["records"]
    assert [r["wall_time_s"] for r in first] == [r["wall_time_s"] for r in second]


def test_each_cell_is_degraded_and_prepared_once_for_all_its_methods(tmp_path, monkeypatch):
    from recon.experiments import stability as module

    built = []

    def counting(clouds, **cell):
        built.append(cell["cell"])
        return module.cell_cloud.__wrapped__(clouds, **cell)

    counting.__wrapped__ = module.cell_cloud
    monkeypatch.setattr(module, "cell_cloud", counting)
    points, view, _ = sphere_points(900, seed=11)  # a cloud no other test's cache holds
    report = stability(tmp_path, clouds={"base": (points, view, False)}, truth=sphere_mesh(3),
                       names=["convex-hull", "test-abort"], noise=(0.0, 0.03),
                       density=(1.0, 0.5), outliers=(0.0,), scheduler="threads", n_workers=2,
                       score_options=FAST_SCORE)
    assert sorted(built) == [(0, 0, 0), (0, 1, 0), (1, 0, 0), (1, 1, 0)]
    records = report["records"]  # method by method, each on its cell's points
    assert [r["method"] for r in records] == ["convex-hull"] * 4 + ["test-abort"] * 4
    hull = {(r["noise_sigma3_m"], r["density"]): r["n_points"] for r in records[:4]}
    assert hull == {(0.0, 1.0): 900, (0.0, 0.5): 450, (0.03, 1.0): 900, (0.03, 0.5): 450}
    for r in records[:4]:  # where each run's time went: the fit, then checks and scoring
        assert r["process_time_s"] > r["wall_time_s"] + r["score_time_s"] > r["score_time_s"] > 0


def test_scene_levels_are_fresh_simulations_with_range_noise(tmp_path):
    clouds, truth = simulate_levels("asteroid-lidar", [0.0, 3.0], tmp_path,
                                    overrides=["time.duration=30"], seed=0)
    (p0, _, noisy0, misses0), (p1, _, noisy1, misses1) = clouds["0"], clouds["3"]
    assert noisy0 and noisy1 and len(truth[1]) > 1000
    assert len(misses0) > 0 and len(misses1) > 0   # each level's log's own free space
    assert (tmp_path / "logs" / "noise-3.h5").is_file()
    from metrics import point_mesh_distance

    assert point_mesh_distance(p0, truth)[0].max() < 1e-3
    assert np.std(point_mesh_distance(p1, truth)[0]) > 0.3


def test_every_cell_of_a_log_carries_its_missed_beams(tmp_path):
    from recon import api
    from recon.experiments.stability import StabilityCloud, cell_cloud

    clouds, _ = simulate_levels("asteroid-lidar", [0.3], tmp_path,
                                overrides=["time.duration=30"], seed=0)
    misses = clouds["0.3"].misses
    for density, outliers in ((1.0, 0.0), (0.5, 0.05)):   # no degradation changes free space
        cloud = cell_cloud(clouds, noise_key="0.3", noise_sigma3=0.3, density=density,
                           outliers=outliers, cell=(0, 0, 0), seed=0)
        assert cloud.misses is misses
    # a log given as it is: its own missed beams, the same ones
    given, _ = api._stability_clouds(tmp_path / "logs" / "noise-0.3.h5", tmp_path / "out", None,
                                     1.0, (), (0.3,), 0)
    assert given["base"].misses.direction.tobytes() == misses.direction.tobytes()
    points, view, _ = sphere_points(300)
    plain = cell_cloud({"base": StabilityCloud(points, view, False)}, noise_key="base",
                       noise_sigma3=0.0, density=1.0, outliers=0.0, cell=(0, 0, 0), seed=0)
    assert plain.misses is None   # a cloud file records no misses


@pytest.mark.parametrize("kwargs, match", [
    ({"noise": ()}, "noise needs at least one level"),
    ({"density": (0.0,)}, r"density level 0 is out of range \(must be \[1e-09, 1\]\)"),
    ({"density": (1.5,)}, "density level 1.5 is out of range"),
    ({"outliers": (-0.1,)}, "outliers level -0.1 is out of range"),
    ({"outliers": (1.5,)}, r"outliers level 1.5 is out of range \(must be \[0, 1\]\)"),
    ({"outliers": (1e6,)}, "outliers level 1e[+]06 is out of range"),
    ({"noise": (0.1, 0.1)}, "noise levels repeat"),
])
def test_bad_levels_are_named(tmp_path, kwargs, match):
    points, view, _ = sphere_points(200)
    with pytest.raises(ParameterError, match=match) as info:
        stability(tmp_path, clouds={"base": (points, view, False)}, truth=sphere_mesh(2),
                  names=["convex-hull"], **kwargs)
    assert info.value.argument == next(iter(kwargs))


def test_a_grid_too_long_to_run_is_refused_with_its_estimate():
    from recon.experiments.stability import MAX_SWEEP_S, check_grid

    levels = [i / 1000 for i in range(1, 1001)]
    with pytest.raises(ParameterError, match=r"^noise, density and outliers make 2,000,000 "
                                             r"cells; with 1 method\(s\) that is 2,000,000 "
                                             r"runs, at least [\d.]+ days on 2 worker\(s\)"):
        check_grid(levels, levels, (0.0, 0.02), 1, samples=31_250, workers=2)
    # 300 x 300 x 2 cells of one method: about a day on 2 workers at the least
    assert check_grid(levels[:300], levels[:300], (0.0, 0.02), 1, samples=31_250,
                      workers=2)[2] == (0, 0.02)
    assert check_grid((0.0,), (1.0,), (0.0,), 14, samples=31_250, workers=1) == ((0.0,), (1.0,),
                                                                                 (0.0,))
    assert MAX_SWEEP_S == 7 * 86400
    # fast runs on many workers: the runs' count bounds the sweep still
    with pytest.raises(ParameterError, match=r"2,000,000 runs, .* a sweep may have at most "
                                             r"200,000 runs and take at most 7 days"):
        check_grid(levels, levels, (0.0, 0.02), 1, samples=100, workers=64)


def test_the_api_refuses_a_grid_before_reading_or_writing_anything(tmp_path, monkeypatch):
    from recon import api
    from recon.surfaces import isolation

    monkeypatch.setattr(isolation, "start_workers", lambda *a: pytest.fail("workers started"))
    levels = [i / 1000 for i in range(1, 1001)]
    with pytest.raises(ParameterError, match="2,000,000 runs"):
        api.stability(tmp_path / "missing.ply", output=tmp_path / "out", noise=levels,
                      density=levels, methods=["convex-hull"])
    assert not (tmp_path / "out").exists()


def test_a_serial_grid_is_estimated_on_one_worker(tmp_path):
    """'serial' runs one case at a time whatever ``n_workers`` says: its estimate counts one."""
    from recon import api

    levels = [i / 100 for i in range(1, 101)]
    with pytest.raises(ParameterError, match=r"20,000 runs, at least [\d.]+ days on 1 "
                                             r"worker\(s\)"):
        api.stability(tmp_path / "missing.ply", output=tmp_path / "out", noise=levels,
                      density=levels, methods=["convex-hull"], scheduler="serial", n_workers=8,
                      samples=2_000_000)


def test_a_plain_cloud_needs_a_truth_and_takes_no_scene_overrides(tmp_path):
    from formats.cloud_io import write_cloud
    from formats.geometry import Cloud
    from recon import api

    points, _, _ = sphere_points(200)
    path = tmp_path / "sphere.ply"
    write_cloud(path, Cloud(points))
    with pytest.raises(ParameterError, match=r"^truth must be given: .*sphere\.ply is a cloud, "
                                             r"not a strike log with truth$") as info:
        api.stability(path, output=tmp_path / "out", methods=["convex-hull"])
    assert info.value.argument == "truth"
    with pytest.raises(ParameterError, match=r"^overrides: a cloud or a log \(.*sphere\.ply\) "
                                             r"takes none, only a scene does$") as info:
        api.stability(path, output=tmp_path / "out", overrides=["x=1"])
    assert info.value.argument == "overrides"
