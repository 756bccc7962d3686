"""Target spin, chaser orbit and sensor pointing against hand-computed geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sim import motion


def _orbit(**kwargs) -> motion.Orbit:
    base = {"radius": 750.0, "mu": 2.0, "inclination": math.radians(85.0), "node": 0.0,
            "phase": 0.0, "frame": np.eye(3)}
    return motion.Orbit(**(base | kwargs))


def test_target_spins_about_body_z_with_the_papers_period():
    t = np.array([0.0, 15480.0 / 4, 15480.0])
    rot = motion.target_attitude(t, spin_period=15480.0, spin_axis=[0, 0, 1],
                                 attitude=[0, 0, 0, 1])
    # A quarter turn sends body x to inertial y (counter-clockwise about +z).
    assert np.allclose(rot[1].apply([1, 0, 0]), [0, 1, 0], atol=1e-12)
    assert np.allclose(rot[2].as_matrix(), np.eye(3), atol=1e-12)
    assert np.allclose(rot[0].as_matrix(), np.eye(3))


def test_any_spin_axis_and_initial_attitude():
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    q0 = Rotation.from_euler("xyz", [10, -20, 30], degrees=True)
    t = np.array([0.0, 250.0, 5000.0])
    rot = motion.target_attitude(t, spin_period=1000.0, spin_axis=axis, attitude=q0.as_quat())
    # The spin axis keeps its inertial direction; whole periods later the attitude repeats.
    assert np.allclose(rot.apply(axis), q0.apply(axis), atol=1e-12)
    assert np.allclose(rot[2].as_matrix(), q0.as_matrix(), atol=1e-9)
    # A quarter period later: a quarter turn about the body axis, after the initial attitude.
    quarter = q0 * Rotation.from_rotvec(axis * math.pi / 2)
    assert np.allclose(rot[1].as_matrix(), quarter.as_matrix(), atol=1e-12)
    still = motion.target_attitude(t, spin_period=math.inf, spin_axis=axis, attitude=q0.as_quat())
    assert np.allclose(still.as_matrix(), q0.as_matrix())


def test_circular_orbit_radius_period_inclination_node():
    orbit = _orbit(node=math.radians(30.0), phase=0.3)
    period = 2 * math.pi / orbit.mean_motion
    t = np.linspace(0.0, period, 101)
    r, v = orbit.state(t)
    assert np.allclose(np.linalg.norm(r, axis=1), 750.0)
    assert np.allclose(r[0], r[-1], atol=1e-9)
    normal = np.cross(r[:-1], r[1:])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    assert np.allclose(np.degrees(np.arccos(normal[:, 2])), 85.0)
    # Ascending node: the orbit crosses z = 0 going up at longitude 30 deg.
    crossing = np.cross([0, 0, 1], normal[0])
    assert np.degrees(math.atan2(crossing[1], crossing[0])) == pytest.approx(30.0)
    # Along-track is the unit velocity: perpendicular to r, matching a finite difference.
    assert np.allclose(np.einsum("ij,ij->i", r, v), 0.0, atol=1e-9)
    dt = 1e-3
    fd = (orbit.state(t + dt)[0] - orbit.state(t - dt)[0]) / (2 * dt)
    assert np.allclose(fd / np.linalg.norm(fd, axis=1, keepdims=True), v, atol=1e-6)
    assert np.allclose(np.linalg.norm(fd, axis=1), math.sqrt(2.0 / 750.0), rtol=1e-6)


def test_inclination_change_at_the_next_node_keeps_position():
    orbit = _orbit(change_time=20000.0, change_inclination=math.radians(76.0))
    tc = orbit.maneuver_time
    half = math.pi / orbit.mean_motion
    assert 20000.0 <= tc < 20000.0 + half
    r_before, _ = orbit.state(np.array([tc - 1e-6]))
    r_at, _ = orbit.state(np.array([tc]))
    assert abs(r_at[0, 2]) < 1e-6                       # at a node
    assert np.allclose(r_before, r_at, atol=1e-3)       # no jump
    for t0, inc in ((tc - 4 * half / 3, 85.0), (tc + half / 3, 76.0)):
        r, _ = orbit.state(np.array([t0, t0 + 100.0]))
        n = np.cross(r[0], r[1])
        assert np.degrees(np.arccos(n[2] / np.linalg.norm(n))) == pytest.approx(inc)


def test_orbit_elements_follow_a_tilted_spin_axis():
    spin_axis = np.array([0.0, math.sin(0.4), math.cos(0.4)])
    orbit = _orbit(frame=motion.equatorial_frame(spin_axis))
    r, _ = orbit.state(np.array([0.0, 100.0]))
    n = np.cross(r[0], r[1])
    assert math.degrees(math.acos(np.dot(n, spin_axis) / np.linalg.norm(n))) == pytest.approx(85.0)
    assert np.allclose(motion.equatorial_frame([0, 0, 1]), np.eye(3))


def test_nominal_pointing_is_right_handed_with_boresight_on_the_centre():
    orbit = _orbit()
    r, v = orbit.state(np.linspace(0, 50000, 9))
    m = motion.nominal_sensor_attitude(r, v)
    assert np.allclose(np.linalg.det(m), 1.0)
    assert np.allclose(m @ m.transpose(0, 2, 1), np.eye(3), atol=1e-12)
    assert np.allclose(m[:, :, 2], -r / 750.0)       # +z_S on the target centre
    assert np.allclose(m[:, :, 0], v)                # +x_S along-track


def test_slew_swings_the_boresight_normal_to_the_orbit_plane():
    orbit = _orbit()
    t = np.arange(0.0, 1000.0, 5.0)
    r, v = orbit.state(t)
    m = motion.nominal_sensor_attitude(r, v) @ motion.slew_rotation(
        t, amplitude=math.radians(2.0), period=125.0, axis=[1, 0, 0], phase=0.0).as_matrix()
    boresight = m[:, :, 2]
    off = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", boresight, -r / 750.0), -1, 1)))
    assert off.max() == pytest.approx(2.0, abs=0.01)
    expected = 2.0 * np.abs(np.sin(2 * math.pi * t / 125.0))
    assert np.allclose(off, expected, atol=1e-6)
    # The swing stays in the plane spanned by nadir and the orbit normal.
    assert np.allclose(np.einsum("ij,ij->i", boresight, v), 0.0, atol=1e-12)
