"""The gap-seeking attitude law: aim the boresight at what the chaser has not yet struck.

A closed loop (``attitude.mode = "gaps"``): the pipeline (sim/pipeline.py) simulates one
replanning interval at a time, asks :meth:`GapSeeker.command` for the boresight of every shot of
the next interval, and hands back what the log records of it (:meth:`GapSeeker.observe`). The law
sees only those recorded strikes, never the truth, and knows the target's spin and its own orbit.

What it keeps, in the target body frame B:

- **a map of directions** from the target centre, ``GAP_CELLS`` cells of a Fibonacci sphere, each
  counting the strikes whose footprint (``GAP_FOOTPRINT_FRACTION`` of the strikes' extent)
  covers it: a cell with no strike is a gap;
- **a proxy surface**: a centred quadric ``p^T A p = 1`` fitted to the mean strike of every struck
  cell (a sphere of their median radius while the fit is not an ellipsoid), which gives each gap a
  point ``r(u) u`` to aim at, a normal and an area.

Every interval it predicts, shot by shot, where the chaser is in B (its orbit and the known spin),
which gaps face it within ``GAP_MAX_INCIDENCE_DEG`` and lie within ``attitude.max_offset_deg`` of
the nominal boresight (when no gap is in view during the interval, the least-struck cells in
view take their place, so the beam densifies the sparsest surface instead of idling), and turns
the boresight by at most ``max_rate * step``:

1. onto the nearest such gap within that reach (so the beam sweeps a gap shot by shot at about
   one footprint per shot, the cheapest slew that covers new ground), marking its footprint as
   expected so the next shot moves on;
2. else toward the most valuable gap region: the unstruck area within ``GAP_REGION_DEG`` of a cell,
   divided by the shots needed to get there;
3. else (nothing of the target in view within the limits) it holds its offset, which costs no
   slew.

The commanded attitude is the nominal one (sim/motion.py) turned by the smallest rotation that
takes the nominal boresight ``+z`` onto the commanded one, and is recorded like any other.

The map assumes a target that is star-shaped about its centre (every direction meets the surface
once); on a satellite with thin panels both faces of a panel fall in the same cells, so the law
takes a panel's second face as seen when its first is.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from formats.strike_log import StrikeChunk
from sim.defaults import (
    GAP_CELLS,
    GAP_FOOTPRINT_FRACTION,
    GAP_MAX_INCIDENCE_DEG,
    GAP_REGION_DEG,
)

# Fewest struck cells for the quadric fit (6 unknowns, with margin); a sphere before that.
MIN_FIT_CELLS = 30
# The quadric's radii are trusted within this factor of the struck radii (else a sphere).
FIT_RADIUS_SLACK = 2.0
# Coarse cells (6.3 deg apart) on which the value of gap regions is summed.
REGION_CELLS = 1024
# Lowest cosine between a cell's direction and its proxy normal used for its area.
MIN_AREA_COSINE = 0.2


def fibonacci_directions(n: int) -> np.ndarray:
    """``n`` unit vectors (n, 3) spread evenly over the sphere (Fibonacci lattice)."""
    k = np.arange(n, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = math.pi * (3.0 - math.sqrt(5.0)) * k
    rho = np.sqrt(1.0 - z * z)
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)


def turn_from_boresight(boresight: np.ndarray) -> np.ndarray:
    """Smallest rotations taking ``+z`` onto each unit vector of ``boresight`` (n, 3).

    Returns
    -------
    (n, 3, 3) float64 matrices sending commanded-sensor vectors to the nominal sensor frame.
    """
    b = np.asarray(boresight, dtype=np.float64)
    axis = np.cross([0.0, 0.0, 1.0], b)
    sine = np.linalg.norm(axis, axis=1)
    angle = np.arctan2(sine, b[:, 2])
    safe = np.where(sine > 0, sine, 1.0)
    return Rotation.from_rotvec(axis / safe[:, None] * angle[:, None]).as_matrix()


def body_points(chunk: StrikeChunk) -> np.ndarray:
    """Strike positions (n, 3) [m, B] from what a log records (formats/SPEC.md, registration)."""
    row = chunk.shot - chunk.shot_offset
    shots = chunk.shots
    inertial = shots.sensor_position[row] + Rotation.from_quat(
        shots.sensor_attitude[row]).apply(chunk.range[:, None] * chunk.direction)
    return Rotation.from_quat(shots.target_attitude[row]).inv().apply(inertial)


class GapSeeker:
    """The gap-seeking law of one run (see the module docstring).

    Parameters
    ----------
    step : float, seconds
        Time between shots.
    max_rate : float, rad/s
        Slew-rate limit of the boresight.
    max_offset : float, rad
        Largest angle between the commanded and the nominal boresight.
    poses : callable
        ``poses(t) -> (position (n, 3) [m, I], target Rotation B->I, nominal (n, 3, 3) sending
        nominal-sensor vectors to I)`` at times ``t`` (n,) [s]: the chaser's knowledge of its
        orbit and of the target's spin.
    """

    def __init__(self, *, step: float, max_rate: float, max_offset: float, poses):
        self.step, self.max_rate, self.max_offset = step, max_rate, max_offset
        self._poses = poses
        self.cells = fibonacci_directions(GAP_CELLS)
        self._tree = cKDTree(self.cells)
        self.hits = np.zeros(GAP_CELLS, dtype=np.int64)      # strikes covering each cell
        self._radius_sum = np.zeros(GAP_CELLS)               # of the strikes in each cell
        self._in_cell = np.zeros(GAP_CELLS, dtype=np.int64)
        self._lo = np.full(3, np.inf)                         # strikes' bounding box [m, B]
        self._hi = np.full(3, -np.inf)
        self.boresight = np.array([0.0, 0.0, 1.0])           # commanded, nominal frame
        # Regions on a coarse grid: each cell's region is that of its nearest coarse cell.
        coarse = fibonacci_directions(REGION_CELLS)
        self._parent = cKDTree(coarse).query(self.cells)[1]
        chord = 2.0 * math.sin(math.radians(GAP_REGION_DEG) / 2.0)
        pairs = cKDTree(coarse).query_pairs(chord, output_type="ndarray")
        i = np.concatenate([pairs[:, 0], pairs[:, 1], np.arange(REGION_CELLS)])
        j = np.concatenate([pairs[:, 1], pairs[:, 0], np.arange(REGION_CELLS)])
        self._region = csr_matrix((np.ones(len(i)), (i, j)), shape=(REGION_CELLS,) * 2)
        self.n_strikes = 0

    # ------------------------------------------------------------------ the map

    @property
    def footprint(self) -> float:
        """Radius [m] a strike is taken to cover: a fraction of the strikes' extent."""
        if self.n_strikes == 0:
            return 0.0
        return GAP_FOOTPRINT_FRACTION * float(np.linalg.norm(self._hi - self._lo))

    def _mark(self, points: np.ndarray, counts: np.ndarray) -> None:
        """Add 1 to ``counts`` of every cell within the footprint of each point (n, 3) [m, B]."""
        radius = np.linalg.norm(points, axis=1)
        ok = radius > 0
        points, radius = points[ok], radius[ok]
        if not len(points):
            return
        u = points / radius[:, None]
        # Chord on the unit sphere of the footprint seen from the centre, and the nearest cell.
        chord = np.minimum(self.footprint / radius, 2.0)
        for members in self._tree.query_ball_point(u, chord, return_sorted=False):
            counts[members] += 1
        counts[self._tree.query(u)[1]] += 1

    def observe(self, chunk: StrikeChunk) -> None:
        """Add recorded strikes (a block as ``StrikeLog.iter_chunks`` yields) to the map."""
        if not len(chunk.range):
            return
        points = body_points(chunk)
        self._lo = np.minimum(self._lo, points.min(axis=0))
        self._hi = np.maximum(self._hi, points.max(axis=0))
        self.n_strikes += len(points)
        radius = np.linalg.norm(points, axis=1)
        cell = self._tree.query(points / radius[:, None])[1]
        np.add.at(self._radius_sum, cell, radius)
        np.add.at(self._in_cell, cell, 1)
        self._mark(points, self.hits)

    def proxy(self) -> tuple[np.ndarray, np.ndarray]:
        """The proxy surface over every cell: points (c, 3) [m, B] and unit normals (c, 3)."""
        struck = self._in_cell > 0
        radius = self._radius_sum[struck] / self._in_cell[struck]
        u = self.cells[struck]
        sphere = float(np.median(radius))
        if struck.sum() >= MIN_FIT_CELLS:
            p = u * radius[:, None]
            design = np.stack([p[:, 0] ** 2, p[:, 1] ** 2, p[:, 2] ** 2, 2 * p[:, 0] * p[:, 1],
                               2 * p[:, 0] * p[:, 2], 2 * p[:, 1] * p[:, 2]], axis=1)
            a = np.linalg.lstsq(design, np.ones(len(p)), rcond=None)[0]
            quadric = np.array([[a[0], a[3], a[4]], [a[3], a[1], a[5]], [a[4], a[5], a[2]]])
            if np.linalg.eigvalsh(quadric).min() > 0:
                r = 1.0 / np.sqrt(np.einsum("ci,ij,cj->c", self.cells, quadric, self.cells))
                if (r.min() > radius.min() / FIT_RADIUS_SLACK
                        and r.max() < radius.max() * FIT_RADIUS_SLACK):
                    points = self.cells * r[:, None]
                    normals = points @ quadric
                    return points, normals / np.linalg.norm(normals, axis=1, keepdims=True)
        return self.cells * sphere, self.cells.copy()

    # ------------------------------------------------------------------ the plan

    def command(self, t: np.ndarray) -> np.ndarray:
        """Plan the next interval: the commanded boresight of each shot at times ``t`` (n,) [s].

        Returns
        -------
        (n, 3, 3) float64 matrices sending commanded-sensor vectors to the nominal sensor frame
        (the attitude offset the pipeline applies).
        """
        n = len(t)
        out = np.empty((n, 3))
        if self.n_strikes == 0:                  # nothing seen yet: nadir, or hold
            out[:] = self.boresight
            return turn_from_boresight(out)
        points, normals = self.proxy()
        position, target, nominal = self._poses(np.asarray(t, dtype=np.float64))
        m_ib = target.as_matrix().transpose(0, 2, 1)
        chaser = np.einsum("nij,nj->ni", m_ib, position)              # B
        to_nominal = np.matmul(m_ib, nominal).transpose(0, 2, 1)       # sends B to nominal
        cos_incidence = math.cos(math.radians(GAP_MAX_INCIDENCE_DEG))

        def in_view(cells: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
            """Which ``cells`` shot ``k`` can aim at, and their aim directions (nominal)."""
            aim = points[cells] - chaser[k]
            aim /= np.sqrt(np.einsum("ci,ci->c", aim, aim))[:, None]
            faces = -np.einsum("ci,ci->c", aim, normals[cells]) >= cos_incidence
            aim_n = aim @ to_nominal[k].T
            return faces & (aim_n[:, 2] >= math.cos(self.max_offset)), aim_n

        # Cells in view during the interval (at its start, middle or end), and of those the
        # least struck: gaps while there are any, else the sparsest cells.
        every = np.arange(GAP_CELLS)
        seen = np.zeros(GAP_CELLS, dtype=bool)
        for k in sorted({0, n // 2, n - 1}):
            seen |= in_view(every, k)[0]
        level = int(self.hits[seen].min()) if seen.any() else 0
        gap = seen & (self.hits <= level)
        cosine = np.maximum(np.einsum("ci,ci->c", self.cells, normals), MIN_AREA_COSINE)
        area = np.linalg.norm(points, axis=1) ** 2 * (4.0 * math.pi / GAP_CELLS) / cosine
        unstruck = np.bincount(self._parent, weights=np.where(gap, area, 0.0),
                               minlength=REGION_CELLS)
        region = (self._region @ unstruck)[self._parent]
        reach = self.max_rate * self.step
        expected = np.zeros(GAP_CELLS, dtype=np.int64)
        candidates = np.flatnonzero(gap)
        for k in range(n):
            b = self.boresight
            open_ = candidates[self.hits[candidates] + expected[candidates] <= level]
            ok, aim_n = in_view(open_, k)
            if ok.any():
                aim_n, cells = aim_n[ok], open_[ok]
                turn = np.arccos(np.clip(aim_n @ b, -1.0, 1.0))
                near = turn <= reach
                if near.any():
                    pick = np.flatnonzero(near)[np.argmin(turn[near])]
                    self.boresight = aim_n[pick]
                    self._mark(points[cells[pick]][None], expected)
                else:
                    worth = region[cells] / np.ceil(turn / reach)
                    goal = aim_n[np.argmax(worth)]
                    self.boresight = _turn_toward(b, goal, reach)
            out[k] = self.boresight
        return turn_from_boresight(out)


def _turn_toward(b: np.ndarray, goal: np.ndarray, angle: float) -> np.ndarray:
    """Unit vector ``b`` turned toward ``goal`` by ``angle`` [rad] in their common plane."""
    cos = float(np.clip(b @ goal, -1.0, 1.0))
    total = math.acos(cos)
    if total <= angle:
        return goal
    side = goal - cos * b
    side /= np.linalg.norm(side)
    return math.cos(angle) * b + math.sin(angle) * side
