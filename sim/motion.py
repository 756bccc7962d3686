"""Where the chaser is and where everything points, at any batch of times.

Frames (formats/SPEC.md): B is the target body frame, I the target-centred inertial frame (z the
target's spin axis at t = 0 for the default attitude), S the sensor frame (+z boresight, +x
azimuth, +y elevation).

- **Target attitude**: a uniform spin about a body-fixed axis ``a_B``::

      R_BI(t) = R_BI(0) Rot(a_B, 2 pi t / P)

  so the spin axis is fixed in both frames (``R_BI(0) a_B`` in I).
- **Orbit**: circular Keplerian about the target centre, with its elements measured in the
  target's equatorial frame Q (z along the spin axis in I; Q = I for the default attitude).
  An inclination change is made at the first node crossing at or after ``change_time``: there a
  single impulse rotates the orbit plane about the line of nodes, keeping radius, node and the
  argument of latitude continuous (the cheapest way to change inclination alone).
- **Sensor attitude**: nominal pointing puts the boresight on the target centre with
  ``+z_S = -r`` (nadir), ``+x_S`` along-track and ``+y_S = z_S x x_S`` (minus the orbit normal);
  an optional slew ``theta(t) = A sin(2 pi t / P_s + phi)`` turns the sensor about a fixed axis of
  that nominal frame. About ``+x_S`` (the default) the boresight swings in the plane normal to the
  orbit plane, as in the paper.
- **From SPICE kernels** (``[orbit] kind = "spice"``, :class:`SpiceGeometry`): the chaser's
  position and velocity relative to the target (``spkezr``, geometric), the target attitude from
  its body-fixed frame and, when a sensor frame is named, the sensor attitude (``pxform``), at
  ``ET = start + t``. Without a sensor frame the nominal pointing above (and the slew) applies
  to the kernels' trajectory. One ``spkezr`` and one or two ``pxform`` calls a shot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from formats import spice


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def target_attitude(t: np.ndarray, *, spin_period: float, spin_axis, attitude) -> Rotation:
    """Target attitude at times ``t``.

    Parameters
    ----------
    t : (n,) float64, seconds
    spin_period : float, seconds (``inf``: no spin)
    spin_axis : 3 floats, body frame B (normalised here)
    attitude : 4 floats, quaternion (x, y, z, w), B->I at t = 0

    Returns
    -------
    Rotation of length n that sends B vectors to I.
    """
    initial = Rotation.from_quat(attitude)
    if math.isinf(spin_period):
        return initial * Rotation.from_rotvec(np.zeros((len(t), 3)))
    angle = (2.0 * math.pi / spin_period) * np.asarray(t, dtype=np.float64)
    return initial * Rotation.from_rotvec(angle[:, None] * _unit(spin_axis))


def equatorial_frame(spin_axis_inertial) -> np.ndarray:
    """Columns (3, 3): the axes of the equatorial frame Q expressed in I (sends Q to I).

    ``z_Q`` is the spin axis; ``x_Q`` is the projection of ``x_I`` on the equator (of ``y_I``
    when the spin axis is within 25 deg of ``x_I``). For a spin axis along ``z_I``, Q = I.
    """
    z = _unit(spin_axis_inertial)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = _unit(helper - np.dot(helper, z) * z)
    return np.stack([x, np.cross(z, x), z], axis=1)


@dataclass(frozen=True)
class Orbit:
    """A circular orbit about the target centre, with an optional inclination change.

    Attributes
    ----------
    radius : float, metres
    mu : float, m^3/s^2
    inclination, node, phase : float, radians
        Inclination to the equatorial plane, longitude of the ascending node and argument of
        latitude at t = 0, all in the equatorial frame Q.
    frame : (3, 3) float64
        Sends Q vectors to I (:func:`equatorial_frame`).
    change_time : float or None, seconds
        Requested time of the inclination change.
    change_inclination : float or None, radians
    """

    radius: float
    mu: float
    inclination: float
    node: float
    phase: float
    frame: np.ndarray
    change_time: float | None = None
    change_inclination: float | None = None

    @property
    def mean_motion(self) -> float:
        """Angular rate [rad/s]."""
        return math.sqrt(self.mu / self.radius ** 3)

    @property
    def maneuver_time(self) -> float | None:
        """Time [s] of the inclination change: the first node crossing at or after change_time."""
        if self.change_time is None:
            return None
        n = self.mean_motion
        k = math.ceil((self.phase + n * self.change_time) / math.pi - 1e-12)
        return (k * math.pi - self.phase) / n

    def state(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position and along-track direction at times ``t``.

        Parameters
        ----------
        t : (n,) float64, seconds

        Returns
        -------
        position : (n, 3) float64, metres, inertial frame I
        along_track : (n, 3) float64, unit vectors in I (direction of motion)
        """
        t = np.asarray(t, dtype=np.float64)
        u = self.phase + self.mean_motion * t
        inc = np.full_like(t, self.inclination)
        t_change = self.maneuver_time
        if t_change is not None:
            inc[t >= t_change] = self.change_inclination
        cu, su = np.cos(u), np.sin(u)
        ci, si = np.cos(inc), np.sin(inc)
        co, so = math.cos(self.node), math.sin(self.node)
        r_hat = np.stack([co * cu - so * su * ci, so * cu + co * su * ci, su * si], axis=1)
        v_hat = np.stack([-co * su - so * cu * ci, -so * su + co * cu * ci, cu * si], axis=1)
        return self.radius * r_hat @ self.frame.T, v_hat @ self.frame.T


