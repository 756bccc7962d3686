"""Beam patterns: counts, angles between beams, skewed grids, as logged."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formats.strike_log import StrikeLog
from sim.sensors import beam_pattern, cone_pattern
from tests.sim.conftest import run_scene


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0)))


def test_single_beam_is_the_boresight():
    p = beam_pattern("single", fov_deg=[10, 10])
    assert p.n_beams == 1 and np.allclose(p.directions, [[0, 0, 1]])
    assert p.field_of_view == (0, 0, 0, 0) and not p.reports_angles


def test_cross_has_a_centre_beam_and_four_at_the_field_of_view_extremes():
    p = beam_pattern("cross", fov_deg=[10, 6])
    d = p.directions
    assert p.n_beams == 5 and np.allclose(d[0], [0, 0, 1])
    assert [_angle_deg(d[0], d[k]) for k in range(1, 5)] == pytest.approx([5, 5, 3, 3])
    assert _angle_deg(d[1], d[2]) == pytest.approx(10)
    assert _angle_deg(d[3], d[4]) == pytest.approx(6)
    # Azimuth beams tilt towards +-x in the x-z plane, elevation beams towards +-y.
    assert np.allclose(d[1:3, 1], 0) and d[1, 0] > 0 > d[2, 0]
    assert np.allclose(d[3:5, 0], 0) and d[3, 1] > 0 > d[4, 1]
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)


def test_zigzag_alternates_between_two_offset_rows():
    p = beam_pattern("zigzag", fov_deg=[20, 10], beams=5)
    assert p.n_beams == 5
    assert np.allclose(np.degrees(p.azimuth), [-10, -5, 0, 5, 10])
    assert np.allclose(np.degrees(p.elevation), [5, -5, 5, -5, 5])
    # Consecutive beams are in opposite rows; each row is evenly spaced at twice the step.
    upper, lower = p.directions[0::2], p.directions[1::2]
    assert np.allclose(upper[:, 1], math.sin(math.radians(5)))
    assert np.allclose(lower[:, 1], -math.sin(math.radians(5)))


def test_grid_resolution_and_skewed_field_of_view():
    centred = beam_pattern("grid", fov_deg=[20, 20], resolution=[5, 5])
    skewed = beam_pattern("grid", fov_deg=[-10, 5, -10, 10], resolution=[5, 5])  # paper Fig. 3b
    for p in (centred, skewed):
        assert p.n_beams == 25 and p.reports_angles
    assert np.allclose(np.degrees(centred.azimuth.reshape(5, 5)[0]), [-10, -5, 0, 5, 10])
    assert np.allclose(np.degrees(skewed.azimuth.reshape(5, 5)[0]), [-10, -6.25, -2.5, 1.25, 5])
    assert np.allclose(np.degrees(skewed.elevation.reshape(5, 5)[:, 0]), [-10, -5, 0, 5, 10])
    assert np.allclose(skewed.field_of_view, np.radians([-10, 5, -10, 10]))
    # The skewed grid's centre of mass sits off the boresight towards -x (azimuth).
    mean = skewed.directions.mean(axis=0)
    assert mean[0] < 0 and abs(mean[1]) < 1e-12
    single_row = beam_pattern("grid", fov_deg=[20, 20], resolution=[4, 1])
    assert np.allclose(single_row.elevation, 0.0)


def test_pattern_is_written_to_the_log(tmp_path):
    _, path = run_scene(tmp_path, "asteroid-lidar", "time.duration=20",
                        "sensor.resolution=[7, 3]", "sensor.field_of_view_deg=[-4, 8, -2, 2]")
    with StrikeLog(path) as log:
        sensor = log.sensor
    expected = beam_pattern("grid", fov_deg=[-4, 8, -2, 2], resolution=[7, 3])
    assert sensor.pattern == "grid" and sensor.reports_angles
    assert np.allclose(sensor.beam_directions, expected.directions)
    assert np.allclose(sensor.field_of_view, np.radians([-4, 8, -2, 2]))
    assert sensor.range_max == 5000.0


def test_cone_pattern_fills_the_cone():
    polar, azimuth = cone_pattern(30, 0.6e-3)
    assert len(polar) == 30 and polar.max() <= 0.6e-3 and polar.min() > 0
    # Evenly spread: the offsets' centroid is near the axis, far inside the cone.
    offsets = np.stack([polar * np.cos(azimuth), polar * np.sin(azimuth)], axis=1)
    assert np.linalg.norm(offsets.mean(axis=0)) < 0.05 * 0.6e-3
