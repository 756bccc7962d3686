"""End-to-end: what the log records puts every strike on the truth mesh, in the right frame."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import sim
import sim.pipeline
from formats.strike_log import StrikeLog
from sim.raycast import ExactHits
from tests.sim.conftest import distance_to_mesh, read_all, registered_points, run_scene

NOISE_FREE = [
    ("asteroid-lrf", ["time.duration=3000"]),
    ("asteroid-lrf-slew", ["time.duration=3000"]),
    ("asteroid-cross", ["time.duration=3000"]),
    ("asteroid-zigzag", ["time.duration=3000", "orbit.inclination_deg=30"]),
    ("asteroid-lidar", ["time.duration=100", "sensor.resolution=[24, 24]"]),
    ("rso-a-cross", ["time.duration=20000", "slew.amplitude_deg=3"]),
    ("rso-b-lrf", ["time.duration=20000", "slew.amplitude_deg=2", "sensor.pattern=grid",
                   "sensor.field_of_view_deg=[5, 5]", "sensor.resolution=[6, 6]"]),
]


@pytest.mark.parametrize(("scene", "overrides"), NOISE_FREE, ids=[s for s, _ in NOISE_FREE])
def test_noise_free_strikes_lie_on_the_truth_mesh(tmp_path, scene, overrides):
    summary, path = run_scene(tmp_path, scene, *overrides)
    points = registered_points(path)
    with StrikeLog(path) as log:
        vertices, faces = log.truth_mesh()
        truth = log.truth_strikes()
        _, _, recorded_range = log.strikes()
    assert summary["strikes"] == len(points) > 0
    size = np.ptp(vertices, axis=0).max()
    sample = np.random.default_rng(0).choice(len(points), min(1500, len(points)), replace=False)
    assert distance_to_mesh(points[sample], vertices, faces).max() <= 1e-6 * size
    # The truth group agrees with what was recorded, and its facet ids are right.
    assert np.allclose(truth.point, points, rtol=0, atol=1e-9 * size)
    assert np.array_equal(truth.range, recorded_range)
    a, b, c = (vertices[faces[truth.facet, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    offset = np.einsum("ij,ij->i", normal, points[:, None, :].squeeze(1) - a)
    assert np.all(np.abs(offset) <= 1e-9 * size * np.linalg.norm(normal, axis=1))


def test_body_fixed_marker_faces_land_where_expected(tmp_path, box_obj):
    """Box [-1, 1] x [-2, 2] x [-3, 3] turned 90 deg about z at t = 0 (body x -> inertial y).

    The chaser starts on +x_I (node 0, phase 0) at 100 m in a polar orbit, so S has x_S = +z_I
    (along-track), y_S = +y_I and z_S = -x_I. The boresight meets the body's -y face, which the
    attitude turns to face +x_I; a quarter spin later the body's -x face faces the chaser.
    """
    scene_file = tmp_path / "marker.toml"
    scene_file.write_text(f"""
