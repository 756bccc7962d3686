"""Self-calibration of pose knowledge from the strikes alone: ``recon ingest LOG --refine``.

A constant pose-knowledge error (a boresight misalignment, a position bias) moves every strike
of a pass the same way in the sensor's or the inertial frame, but those frames turn against the
body frame as the chaser orbits and the target spins. Passes that see the same patch of surface
from different geometry therefore place it in different places, and the disagreement says which
error it was: the crossover adjustment with which NEAR's laser rangefinder and OSIRIS-REx's OLA
data were corrected.

Coarse first (``_coarse_start``): a spinning target turns a constant inertial position bias in
the body frame, so passes at different spin phases place a surface up to twice the bias apart,
beyond the fine neighbourhoods, and a fit from the recorded poses does not leave their basin
(RSO-A: 1 m found as 0.03 m). Short fits (the steps below) of every ``COARSE_THIN``-th strike,
whose neighbourhoods are about three times as wide, start from each node of a grid of biases
across the spin axis; the end whose residuals scatter least starts the fine fit. Then,
repeatedly until the corrections stop moving the points (``STOP_MOVE_M``):

1. register a seeded sample of strikes with the recorded poses, corrected by the current
   estimate (none at first);
2. compare each point with the consensus of the other passes around it: the centroid of its
   nearest points taken ``PAIR_GAP_STEPS`` shots or more away (never its own track), along the
   normal of the local plane of the consensus cloud, ``r = n . (p - c)``, where that plane faces
   the point's sensor (``MIN_FACING``; a neighbourhood not much wider than the range noise has
   its least-squares normal across the beam, and residuals along it reward smearing surfaces
   along the line of sight);
3. take a robust Gauss-Newton step on every parameter (Huber-weighted least squares; the point
   and the centroid both move with the parameters; a weak prior holds at zero what the data
   cannot see).

The guard: a step can make the passes agree worse (beyond the capture range of the linearised
consensus, about 0.1 deg on RSO-A), and a fit can explain range noise (a short noisy log "found"
0.12 deg where there was none). So the result is never simply the last iterate:

4. the estimate is the iterate, the zero correction (the recorded poses) among them, with the
   lowest mean loss of the fitted strikes' residuals (Huber, capped at ``OUTLIER_SIGMAS``; a
   strike without a consensus scores the cap);
5. when the observable parameters together lie beyond their uncertainty (chi-square, one-sided
   ``SIGNIFICANCE_Z``-sigma), the whole estimate is kept: parameters that trade off against each
   other are each uncertain, their combination is not; otherwise a parameter is kept only if
   observable and larger than ``SIGNIFICANCE_Z`` of its 1-sigma;
6. the kept correction is applied only if a second, disjoint sample of strikes, which the fit
   never saw (independent range noise, so no noise the fit explained can help it), agrees with
   the other passes better with it than with the recorded poses by more than ``SIGNIFICANCE_Z``
   cluster-robust standard errors. Otherwise the correction is exactly zero and the cloud is
   registered with the recorded poses, bit for bit.

Parameters not kept are reported as 0, ``[not observable]`` or ``[not significant]``; one the data
see only together with another, applied with it, as ``[not observable alone]``.

Parameters (misalignment and position piecewise-linear in time over knots ``interval`` seconds
apart, or constant):

- ``misalignment``: a rotation vector in S; the true sensor attitude is the recorded one times
  its inverse: a boresight misalignment plus any constant attitude bias, which no data can tell
  apart. About a single beam's own axis it moves no strike: not observable, reported so.
- ``position``: the recorded sensor position minus the true one, in the inertial frame I (a
  target ephemeris error). Along the spin axis it shifts the whole cloud: not observable.
- ``spin_rate`` (constant): the true spin rate minus that of the recorded target attitudes,
  about the axis they turn about; the attitude at ``t = 0`` is taken as known.

What the data cannot separate, for a single beam looking at the target's centre: a position error
in the orbital frame is, at range ``rho``, the displacement of a misalignment of ``error / rho``
(only the spread of the range tells them apart), so a cross-track misalignment trades off against
a position error along the orbit normal (their estimates move together, and their uncertainties
say so), and a radial position error is a range bias, which only scales the cloud. Neither is a
parameter here; an orbital-frame error ends up in the misalignment estimate, which still corrects
the cloud.

Each estimate comes with its 1-sigma uncertainty from the cluster-robust (sandwich) covariance
of the Huber-weighted fit (prior included): neighbouring residuals share points, so they are
summed per cell of a few neighbourhoods before their scatter is taken (the formal, independent
residuals' uncertainty was 1.6 to 3 times smaller on the benchmark's logs); an unobservable
parameter keeps its prior's sigma. The log's ``/truth`` group is never read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from scipy.stats import chi2, norm

from formats import Shots, StrikeChunk, StrikeLog
from formats.errors import InputError, ParameterError
from formats.memory import check_memory

# Strikes sampled for the estimate (seeded, uniform): 30,000 of the demo's 77,400 estimate a
# misalignment to ~0.002 deg; more adds little to a handful of parameters and costs time. The
# correction is applied to every strike.
MAX_POINTS = 30_000
# Other passes are this many shots away: a single-beam track advances ~0.6 m per 10 s shot on
# the paper's asteroid, so 30 shots keep every consensus point off the point's own track.
PAIR_GAP_STEPS = 30
# Nearest neighbours of each point: its plane, and the other-pass points of its consensus. 32
# neighbours span several single-beam tracks (recon/surfaces/normals.py: 98.5 % of the normals
# agree in sign with the truth at 64, 93.9 % at 32).
NEIGHBOURS = 32
# Fewest other-pass neighbours that make a consensus, and fewest consensus points to refine.
MIN_CONSENSUS = 3
MIN_ROWS = 50
# Other-pass neighbours farther than this multiple of the median distance to the nearest one are
# left out of the consensus (the local plane no longer describes them).
PAIR_DISTANCE_FACTOR = 3.0
# The local plane must face the strike's sensor: its normal at most acos(MIN_FACING) = 72.5
# deg from the line of sight. On the generated satellites at 250 m, 32 neighbours span ~0.25 m, not
# much more than the 0.1 m (1 sigma) range noise along the beam, and where the noise dominates,
# the least-squares normal lies across the beam: residuals along it ignore the range and measure
# sideways offsets, which a runaway misalignment (a 0.5 deg one "corrected" to -2.15 deg on
# satellite seed 1) reduces by smearing surfaces into curtains along the line of sight.
MIN_FACING = 0.3
# Weak priors (1 sigma) that hold parameters the data cannot see at zero: a degree of attitude,
# 10 m of position, 0.1 % of the spin rate; each far above what the data resolve when they can.
PRIOR_ATTITUDE_RAD = math.radians(1.0)
PRIOR_POSITION_M = 10.0
PRIOR_SPIN_FRACTION = 1e-3
# A parameter is "observable" when the data shrink its prior uncertainty at least this much.
OBSERVABLE_SHRINK = 0.5
# ... and "seen at all" (if only together with another parameter) when they shrink it at all,
# below this fraction: what the data do not see at all stays 0.
SEEN_SHRINK = 0.99
# Outer iterations: stop when no sampled point moves more than STOP_MOVE_M further.
MAX_ITERATIONS = 15
STOP_MOVE_M = 5e-3
# Residuals this many robust sigmas from the median are left out of a step (consensus across an
# edge, planes across a thin part); the Huber weights weigh down the rest.
OUTLIER_SIGMAS = 4.0
# Robust steps: Huber weights beyond this many residual sigmas, reweighted this often.
HUBER_SIGMAS = 1.5
IRLS_ITERATIONS = 5
# Parameter combinations that move the residuals less than this fraction as much as the best
# determined one are not stepped along: on RSO-A at 250 m the range varies by ~4 %, too little to
# separate a cross-track misalignment from a position error along the orbit normal, and noise
# drove the pair metres apart; on the asteroid (range 460 to 660 m) the pair stays above it.
WEAK_DIRECTION = 0.1
# The guard. A correction fitted to the range noise of the fitted strikes cannot make other
# strikes (independent noise) agree better, a real pose error's can: the estimate is kept only
# if the held-out strikes' mean loss (_loss) drops by more than this many standard errors (a
# one-sided 3-sigma test, 0.13 % false alarms), and each parameter only if it exceeds this many
# of its own 1-sigma. Neighbouring residuals share points, so standard errors sum the residuals
# per cubic cell CELL_NEIGHBOURHOODS times the distance to the NEIGHBOURS-th neighbour wide
# (cluster-robust; the cells are several neighbourhoods across, so few residuals share points
# across a cell's border).
SIGNIFICANCE_Z = 3.0
CELL_NEIGHBOURHOODS = 4.0
# Iterates farther than this many prior sigmas from zero (3 deg, 30 m) are no candidates: pass
# agreement has spurious minima far out. A 2,000-point fit of RSO-A at 0.5 deg ran to 7.4 deg,
# which smears the panels into curtains along the line of sight whose planes hold the range
# noise, and "agreed" to 0.02 m, below the noise; held-out strikes agree there too.
PLAUSIBLE_PRIORS = 3.0
# The coarse stage (_coarse_start): a grid of constant position biases across the spin axis,
# COARSE_POSITION_M either way in steps of COARSE_STEP_M, scored on every COARSE_THIN-th fitted
# strike with the loss at the scale of a step.
COARSE_POSITION_M = 2.0
COARSE_STEP_M = 1.0
COARSE_THIN = 10
COARSE_ITERATIONS = 6
# Ends of the coarse fits whose robust scatter lies within this many standard errors of the
# best's agree equally well; the standard error of a 1.4826-MAD sigma of n Gaussian residuals is
# MAD_ERROR * sigma / sqrt(n) (its asymptotic efficiency is 37 %: 1 / sqrt(2 * 0.37) = 1.17).
COARSE_TIE = 2.0
MAD_ERROR = 1.17
# Points per block of the consensus: (block, NEIGHBOURS, 3, 7) float64 is ~15 MB.
BLOCK = 4096
# Consistent 1.4826 * median absolute deviation: the 1-sigma of Gaussian residuals.
MAD_TO_SIGMA = 1.4826
# A spin slower than this many turns over the whole log is treated as no spin (no parameter).
MIN_SPIN_TURNS = 0.05
# Memory of a refinement, estimated before it starts (_check_size), in float64 values: per shot
# of the log (its 12 recorded values, read whole, and the checks' and spin_of's temporaries);
# (p, p) matrices _solve holds at once for p parameters.
SHOT_VALUES = 36
DENSE_MATRICES = 16
# Time of a refinement, estimated before it starts (``refine_seconds``). One Gauss-Newton step
# (``_descend``) of m sampled strikes with k knots (p = 6 k + 1 parameters) takes
#     m (STEP_POINT_S + STEP_KNOT_S k + STEP_PAIR_S p^2) + STEP_SQUARE_S p^2 + STEP_CUBE_S p^3
# seconds: the consensus of every strike (neighbours, planes) and its design (the hat weights of
# NEIGHBOURS neighbours per knot); the IRLS_ITERATIONS weighted normal matrices (m p^2); their
# eigen-decompositions, solves and products (p^3, and p^2 besides). A refinement takes at most
# MAX_ITERATIONS steps of its fitted strikes and, when the target spins, COARSE_ITERATIONS steps
# of every COARSE_THIN-th one from each of the coarse grid's 25 starts; the estimate counts them
# all (a fit of a few knots often stops after 3 or 4 fine steps). Measured on polyhedron-50m-lidar
# and satellite-j-cross (suite logs; docs/decisions.md, "the refinement's time estimate"):
# STEP_PAIR_S, STEP_SQUARE_S and STEP_CUBE_S fitted to the steps' dense algebra (``_solve``, the
# coarse and fine samples, p = 300 to 3,600), then STEP_POINT_S and STEP_KNOT_S to whole
# refinements at the defaults (medians of 3 runs, s; the model's in brackets):
#     knots                                   1          5         20         50        100
#     30,000 sampled strikes           11.6 (16)  16.3 (19)  33.6 (31)  57.2 (65)   124 (156)
#     10,000                            5.0 (5)    7.1 (6)   15.0 (11)  30.8 (28)  79.4 (85)
#     2,606 (satellite J)               2.0 (1)    3.4 (2)    5.7 (4)   17.1 (15)
# The model stays within 0.5 to 1.4 times these. Of 600 knots of 30,000 strikes (the most they
# can estimate) it makes 1.7 h, the coarse stage's solves most of it (38 s each measured at 3,600
# parameters, 32 s by the model). With other jobs on the machine runs took up to 2.7 times as
# long (the two BLAS threads wait for each other).
STEP_POINT_S = 1.7e-5
STEP_KNOT_S = 7.4e-7
STEP_PAIR_S = 7.9e-11
STEP_SQUARE_S = 5.3e-7
STEP_CUBE_S = 4.8e-10
# Estimates longer than this are said before the refinement starts (``announce``).
ANNOUNCE_S = 30.0
# Longest refinement accepted, by that estimate: a day. Hours are allowed: the most knots the
# default 30,000 strikes can estimate (MIN_ROWS a knot) take 1.7 h, so at the defaults the knot
# count is refused first. A stability sweep may take a week, but it keeps what it finished
# (--resume); a refinement stopped keeps nothing, and a day of it is more strikes
# (``max_points``) than a refinement needs, or an interval meant longer.
MAX_REFINE_S = 86400.0


def spin_of(shots: Shots) -> tuple[np.ndarray, float]:
    """Spin axis (3,) in B and rate [rad/s] of the recorded target attitudes (rate 0: no spin).

    From the rotation between consecutive recorded attitudes, ``R_BI(t_i)^T R_BI(t_i+1)``.
    """
    if len(shots) < 2:
        return np.array([0.0, 0.0, 1.0]), 0.0
    target = Rotation.from_quat(shots.target_attitude)
    turns = (target[:-1].inv() * target[1:]).as_rotvec()
    total = turns.sum(axis=0)
    span = float(shots.time[-1] - shots.time[0])
    angle = float(np.linalg.norm(total))
    if angle < MIN_SPIN_TURNS * 2.0 * math.pi or span <= 0:
        return np.array([0.0, 0.0, 1.0]), 0.0
    return total / angle, angle / span


@dataclass
class PoseCorrection:
    """Corrections of the recorded poses, piecewise-linear in time.

    Attributes
    ----------
    knots : (k,) float64, seconds
        Knot times (one knot: constant).
    misalignment : (k, 3) float64, radians, rotation vectors in S
    position : (k, 3) float64, metres, I: recorded sensor position minus the true one
    spin_rate : float, rad/s
        Added to the recorded spin rate about ``spin_axis``.
    spin_axis : (3,) float64, unit vector, B
    """

    knots: np.ndarray
    misalignment: np.ndarray
    position: np.ndarray
    spin_rate: float = 0.0
    spin_axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))

    def weights(self, t: np.ndarray) -> np.ndarray:
        """Hat-function weights (n, k) of times ``t`` [s]: linear between knots, constant
        beyond the ends."""
        k = len(self.knots)
        if k == 1:
            return np.ones((len(t), 1))
        x = np.interp(t, self.knots, np.arange(k, dtype=np.float64))
        low = np.clip(np.floor(x).astype(np.int64), 0, k - 2)
        frac = x - low
        w = np.zeros((len(t), k))
        rows = np.arange(len(t))
        w[rows, low] = 1.0 - frac
        w[rows, low + 1] = frac
        return w

    def is_zero(self) -> bool:
        """Whether the correction changes nothing (every parameter exactly 0)."""
        return not (self.misalignment.any() or self.position.any() or self.spin_rate)

    def correct(self, shots: Shots) -> Shots:
        """The shots with corrected poses (time unchanged); the same object when the correction
        is zero, so a log refined to nothing registers to the same bytes."""
        if len(shots) == 0 or self.is_zero():
            return shots
        w = self.weights(shots.time)
        position = shots.sensor_position - w @ self.position
        sensor = (Rotation.from_quat(shots.sensor_attitude)
                  * Rotation.from_rotvec(w @ self.misalignment).inv())
        target = Rotation.from_quat(shots.target_attitude)
        if self.spin_rate:
            target = target * Rotation.from_rotvec((self.spin_rate * shots.time)[:, None]
                                                   * self.spin_axis)
        return Shots(shots.time, position, sensor.as_quat(), target.as_quat())

    def correct_chunk(self, chunk: StrikeChunk) -> StrikeChunk:
        """A block of strikes with its shots' poses corrected."""
        return replace(chunk, shots=self.correct(chunk.shots))