def nominal_sensor_attitude(position: np.ndarray, along_track: np.ndarray) -> np.ndarray:
    """Boresight on the target centre: matrices (n, 3, 3) that send S vectors to I.

    Columns are the sensor axes in I: ``x_S`` along-track, ``y_S = z_S x x_S``, ``z_S`` from the
    sensor to the target centre.

    Parameters
    ----------
    position : (n, 3) float64, metres, I
    along_track : (n, 3) float64, unit vectors in I, perpendicular to ``position``
    """
    z = -position / np.linalg.norm(position, axis=1, keepdims=True)
    x = along_track
    return np.stack([x, np.cross(z, x), z], axis=2)


def slew_rotation(t: np.ndarray, *, amplitude: float, period: float, axis,
                  phase: float) -> Rotation:
    """The sinusoidal slew, a rotation of the sensor about ``axis`` of its nominal frame.

    Parameters
    ----------
    t : (n,) float64, seconds
    amplitude, phase : float, radians
    period : float, seconds
    axis : 3 floats, nominal sensor frame (normalised here)

    Returns
    -------
    Rotation of length n that sends S vectors to the nominal sensor frame.
    """
    angle = amplitude * np.sin(2.0 * math.pi * np.asarray(t, np.float64) / period + phase)
    return Rotation.from_rotvec(angle[:, None] * _unit(axis))


@dataclass
class SpiceGeometry:
    """Positions and attitudes read from SPICE kernels, with :class:`Orbit`'s ``state``.

    Attributes
    ----------
    kernels : list of str
        Files loaded by :meth:`open` (SPK, CK, FK, SCLK, PCK, meta-kernels).
    observer, target : str
        NAIF names or IDs of the sensor and of the target centre (the origin of I and B).
    inertial_frame : str
        The log's inertial frame I.
    target_frame : str
        The target's body-fixed frame B.
    sensor_frame : str or None
        The sensor frame S (+z the boresight); None: nominal pointing from the trajectory.
    epoch_et : float
        ET [s, TDB past J2000] of t = 0.
    """

    kernels: list
    observer: str
    target: str
    inertial_frame: str
    target_frame: str
    sensor_frame: str | None
    epoch_et: float
    _loaded: object = field(default=None, repr=False)

    maneuver_time = None   # no impulse of recon's own: whatever the kernels hold is flown

    def open(self) -> SpiceGeometry:
        """Load the kernels (until :meth:`close`)."""
        if self._loaded is None:
            self._loaded = spice.loaded(self.kernels, "orbit.kernels")
            self._loaded.__enter__()
        return self

    def close(self) -> None:
        """Unload the kernels."""
        if self._loaded is not None:
            loaded, self._loaded = self._loaded, None
            loaded.__exit__(None, None, None)

    def _et(self, t) -> np.ndarray:
        return self.epoch_et + np.asarray(t, dtype=np.float64)

    def state(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position and along-track direction at times ``t``, as :meth:`Orbit.state`.

        Parameters
        ----------
        t : (n,) float64, seconds since the first shot

        Returns
        -------
        position : (n, 3) float64, metres, inertial frame I
        along_track : (n, 3) float64, unit vectors in I: the velocity's part perpendicular to
            the position (any perpendicular direction where the chaser hovers)
        """
        position, velocity = spice.states(self.observer, self.target, self.inertial_frame,
                                          self._et(t))
        r_hat = position / np.linalg.norm(position, axis=1, keepdims=True)
        along = velocity - np.einsum("ij,ij->i", velocity, r_hat)[:, None] * r_hat
        norm = np.linalg.norm(along, axis=1)
        still = norm <= 1e-12 * np.maximum(np.linalg.norm(velocity, axis=1), 1.0)
        if still.any():
            helper = np.where((np.abs(r_hat[still, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0],
                              [0.0, 1.0, 0.0])
            along[still] = np.cross(r_hat[still], helper)
            norm[still] = np.linalg.norm(along[still], axis=1)
        return position, along / norm[:, None]

    def target_attitude(self, t: np.ndarray) -> Rotation:
        """Rotation of length n that sends B vectors to I at times ``t`` [s]."""
        return Rotation.from_matrix(spice.rotations(self.target_frame, self.inertial_frame,
                                                    self._et(t)))

    def sensor_attitude(self, t: np.ndarray) -> np.ndarray:
        """Matrices (n, 3, 3) that send S vectors to I at times ``t`` [s] (needs
        ``sensor_frame``)."""
        return spice.rotations(self.sensor_frame, self.inertial_frame, self._et(t))