[target]
kind = "mesh"
path = "{box_obj}"
attitude = [0.0, 0.0, {math.sin(math.pi / 4)!r}, {math.cos(math.pi / 4)!r}]
[orbit]
radius = 100.0
inclination_deg = 90.0
period = 1e15
[time]
step = 3870.0
duration = 7740.0
[sensor]
pattern = "cross"
field_of_view_deg = [1.0, 1.0]
""")
    _, path = run_scene(tmp_path, scene_file)
    with StrikeLog(path) as log:
        shot, beam, rng = log.strikes()
        point = log.truth_strikes().point
    registered = registered_points(path)
    tan = math.tan(math.radians(0.5))
    expected = {
        (0, 0): ([0, -2, 0], 98.0),                     # boresight on the -y face
        (0, 1): ([0, -2, 98 * tan], 98 / math.cos(math.radians(0.5))),   # +azimuth: +z_I
        (0, 2): ([0, -2, -98 * tan], None),
        (0, 3): ([98 * tan, -2, 0], None),              # +elevation: +y_I, which is +x_B
        (0, 4): ([-98 * tan, -2, 0], None),
        (1, 0): ([-1, 0, 0], 99.0),                     # a quarter spin later: the -x face
    }
    for (s, b), (p, r) in expected.items():
        row = np.flatnonzero((shot == s) & (beam == b))
        assert len(row) == 1, (s, b)
        assert np.allclose(point[row[0]], p, atol=1e-6)
        assert np.allclose(registered[row[0]], p, atol=1e-6)
        if r is not None:
            assert rng[row[0]] == pytest.approx(r, abs=1e-6)


def test_same_seed_same_datasets_other_seed_differs(tmp_path):
    overrides = ["time.duration=300", "sensor.resolution=[8, 8]", "errors.dilation_alpha=0.0002"]
    runs = [read_all(run_scene(tmp_path, "asteroid-lidar-noise", *overrides, seed=seed,
                               name=f"{i}.h5")[1]) for i, seed in enumerate((5, 5, 6))]
    assert runs[0].keys() == runs[1].keys()
    for key in runs[0]:
        assert np.array_equal(runs[0][key], runs[1][key]), key
    assert not np.array_equal(runs[0]["strikes/range"], runs[2]["strikes/range"])
    assert not np.array_equal(runs[0]["shots/sensor_position"], runs[2]["shots/sensor_position"])
    assert np.array_equal(runs[0]["truth/point"], runs[2]["truth/point"])   # truth: no noise


def test_results_do_not_depend_on_threads_or_chunking(tmp_path, monkeypatch):
    overrides = ["time.duration=400", "sensor.resolution=[10, 10]"]
    base = read_all(run_scene(tmp_path, "asteroid-lidar-noise", *overrides, workers=2)[1])
    one = read_all(run_scene(tmp_path, "asteroid-lidar-noise", *overrides, workers=1,
                             name="one.h5")[1])
    for key in base:
        assert np.array_equal(base[key], one[key]), key
    # Noise-free, the chunk size changes nothing either (noise streams are per chunk).
    free = read_all(run_scene(tmp_path, "asteroid-lidar", *overrides, name="free.h5")[1])
    monkeypatch.setattr(sim.pipeline, "RAYS_PER_CHUNK", 700)   # 7 shots per chunk
    small = read_all(run_scene(tmp_path, "asteroid-lidar", *overrides, name="small.h5")[1])
    for key in free:
        assert np.array_equal(free[key], small[key]), key


def test_slew_amplitude_is_visible_in_recorded_poses(tmp_path):
    _, path = run_scene(tmp_path, "asteroid-lrf-slew", "time.duration=2000")
    with StrikeLog(path) as log:
        shots = log.shots()
    boresight = Rotation.from_quat(shots.sensor_attitude).apply([0, 0, 1])
    nadir = -shots.sensor_position / np.linalg.norm(shots.sensor_position, axis=1, keepdims=True)
    off = np.degrees(np.arctan2(np.linalg.norm(np.cross(boresight, nadir), axis=1),
                                np.einsum("ij,ij->i", boresight, nadir)))
    assert np.allclose(off, 2.0 * np.abs(np.sin(2 * np.pi * shots.time / 125.0)), atol=1e-9)
    # In the plane normal to the orbit plane: no along-track component.
    velocity = np.gradient(shots.sensor_position, shots.time, axis=0)
    along = velocity / np.linalg.norm(velocity, axis=1, keepdims=True)
    assert np.abs(np.einsum("ij,ij->i", boresight, along)[1:-1]).max() < 1e-6   # central diffs


def test_inclination_change_is_visible_in_recorded_poses(tmp_path):
    summary, path = run_scene(tmp_path, "rso-a-inclination-change", "time.step=60")
    change = summary["inclination_change_s"]
    assert 154800.0 <= change < 154800.0 + summary["orbit_period_s"] / 2
    with StrikeLog(path) as log:
        shots = log.shots()
    r = shots.sensor_position
    normal = np.cross(r[:-1], r[1:])
    inclination = np.degrees(np.arccos(normal[:, 2] / np.linalg.norm(normal, axis=1)))
    before = shots.time[1:] <= change
    after = shots.time[:-1] >= change
    assert np.allclose(inclination[before], 85.0, atol=1e-6)
    assert np.allclose(inclination[after], 76.0, atol=1e-6)
    assert np.allclose(np.linalg.norm(r, axis=1), 250.0)


def test_range_limits(tmp_path):
    # The asteroid's surface is 462 to 664 m from a sensor 750 m out.
    summary, _ = run_scene(tmp_path, "asteroid-lrf", "time.duration=2000",
                           "sensor.range_max=400")
    assert summary["strikes"] == 0 and summary["shots"] == 200
    summary, path = run_scene(tmp_path, "asteroid-lrf", "time.duration=20000",
                              "sensor.range_min=600", name="near.h5")
    with StrikeLog(path) as log:
        _, _, rng = log.strikes()
    assert 0 < summary["strikes"] < summary["shots"] and rng.min() >= 600.0


def test_open3d_backend_gives_the_same_strikes(tmp_path):
    overrides = ["time.duration=300", "sensor.resolution=[12, 12]"]
    embree = read_all(run_scene(tmp_path, "asteroid-lidar", *overrides)[1])
    summary, path = run_scene(tmp_path, "asteroid-lidar", *overrides, backend="open3d",
                              name="o3d.h5")
    assert summary["backend"] == "open3d"
    other = read_all(path)
    for key in ("strikes/shot", "strikes/beam", "truth/facet"):
        assert np.array_equal(embree[key], other[key]), key
    assert np.allclose(embree["strikes/range"], other["strikes/range"], rtol=0, atol=1e-9)


def test_exact_hits_near_edges_stay_on_the_mesh():
    """Rays aimed within float32 resolution of box edges and corners, from 750 m."""
    vertices, faces = sim.targets.box([-2.5, -2.5, -2.5], [2.5, 2.5, 2.5])
    exact = ExactHits(vertices, faces)
    rng = np.random.default_rng(1)
    n = 20000
    origin = rng.normal(size=(n, 3))
    origin *= 750.0 / np.linalg.norm(origin, axis=1, keepdims=True)
    # Targets on edges and corners of the cube, nudged by up to 1e-4 m.
    target = rng.choice([-2.5, 2.5], size=(n, 3))
    free = rng.integers(0, 3, n)
    target[np.arange(n) % 2 == 0, free[np.arange(n) % 2 == 0]] = rng.uniform(-2.5, 2.5, n // 2)
    target += rng.normal(scale=1e-4, size=(n, 3))
    direction = target - origin
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    caster = sim.raycast.EmbreeBackend(vertices, faces)
    face, u, v = caster.first_hit_uv(origin.astype(np.float32), direction.astype(np.float32))
    ok = face >= 0
    t, facet, hit = exact.refine(origin[ok], direction[ok], face[ok], u[ok], v[ok], scale=750.0)
    point = origin[ok][hit] + t[hit, None] * direction[ok][hit]
    assert hit.mean() > 0.9
    assert distance_to_mesh(point, vertices, faces).max() < 1e-8   # INSIDE_TOLERANCE x 7 m
    # And the returned facet is the one the point lies in.
    a, b, c = (vertices[faces[facet[hit], k]] for k in range(3))
    area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    parts = sum(np.linalg.norm(np.cross(q - point, r - point), axis=1)
                for q, r in ((a, b), (b, c), (c, a)))
    assert np.allclose(parts, area, rtol=1e-9)
    # Same answers when every hit is checked in float64 (no float32 barycentrics).
    t2, facet2, hit2 = exact.refine(origin[ok], direction[ok], face[ok])
    assert np.array_equal(hit, hit2) and np.allclose(t[hit], t2[hit2], rtol=0, atol=1e-9)
    assert np.array_equal(facet[hit], facet2[hit2])


def test_exact_hits_reject_parallel_and_backward_rays():
    vertices, faces = sim.targets.box([-1, -1, -1], [1, 1, 1])
    exact = ExactHits(vertices, faces)
    top = int(np.flatnonzero(np.all(vertices[faces][:, :, 2] == 1.0, axis=1))[0])
    origins = np.array([[0.0, 0.0, 5.0], [0.0, 0.0, 5.0]])
    directions = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    reported = np.full(2, top)
    _, _, hit = exact.refine(origins, directions, reported, np.full(2, 0.3, np.float32),
                             np.full(2, 0.3, np.float32), scale=5.0)
    assert not hit.any()              # parallel to the top face, and pointing away from it
    assert np.array_equal(reported, np.full(2, top))   # the caller's array is left alone