@dataclass
class Refinement:
    """What the self-calibration estimated, with uncertainties, and how well the passes agree.

    Attributes
    ----------
    correction : PoseCorrection
    sigma : PoseCorrection
        1-sigma uncertainties of every parameter (same layout).
    observable : dict of str -> (k, 3) bool or bool
        Parameters the data constrain (uncertainty below half the prior's); the others are 0.
    significant : dict of str -> (k, 3) bool or bool
        Parameters the held-out strikes confirm; the others are 0 in ``correction``.
    check_z : float
        How much better the held-out strikes agree with the other passes under ``correction``
        than under the recorded poses, in standard errors (0: nothing confirmed, no correction).
    residual_before_m, residual_after_m : float
        Robust scatter (1.4826 MAD) of the fitted strikes' crossover residuals before and after.
    n_points, n_pairs, iterations : int
        Strikes fitted, of them compared with a consensus, Gauss-Newton steps.
    """

    correction: PoseCorrection
    sigma: PoseCorrection
    observable: dict
    significant: dict
    check_z: float
    residual_before_m: float
    residual_after_m: float
    n_points: int
    n_pairs: int
    iterations: int

    def to_dict(self) -> dict:
        """A JSON-ready summary: estimates and 1-sigma in degrees, metres and ppm."""
        c, s = self.correction, self.sigma
        out = {"knots_s": c.knots.tolist(),
               "misalignment_deg": np.degrees(c.misalignment).tolist(),
               "misalignment_sigma_deg": np.degrees(s.misalignment).tolist(),
               "misalignment_observable": self.observable["misalignment"].tolist(),
               "misalignment_significant": self.significant["misalignment"].tolist(),
               "position_bias_m": c.position.tolist(),
               "position_bias_sigma_m": s.position.tolist(),
               "position_observable": self.observable["position"].tolist(),
               "position_significant": self.significant["position"].tolist(),
               "spin_axis": c.spin_axis.tolist(), "spin_rate_rad_s": c.spin_rate,
               "spin_rate_sigma_rad_s": s.spin_rate,
               "spin_observable": bool(self.observable["spin"]),
               "spin_significant": bool(self.significant["spin"]), "check_z": self.check_z,
               "residual_before_m": self.residual_before_m,
               "residual_after_m": self.residual_after_m, "n_points": self.n_points,
               "n_pairs": self.n_pairs, "iterations": self.iterations}
        return out

    def lines(self) -> list[str]:
        """Human-readable lines: each estimate with its 1-sigma (constant part: the mean)."""
        c, s = self.correction, self.sigma
        out = [f"pass agreement (robust sigma of residuals to the other passes): "
               f"{self.residual_before_m:.3f} m -> {self.residual_after_m:.3f} m "
               f"({self.n_pairs:,} of {self.n_points:,} sampled points, "
               f"{self.iterations} iterations)",
               (f"held-out strikes agree better by {self.check_z:.1f} standard errors"
                if self.check_z else "held-out strikes confirm no correction: poses unchanged")]
        what = "constant" if len(c.knots) == 1 else f"mean of {len(c.knots)} knots"
        for axis, name in enumerate("xyz"):
            value = np.degrees(c.misalignment[:, axis]).mean()
            out.append(f"misalignment about S {name}: {value:+.5f} +/- "
                       f"{np.degrees(s.misalignment[:, axis]).mean():.5f} deg ({what})"
                       + self._flag("misalignment", axis))
        for axis, name in enumerate("xyz"):
            out.append(f"position bias along I {name}: {c.position[:, axis].mean():+.3f} +/- "
                       f"{s.position[:, axis].mean():.3f} m ({what})"
                       + self._flag("position", axis))
        if s.spin_rate:
            out.append(f"spin rate correction: {c.spin_rate:+.4g} +/- {s.spin_rate:.2g} rad/s"
                       + self._flag("spin"))
        return out

    def _flag(self, name: str, axis: int | None = None) -> str:
        """"  [not observable]", "  [not observable alone]" (applied: seen only together with
        another parameter), "  [not significant]" or nothing, for one parameter."""
        observable, significant = self.observable[name], self.significant[name]
        if axis is not None:
            observable, significant = observable[:, axis].any(), significant[:, axis].any()
        if not observable:
            return "  [not observable alone]" if significant else "  [not observable]"
        return "" if significant else "  [not significant]"


