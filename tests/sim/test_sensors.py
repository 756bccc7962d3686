"""Beam patterns: counts, angles between beams, skewed grids, as logged."""

from __future__ import annotations

import math

import numpy as np
import pytest

from formats.errors import SceneError
from formats.strike_log import StrikeLog
from sim import sensors
from sim.scene import load_scene
from sim.sensors import Pattern, beam_pattern, cone_pattern
from tests.sim.conftest import run_scene


def _grid(fov_deg, resolution):
    return beam_pattern({"pattern": "grid", "field_of_view_deg": fov_deg,
                         "resolution": resolution})


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0)))


def test_single_beam_is_the_boresight():
    p = beam_pattern({"pattern": "single"})
    assert p.n_beams == 1 and np.allclose(p.directions, [[0, 0, 1]])
    assert p.field_of_view == (0, 0, 0, 0) and not p.reports_angles


def test_cross_has_a_centre_beam_and_four_at_the_field_of_view_extremes():
    p = beam_pattern({"pattern": "cross", "field_of_view_deg": [10, 6]})
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
    p = beam_pattern({"pattern": "zigzag", "field_of_view_deg": [20, 10], "beams": 5})
    assert p.n_beams == 5
    assert np.allclose(np.degrees(p.azimuth), [-10, -5, 0, 5, 10])
    assert np.allclose(np.degrees(p.elevation), [5, -5, 5, -5, 5])
    # Consecutive beams are in opposite rows; each row is evenly spaced at twice the step.
    upper, lower = p.directions[0::2], p.directions[1::2]
    assert np.allclose(upper[:, 1], math.sin(math.radians(5)))
    assert np.allclose(lower[:, 1], -math.sin(math.radians(5)))


def test_grid_resolution_and_skewed_field_of_view():
    centred = _grid([20, 20], [5, 5])
    skewed = _grid([-10, 5, -10, 10], [5, 5])  # paper Fig. 3b
    for p in (centred, skewed):
        assert p.n_beams == 25 and p.reports_angles
    assert np.allclose(np.degrees(centred.azimuth.reshape(5, 5)[0]), [-10, -5, 0, 5, 10])
    assert np.allclose(np.degrees(skewed.azimuth.reshape(5, 5)[0]), [-10, -6.25, -2.5, 1.25, 5])
    assert np.allclose(np.degrees(skewed.elevation.reshape(5, 5)[:, 0]), [-10, -5, 0, 5, 10])
    assert np.allclose(skewed.field_of_view, np.radians([-10, 5, -10, 10]))
    # The skewed grid's centre of mass sits off the boresight towards -x (azimuth).
    mean = skewed.directions.mean(axis=0)
    assert mean[0] < 0 and abs(mean[1]) < 1e-12
    single_row = _grid([20, 20], [4, 1])
    assert np.allclose(single_row.elevation, 0.0)


def test_pattern_is_written_to_the_log(tmp_path):
    _, path = run_scene(tmp_path, "asteroid-lidar", "time.duration=20",
                        "sensor.resolution=[7, 3]", "sensor.field_of_view_deg=[-4, 8, -2, 2]")
    with StrikeLog(path) as log:
        sensor = log.sensor
    expected = _grid([-4, 8, -2, 2], [7, 3])
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


def test_every_pattern_counts_the_beams_it_builds():
    for name in sensors.PATTERNS:
        sensor = {"pattern": name, "field_of_view_deg": [10, 6], "beams": 7,
                  "resolution": [4, 3]}
        assert sensors.n_beams(sensor) == beam_pattern(sensor).n_beams, name


def _ring(sensor, fov):
    """A test pattern: ``beams`` beams on a circle of the field of view's azimuth half-extent."""
    angle = np.linspace(0.0, 2.0 * np.pi, int(sensor["beams"]), endpoint=False)
    return fov[1] * np.cos(angle), fov[1] * np.sin(angle)


@pytest.fixture
def ring_pattern(monkeypatch):
    """Register a new pattern the way a pattern module would: one ``register`` call."""
    monkeypatch.setitem(sensors.PATTERNS, "ring", None)   # removed again after the test
    return sensors.register(Pattern("ring", _ring, lambda sensor: int(sensor["beams"]),
                                    keys=("field_of_view_deg", "beams")))


def test_a_registered_pattern_is_checked_costed_and_simulated(tmp_path, ring_pattern):
    overrides = ("sensor.pattern=ring", "sensor.beams=6", "sensor.field_of_view_deg=[8, 8]",
                 "time.duration=30")
    scene = load_scene("asteroid-lrf", list(overrides))
    assert scene.cost.beams == 6
    summary, path = run_scene(tmp_path, "asteroid-lrf", *overrides)
    assert summary["pattern"] == "ring" and summary["beams"] == 6
    with StrikeLog(path) as log:
        sensor, n_strikes = log.sensor, log.n_strikes
    # A pattern formats/SPEC.md does not name is recorded as "custom", with its beams.
    assert sensor.pattern == "custom" and not sensor.reports_angles
    assert np.allclose(sensor.beam_directions, beam_pattern(scene.values["sensor"]).directions)
    off_boresight = [_angle_deg([0, 0, 1], d) for d in sensor.beam_directions]
    assert off_boresight == pytest.approx([4] * 6, abs=0.01)
    assert n_strikes > 0
    # The keys it does not read are refused, and the others' patterns still refuse its keys.
    with pytest.raises(SceneError, match=r"sensor.resolution is only used when sensor.pattern "
                                         r'is "grid", not "ring"'):
        load_scene("asteroid-lrf", [*overrides, "sensor.resolution=[2, 2]"])
    with pytest.raises(SceneError, match=r'sensor.beams is only used when sensor.pattern is '
                                         r'"zigzag" or "ring", not "cross"'):
        load_scene("asteroid-lrf", ["sensor.pattern=cross", "sensor.beams=3"])


def test_an_unknown_pattern_names_the_registered_ones():
    with pytest.raises(SceneError, match=r"sensor.pattern must be one of single, cross, zigzag, "
                                         r"grid, got 'ring'"):
        load_scene("asteroid-lrf", ["sensor.pattern=ring"])
