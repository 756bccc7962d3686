"""The gap-seeking attitude law: aim the boresight at what the chaser has not yet seen.

A closed loop (``attitude.mode = "gaps"``): the pipeline (sim/pipeline.py) simulates one
replanning interval at a time, asks :meth:`GapSeeker.command` for the boresight of every shot of
the next interval, and hands back what the log records of it (:meth:`GapSeeker.observe`). The law
sees only those recorded shots and strikes, never the truth, and knows its sensor's beams, the
target's spin and its own orbit.

What it keeps: a voxel map in the target body frame B (sim/surface_map.py) of the voxels struck
(occupied, with the side they were seen from) and those the beams crossed (free), from every
recorded beam, struck or not (:meth:`GapSeeker.observe` only keeps an interval's record; the map
takes it when the law next plans). Its voxel edge is ``GAP_VOXEL_FRACTION`` of the target's size
seen so far (the diagonal of the strikes' bounding box, or twice the farthest strike from the
target's centre if more: the first strikes on a large body already tell its scale), which is
about the coverage metric's tau, and at least ``GAP_VOXEL_MIN_DEG`` seen from the target's
range; when that edge drifts by more than ``GAP_VOXEL_REBUILD`` as the target is seen, the map is
rebuilt from every beam so far.

The **frontier** is the unknown voxels next to a struck one: surface continuing into space no
beam has examined, including the far side of a thin plate seen from one side.

**The plan** (:meth:`GapSeeker.command`). The law plans at most every ``GAP_PLAN_INTERVALS``
intervals: it takes the intervals observed since into the map (all at once) and chooses the
plan's candidates, the frontier voxels, one per cube of ``GAP_BLOCK_VOXELS`` voxels on a side
(a strike is expected to settle the frontier around its aim). Every interval it then predicts,
from its orbit and the known spin, where the chaser is in B at the interval's middle shot and
``GAP_HORIZON_INTERVALS`` intervals after its end, and which of the candidates not yet aimed at
a beam from there would reach before striking a struck voxel (a depth image of the map,
:meth:`SurfaceMap.visible`). Of those visible at the middle shot and within
``attitude.max_offset_deg`` of the nominal boresight, the interval's shots take one each: first
those predicted hidden later (see it now or wait), then in a sweep, rows two voxels wide across
the view, alternately left and right, going on from the boresight's row (the rows below it, then
from the top), so that consecutive aims lie next to each other. A shot
whose aim is beyond one step's reach (``max_rate * step``) turns toward it at the rate limit;
shots left over when the visible candidates run out hold the boresight, and the law plans anew
before the next interval (its candidates are used up; the map has grown). So the map, the
frontier and the candidates cost once per plan, the prediction and the sweep once per interval.

**When the frontier runs out** (``GAP_IDLE_INTERVALS`` intervals in a row with nothing visible
to aim at) the least-struck surface voxels join the candidates for the rest of the run
(``GAP_RESIDUAL_QUANTILE``): a voxel holding one strike can hold surface farther than the
coverage tolerance from it, and a voxel an oblique beam crossed beside a thin panel is marked
free although part of the panel lies in it. So the law keeps striking the surface it has seen
least, where a fixed slew would keep sweeping, and never idles. With no candidate at all the
boresight holds its offset (no slew).

The commanded attitude is the nominal one (sim/motion.py) turned by the smallest rotation that
takes the nominal boresight ``+z`` onto the commanded one, and is recorded like any other.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from formats.strike_log import StrikeChunk
from formats.strike_log.schema import Shots
from sim.defaults import (
    GAP_BLOCK_VOXELS,
    GAP_HORIZON_INTERVALS,
    GAP_IDLE_INTERVALS,
    GAP_MARGIN_FRACTION,
    GAP_MAX_CANDIDATES,
    GAP_PLAN_INTERVALS,
    GAP_REBUILD_BEAMS,
    GAP_RESIDUAL_QUANTILE,
    GAP_VOXEL_FRACTION,
    GAP_VOXEL_MIN_DEG,
    GAP_VOXEL_REBUILD,
)
from sim.surface_map import SurfaceMap, pack, unpack


def turn_from_boresight(boresight: np.ndarray) -> np.ndarray:
    """Smallest rotations taking ``+z`` onto each unit vector of ``boresight`` (n, 3), none
    within 90 deg of ``-z`` (Rodrigues' formula about ``z x b``: I + K + K^2 / (1 + cos)).

    Returns
    -------
    (n, 3, 3) float64 matrices sending commanded-sensor vectors to the nominal sensor frame.
    """
    x, y, z = np.asarray(boresight, dtype=np.float64).reshape(-1, 3).T
    k = 1.0 / (1.0 + z)
    return np.stack([np.stack([1.0 - k * x * x, -k * x * y, x], axis=1),
                     np.stack([-k * x * y, 1.0 - k * y * y, y], axis=1),
                     np.stack([-x, -y, z], axis=1)], axis=1)


def body_points(chunk: StrikeChunk) -> np.ndarray:
    """Strike positions (n, 3) [m, B] from what a log records (formats/SPEC.md, registration)."""
    row = chunk.shot - chunk.shot_offset
    shots = chunk.shots
    inertial = shots.sensor_position[row] + Rotation.from_quat(
        shots.sensor_attitude[row]).apply(chunk.range[:, None] * chunk.direction)
    return Rotation.from_quat(shots.target_attitude[row]).inv().apply(inertial)


def recorded_beams(chunk: StrikeChunk, beams: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every beam of every shot of ``chunk``, from what the log records, in B.

    Parameters
    ----------
    chunk : StrikeChunk
        The strikes of shots ``chunk.shot_offset ..`` and those shots (``chunk.shots``).
    beams : (b, 3) float64, unit vectors, sensor frame: the sensor's beam directions

    Returns
    -------
    origins : (m, 3) float64, metres, B: the recorded sensor position of each beam
    directions : (m, 3) float64, unit vectors, B: measured for strikes, nominal for misses
    ranges : (m,) float64, metres: recorded range, inf for a beam that struck nothing
    """
    shots, b = chunk.shots, len(beams)
    n = len(shots.time)
    to_body = Rotation.from_quat(shots.target_attitude).inv()
    sensor = Rotation.from_quat(shots.sensor_attitude)
    origin = to_body.apply(shots.sensor_position)
    row = chunk.shot - chunk.shot_offset
    missed = np.ones(n * b, dtype=bool)
    missed[row * b + chunk.beam] = False
    miss = np.flatnonzero(missed)
    miss_row, miss_beam = miss // b, miss % b
    directions = np.concatenate([
        to_body[row].apply(sensor[row].apply(chunk.direction)) if len(row) else
        np.zeros((0, 3)),
        to_body[miss_row].apply(sensor[miss_row].apply(beams[miss_beam])) if len(miss) else
        np.zeros((0, 3))])
    origins = np.concatenate([origin[row], origin[miss_row]])
    ranges = np.concatenate([np.asarray(chunk.range, dtype=np.float64),
                             np.full(len(miss), np.inf)])
    return origins, directions, ranges


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
    beams : (b, 3) float64, unit vectors, sensor frame
        The sensor's beam directions (misses are recorded as shots without strikes).
    """

    def __init__(self, *, step: float, max_rate: float, max_offset: float, poses,
                 beams: np.ndarray):
        self.step, self.max_rate, self.max_offset = step, max_rate, max_offset
        self._poses = poses
        self.beams = np.asarray(beams, dtype=np.float64).reshape(-1, 3)
        self.boresight = np.array([0.0, 0.0, 1.0])           # commanded, nominal frame
        self.map: SurfaceMap | None = None
        self._origins, self._directions, self._ranges = [], [], []
        self._pending: list[StrikeChunk] = []                # observed since the last plan
        self._keys = np.zeros(0, dtype=np.int64)             # the plan's candidates,
        self._centres = np.zeros((0, 3))                     # their centres [m, B]
        self._used = np.zeros(0, dtype=bool)                 # and those aimed at
        self._age = 0                                        # intervals since the plan
        self._short = True                                   # the last interval held a shot
        self._lo = np.full(3, np.inf)                         # strikes' bounding box [m, B]
        self._hi = np.full(3, -np.inf)
        self.n_strikes = 0
        self._range_sum = 0.0
        self._radius = 0.0                                   # farthest strike from the centre
        self.residual = False                                # frontier exhausted
        self._idle = 0                                       # intervals with nothing to aim at

    # ------------------------------------------------------------------ the map

    def voxel_size(self) -> float:
        """The voxel edge [m] the strikes so far call for (module docstring)."""
        diagonal = max(float(np.linalg.norm(self._hi - self._lo)), 2.0 * self._radius)
        distance = self._range_sum / self.n_strikes
        return max(GAP_VOXEL_FRACTION * diagonal,
                   distance * math.tan(math.radians(GAP_VOXEL_MIN_DEG)))

    def _margin(self) -> float:
        return GAP_MARGIN_FRACTION * float(np.linalg.norm(self._hi - self._lo))

    def observe(self, chunk: StrikeChunk) -> None:
        """Take the recorded shots and strikes of an interval (a block as
        ``StrikeLog.iter_chunks`` yields, with all its shots); they go into the map when the
        law next plans."""
        self._pending.append(chunk)

    def _update(self) -> None:
        """Add the intervals observed since the last plan to the map, all at once."""
        if not self._pending:
            return
        origins, directions, ranges = recorded_beams(merge_chunks(self._pending), self.beams)
        self._pending = []
        self._origins.append(origins)
        self._directions.append(directions)
        self._ranges.append(ranges)
        hit = np.isfinite(ranges)
        if hit.any():
            end = origins[hit] + ranges[hit, None] * directions[hit]
            self._lo = np.minimum(self._lo, end.min(axis=0))
            self._hi = np.maximum(self._hi, end.max(axis=0))
            self.n_strikes += int(hit.sum())
            self._range_sum += float(ranges[hit].sum())
            self._radius = max(self._radius, float(np.sqrt((end * end).sum(axis=1)).max()))
        if self.n_strikes == 0:
            return
        size = self.voxel_size()
        if self.map is None or abs(math.log(size / self.map.size)) > math.log(GAP_VOXEL_REBUILD):
            self._rebuild(size)
        else:
            self.map.add(origins, directions, ranges, margin=self._margin())

    def _rebuild(self, size: float) -> None:
        """A new map of edge ``size`` [m] from every recorded beam: all strikes first (so the
        region traversed is the whole target's), then the free space, a block at a time."""
        self.map = SurfaceMap(size)
        self._origins = [np.concatenate(self._origins)]
        self._directions = [np.concatenate(self._directions)]
        self._ranges = [np.concatenate(self._ranges)]
        origins, directions, ranges = self._origins[0], self._directions[0], self._ranges[0]
        self.map.strike(origins, directions, ranges)
        for start in range(0, len(ranges), GAP_REBUILD_BEAMS):
            block = slice(start, start + GAP_REBUILD_BEAMS)
            self.map.carve(origins[block], directions[block], ranges[block],
                           margin=self._margin())

    def _candidates(self) -> np.ndarray:
        """Sorted keys of the voxels worth a shot: the frontier, and once it is exhausted, the
        least-struck surface voxels too; an even subset of at most ``GAP_MAX_CANDIDATES``."""
        keys = self.map.frontier()
        if self.residual:
            few = self.map.count <= np.quantile(self.map.count, GAP_RESIDUAL_QUANTILE)
            keys = np.union1d(keys, self.map.occupied[few])
        if len(keys) > GAP_MAX_CANDIDATES:
            keys = keys[::-(-len(keys) // GAP_MAX_CANDIDATES)]
        return keys

    def _after_interval(self, aimed: bool) -> None:
        """Count intervals with nothing to aim at; after ``GAP_IDLE_INTERVALS`` of them in a
        row the frontier is taken as exhausted and the least-struck surface voxels join it."""
        self._idle = 0 if aimed else self._idle + 1
        if self._idle >= GAP_IDLE_INTERVALS:
            self.residual = True

    # ------------------------------------------------------------------ the plan

    def command(self, t: np.ndarray) -> np.ndarray:
        """The commanded boresight of each shot at times ``t`` (n,) [s] of the next interval
        (module docstring: a new plan when the last is ``GAP_PLAN_INTERVALS`` old or ran
        short, then this interval's sweep of its candidates).

        Returns
        -------
        (n, 3, 3) float64 matrices sending commanded-sensor vectors to the nominal sensor frame
        (the attitude offset the pipeline applies).
        """
        t = np.asarray(t, dtype=np.float64)
        if self._short or self._age >= GAP_PLAN_INTERVALS:
            self._plan()
        pick, out = np.full(len(t), -1), np.tile(self.boresight, (len(t), 1))
        if len(self._keys) and len(t):
            pick, out = self._sweep(t)
            self.boresight = out[-1]
        self._age += 1
        self._short = bool((pick < 0).any())
        self._after_interval(bool((pick >= 0).any()))
        return turn_from_boresight(out)

    def _plan(self) -> None:
        """Take what was observed into the map and choose the candidates of the next
        ``GAP_PLAN_INTERVALS`` intervals: one per cube of ``GAP_BLOCK_VOXELS`` voxels."""
        self._update()
        self._age = 0
        keys = np.zeros(0, dtype=np.int64) if self.map is None else self._candidates()
        self._keys = _spread(keys, GAP_BLOCK_VOXELS)
        self._centres = self.map.centres(self._keys) if len(keys) else np.zeros((0, 3))
        self._used = np.zeros(len(self._keys), dtype=bool)

    def _sweep(self, t: np.ndarray) -> np.ndarray:
        """Aim the shots at times ``t`` (n,) [s] of one interval: the plan's candidates not yet
        aimed at, predicted visible from the interval's middle shot and within the offset
        limit, those predicted hidden ``GAP_HORIZON_INTERVALS`` intervals on first, in a sweep.

        Returns
        -------
        pick : (n,) int: the open candidate each shot aims at, or -1 (held)
        boresight : (n, 3) float64, unit vectors, nominal sensor frame
        """
        n = len(t)
        open_ = np.flatnonzero(~self._used)
        centres = self._centres[open_]
        lookahead = t[-1] + GAP_HORIZON_INTERVALS * n * self.step
        position, target, nominal = self._poses(np.append(t, lookahead))
        m_ib = target.as_matrix().transpose(0, 2, 1)
        chaser = np.einsum("nij,nj->ni", m_ib, position)              # B
        to_nominal = np.matmul(m_ib, nominal).transpose(0, 2, 1)       # sends B to nominal
        middle = n // 2
        seen = self.map.visible(chaser[[middle, n]], centres)
        aim = (centres - chaser[middle]) @ to_nominal[middle].T
        aim /= np.linalg.norm(aim, axis=1)[:, None]
        ok = np.flatnonzero(seen[0] & (aim[:, 2] >= math.cos(self.max_offset)))
        # The sweep: rows two voxels wide as seen from the chaser, alternately left and right.
        band = GAP_BLOCK_VOXELS * self.map.size / np.linalg.norm(chaser[middle])
        row = np.floor(aim[ok, 1] / band).astype(np.int64)
        across = np.where(row % 2 == 0, aim[ok, 0], -aim[ok, 0])
        # The sweep goes on from the boresight's row: the rows below it first, then from the top.
        later = row >= math.floor(float(self.boresight[1]) / band)
        chosen = ok[np.lexsort((across, row, ~later, seen[1, ok]))][:n]
        self._used[open_[chosen]] = True
        pick = np.full(n, -1)
        pick[:len(chosen)] = chosen
        return pick, self._steer(pick, centres, chaser[:n], to_nominal[:n])

    def _steer(self, pick: np.ndarray, centres: np.ndarray, chaser: np.ndarray,
               to_nominal: np.ndarray) -> np.ndarray:
        """Boresights (n, 3) that aim shot ``k`` at ``centres[pick[k]]`` (hold where ``pick``
        is -1), within ``max_offset`` of the nominal one and ``max_rate`` per step.

        Parameters
        ----------
        pick : (n,) int: candidate of each shot, or -1
        centres : (c, 3) float64, metres, B
        chaser : (n, 3) float64, metres, B: the chaser at each shot
        to_nominal : (n, 3, 3) float64: sends B vectors to the nominal sensor frame per shot
        """
        n = len(pick)
        aimed = pick >= 0
        g = np.einsum("nij,nj->ni", to_nominal[aimed], centres[pick[aimed]] - chaser[aimed])
        g /= np.linalg.norm(g, axis=1)[:, None]
        # Within the offset limit: a goal beyond it goes onto the cone's edge, toward it.
        cos = math.cos(self.max_offset)
        beyond = g[:, 2] < cos
        side = g[beyond, :2] / np.linalg.norm(g[beyond, :2], axis=1)[:, None]
        g[beyond] = np.column_stack([math.sin(self.max_offset) * side,
                                     np.full(len(side), cos)])
        goal = np.empty((n, 3))
        goal[aimed] = g
        # Hold the last goal where nothing is picked.
        last = np.maximum.accumulate(np.where(aimed, np.arange(n), -1))
        goal = np.where((last >= 0)[:, None], goal[np.maximum(last, 0)], self.boresight)
        # Within the rate limit: turn toward a goal beyond one step's reach.
        reach = self.max_rate * self.step
        before = np.vstack([self.boresight, goal[:-1]])
        turn = np.arccos(np.clip(np.einsum("ni,ni->n", goal, before), -1.0, 1.0))
        late = np.flatnonzero(turn > reach)
        if len(late):
            b = goal[late[0] - 1] if late[0] else self.boresight
            for k in range(late[0], n):          # only once a goal is out of reach
                b = goal[k] = _turn_toward(b, goal[k], reach)
        return goal


def _spread(keys: np.ndarray, block: int) -> np.ndarray:
    """The first of ``keys`` (sorted) in each cube of ``block`` voxels on a side: candidates
    that one strike each settles, evenly over the map."""
    cube = pack(np.floor_divide(unpack(keys), block))
    return keys[np.sort(np.unique(cube, return_index=True)[1])]


def merge_chunks(chunks: list[StrikeChunk]) -> StrikeChunk:
    """One chunk of consecutive chunks (each with its shots, the shots following on)."""
    if len(chunks) == 1:
        return chunks[0]
    shots = Shots(*(np.concatenate([getattr(c.shots, name) for c in chunks]) for name in
                    ("time", "sensor_position", "sensor_attitude", "target_attitude")))
    return StrikeChunk(start=chunks[0].start, shot=np.concatenate([c.shot for c in chunks]),
                       beam=np.concatenate([c.beam for c in chunks]),
                       range=np.concatenate([c.range for c in chunks]),
                       direction=np.concatenate([c.direction for c in chunks]), shots=shots,
                       shot_offset=chunks[0].shot_offset)


def _turn_toward(b: np.ndarray, goal: np.ndarray, angle: float) -> np.ndarray:
    """Unit vector ``b`` turned toward ``goal`` by ``angle`` [rad] in their common plane."""
    (bx, by, bz), (gx, gy, gz) = b.tolist(), goal.tolist()      # three floats: plain Python
    cos = min(max(bx * gx + by * gy + bz * gz, -1.0), 1.0)
    if math.acos(cos) <= angle:
        return goal
    sx, sy, sz = gx - cos * bx, gy - cos * by, gz - cos * bz
    norm = math.sqrt(sx * sx + sy * sy + sz * sz)
    c, s = math.cos(angle), math.sin(angle) / norm
    return np.array([c * bx + s * sx, c * by + s * sy, c * bz + s * sz])