@dataclass
class _Sample:
    """The sampled strikes with their recorded shots, one row per strike."""

    time: np.ndarray        # (n,) s
    vector: np.ndarray      # (n, 3) m, S: range times measured direction
    shots: Shots            # recorded poses, one row per strike


def _samples(log: StrikeLog, max_points: int, seed: int) -> tuple[_Sample, _Sample]:
    """Two disjoint seeded uniform samples of strikes (recorded values only): at most
    ``max_points`` to fit and as many to check the fit. A log of fewer than twice
    ``max_points`` strikes is cut in two halves at random."""
    n = log.n_strikes
    if n >= 2 * max_points:
        fit = np.sort(np.random.default_rng(seed).choice(n, max_points, replace=False))
        rest = np.setdiff1d(np.arange(n), fit)
        check = np.sort(np.random.default_rng([seed, 1]).choice(rest, max_points,
                                                                replace=False))
    else:
        order = np.random.default_rng([seed, 1]).permutation(n)
        cut = (n + 1) // 2
        fit, check = np.sort(order[:cut]), np.sort(order[cut:])
    both = _sample(log, np.union1d(fit, check))
    at = np.searchsorted(np.union1d(fit, check), fit)
    mask = np.zeros(len(both.time), dtype=bool)
    mask[at] = True
    return _subset(both, mask), _subset(both, ~mask)


def _sample(log: StrikeLog, keep: np.ndarray) -> _Sample:
    """The strikes of sorted indices ``keep`` (recorded values only)."""
    parts = []
    for chunk in log.iter_chunks():
        rows = keep[(keep >= chunk.start) & (keep < chunk.start + len(chunk))] - chunk.start
        if not len(rows):
            continue
        r = chunk.shot[rows] - chunk.shot_offset
        s = chunk.shots
        parts.append((s.time[r], chunk.range[rows, None] * chunk.direction[rows],
                      s.sensor_position[r], s.sensor_attitude[r], s.target_attitude[r]))
    time, vector, position, sensor, target = (np.concatenate(p) for p in zip(*parts,
                                                                               strict=True))
    return _Sample(time, vector, Shots(time, position, sensor, target))


def _register(sample: _Sample, shots: Shots
              ) -> tuple[np.ndarray, np.ndarray, Rotation, Rotation]:
    """Body-frame points (n, 3) of the sample under ``shots``, their view points (n, 3) and
    the rotations."""
    sensor = Rotation.from_quat(shots.sensor_attitude)
    target = Rotation.from_quat(shots.target_attitude)
    to_body = target.inv()
    points = to_body.apply(shots.sensor_position + sensor.apply(sample.vector))
    return points, to_body.apply(shots.sensor_position), sensor, target


