"""Pose-knowledge error models: the poses a chaser records are not quite the poses it had.

The paper registers strikes "with a priori knowledge of the RSO attitude" and leaves pointing
knowledge open; real missions could not (NEAR's laser rangefinder and OSIRIS-REx's OLA needed
crossover and pointing adjustments). These models change only what the log records in
``/shots``; ``/truth`` keeps the true poses (formats/SPEC.md, /sensor/errors). With ``t`` a
shot's time and ``t' = t + time_tag_offset``:

- **sensor attitude**: ``R_SI_recorded = R_SI(t') E Rot(b + w(t))``. ``E`` is the boresight
  misalignment, a constant rotation of the sensor against where its mounting is believed to
  be; ``b`` a constant attitude-knowledge bias and ``w`` a random walk (an independent Wiener
  process per axis, 1-sigma ``attitude_walk * sqrt(t)``), both rotation vectors in S, as a
  star tracker's slowly wandering error. A constant bias in S is indistinguishable from a
  misalignment; both are kept because missions budget them separately.
- **chaser position**: ``r_recorded = r(t') + F(t) (p + g(t))``, ``F`` the local orbital frame
  of the true orbit (radial, along-track, cross-track: how relative navigation states its
  errors), ``p`` a constant bias and ``g`` a first-order Gauss-Markov process (stationary
  1-sigma ``position_drift`` per axis, correlation time ``position_drift_time``). The white
  per-shot error ``position_sigma3`` (sim/noise.py) adds to this, and so does a constant bias
  in the inertial frame, ``position_bias_inertial`` (a target ephemeris error when the chaser's
  own orbit is known inertially).
- **target attitude**: recorded from the spin model with the known spin axis (the true one
  tilted by ``spin_axis_error`` about a direction drawn from the seed) and the known period
  (true plus ``spin_period_error``), at ``t'``; the attitude at ``t = 0`` is known.
- **time tags**: every recorded pose is the true pose at ``t'``.

The walk and the drift depend on the whole history, so they are drawn once for all the shots of
the campaign (each from its own stream, sim/noise.py) when the run is planned: the same seed
gives the same errors whatever the chunking, and switching one model on leaves the others'
draws unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from formats.strike_log import SensorErrors
from sim import noise
from sim.motion import Orbit, SpiceGeometry, target_attitude

# A pose function: true (position (n, 3) m in I, target Rotation B->I, sensor (n, 3, 3) S->I)
# at times (n,) s; sim/pipeline.py's ``poses``.
PoseFunction = Callable[[np.ndarray], tuple[np.ndarray, Rotation, np.ndarray]]


@dataclass(frozen=True)
class PoseKnowledge:
    """The pose-knowledge errors of one run, drawn for every shot.

    Attributes
    ----------
    errors : SensorErrors
        The models and their sizes (SI units).
    attitude : (n_shots, 3) float64, radians, rotation vectors in S
        ``b + w(t)`` of every shot.
    position : (n_shots, 3) float64, metres, (radial, along-track, cross-track)
        ``p + g(t)`` of every shot.
    spin : dict or None
        The known spin (``spin_period``, ``spin_axis`` in B, ``attitude`` at t = 0), as
        ``sim.motion.target_attitude`` takes it; None for a SPICE-driven target, whose attitude
        is known as the kernels give it.
    orbit : Orbit or sim.motion.SpiceGeometry
        The true orbit, whose local frame the position error is stated in.
    """

    errors: SensorErrors
    attitude: np.ndarray
    position: np.ndarray
    spin: dict | None
    orbit: Orbit | SpiceGeometry


def random_walk(sigma_rate: float, step: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """Three independent Wiener processes sampled every ``step``, zero at the first sample.

    Parameters
    ----------
    sigma_rate : float, unit per sqrt(second)
    step : float, seconds
    n : int
    rng : numpy.random.Generator

    Returns
    -------
    (n, 3) float64: 1-sigma ``sigma_rate * sqrt(k * step)`` at sample ``k``.
    """
    increments = rng.normal(0.0, sigma_rate * math.sqrt(step), (n, 3))
    increments[0] = 0.0
    return np.cumsum(increments, axis=0)


def gauss_markov(sigma: float, correlation_time: float, step: float, n: int,
                 rng: np.random.Generator) -> np.ndarray:
    """Three independent stationary first-order Gauss-Markov processes, sampled every ``step``.

    The exact discretisation ``g[k+1] = phi g[k] + sqrt(1 - phi^2) sigma e[k]``, ``phi =
    exp(-step / tau)``, started from the stationary distribution.

    Parameters
    ----------
    sigma : float
        Stationary 1-sigma, any unit.
    correlation_time : float, seconds
    step : float, seconds
    n : int
    rng : numpy.random.Generator

    Returns
    -------
    (n, 3) float64, the unit of ``sigma``.
    """
    from scipy.signal import lfilter  # scipy.signal takes most of a second to import

    phi = math.exp(-step / correlation_time)
    drive = rng.standard_normal((n, 3)) * sigma
    drive[1:] *= math.sqrt(1.0 - phi * phi)
    return lfilter([1.0], [1.0, -phi], drive, axis=0)


def known_spin_axis(axis, tilt: float, rng: np.random.Generator) -> np.ndarray:
    """The spin axis tilted by ``tilt`` [rad] toward a direction drawn uniformly about it.

    Parameters
    ----------
    axis : 3 floats, body frame B (normalised here)
    tilt : float, radians
    rng : numpy.random.Generator

    Returns
    -------
    (3,) float64 unit vector, B.
    """
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(a, helper)
    u /= np.linalg.norm(u)
    hinge = Rotation.from_rotvec(rng.uniform(0.0, 2.0 * math.pi) * a).apply(u)
    return Rotation.from_rotvec(tilt * hinge).apply(a)


def plan_knowledge(errors: SensorErrors, *, seed: int, n_shots: int, step: float, spin: dict,
                   orbit: Orbit) -> PoseKnowledge | None:
    """Draw the pose-knowledge errors of a whole run (None when every model is off).

    Parameters
    ----------
    errors : SensorErrors
    seed : int
    n_shots : int
    step : float, seconds between shots
    spin : dict
        The true spin (``spin_period``, ``spin_axis``, ``attitude``).
    orbit : Orbit
    """
    if not errors.pose:
        return None
    attitude = np.broadcast_to(np.asarray(errors.attitude_bias, dtype=np.float64),
                               (n_shots, 3)).copy()
    if errors.attitude_walk > 0:
        attitude += random_walk(errors.attitude_walk, step, n_shots,
                                noise.stream(seed, noise.STREAM_ATTITUDE_WALK, 0))
    position = np.broadcast_to(np.asarray(errors.position_bias, dtype=np.float64),
                               (n_shots, 3)).copy()
    if errors.position_drift > 0:
        position += gauss_markov(errors.position_drift, errors.position_drift_time, step,
                                 n_shots, noise.stream(seed, noise.STREAM_POSITION_DRIFT, 0))
    if spin is None:   # SPICE-driven: the target attitude is known as the kernels give it
        return PoseKnowledge(errors=errors, attitude=attitude, position=position, spin=None,
                             orbit=orbit)
    known = dict(spin)
    if errors.spin_axis_error > 0:
        known["spin_axis"] = known_spin_axis(spin["spin_axis"], errors.spin_axis_error,
                                             noise.stream(seed, noise.STREAM_SPIN_AXIS, 0))
    known["spin_period"] = spin["spin_period"] + errors.spin_period_error
    return PoseKnowledge(errors=errors, attitude=attitude, position=position, spin=known,
                         orbit=orbit)


def orbital_frame(orbit: Orbit, t: np.ndarray) -> np.ndarray:
    """Local orbital frames (n, 3, 3) at times ``t``: columns radial, along-track, cross-track
    (unit vectors in I); multiplied by a (radial, along, cross) vector it gives I."""
    position, along = orbit.state(t)
    radial = position / np.linalg.norm(position, axis=1, keepdims=True)
    return np.stack([radial, along, np.cross(radial, along)], axis=2)


def record(knowledge: PoseKnowledge, first: int, t: np.ndarray, pose_at: PoseFunction
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The recorded poses of shots ``first .. first + len(t) - 1``.

    Parameters
    ----------
    knowledge : PoseKnowledge
    first : int
        Index of the first shot (row of ``knowledge.attitude`` and ``.position``).
    t : (n,) float64, seconds, the shots' times
    pose_at : callable
        True poses at given times (sim/pipeline.py ``poses``).

    Returns
    -------
    position : (n, 3) float64, metres, I
    sensor_attitude : (n, 4) float64, quaternion (x, y, z, w), S->I
    target_attitude : (n, 4) float64, quaternion (x, y, z, w), B->I
    """
    e = knowledge.errors
    tagged = t + e.time_tag_offset
    position, true_target, sensor = pose_at(tagged)
    rows = slice(first, first + len(t))
    position = (position + np.asarray(e.position_bias_inertial)
                + np.einsum("nij,nj->ni", orbital_frame(knowledge.orbit, t),
                            knowledge.position[rows]))
    error = (Rotation.from_rotvec(np.asarray(e.boresight_misalignment))
             * Rotation.from_rotvec(knowledge.attitude[rows]))
    sensor = (Rotation.from_matrix(sensor) * error).as_quat()
    target = (true_target if knowledge.spin is None else
              target_attitude(tagged, **knowledge.spin)).as_quat()
    return position, sensor, target
