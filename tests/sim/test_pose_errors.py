"""Pose-knowledge error models: what /shots records against the true poses /truth keeps."""

from __future__ import annotations

import math

import h5py
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import sim
from formats.strike_log import StrikeLog
from sim.pose_errors import gauss_markov, known_spin_axis, random_walk
from tests.sim.conftest import read_all, run_scene

SHORT = "time.duration=2000"


def _angle_between(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    return (Rotation.from_quat(q_a).inv() * Rotation.from_quat(q_b)).magnitude()


def test_misalignment_and_position_bias_are_what_the_shots_record(tmp_path):
    """Recorded R_SI = true R_SI E; recorded r - true r = F (radial, along, cross) bias."""
    bias = np.array([0.4, -1.0, 2.5])
    _, path = run_scene(tmp_path, "asteroid-lrf", SHORT,
                        "errors.boresight_misalignment_deg=[0.05, -0.02, 0.1]",
                        f"errors.position_bias=[{bias[0]}, {bias[1]}, {bias[2]}]")
    data = read_all(path)
    error = Rotation.from_rotvec(np.radians([0.05, -0.02, 0.1]))
    expected = (Rotation.from_quat(data["truth/sensor_attitude"]) * error).as_quat()
    assert np.all(_angle_between(expected, data["shots/sensor_attitude"]) < 1e-12)
    true_r = data["truth/sensor_position"]
    delta = data["shots/sensor_position"] - true_r
    radial = true_r / np.linalg.norm(true_r, axis=1, keepdims=True)
    np.testing.assert_allclose(np.einsum("ij,ij->i", delta, radial), bias[0], atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(delta, axis=1), np.linalg.norm(bias), rtol=1e-12)
    # The target attitude and every strike are untouched: the errors are in knowledge only.
    np.testing.assert_array_equal(data["shots/target_attitude"], data["truth/target_attitude"])
    with StrikeLog(path) as log:
        recorded = log.sensor.errors
    assert recorded.boresight_misalignment == pytest.approx(np.radians([0.05, -0.02, 0.1]))
    assert recorded.position_bias == pytest.approx(tuple(bias)) and recorded.pose


def test_inertial_position_bias_is_constant_in_the_inertial_frame(tmp_path):
    data = read_all(run_scene(tmp_path, "asteroid-lrf", SHORT,
                              "errors.position_bias_inertial=[1.0, -2.0, 0.5]")[1])
    np.testing.assert_allclose(data["shots/sensor_position"] - data["truth/sensor_position"],
                               np.broadcast_to([1.0, -2.0, 0.5], (*data["shots/time"].shape, 3)),
                               atol=1e-9)


def test_pose_errors_leave_the_truth_and_the_strikes_unchanged(tmp_path):
    clean = read_all(run_scene(tmp_path, "asteroid-lrf", SHORT, "errors.range_sigma3=0.3",
                               seed=4, name="clean.h5")[1])
    posed = read_all(run_scene(tmp_path, "asteroid-lrf", SHORT, "errors.range_sigma3=0.3",
                               "errors.boresight_misalignment_deg=[0.1, 0, 0]",
                               "errors.attitude_walk_arcsec=20", "errors.position_drift=1",
                               "errors.spin_period_error=5", seed=4, name="posed.h5")[1])
    for name in ("strikes/range", "strikes/shot", "truth/point", "truth/sensor_position",
                 "truth/sensor_attitude", "truth/target_attitude", "shots/time"):
        np.testing.assert_array_equal(clean[name], posed[name])
    for name in ("shots/sensor_position", "shots/sensor_attitude", "shots/target_attitude"):
        assert not np.array_equal(clean[name], posed[name])


def test_random_walk_grows_as_the_square_root_of_time():
    rng = np.random.default_rng(0)
    walks = np.stack([random_walk(2.0, 10.0, 401, rng) for _ in range(300)])  # (runs, n, 3)
    assert not walks[:, 0].any()
    std = walks.reshape(-1, 401 * 3).std(axis=0).reshape(401, 3).mean(axis=1)
    expected = 2.0 * np.sqrt(10.0 * np.arange(401))
    np.testing.assert_allclose(std[100:], expected[100:], rtol=0.1)


def test_gauss_markov_is_stationary_with_its_correlation_time():
    g = gauss_markov(1.5, 100.0, 10.0, 200_000, np.random.default_rng(1))
    assert g.std() == pytest.approx(1.5, rel=0.03)
    lag = 10   # 100 s: correlation exp(-1)
    r = np.mean(g[lag:] * g[:-lag]) / g.var()
    assert r == pytest.approx(math.exp(-1.0), abs=0.03)


def test_known_spin_axis_is_tilted_by_the_error():
    a = known_spin_axis([0.0, 0.0, 2.0], math.radians(0.5), np.random.default_rng(3))
    assert np.degrees(np.arccos(a[2])) == pytest.approx(0.5, rel=1e-9)
    assert np.linalg.norm(a) == pytest.approx(1.0)


def test_spin_knowledge_errors_grow_with_time(tmp_path):
    """A 5 s longer known period lags 2 pi t (1/P - 1/(P + 5)) behind the true spin."""
    data = read_all(run_scene(tmp_path, "asteroid-lrf", "time.duration=20000",
                              "errors.spin_period_error=5")[1])
    t = data["shots/time"]
    lag = _angle_between(data["truth/target_attitude"], data["shots/target_attitude"])
    expected = 2 * math.pi * t * (1 / 15480.0 - 1 / 15485.0)
    np.testing.assert_allclose(lag, expected, atol=1e-9)
    tilted = read_all(run_scene(tmp_path, "asteroid-lrf", "time.duration=20000",
                                "errors.spin_axis_error_deg=0.2", name="tilt.h5")[1])
    angle = _angle_between(tilted["truth/target_attitude"], tilted["shots/target_attitude"])
    assert angle[0] == 0 and angle.max() > math.radians(0.2)


def test_time_tag_offset_records_the_pose_one_step_later(tmp_path):
    data = read_all(run_scene(tmp_path, "asteroid-lrf-slew", SHORT, "errors.time_tag_offset=10")[1])
    np.testing.assert_allclose(data["shots/sensor_position"][:-1],
                               data["truth/sensor_position"][1:], atol=1e-9)
    assert np.all(_angle_between(data["shots/sensor_attitude"][:-1],
                                 data["truth/sensor_attitude"][1:]) < 1e-9)


def test_pose_errors_are_seeded_and_independent_of_the_chunking(tmp_path):
    errs = ("errors.attitude_walk_arcsec=30", "errors.position_drift=2",
            "errors.spin_axis_error_deg=0.1")
    a = read_all(run_scene(tmp_path, "asteroid-lrf", SHORT, *errs, seed=5, name="a.h5",
                           workers=1)[1])
    b = read_all(run_scene(tmp_path, "asteroid-lrf", SHORT, *errs, seed=5, name="b.h5",
                           workers=2)[1])
    c = read_all(run_scene(tmp_path, "asteroid-lrf", SHORT, *errs, seed=6, name="c.h5")[1])
    for name in ("shots/sensor_position", "shots/sensor_attitude", "shots/target_attitude"):
        np.testing.assert_array_equal(a[name], b[name])
        assert not np.array_equal(a[name], c[name])


def test_logs_without_pose_error_attributes_read_as_zero(tmp_path):
    _, path = run_scene(tmp_path, "asteroid-lrf", "time.duration=100")
    with h5py.File(path, "r+") as f:
        for name in ("boresight_misalignment", "time_tag_offset"):
            del f["sensor/errors"].attrs[name]
    with StrikeLog(path) as log:
        assert log.sensor.errors.boresight_misalignment == (0.0, 0.0, 0.0)
        assert not log.sensor.errors.pose
    with h5py.File(path, "r+") as f:
        f["sensor/errors"].attrs["position_bias"] = np.array([1.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="'position_bias' must be 3 finite numbers"):
        StrikeLog(path)


@pytest.mark.parametrize(("override", "message"), [
    ("errors.boresight_misalignment_deg=[0, 20, 0]", "between -10 and 10 deg"),
    ("errors.time_tag_offset=-100", "time_tag_offset must be between -60 and 60"),
    ("errors.position_drift=-1", "position_drift must be"),
    ("errors.spin_period_error=-20000", "known spin period -4520 s"),
    ("errors.attitude_walk_arcsec=[1, 2]", "attitude_walk_arcsec must be a number"),
])
def test_bad_pose_error_keys_are_refused_with_their_name(override, message):
    with pytest.raises(sim.SceneError, match=message):
        sim.load_scene("asteroid-lrf", [override])


def test_scene_pose_errors_are_converted_once_to_si():
    errors = sim.load_scene("asteroid-lrf", ["errors.attitude_bias_arcsec=[3600, 0, 0]",
                                             "errors.attitude_walk_arcsec=60"]).errors
    assert errors.attitude_bias == pytest.approx((math.radians(1.0), 0.0, 0.0))
    # 60 arcsec per sqrt(hour) is 1 arcsec per sqrt(second).
    assert errors.attitude_walk == pytest.approx(math.radians(1 / 3600))