def _consensus(points: np.ndarray, view: np.ndarray, time: np.ndarray, gap: float,
               jac: np.ndarray | None = None, weights: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Each point against the consensus of the other passes around it, linearised.

    The consensus at point ``i`` is the centroid ``c_i`` of its ``NEIGHBOURS`` nearest points
    that belong to other passes (``gap`` seconds or more away), saw the surface from the same side
    as the point (so the two faces of a thin panel stay apart) and lie within
    ``PAIR_DISTANCE_FACTOR`` times the median distance to the nearest such point; the normal is
    that of the least-squares plane of all ``NEIGHBOURS`` (the consensus cloud), which must face
    the point's sensor by at least ``MIN_FACING`` (cosine). The residual is
    ``n . (p_i - c_i)``: the centroid surrounds the point, so an error of the normal barely
    matters. Both the point and the centroid move with the parameters.

    Returns
    -------
    rows : (m,) int64
        Points with a consensus.
    residual : (m,) float64, metres
    design : (m, p) float64 or None
        Change of each residual per unit of each parameter (None without ``jac``).
    """
    index, other, normal = _partners(points, view, time, gap)
    if not other.any():
        return (np.zeros(0, np.int64), np.zeros(0),
                None if jac is None else np.zeros((0, _n_params(jac, weights))))
    neighbours = points[index]                                                 # (n, k, 3)
    count = other.sum(axis=1)
    rows = np.flatnonzero(count >= MIN_CONSENSUS)
    residual = np.empty(len(rows))
    design = None if jac is None else np.empty((len(rows), _n_params(jac, weights)))
    for start in range(0, len(rows), BLOCK):
        r = rows[start:start + BLOCK]
        n_r = normal[r]
        share = other[r] / count[r][:, None]                                   # (b, k)
        centroid = np.einsum("bk,bki->bi", share, neighbours[r])
        residual[start:start + len(r)] = np.einsum("bi,bi->b", n_r, points[r] - centroid)
        if design is None:
            continue
        # How the point and the centroid move along this point's normal (the centroid's motion
        # exactly, so a translation of everything leaves the residual unchanged).
        own = np.einsum("bi,bij->bj", n_r, jac[r])                             # (b, g)
        theirs = np.einsum("bi,bkij->bkj", n_r, jac[index[r]])                 # (b, k, g)
        knots = (np.einsum("bK,bg->bKg", weights[r], own[:, :6])
                 - np.einsum("bk,bkK,bkg->bKg", share, weights[index[r]], theirs[:, :, :6]))
        spin = own[:, 6:] - np.einsum("bk,bkg->bg", share, theirs[:, :, 6:])
        design[start:start + len(r)] = np.concatenate(
            [knots[:, :, :3].reshape(len(r), -1), knots[:, :, 3:].reshape(len(r), -1), spin],
            axis=1)
    return rows, residual, design


def _partners(points: np.ndarray, view: np.ndarray, time: np.ndarray, gap: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which neighbours of each point make its consensus (``_consensus``).

    Parameters
    ----------
    points, view : (n, 3) float64, metres, B
        The points and their sensor positions.
    time : (n,) float64, seconds
    gap : float, seconds
        Other passes are at least this far apart in time.

    Returns
    -------
    index : (n, k) int64
        The ``NEIGHBOURS`` nearest points of each point (itself first).
    other : (n, k) bool
        Those of other passes, seen from the point's side of its plane, within
        ``PAIR_DISTANCE_FACTOR`` of the nearest such distance, of a plane facing the point's
        sensor (all False when fewer than two points have any).
    normal : (n, 3) float64
        Unit normal of each neighbourhood's least-squares plane, toward the point's sensor.
    """
    tree = cKDTree(points)
    k = min(NEIGHBOURS, len(points))
    distance, index = tree.query(points, k=k, workers=-1)
    neighbours = points[index]                                                 # (n, k, 3)
    centred = neighbours - neighbours.mean(axis=1, keepdims=True)
    normal = np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred))[1][:, :, 0]
    sight = view - points                                                      # toward sensor
    normal *= np.where(np.einsum("ni,ni->n", normal, sight) < 0, -1.0, 1.0)[:, None]
    same_side = np.einsum("ni,nki->nk", normal, sight[index]) > 0
    other = (np.abs(time[index] - time[:, None]) >= gap) & same_side
    # A surface seen within MIN_FACING of edge-on, or a neighbourhood so small that the range
    # noise along the beam is its largest spread (its least-squares "normal" then lies across
    # the beam), holds no crossover: left out.
    facing = np.einsum("ni,ni->n", normal, sight) / np.maximum(np.linalg.norm(sight, axis=1),
                                                                1e-300)
    other &= (facing >= MIN_FACING)[:, None]
    has = other.any(axis=1)
    if has.sum() < 2:
        return index, np.zeros_like(other), normal
    nearest = distance[has, np.argmax(other[has], axis=1)]
    other &= distance <= PAIR_DISTANCE_FACTOR * np.median(nearest)
    return index, other, normal


def _n_params(jac: np.ndarray, weights: np.ndarray) -> int:
    return 6 * weights.shape[1] + jac.shape[2] - 6


def _jacobian(sample: _Sample, points: np.ndarray, sensor: Rotation, target: Rotation,
              spin_axis: np.ndarray | None) -> np.ndarray:
    """How each body-frame point moves per unit of each parameter group: (n, 3, 6 or 7).

    Columns: misalignment (3, radians, S), position (3, metres), spin rate (rad/s).
    """
    n = len(points)
    to_body = target.inv()
    v = sample.vector
    # d p_B / d omega = R_BI^T R_SI [v]x: the rotated strike turns by -omega in S.
    skew = np.zeros((n, 3, 3))
    skew[:, 0, 1], skew[:, 0, 2] = -v[:, 2], v[:, 1]
    skew[:, 1, 0], skew[:, 1, 2] = v[:, 2], -v[:, 0]
    skew[:, 2, 0], skew[:, 2, 1] = -v[:, 1], v[:, 0]
    m = to_body.as_matrix() @ sensor.as_matrix()
    columns = [m @ skew, -to_body.as_matrix()]
    if spin_axis is not None:
        columns.append(-(sample.time[:, None] * np.cross(spin_axis, points))[:, :, None])
    return np.concatenate(columns, axis=2)


def _robust_sigma(r: np.ndarray) -> float:
    return float(MAD_TO_SIGMA * np.median(np.abs(r - np.median(r)))) if len(r) else 0.0


def refine(log_path, *, interval: float | None = None, spin: bool = False,
           max_points: int = MAX_POINTS, seed: int = 0, progress=None, announce=None
           ) -> Refinement:
    """Estimate the constant and slowly varying pose-knowledge errors of a log from its strikes.

    Guarded: the estimate is the iterate (the zero correction, the recorded poses, among them)
    whose fitted strikes agree best with the other passes, and it is kept only where strikes held
    out of the fit agree significantly better with it than without it; every other parameter is
    reported, and applied, as 0 (module docstring).

    Parameters
    ----------
    log_path : str or os.PathLike
        A strike log; only its recorded shots and strikes are read.
    interval : float, optional, seconds
        Knot spacing of slowly varying errors (None: constant errors only).
    spin : bool
        Also estimate a spin-rate correction (off by default: on RSO-A's flat faces a spin-rate
        change lets the fit slide faces along themselves and it runs away; see
        docs/pointing-knowledge.md).
    max_points : int
        Strikes sampled for the fit; as many others (disjoint) check it.
    seed : int
        Seed of the samples.
    progress : callable, optional
        Called as ``progress(done, total)`` after every step of the fit, ``done`` of the
        ``total`` estimated seconds (``refine_seconds``; steps a converged fit did not need
        count as done).
    announce : callable, optional
        Called with one line saying how long the refinement is estimated to take, before it
        starts, when that is more than ``ANNOUNCE_S``.

    Returns
    -------
    Refinement
        Apply ``refinement.correction`` to the shots to register the corrected cloud.

    Raises
    ------
    ParameterError
        Bad options, or ``interval`` too short for the strikes to estimate its knots or for
        the refinement to end within ``MAX_REFINE_S`` (by ``refine_seconds``).
    InputError
        Too few strikes seen twice to estimate anything, or the problem does not fit in the
        memory available.
    """
    _check_options(interval, max_points)
    problem = _problem(log_path, interval, spin, max_points, seed, announce)
    clock = _Progress(progress, problem.seconds)
    start = _coarse_start(problem, clock)
    tried, iterations = _fine(problem, start, clock)
    best, formal, robust = _best(problem, tried)
    observable, sigma, keep = _judged(problem, best, formal, robust)
    correction, significant, check_z = _checked(best, keep, problem.check, problem.pairs,
                                                problem.log_path)
    before, _, _ = problem.pairs.residuals(problem.fit, problem.zero)
    after, _, _ = problem.pairs.residuals(problem.fit, correction)
    clock.advance(problem.seconds)
    return Refinement(correction=correction, sigma=sigma, observable=observable,
                      significant=significant, check_z=check_z,
                      residual_before_m=_robust_sigma(before[np.isfinite(before)]),
                      residual_after_m=_robust_sigma(after[np.isfinite(after)]),
                      n_points=len(problem.fit.time), n_pairs=int(np.isfinite(after).sum()),
                      iterations=iterations)


