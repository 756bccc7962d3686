"""Missed beams: the free space a strike log records without a row.

Every shot fires every beam (formats/SPEC.md, ``/strikes``), so a (shot, beam) pair with no
strike row is a miss: the beam crossed free space from ``range_min`` to ``range_max`` (or met
nothing it could range). In the body frame a missed beam of shot ``i`` and beam ``j`` is the
ray from the recorded sensor position along the beam's nominal direction, placed exactly as a
strike is (``recon.registration.ingest.register_chunk``):

    origin_B    = R_BI^T r_I
    direction_B = R_BI^T R_SI d_S(j)

(``d_S(j)``: row ``j`` of ``/sensor/beam_directions``; a miss reports no angle offsets). Only the
recorded shots and the sensor are read; the log's ``/truth`` group never is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from formats import StrikeLog

# Missed beams kept (a seeded subsample): a surface's fraction of them cut has a standard
# error below 0.5 / sqrt(n) = 0.35 %, and one batched cast per surface stays cheap.
MAX_MISSES = 20_000
# Pairs drawn per miss kept: most of a scanning grid's misses pass far from the target; the
# draw is bounded so that a long log costs the same as a short one.
DRAW_FACTOR = 20


@dataclass(frozen=True)
class MissedBeams:
    """Missed beams in the body frame (module docstring).

    Attributes
    ----------
    origin : (m, 3) float64, metres, body frame
        Recorded sensor position of each miss's shot.
    direction : (m, 3) float64, unit vectors, body frame
        The beam's nominal direction.
    range_min, range_max : float, metres
        The span of each ray the sensor would have ranged: free space along it.
    shot, beam : (m,) int64
        The (shot, beam) pair of each miss.
    n_missed : int
        Misses of the whole log before the box and the subsample (estimated from the pairs
        drawn when the log has more than ``DRAW_FACTOR * limit`` pairs).
    """

    origin: np.ndarray
    direction: np.ndarray
    range_min: float
    range_max: float
    shot: np.ndarray
    beam: np.ndarray
    n_missed: int

    def __len__(self) -> int:
        return len(self.origin)


def beam_rays(shots, beam_directions: np.ndarray, row: np.ndarray, beam: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions (m, 3) in the body frame of beams ``beam`` (m,) fired at
    shot rows ``row`` (m,) of ``shots`` (``formats`` ``Shots``): the rotations of
    ``register_chunk`` applied to the nominal direction."""
    to_body = Rotation.from_quat(shots.target_attitude[row]).inv()
    direction = to_body.apply(Rotation.from_quat(shots.sensor_attitude[row]).apply(
        np.asarray(beam_directions, dtype=np.float64)[beam]))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return to_body.apply(shots.sensor_position[row]), direction


def ray_box(origin: np.ndarray, direction: np.ndarray, low: np.ndarray, high: np.ndarray,
            near: float, far: float) -> np.ndarray:
    """Whether each ray's segment ``[near, far]`` (metres along it) meets the axis-aligned box
    ``low``..``high`` (3,) (slab test, vectorised; (m,) bool)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = 1.0 / direction
        a = (low - origin) * inverse
        b = (high - origin) * inverse
    lo = np.where(np.isnan(a), -np.inf, np.minimum(a, b))
    hi = np.where(np.isnan(a), np.inf, np.maximum(a, b))
    inside = (direction != 0) | ((origin >= low) & (origin <= high))
    enter = np.maximum(lo.max(axis=1), near)
    leave = np.minimum(hi.min(axis=1), far)
    return inside.all(axis=1) & (enter <= leave)


def missed_beams(log_path, *, low: np.ndarray, high: np.ndarray,
                 limit: int = MAX_MISSES, seed: int = 0) -> MissedBeams:
    """The log's missed beams whose free span passes through a box, a seeded subsample.

    Parameters
    ----------
    log_path : str or Path
        A strike log.
    low, high : (3,) float64, metres, body frame
        The box (the strikes' bounding box, widened by the caller's margin): a miss far from
        the strikes says nothing of a surface fitted to them.
    limit : int
        Most misses kept.
    seed : int
        Seed of the draw.

    Returns
    -------
    MissedBeams
    """
    low, high = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
    with StrikeLog(log_path) as log:
        sensor = log.sensor
        n_beams = sensor.n_beams
        shots = log.shots()
        shot, beam, _ = log.strikes()
    fired = len(shots) * n_beams
    struck = np.sort(shot.astype(np.int64) * n_beams + beam)   # uint32 would overflow
    draw = min(fired, DRAW_FACTOR * limit)
    rng = np.random.default_rng(seed)
    pair = np.sort(rng.choice(fired, draw, replace=False)) if draw < fired else np.arange(fired)
    at = np.searchsorted(struck, pair)
    hit = (at < len(struck)) & (struck[np.minimum(at, len(struck) - 1)] == pair)
    pair = pair[~hit]
    n_missed = round(len(pair) * fired / max(draw, 1))
    row, which = pair // n_beams, pair % n_beams
    origin, direction = beam_rays(shots, sensor.beam_directions, row, which)
    near = ray_box(origin, direction, low, high, sensor.range_min, sensor.range_max)
    keep = np.flatnonzero(near)
    if len(keep) > limit:
        keep = np.sort(rng.choice(keep, limit, replace=False))
    return MissedBeams(origin[keep], direction[keep], float(sensor.range_min),
                       float(sensor.range_max), row[keep].astype(np.int64),
                       which[keep].astype(np.int64), int(n_missed))
