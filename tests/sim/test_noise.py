"""Error models: configured 3-sigma values come out of the recorded data; the truth stays clean."""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from formats.strike_log import SensorInfo, StrikeLog, directions_to_angles
from tests.sim.conftest import read_all, registered_points, run_scene


def _std_matches(samples: np.ndarray, sigma: float, tolerance: float = 0.04) -> None:
    """Zero mean and the expected standard deviation, within sampling error."""
    n = samples.size
    assert abs(samples.mean()) < 5 * sigma / math.sqrt(n)
    assert samples.std() == pytest.approx(sigma, rel=tolerance)
    assert tolerance > 5 / math.sqrt(2 * n)   # the tolerance is beyond sampling noise


def _true_directions_in_sensor_frame(log: StrikeLog, shot, point_b) -> np.ndarray:
    truth = log.truth_shots()
    p_i = Rotation.from_quat(truth.target_attitude[shot]).apply(point_b)
    v_s = Rotation.from_quat(truth.sensor_attitude[shot]).inv().apply(
        p_i - truth.sensor_position[shot])
    return v_s / np.linalg.norm(v_s, axis=1, keepdims=True)


class SimulatedBeams(NamedTuple):
    """What the angle-error tests read back from a simulated log."""

    path: Path
    sensor: SensorInfo
    beam: np.ndarray          # (s,) beam index of each strike
    recorded: np.ndarray      # (s,) recorded range, metres
    true_range: np.ndarray    # (s,) truth range, metres
    true_direction: np.ndarray  # (s, 3) unit vectors, sensor frame: where each strike truly went


def _simulate_beams(tmp_path, preset: str, *overrides: str) -> SimulatedBeams:
    """Simulate ``preset`` with ``overrides`` and read back its strikes and true directions."""
    _, path = run_scene(tmp_path, preset, *overrides)
    with StrikeLog(path) as log:
        shot, beam, recorded = log.strikes()
        truth = log.truth_strikes()
        true_direction = _true_directions_in_sensor_frame(log, shot, truth.point)
        return SimulatedBeams(path, log.sensor, beam, recorded, truth.range, true_direction)


def test_fixed_lrf_range_and_pose_errors(tmp_path):
    summary, path = run_scene(tmp_path, "asteroid-cross-noise")   # 0.3 m range, 2 m pose
    with StrikeLog(path) as log:
        _, _, recorded = log.strikes()
        truth = log.truth_strikes()
        shots, true_shots = log.shots(), log.truth_shots()
        errors = log.sensor.errors
    assert summary["strikes"] > 15000
    _std_matches(recorded - truth.range, 0.1)
    _std_matches(shots.sensor_position - true_shots.sensor_position, 2.0 / 3.0)
    # Only the position is perturbed: attitudes are recorded as they were.
    assert np.array_equal(shots.sensor_attitude, true_shots.sensor_attitude)
    assert (errors.range_sigma3, errors.position_sigma3, errors.azimuth_sigma3) == (0.3, 2.0, 0)


def test_lidar_reports_angles_with_the_configured_error(tmp_path):
    run = _simulate_beams(tmp_path, "asteroid-lidar-noise", "time.duration=300",
                          "errors.position_sigma3=0")
    offsets = read_all(run.path)
    az_off, el_off = offsets["strikes/azimuth_offset"], offsets["strikes/elevation_offset"]
    sigma = math.radians(0.2) / 3.0
    _std_matches(az_off, sigma)
    _std_matches(el_off, sigma)
    _std_matches(run.recorded - run.true_range, 1.0 / 3.0)
    assert np.corrcoef(az_off, el_off)[0, 1] == pytest.approx(0.0, abs=0.05)
    # The LIDAR fired along its nominal beams: the truth lies exactly on them.
    assert np.allclose(run.true_direction, run.sensor.beam_directions[run.beam], atol=1e-9)
    assert run.sensor.errors.azimuth_sigma3 == pytest.approx(math.radians(0.2))


def test_fixed_lrf_angle_error_is_a_pointing_error(tmp_path):
    run = _simulate_beams(tmp_path, "asteroid-cross", "errors.azimuth_sigma3_deg=0.3",
                          "errors.elevation_sigma3_deg=0.15")
    az, el = directions_to_angles(run.true_direction)
    az0, el0 = directions_to_angles(run.sensor.beam_directions[run.beam])
    _std_matches(az - az0, math.radians(0.3) / 3.0)
    _std_matches(el - el0, math.radians(0.15) / 3.0)
    # The range was measured along the true beam: no range error here.
    assert np.array_equal(run.recorded, run.true_range)