def _check_options(interval: float | None, max_points: int) -> None:
    if interval is not None and not (math.isfinite(interval) and interval > 0):
        raise ParameterError(f"interval must be a positive number of seconds, got {interval}",
                             argument="interval")
    if max_points < 100:
        raise ParameterError(f"max_points must be at least 100, got {max_points}",
                             argument="max_points")


def _knot_count(span: float, interval: float) -> float:
    """Knots ``interval`` seconds apart over ``span`` seconds, ends included (at least 2); inf
    for an interval too short to count them."""
    steps = span / interval
    return max(2.0, math.ceil(steps) + 1.0) if math.isfinite(steps) else math.inf


def _check_size(log: StrikeLog, interval: float | None, max_points: int) -> None:
    """Refuse, before the shots are read, knots too many for the sampled strikes to estimate
    (fewer than ``MIN_ROWS`` a knot on average) and a problem that does not fit in memory.

    The problem of ``k`` knots has ``p = 6 k + 1`` parameters: hat weights (n, k) and a design
    (n, p) of the ``n`` fitted strikes (and two copies of it in a step), a block of the
    consensus (the neighbours' hat weights, ``BLOCK`` x ``NEIGHBOURS`` x k, and two products of
    ``BLOCK`` x k x 6), and ``DENSE_MATRICES`` (p, p) matrices of the normal equations, each
    float64. The normal equations couple knots far apart in time (the other passes), so they are
    dense.

    Raises
    ------
    ParameterError
        Too many knots: ``interval`` is too short for the log's duration.
    InputError
        The log's shots, or the problem, need more memory than is available.
    """
    n_fit = min(max_points, (log.n_strikes + 1) // 2)
    knots = 1
    if interval is not None:
        span = float(log.shots(log.n_shots - 1).time[0] - log.shots(0, 1).time[0])
        most = n_fit // MIN_ROWS
        count = _knot_count(span, interval)
        if count > most:
            instead = _instead(span, most)
            made = f"{count:,.0f}" if math.isfinite(count) else "too many"
            raise ParameterError(
                f"interval {interval:g} s makes {made} knots over the log's {span:g} s, more "
                f"than its {n_fit:,} sampled strikes can estimate ({most:,} knots, at least "
                f"{MIN_ROWS} strikes a knot); {instead}", argument="interval")
        knots = int(count)
    p = 6 * knots + 1
    values = (SHOT_VALUES * log.n_shots + n_fit * (knots + 3 * p)
              + BLOCK * (NEIGHBOURS + 12) * knots + DENSE_MATRICES * p * p)
    check_memory(f"{log.path}: refining the poses of its {log.n_shots:,} shots with {knots:,} "
                 f"knot{'s' * (knots > 1)}", 8 * values, InputError,
                 advice="give a longer interval" if knots > 1 else "")


def _coarse_nodes() -> int:
    """Starts of the coarse stage: the nodes of its grid (``_coarse_start``)."""
    return (2 * round(COARSE_POSITION_M / COARSE_STEP_M) + 1) ** 2


def step_seconds(n_points: int, knots: int) -> float:
    """Estimated time [s] of one step of the fit (``_descend``) of ``n_points`` sampled
    strikes with ``knots`` knots: the time model beside ``STEP_POINT_S``."""
    p = 6 * knots + 1
    return (n_points * (STEP_POINT_S + STEP_KNOT_S * knots + STEP_PAIR_S * p * p)
            + STEP_SQUARE_S * p * p + STEP_CUBE_S * p ** 3)


def refine_seconds(n_points: int, knots: int, *, coarse: bool = True) -> float:
    """Estimated time [s] of a refinement of ``n_points`` fitted strikes with ``knots`` knots:
    ``MAX_ITERATIONS`` steps of them and, with ``coarse`` (a spinning target),
    ``COARSE_ITERATIONS`` steps of every ``COARSE_THIN``-th one from each coarse start.

    At the speed measured for ``STEP_POINT_S`` and the other constants; a fit that converges
    early takes less.
    """
    seconds = MAX_ITERATIONS * step_seconds(n_points, knots)
    if coarse:
        seconds += (_coarse_nodes() * COARSE_ITERATIONS
                    * step_seconds(-(-n_points // COARSE_THIN), knots))
    return seconds


def duration_text(seconds: float) -> str:
    """A duration in the unit a person reads it in: "40 s", "25 min", "3.2 h", "2.5 days"."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 90 * 60:
        return f"{seconds / 60:.0f} min"
    if seconds < 48 * 3600:
        return f"{seconds / 3600:.2g} h"
    return f"{seconds / 86400:.2g} days"


def _instead(span: float, most: int) -> str:
    """What to ask for when at most ``most`` knots are acceptable over ``span`` seconds: the
    shortest interval that makes no more, rounded up to 4 digits (rounded to nearest, 1990 s
    for 4 knots read "663.3 s", which makes 5), or no interval."""
    if most < 2:
        return "refine constant errors only (no interval)"
    shortest = span / (most - 1)
    decimals = max(0, 3 - math.floor(math.log10(shortest)))
    unit = 10.0 ** (math.floor(math.log10(shortest)) - 3)
    units = math.ceil(shortest / unit)
    while True:
        text = f"{units * unit:.{decimals}f}"
        text = text.rstrip("0").rstrip(".") if "." in text else text
        if _knot_count(span, float(text)) <= most:
            return f"give at least {text} s"
        units += 1


def _check_time(log_path, interval: float | None, span: float, knots: int, max_points: int,
                n_points: int, *, coarse: bool) -> float:
    """The refinement's estimated time [s] (``refine_seconds``), refused beyond
    ``MAX_REFINE_S``.

    Raises
    ------
    ParameterError
        The estimate exceeds ``MAX_REFINE_S``: names ``interval`` and the shortest one whose
        knots would be within it (``max_points`` when even constant errors would not).
    """
    seconds = refine_seconds(n_points, knots, coarse=coarse)
    if seconds <= MAX_REFINE_S:
        return seconds
    limit = duration_text(MAX_REFINE_S)
    estimate = (f"would take about {duration_text(seconds)}, more than the {limit} a "
                "refinement may take")
    if interval is None or refine_seconds(n_points, 1, coarse=coarse) > MAX_REFINE_S:
        raise ParameterError(f"max_points {max_points:,} samples {n_points:,} strikes of "
                             f"{log_path}; refining them {estimate}; sample fewer",
                             argument="max_points")
    low, high = 1, knots    # within the limit, beyond it
    while high - low > 1:
        middle = (low + high) // 2
        low, high = ((middle, high) if refine_seconds(n_points, middle, coarse=coarse)
                     <= MAX_REFINE_S else (low, middle))
    raise ParameterError(
        f"interval {interval:g} s makes {knots:,} knots over the log's {span:g} s; refining "
        f"them with {n_points:,} sampled strikes {estimate} (at most {low:,} knots); "
        f"{_instead(span, low)}", argument="interval")


class _Progress:
    """How far a refinement is, in its estimated seconds (``step_seconds``), for a
    ``progress(done, total)`` callable (None: nobody listens)."""

    def __init__(self, report, total: float):
        self.report, self.total, self.done = report, total, 0.0

    def advance(self, seconds: float) -> None:
        self.done = min(self.done + seconds, self.total)
        if self.report is not None:
            self.report(self.done, self.total)


@dataclass
class _Problem:
    """What one refinement works on: the samples, how they are compared, the parameters."""

    log_path: object
    fit: _Sample            # strikes fitted
    check: _Sample          # strikes held out to check the fit
    pairs: _Pairs
    zero: PoseCorrection    # the recorded poses, with the knots and the spin axis
    weights: np.ndarray     # (n_fit, k) hat weights of the fitted strikes' times
    prior: np.ndarray       # (p,) prior 1-sigma of every parameter, in the solver's order
    spin_inertial: np.ndarray | None  # (3,) spin axis in I, None: the target does not spin
    seconds: float          # the estimated time (refine_seconds)


def _problem(log_path, interval: float | None, spin: bool, max_points: int, seed: int,
             announce=None) -> _Problem:
    """Read the samples of a log and set up the parameters and their priors, once the knots,
    the memory (``_check_size``) and the time (``_check_time``) are found acceptable."""
    with StrikeLog(log_path) as log:
        if log.n_strikes < 100:
            raise InputError(f"{log_path}: {log.n_strikes} strikes are too few to refine the "
                              "poses (at least 100)")
        _check_size(log, interval, max_points)
        all_shots = log.shots()
        axis, rate = spin_of(all_shots)
        t0, t1 = float(all_shots.time[0]), float(all_shots.time[-1])
        knots = (np.array([t0]) if interval is None
                 else np.linspace(t0, t1, int(_knot_count(t1 - t0, interval))))
        seconds = _check_time(log_path, interval, t1 - t0, len(knots), max_points,
                              min(max_points, (log.n_strikes + 1) // 2), coarse=rate > 0)
        if announce is not None and seconds > ANNOUNCE_S:
            what = ("constant errors" if interval is None
                    else f"{len(knots):,} knots over {t1 - t0:,.0f} s")
            announce(f"refining {what}: about {duration_text(seconds)}")
        fit, check = _samples(log, max_points, seed)
    k = len(knots)
    step = float(np.median(np.diff(all_shots.time))) if len(all_shots) > 1 else 1.0
    pairs = _Pairs(PAIR_GAP_STEPS * step, axis if rate > 0 and spin else None)
    zero = PoseCorrection(knots, np.zeros((k, 3)), np.zeros((k, 3)), 0.0, axis)
    # Prior 1-sigma of every parameter, in the solver's order (per knot: omega 3, position 3).
    prior = np.concatenate([np.repeat([[PRIOR_ATTITUDE_RAD] * 3], k, axis=0).ravel(),
                            np.full(3 * k, PRIOR_POSITION_M)]
                           + ([[PRIOR_SPIN_FRACTION * rate]] if pairs.spin_axis is not None
                              else []))
    spin_inertial = (Rotation.from_quat(all_shots.target_attitude[0]).apply(axis)
                     if rate > 0 else None)
    return _Problem(log_path, fit, check, pairs, zero, zero.weights(fit.time), prior,
                    spin_inertial, seconds)


def _coarse_start(problem: _Problem, clock: _Progress | None = None) -> PoseCorrection:
    """Where the fine fit starts: the best of short fits of a thinned sample from a grid of
    constant position biases across the spin axis (module docstring).

    A spinning target turns a constant inertial bias in the body frame, so passes at different
    spin phases place the same surface up to twice the bias apart: beyond the neighbourhoods of
    the fine fit, whose linearised consensus then barely sees it. Every ``COARSE_THIN``-th fitted
    strike (neighbourhoods about three times as wide) is fitted for ``COARSE_ITERATIONS`` steps
    from each node of a grid ``COARSE_POSITION_M`` either way in steps of ``COARSE_STEP_M``, in
    the plane across the spin axis (along it, a bias shifts the whole cloud); the end with the
    smallest robust scatter of its residuals to the other passes wins (the recorded poses among
    the ends; of ends that agree equally well, the smallest correction). A target that does
    not spin has no such search (a constant inertial bias is then a shift of the whole cloud).
    """
    if problem.spin_inertial is None:
        return problem.zero
    coarse = _subset(problem.fit, np.arange(0, len(problem.fit.time), COARSE_THIN))
    weights = problem.zero.weights(coarse.time)
    axis = problem.spin_inertial
    across = np.linalg.svd(np.eye(3) - np.outer(axis, axis))[0][:, :2]      # (3, 2)
    half = round(COARSE_POSITION_M / COARSE_STEP_M)
    steps = COARSE_STEP_M * np.arange(-half, half + 1)
    nodes = np.stack(np.meshgrid(steps, steps, indexing="ij"), axis=-1).reshape(-1, 2) @ across.T
    k = len(problem.zero.knots)
    ends = [problem.zero]
    for node in nodes:
        start = replace(problem.zero, position=np.repeat(node[None], k, axis=0))
        tried, _ = _descend(problem, coarse, weights, start, COARSE_ITERATIONS, clock)
        ends += [entry[1] for entry in tried[-1:]]
    residuals = [problem.pairs.residuals(coarse, end)[0] for end in ends]
    finite = np.array([np.isfinite(r).sum() for r in residuals])
    scatter = np.array([_robust_sigma(r[np.isfinite(r)]) if n >= 0.5 * finite[0] else np.inf
                        for r, n in zip(residuals, finite, strict=True)])
    # Ends within COARSE_TIE standard errors of the best scatter agree equally well (ends along a
    # valley the data cannot resolve, such as a cross-track misalignment against a position
    # error along the orbit normal): the smallest correction, in prior sigmas, of them wins.
    best = int(np.argmin(scatter))
    tie = scatter <= scatter[best] * (1.0 + COARSE_TIE * MAD_ERROR / math.sqrt(finite[best]))
    size = [np.linalg.norm(_vector(end, problem.pairs.spin_axis) / problem.prior)
            for end in ends]
    return ends[int(np.argmin(np.where(tie, size, np.inf)))]


def _descend(problem: _Problem, sample: _Sample, weights: np.ndarray, start: PoseCorrection,
             iterations: int, clock: _Progress | None = None) -> tuple[list, int]:
    """Robust Gauss-Newton steps from ``start`` until no strike of ``sample`` moves
    ``STOP_MOVE_M`` (at most ``iterations`` steps).

    Parameters
    ----------
    weights : (n, k) float64
        Hat weights of the sample's times.
    clock : _Progress, optional
        Advanced by ``step_seconds`` after every step, and by the steps not needed at the end.

    Returns
    -------
    tried : list of [residual (n,), PoseCorrection, formal (p, p), robust (p, p)]
        Every iterate, with the sample's residuals and the covariances of the step taken from it
        (the last step's for the last iterate); empty when the start leaves fewer than
        ``MIN_ROWS`` strikes with a consensus.
    iterations : int
        Steps taken.
    """
    pairs, clock = problem.pairs, clock or _Progress(None, 0.0)
    step = step_seconds(len(sample.time), len(problem.zero.knots))
    estimate, previous, cluster, tried, taken = start, None, None, [], 0
    for iteration in range(1, iterations + 1):
        residual, points, design = pairs.residuals(sample, estimate, weights)
        moved = (0.0 if previous is None
                 else float(np.max(np.linalg.norm(points - previous, axis=1))))
        rows = np.flatnonzero(np.isfinite(residual))
        if len(rows) < MIN_ROWS:
            break
        if cluster is None:
            cluster = _cells(points)
        tried.append([residual, estimate, *tried[-1][2:]] if tried else [residual, estimate])
        if previous is not None and moved < STOP_MOVE_M:
            break
        previous = points
        r, d = residual[rows], design
        inlier = np.abs(r - np.median(r)) <= OUTLIER_SIGMAS * _robust_sigma(r)
        x, *covariances = _solve(r[inlier], d[inlier], problem.prior,
                                 _robust_sigma(r[inlier]) or 1e-6,
                                 _vector(estimate, pairs.spin_axis), cluster[rows][inlier])
        tried[-1][2:] = covariances
        estimate = _updated(estimate, x, len(problem.zero.knots), pairs.spin_axis is not None)
        taken = iteration
        clock.advance(step)
    else:
        residual, _, _ = pairs.residuals(sample, estimate)
        tried.append([residual, estimate, *tried[-1][2:]])
    clock.advance(step * (iterations - taken))
    return tried, iteration


def _fine(problem: _Problem, start: PoseCorrection, clock: _Progress | None = None
          ) -> tuple[list, int]:
    """The fit of every sampled strike from ``start``: the iterates of ``_descend`` with the
    zero correction (the recorded poses) first, carrying the first step's covariances when the
    fit starts elsewhere."""
    tried, iterations = _descend(problem, problem.fit, problem.weights, start, MAX_ITERATIONS,
                                 clock)
    if not tried or len(tried[0]) < 4:
        rows = 0 if not tried else int(np.isfinite(tried[0][0]).sum())
        raise InputError(f"{problem.log_path}: only {rows} strikes have neighbours from other "
                          "passes; too few to refine the poses")
    if start is not problem.zero:
        tried.insert(0, [problem.pairs.residuals(problem.fit, problem.zero)[0], problem.zero,
                         *tried[0][2:]])
    return tried, iterations


def _best(problem: _Problem, tried: list) -> tuple[PoseCorrection, np.ndarray, np.ndarray]:
    """The plausible iterate (within ``PLAUSIBLE_PRIORS``) with the lowest mean loss at the
    scatter of the best agreement reached, and its formal and robust covariances."""
    spin_axis = problem.pairs.spin_axis
    tried = [entry for entry in tried if np.all(
        np.abs(_vector(entry[1], spin_axis)) <= PLAUSIBLE_PRIORS * problem.prior)]
    scale = _scale(*(entry[0] for entry in tried))
    _, best, formal, robust = min(tried, key=lambda entry: _loss(entry[0], scale).mean())
    return best, formal, robust


def _judged(problem: _Problem, best: PoseCorrection, formal: np.ndarray, robust: np.ndarray
            ) -> tuple[dict, PoseCorrection, dict]:
    """Which parameters the data see (observable), their 1-sigma, and which of them to keep:
    all that the data see, when the observable ones are jointly significant; otherwise those
    observable and beyond ``SIGNIFICANCE_Z`` of their own 1-sigma."""
    spin_axis, knots = problem.pairs.spin_axis, problem.zero.knots
    formal = _uncertainty(formal, len(knots), spin_axis, knots)
    sigma = _uncertainty(robust, len(knots), spin_axis, knots)
    observable = {"misalignment": formal.misalignment < OBSERVABLE_SHRINK * PRIOR_ATTITUDE_RAD,
                  "position": formal.position < OBSERVABLE_SHRINK * PRIOR_POSITION_M,
                  "spin": bool(spin_axis is not None
                               and formal.spin_rate < OBSERVABLE_SHRINK * problem.prior[-1])}
    if _jointly_significant(problem, best, robust, observable):
        # The whole estimate: a parameter the data see only together with another (a
        # cross-track misalignment with a position error along the orbit normal) keeps the
        # value that makes the combination right; what the data do not see at all is 0
        # (about the beam, along the spin axis).
        held = {"misalignment": formal.misalignment < SEEN_SHRINK * PRIOR_ATTITUDE_RAD,
                "position": formal.position < SEEN_SHRINK * PRIOR_POSITION_M,
                "spin": bool(spin_axis is not None
                             and formal.spin_rate < SEEN_SHRINK * problem.prior[-1])}
        return observable, sigma, {name: observable[name] | held[name] for name in observable}
    clear = {"misalignment": np.abs(best.misalignment) > SIGNIFICANCE_Z * sigma.misalignment,
             "position": np.abs(best.position) > SIGNIFICANCE_Z * sigma.position,
             "spin": abs(best.spin_rate) > SIGNIFICANCE_Z * sigma.spin_rate}
    return observable, sigma, {name: observable[name] & clear[name] for name in observable}


def _jointly_significant(problem: _Problem, best: PoseCorrection, robust: np.ndarray,
                         observable: dict) -> bool:
    """Whether the observable parameters of ``best`` together lie beyond their robust
    uncertainty: their Mahalanobis distance from zero exceeds the chi-square quantile of a
    one-sided ``SIGNIFICANCE_Z``-sigma test.

    Parameters that trade off (a cross-track misalignment against a position error along the
    orbit normal) each have a large 1-sigma, while their combination is sharp: tested one by one,
    the sharp ones alone are kept, and alone they make the passes agree worse (RSO-A: the
    position bias without its misalignment).
    """
    mask = _vector(PoseCorrection(best.knots, observable["misalignment"].astype(float),
                                  observable["position"].astype(float),
                                  float(observable["spin"]), best.spin_axis),
                   problem.pairs.spin_axis) > 0
    if not mask.any():
        return False
    x = _vector(best, problem.pairs.spin_axis)[mask]
    distance = float(x @ np.linalg.lstsq(robust[np.ix_(mask, mask)], x, rcond=None)[0])
    return distance > chi2.isf(norm.sf(SIGNIFICANCE_Z), int(mask.sum()))


def _subset(sample: _Sample, rows: np.ndarray) -> _Sample:
    s = sample.shots
    return _Sample(sample.time[rows], sample.vector[rows],
                   Shots(s.time[rows], s.sensor_position[rows], s.sensor_attitude[rows],
                         s.target_attitude[rows]))


@dataclass
class _Pairs:
    """How strikes are compared with the other passes: the time gap to them [s] and the spin
    axis (3,) in B of a spin-rate parameter (None: no such parameter)."""

    gap: float
    spin_axis: np.ndarray | None

    def residuals(self, sample: _Sample, correction: PoseCorrection,
                  weights: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Each strike's residual to the other passes under ``correction``.

        Returns
        -------
        residual : (n,) float64, metres
            NaN where a strike has no consensus of other passes.
        points : (n, 3) float64, metres, B
        design : (m, p) float64 or None
            Rows of the finite residuals, in order (only with ``weights``, the knots' hat
            weights (n, k) of the strikes).
        """
        points, view, sensor, target = _register(sample, correction.correct(sample.shots))
        jac = (None if weights is None
               else _jacobian(sample, points, sensor, target, self.spin_axis))
        rows, r, design = _consensus(points, view, sample.time, self.gap, jac, weights)
        residual = np.full(len(points), np.nan)
        residual[rows] = r
        return residual, points, design


def _loss(residual: np.ndarray, scale: float) -> np.ndarray:
    """Per-strike disagreement with the other passes: the Huber loss of ``residual / scale``
    (``HUBER_SIGMAS``), capped at its value at ``OUTLIER_SIGMAS``, which a strike with no
    consensus (NaN) also scores: (n,) float64, dimensionless."""
    x = np.abs(residual) / scale
    cap = HUBER_SIGMAS * (OUTLIER_SIGMAS - 0.5 * HUBER_SIGMAS)
    with np.errstate(invalid="ignore"):
        huber = np.where(x <= HUBER_SIGMAS, 0.5 * x ** 2, HUBER_SIGMAS * (x - 0.5 * HUBER_SIGMAS))
    return np.where(np.isnan(x), cap, np.minimum(huber, cap))


def _scale(*residuals: np.ndarray) -> float:
    """The smallest robust scatter [m] of several sets of residuals (NaN: no consensus): the
    common scale of their losses."""
    return min(_robust_sigma(r[np.isfinite(r)]) for r in residuals) or 1e-6


def _gain(without: np.ndarray, with_: np.ndarray, scale: float, cluster: np.ndarray
          ) -> float:
    """How much better the strikes agree with a change than without it, in standard errors.

    The mean drop of ``_loss`` over the strikes with a consensus either way, over its
    cluster-robust standard error (neighbouring residuals share points, so the drops are summed
    per cell ``cluster`` (n,) int64 before their scatter is taken).
    """
    both = np.isfinite(without) | np.isfinite(with_)
    drop = _loss(without[both], scale) - _loss(with_[both], scale)
    spread = np.sqrt(np.sum(np.bincount(cluster[both], drop - drop.mean()) ** 2))
    return float(drop.sum() / spread) if spread > 0 else 0.0


def _checked(best: PoseCorrection, keep: dict, check: _Sample, pairs: _Pairs, log_path
             ) -> tuple[PoseCorrection, dict, float]:
    """The estimate as far as the held-out strikes confirm it.

    The parameters in ``keep`` (masks like ``observable``: observable and clear of their
    uncertainty) are kept, the others set to 0, if the checking strikes agree with the other
    passes better with them than with the recorded poses by more than ``SIGNIFICANCE_Z``
    standard errors; otherwise nothing is.

    Returns
    -------
    correction : PoseCorrection
    significant : dict of str -> (k, 3) bool or bool
        The parameters kept.
    z : float
        The correction's gain over the recorded poses on the checking strikes, in standard
        errors (0 when nothing is kept).
    """
    nothing = {name: np.zeros_like(mask, dtype=bool) for name, mask in keep.items()}
    zero = _kept(best, nothing)
    candidate = _kept(best, keep)
    if candidate.is_zero():
        return zero, nothing, 0.0
    base, points, _ = pairs.residuals(check, zero)
    finite = np.isfinite(base)
    if finite.sum() < MIN_ROWS:
        raise InputError(f"{log_path}: only {int(finite.sum())} held-out strikes have "
                          "neighbours from other passes; too few to check the refinement")
    residual, _, _ = pairs.residuals(check, candidate)
    z = _gain(base, residual, _scale(base, residual), _cells(points))
    return (candidate, keep, z) if z > SIGNIFICANCE_Z else (zero, nothing, 0.0)


def _cells(points: np.ndarray) -> np.ndarray:
    """Cell (n,) int64 of each point in a grid of cubes ``CELL_NEIGHBOURHOODS`` times the median
    distance to the ``NEIGHBOURS``-th neighbour wide: residuals in different cells share
    (almost) no points."""
    k = min(NEIGHBOURS, len(points))
    distance = cKDTree(points).query(points, k=[k], workers=-1)[0]
    cell = CELL_NEIGHBOURHOODS * float(np.median(distance)) or 1.0
    return np.unique(np.floor(points / cell).astype(np.int64), axis=0,
                     return_inverse=True)[1].ravel()


def _kept(estimate: PoseCorrection, keep: dict) -> PoseCorrection:
    """The estimate with every parameter not in ``keep`` (masks like ``observable``) set to 0."""
    return PoseCorrection(estimate.knots,
                          np.where(keep["misalignment"], estimate.misalignment, 0.0),
                          np.where(keep["position"], estimate.position, 0.0),
                          estimate.spin_rate if keep["spin"] else 0.0, estimate.spin_axis)


def _vector(estimate: PoseCorrection, spin_axis) -> np.ndarray:
    """The estimate as the solver's parameter vector."""
    parts = [estimate.misalignment.ravel(), estimate.position.ravel()]
    return np.concatenate(parts + ([[estimate.spin_rate]] if spin_axis is not None else []))


def _solve(residual: np.ndarray, design: np.ndarray, prior: np.ndarray, scale: float,
           current: np.ndarray, cluster: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robust Gauss-Newton step: the increment ``x`` minimising the Huber loss of
    ``residual + design x`` (residual scatter ``scale``) plus the prior on ``current + x``.

    Iteratively reweighted least squares on the (p, p) normal equations. Combinations of
    parameters the data barely see (singular values of the column-normalised design below
    ``WEAK_DIRECTION`` of the largest, such as a cross-track misalignment against a position
    error along the orbit normal when the range hardly varies) are left out of the step, so noise
    cannot drive them far along the valley.

    Parameters
    ----------
    cluster : (m,) int64
        Cell of each residual (``_cells``): residuals in one cell share points.

    Returns
    -------
    x : (p,) float64
    formal : (p, p) float64
        Covariance of the parameters after the step: along the directions stepped, the inverse
        of the weighted normal matrix ``N`` (prior included) there, as if the residuals were
        independent; along the directions left out, the prior's (the data did not move them).
    robust : (p, p) float64
        The same with the cluster-robust (sandwich) covariance ``N^-1 (sum_c g_c g_c^T + P)
        N^-1`` along the directions stepped, ``g_c`` the gradient of the cell's weighted
        residuals and ``P`` the prior's precision: neighbouring residuals share points, so they
        are not independent.
    """
    x = np.zeros(design.shape[1])
    precision = np.diag(1.0 / prior ** 2)
    norms = np.sqrt(np.mean(design ** 2, axis=0))
    unit = np.where(norms > 1e-9 * norms.max(), norms, 1.0)
    scaling = np.outer(unit, unit)
    for _ in range(IRLS_ITERATIONS):
        e = np.abs(residual + design @ x)
        w = np.minimum(1.0, HUBER_SIGMAS * scale / np.maximum(e, 1e-12)) / scale ** 2
        data = design.T @ (w[:, None] * design)
        normal = data + precision
        rhs = -(design.T @ (w * residual)) - precision @ current
        # In column-normalised coordinates y = unit * x, step only along the directions the
        # data see well.
        values, vectors = np.linalg.eigh(data / scaling)
        strong = values >= WEAK_DIRECTION ** 2 * values.max()
        kept = vectors[:, strong]
        y = kept @ np.linalg.solve(kept.T @ (normal / scaling) @ kept, kept.T @ (rhs / unit))
        x = y / unit
    # Along the directions stepped, the data's covariance; along the others the estimate stays
    # where it started, known only as well as the prior says.
    inner = kept @ np.linalg.inv(kept.T @ (normal / scaling) @ kept) @ kept.T
    left = vectors[:, ~strong]
    held = (left @ np.linalg.inv(left.T @ (precision / scaling) @ left) @ left.T
            if left.shape[1] else np.zeros_like(inner))
    gradient = np.zeros((int(cluster.max()) + 1 if len(cluster) else 0, design.shape[1]))
    np.add.at(gradient, cluster, (w * (residual + design @ x))[:, None] * design)
    meat = (gradient.T @ gradient + precision) / scaling
    return x, (inner + held) / scaling, (inner @ meat @ inner + held) / scaling


def _updated(estimate: PoseCorrection, x: np.ndarray, k: int, spin: bool) -> PoseCorrection:
    omega, position = x[:3 * k].reshape(k, 3), x[3 * k:6 * k].reshape(k, 3)
    return PoseCorrection(estimate.knots, estimate.misalignment + omega,
                          estimate.position + position,
                          estimate.spin_rate + (float(x[-1]) if spin else 0.0),
                          estimate.spin_axis)


def _uncertainty(covariance: np.ndarray, k: int, spin_axis: np.ndarray | None,
                 knots: np.ndarray) -> PoseCorrection:
    """1-sigma of every parameter, from the diagonal of the covariance."""
    sigma = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    return PoseCorrection(knots, sigma[:3 * k].reshape(k, 3), sigma[3 * k:6 * k].reshape(k, 3),
                          float(sigma[-1]) if spin_axis is not None else 0.0,
                          np.zeros(3) if spin_axis is None else spin_axis)
