"""Registration of strikes into the body frame: exact placement, pose errors, truth-blindness."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from formats import StrikeLog
from recon.registration.ingest import ingest, ingest_to_file, iter_registered
from tests.conftest import SPHERE_RADIUS_M, write_sphere_log


def test_noise_free_strikes_land_on_their_truth_points(sphere_log):
    cloud = ingest(sphere_log)
    with StrikeLog(sphere_log) as log:
        truth = log.truth_strikes().point
    np.testing.assert_allclose(cloud.points, truth, atol=1e-9 * SPHERE_RADIUS_M)


def _edit(path, name, fn):
    with h5py.File(path, "r+") as f:
        f[name][...] = fn(f[name][()])


def test_spinning_target_is_undone_by_the_recorded_attitude(tmp_path):
    """Rotate target attitude and everything inertial by the same rotation: B points unchanged."""
    path = tmp_path / "spin.h5"
    write_sphere_log(path)
    before = ingest(path).points
    n = 40
    spin = Rotation.from_rotvec(np.outer(np.linspace(0, 3, n), [0.3, -0.2, 0.9]))
    _edit(path, "shots/target_attitude", lambda q: (spin * Rotation.from_quat(q)).as_quat())
    _edit(path, "shots/sensor_attitude", lambda q: (spin * Rotation.from_quat(q)).as_quat())
    _edit(path, "shots/sensor_position", lambda p: spin.apply(p))
    np.testing.assert_allclose(ingest(path).points, before, atol=1e-9)
    inertial = ingest(path, frame="inertial")
    with StrikeLog(path) as log:
        shot = log.strikes()[0]
    np.testing.assert_allclose(inertial.points, spin[shot].apply(before), atol=1e-9)


def test_position_error_moves_points_by_that_error_in_the_body_frame(tmp_path):
    path = tmp_path / "pose.h5"
    write_sphere_log(path)
    before = ingest(path)
    rng = np.random.default_rng(11)
    sigma = 2.0 / 3.0  # the paper's 2 m 3-sigma position knowledge error
    error = rng.normal(0, sigma, (40, 3))
    _edit(path, "shots/sensor_position", lambda p: p + error)
    after = ingest(path)
    np.testing.assert_allclose(after.points - before.points, error[before.attributes["shot"]],
                               atol=1e-9)  # identity target attitude: B = I
    moved = np.linalg.norm(after.points - before.points, axis=1)
    assert abs(np.sqrt(np.mean(moved**2)) / (np.sqrt(3) * sigma) - 1) < 0.35


def test_ingest_never_reads_the_truth_group(tmp_path, sphere_log):
    reference = ingest(sphere_log).points
    with h5py.File(sphere_log, "r+") as f:
        f["truth/point"][...] = 0.0  # corrupt truth: registration must not notice
        f["truth/sensor_position"][...] = 1e9
    np.testing.assert_array_equal(ingest(sphere_log).points, reference)


def test_small_chunks_give_identical_points(sphere_log, tmp_path):
    with StrikeLog(sphere_log) as log:
        blocks = list(iter_registered(log, chunk_rows=7))
    np.testing.assert_array_equal(np.concatenate([b[0] for b in blocks]),
                                  ingest(sphere_log).points)


def test_reported_angle_offsets_rotate_the_measured_direction(tmp_path):
    path = tmp_path / "angles.h5"
    write_sphere_log(path, reports_angles=True)
    cloud = ingest(path)
    # Offsets of ~1e-4 rad at 200 m move points by ~2 cm, off the sphere by far less.
    r = np.linalg.norm(cloud.points, axis=1)
    assert np.all(np.abs(r - SPHERE_RADIUS_M) < 0.5)
    assert np.any(np.abs(r - SPHERE_RADIUS_M) > 1e-6)


def test_failed_ingest_leaves_no_output(sphere_log, tmp_path):
    out = tmp_path / "cloud.ply"
    _edit(sphere_log, "shots/time", lambda t: t[::-1].copy())
    with pytest.raises(ValueError, match="time does not increase"):
        ingest_to_file(sphere_log, out)
    assert not out.exists() and list(tmp_path.glob(".cloud*")) == []


# --------------------------------------------------------------------------- simulated logs

SIMULATED = {
    "asteroid-lrf-slew": ["time.duration=20000"],
    "rso-a-cross": ["time.duration=20000"],
    "asteroid-zigzag": ["time.duration=5000"],
    "asteroid-lidar": ["time.duration=300", "sensor.resolution=[8, 8]"],
}


@pytest.mark.parametrize("preset", sorted(SIMULATED))
def test_noise_free_simulated_log_reproduces_truth_hit_points(preset, tmp_path):
    import sim

    scene = sim.load_scene(preset, SIMULATED[preset])
    path = tmp_path / "log.h5"
    sim.simulate(scene, path, seed=3)
    cloud = ingest(path)
    with StrikeLog(path) as log:
        truth = log.truth_strikes().point
        vertices, _ = log.truth_mesh()
    size = np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))
    assert len(cloud) > 100
    np.testing.assert_allclose(cloud.points, truth, rtol=0, atol=1e-6 * size)


def test_simulated_pose_error_moves_points_by_the_configured_sigma(tmp_path):
    import sim

    scene = sim.load_scene("asteroid-lrf", ["time.duration=100000",
                                            "errors.position_sigma3=2.0"])
    path = tmp_path / "pose.h5"
    sim.simulate(scene, path, seed=5)
    cloud = ingest(path)
    with StrikeLog(path) as log:
        truth = log.truth_strikes().point
    displacement = cloud.points - truth
    # Only the recorded position is wrong: each point moves by that error, seen in B.
    sigma = np.sqrt(np.mean(displacement**2, axis=0))
    np.testing.assert_allclose(sigma, 2.0 / 3.0, rtol=0.05)
    assert np.all(np.abs(displacement.mean(axis=0)) < 0.05)


def test_a_log_that_does_not_fit_in_memory_is_refused_up_front(sphere_log, tmp_path,
                                                               monkeypatch):
    """Registering a whole log in memory is estimated from its strike count and refused before
    a strike is read when the memory available is less; streaming to a file still works."""
    from formats import memory
    from formats.errors import InputError
    from recon.inputs import load_geometry
    from recon.registration.ingest import ingest_points

    monkeypatch.setattr(memory, "available_bytes", lambda: 1000)   # below 24 bytes a strike
    read = []
    monkeypatch.setattr(StrikeLog, "iter_chunks", lambda *a, **k: read.append(1) or iter(()))
    expected = rf"^{sphere_log}: registering its 80 strikes in memory needs about 0\.0 MB"
    for load in (ingest, ingest_points, load_geometry,
                 lambda path: load_geometry(path, points_only=True)):
        with pytest.raises(InputError, match=expected):
            load(sphere_log)
    assert not read
    monkeypatch.undo()
    monkeypatch.setattr(memory, "available_bytes", lambda: 1000)
    assert ingest_to_file(sphere_log, tmp_path / "c.ply")["n_points"] == 80