def _incidence(path):
    """tan of the angle between each strike's true beam and its facet's normal, and ranges."""
    with StrikeLog(path) as log:
        shot, _, recorded = log.strikes()
        truth = log.truth_strikes()
        vertices, faces = log.truth_mesh()
        shots = log.truth_shots()
    origin = Rotation.from_quat(shots.target_attitude[shot]).inv().apply(
        shots.sensor_position[shot])
    beam = truth.point - origin
    beam /= np.linalg.norm(beam, axis=1, keepdims=True)
    a, b, c = (vertices[faces[truth.facet, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    cos = np.abs(np.einsum("ij,ij->i", beam, normal))
    return np.sqrt(1 - cos ** 2) / cos, truth, recorded


def test_pulse_dilation_grows_with_incidence_angle(tmp_path):
    """LIDAR: the strike moves in 3D by sigma = alpha * range * tan(incidence) / 3 per axis."""
    alpha = 0.0002
    _, path = run_scene(tmp_path, "asteroid-lidar", "time.duration=200",
                        f"errors.dilation_alpha={alpha}")
    tan, truth, _ = _incidence(path)
    error = registered_points(path) - truth.point
    sigma = alpha * truth.range * tan / 3.0
    ok = tan < 5.0   # away from grazing, all 30 sub-rays see the same smooth surface
    _std_matches(error[ok] / sigma[ok, None], 1.0)
    # Grouped by incidence: the spread grows with tan(theta), as Eq. (1) says.
    edges = np.quantile(tan[ok], [0, 0.25, 0.5, 0.75, 1.0])
    spread = [np.std(error[ok][(tan[ok] >= lo) & (tan[ok] <= hi)])
              for lo, hi in itertools.pairwise(edges)]
    assert np.all(np.diff(spread) > 0)
    assert spread[-1] > 3 * spread[0]


def test_pulse_dilation_on_a_fixed_lrf_is_along_the_beam(tmp_path):
    _, path = run_scene(tmp_path, "asteroid-cross-dilation")
    tan, truth, recorded = _incidence(path)
    sigma = 0.0002 * truth.range * tan / 3.0
    ok = tan < 5.0
    _std_matches((recorded - truth.range)[ok] / sigma[ok], 1.0, tolerance=0.05)
    # Recorded along the nominal beam, which is the true one: no lateral error.
    lateral = registered_points(path) - truth.point
    along = (recorded - truth.range)[:, None]
    with StrikeLog(path) as log:
        errors = log.sensor.errors
    assert np.allclose(np.linalg.norm(lateral, axis=1), np.abs(along[:, 0]), atol=1e-9)
    assert (errors.pulse_dilation_alpha, errors.pulse_dilation_subrays) == (0.0002, 30.0)
    assert errors.pulse_dilation_half_angle == pytest.approx(0.6e-3)


def test_errors_off_record_the_truth_exactly(tmp_path):
    data = read_all(run_scene(tmp_path, "asteroid-lidar", "time.duration=100")[1])
    assert np.array_equal(data["strikes/range"], data["truth/range"])
    assert not data["strikes/azimuth_offset"].any() and not data["strikes/elevation_offset"].any()
    assert np.array_equal(data["shots/sensor_position"], data["truth/sensor_position"])


def test_error_streams_are_independent(tmp_path):
    """Switching one model on leaves the others' draws unchanged (same seed)."""
    base = ["time.duration=3000", "errors.position_sigma3=2"]
    a = read_all(run_scene(tmp_path, "asteroid-cross", *base, seed=9, name="a.h5")[1])
    b = read_all(run_scene(tmp_path, "asteroid-cross", *base, "errors.range_sigma3=0.3",
                           seed=9, name="b.h5")[1])
    assert np.array_equal(a["shots/sensor_position"], b["shots/sensor_position"])
    assert not np.array_equal(a["strikes/range"], b["strikes/range"])


def test_scene_errors_are_converted_once_to_the_recorded_3_sigma_si_values():
    import sim

    scene = sim.load_scene("asteroid-lrf", ["errors.range_sigma3=0.3",
                                            "errors.azimuth_sigma3_deg=0.2",
                                            "errors.dilation_alpha=0.0002"])
    errors = scene.errors
    assert errors.range_sigma3 == 0.3 and errors.range_sigma == pytest.approx(0.1, rel=1e-15)
    assert errors.azimuth_sigma3 == math.radians(0.2)
    assert errors.azimuth_sigma == pytest.approx(math.radians(0.2) / 3, rel=1e-15)
    assert errors.angles and errors.dilation
    assert errors.pulse_dilation_half_angle == pytest.approx(0.6e-3, rel=1e-15)
    assert errors.pulse_dilation_subrays == 30.0
    off = sim.load_scene("asteroid-lrf").errors   # the cone is recorded only when dilation is on
    assert (off.pulse_dilation_half_angle, off.pulse_dilation_subrays) == (0.0, 0.0)
    assert not (off.angles or off.dilation)
