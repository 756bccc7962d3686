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
beam has examined, including the far side of a thin plate seen from one side; less the unknown
voxels the struck ones enclose (a body's interior once its struck shell is closed,
:meth:`SurfaceMap.enclose`), which a plan finds again when ``GAP_ENCLOSE_INTERVALS`` intervals
have passed since the last time (a flood fill over the map: too costly for every plan), the
wait doubled after a fill that found nothing new (no more than ``GAP_ENCLOSE_MIN_FRACTION`` of
the occupied voxels), up to ``GAP_ENCLOSE_MAX_INTERVALS``.

**The plan** (:meth:`GapSeeker.command`). The law plans at most ``GAP_PLAN_INTERVALS`` intervals
apart (``GAP_LARGE_PLAN_INTERVALS`` while the frontier holds more voxels than a plan weighs,
``GAP_MAX_CANDIDATES``; ``GAP_SETTLED_PLAN_INTERVALS`` late in the least-struck phase, below): it
takes the
intervals observed since into the map (all at once) and chooses the plan's candidates, the
frontier voxels, one per cube of ``GAP_BLOCK_VOXELS`` voxels on a side (a strike is expected to
settle the frontier around its aim). Every interval it then predicts, from its orbit and the
known spin, where the chaser is in B at the interval's middle shot. The candidates not yet aimed
at and within ``attitude.max_offset_deg`` of the nominal boresight are taken in a sweep, rows
two voxels wide across the view, alternately left and right, going on from the boresight's row
(the rows below it, then from the top), so that consecutive aims lie next to each other; each is
taken by the next shot when a beam from there is predicted to reach it before a struck voxel (a
walk through the map, :meth:`SurfaceMap.visible`), until every shot has one (so a large map
costs no more visibility tests than the shots need). A shot whose aim is beyond one step's reach
(``max_rate * step``) turns toward it at the rate limit; shots left over when the visible
candidates run out hold the boresight, and while the frontier lasts the law plans anew before
the next interval (its candidates are used up; the map has grown); in the least-struck phase
(below) it waits for the next plan on its cadence. So the map, the frontier and the candidates
cost once per plan, the prediction and the sweep once per interval; a plan is three compiled
calls (the recorded beams, the map's update, the candidates; a fourth when the enclosed voxels
are due) and an interval's sweep one (sim/planner_kernels.py). The poses of an interval (where
the chaser is, the target's attitude, the nominal sensor frame) are those the simulation
computes for its shots anyway, handed to :meth:`GapSeeker.command`.

**When the frontier runs out** (``GAP_IDLE_INTERVALS`` intervals in a row with nothing visible
to aim at) the least-struck surface voxels join the candidates for the rest of the run
(``GAP_RESIDUAL_QUANTILE``): a voxel holding one strike can hold surface farther than the
coverage tolerance from it, and a voxel an oblique beam crossed beside a thin panel is marked
free although part of the panel lies in it. So the law keeps striking the surface it has seen
least, where a fixed slew would keep sweeping, and never idles. In this phase a plan comes
every ``GAP_PLAN_INTERVALS`` intervals and no sooner: an interval that runs out of visible
candidates holds its remaining shots (most of its candidates are hidden from any one place, so
a plan at once finds little new; planning after every short interval made 1.4-2.1 times as many
plans on the spacecraft: docs/decisions.md); once the phase has lasted
``GAP_SETTLED_INTERVALS`` intervals (the settled phase), every ``GAP_SETTLED_PLAN_INTERVALS``,
each plan weighing at most ``GAP_SETTLED_MAX_CANDIDATES`` candidates. When the frontier ran out
because the struck surface closed around it (at most ``GAP_CLOSED_FRONTIER_FRACTION`` frontier
voxels per occupied voxel left: a closed body's shell enclosed), the phase is settled from its
start and plans every ``GAP_CLOSED_PLAN_INTERVALS``. With no candidate at all the boresight
holds its offset (no slew).

**Candidates set aside** (in that least-struck phase). Late in a run most candidates are hidden
from any one place (least-struck voxels hard to see, unknown voxels inside a shell not yet
closed), and an interval that finds fewer visible than it has shots walks them all. So each
candidate keeps a count of the walks that found it hidden (in the map's grid, from plan to
plan); one found hidden ``GAP_ASIDE_WALKS`` times (``GAP_SETTLED_ASIDE_WALKS`` in the settled
phase) is set aside: not walked again by the plan that holds it, not chosen by the next ones. A
plan re-admits every set-aside candidate of its pool (their counts cleared) once
``GAP_ASIDE_INTERVALS`` intervals have passed since the last re-admission, as the chaser's view
of the target turns with its orbit and the target's spin; a rebuilt map starts with none. While
the frontier lasts nothing is set aside (setting aside there too was measured slower to 95 %
coverage: docs/decisions.md).

The commanded attitude is the nominal one (sim/motion.py) turned by the smallest rotation that
takes the nominal boresight ``+z`` onto the commanded one, and is recorded like any other.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from formats.strike_log import StrikeChunk
from sim.defaults import (
    GAP_ASIDE_INTERVALS,
    GAP_ASIDE_WALKS,
    GAP_BLOCK_VOXELS,
    GAP_CLOSED_FRONTIER_FRACTION,
    GAP_CLOSED_PLAN_INTERVALS,
    GAP_ENCLOSE_INTERVALS,
    GAP_ENCLOSE_MAX_INTERVALS,
    GAP_ENCLOSE_MIN_FRACTION,
    GAP_IDLE_INTERVALS,
    GAP_LARGE_PLAN_INTERVALS,
    GAP_MARGIN_FRACTION,
    GAP_MAX_CANDIDATES,
    GAP_PLAN_INTERVALS,
    GAP_RESIDUAL_QUANTILE,
    GAP_SETTLED_ASIDE_WALKS,
    GAP_SETTLED_INTERVALS,
    GAP_SETTLED_MAX_CANDIDATES,
    GAP_SETTLED_PLAN_INTERVALS,
    GAP_VOXEL_FRACTION,
    GAP_VOXEL_MIN_DEG,
    GAP_VOXEL_REBUILD,
)
from sim.surface_map import SurfaceMap

# A hidden count no sweep reaches: nothing is set aside while the frontier lasts.
_NEVER_ASIDE = 1 << 62


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


def recorded_beams(chunks: list[StrikeChunk], beams: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every beam of every shot of consecutive ``chunks``, from what the log records, in B
    (compiled: sim/planner_kernels.py).

    Parameters
    ----------
    chunks : list of StrikeChunk
        Consecutive blocks, each with all its shots (the shots following on): the strikes of
        shots ``chunks[0].shot_offset ..`` and those shots (``chunk.shots``).
    beams : (b, 3) float64, unit vectors, sensor frame: the sensor's beam directions

    Returns
    -------
    origins : (m, 3) float64, metres, B: the recorded sensor position of each beam
    directions : (m, 3) float64, unit vectors, B: measured for strikes, nominal for misses
    ranges : (m,) float64, metres: recorded range, inf for a beam that struck nothing
    stats : (9,) float64: the strikes' box low and high corners [m, B], their number, the sum
        of their ranges [m] and their farthest distance from B's origin [m]
    """
    from sim import planner_kernels as kernels

    def joined(arrays, dtype=np.float64):       # one array of the chunks', as the kernel takes
        return np.asarray(arrays[0] if len(arrays) == 1 else np.concatenate(arrays), dtype=dtype)

    shots = [c.shots for c in chunks]
    return kernels.recorded_beams(
        joined([c.shot for c in chunks], np.int64) - chunks[0].shot_offset,
        joined([c.beam for c in chunks], np.int64), joined([c.range for c in chunks]),
        joined([c.direction for c in chunks]), joined([s.sensor_position for s in shots]),
        joined([s.sensor_attitude for s in shots]), joined([s.target_attitude for s in shots]),
        beams)


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
        from sim.planner_kernels import sweep  # compiled (numba): closed loops only

        self.step, self.max_rate, self.max_offset = step, max_rate, max_offset
        self._sweep, self._reach = sweep, max_rate * step    # the largest turn between shots
        self._poses = poses
        self.beams = np.asarray(beams, dtype=np.float64).reshape(-1, 3)
        self.boresight = np.array([0.0, 0.0, 1.0])           # commanded, nominal frame
        self._held_turn, self._held_of = None, None          # its rotation, and of which
        self.map: SurfaceMap | None = None
        self._origins, self._directions, self._ranges = [], [], []
        self._pending: list[StrikeChunk] = []                # observed since the last plan
        self._keys = np.zeros(0, dtype=np.int64)             # the plan's candidates,
        self._centres = np.zeros((0, 3))                     # their centres [m, B]
        self._used = np.zeros(0, dtype=bool)                 # and those aimed at or set aside
        self._open = 0                                       # candidates not in _used
        self._hidden = np.zeros(0, dtype=np.int64)           # walks that found them hidden
        self._occupancy = None                               # the map's, as the plan left it
        self._age = 0                                        # intervals since the plan
        self._short = True                                   # the last interval held a shot
        self._lo = [math.inf] * 3                            # strikes' bounding box [m, B]
        self._hi = [-math.inf] * 3
        self._diagonal = math.nan                            # of that box [m] (nan: stale)
        self.n_strikes = 0
        self._range_sum = 0.0
        self._radius = 0.0                                   # farthest strike from the centre
        self.residual = False                                # frontier exhausted
        self._idle = 0                                       # intervals with nothing to aim at
        self._residual_from = 0                              # interval the phase began
        self._settle_after = GAP_SETTLED_INTERVALS           # intervals into it: settled
        self._settled_wait = GAP_SETTLED_PLAN_INTERVALS      # then plans this far apart
        self._large = False                                  # frontier > GAP_MAX_CANDIDATES
        self._interval = 0                                   # intervals commanded so far
        self._readmitted = 0                                 # at the last re-admission
        self._enclosed = -GAP_ENCLOSE_INTERVALS              # at the last enclose,
        self._enclose_wait = GAP_ENCLOSE_INTERVALS           # and intervals until the next

    # ------------------------------------------------------------------ the map

    def voxel_size(self) -> float:
        """The voxel edge [m] the strikes so far call for (module docstring)."""
        diagonal = max(self._box_diagonal(), 2.0 * self._radius)
        distance = self._range_sum / self.n_strikes
        return max(GAP_VOXEL_FRACTION * diagonal,
                   distance * math.tan(math.radians(GAP_VOXEL_MIN_DEG)))

    def _box_diagonal(self) -> float:
        """The diagonal [m] of the strikes' bounding box (computed again only when it grew)."""
        if math.isnan(self._diagonal):
            self._diagonal = float(np.linalg.norm(np.subtract(self._hi, self._lo)))
        return self._diagonal

    def _margin(self) -> float:
        return GAP_MARGIN_FRACTION * self._box_diagonal()

    def observe(self, chunk: StrikeChunk) -> None:
        """Take the recorded shots and strikes of an interval (a block as
        ``StrikeLog.iter_chunks`` yields, with all its shots); they go into the map when the
        law next plans."""
        self._pending.append(chunk)

    def _update(self) -> None:
        """Add the intervals observed since the last plan to the map, all at once."""
        if not self._pending:
            return
        origins, directions, ranges, stats = recorded_beams(self._pending, self.beams)
        self._pending = []
        self._origins.append(origins)
        self._directions.append(directions)
        self._ranges.append(ranges)
        stats = stats.tolist()
        if stats[6]:
            lo = [min(a, b) for a, b in zip(self._lo, stats[:3], strict=True)]
            hi = [max(a, b) for a, b in zip(self._hi, stats[3:6], strict=True)]
            if lo != self._lo or hi != self._hi:
                self._lo, self._hi, self._diagonal = lo, hi, math.nan
            self.n_strikes += int(stats[6])
            self._range_sum += stats[7]
            self._radius = max(self._radius, stats[8])
        if self.n_strikes == 0:
            return
        size = self.voxel_size()
        if self.map is None or abs(math.log(size / self.map.size)) > math.log(GAP_VOXEL_REBUILD):
            self._rebuild(size)
        else:
            self.map.add(origins, directions, ranges, margin=self._margin())

    def _rebuild(self, size: float) -> None:
        """A new map of edge ``size`` [m] from every recorded beam: all strikes first (so the
        region traversed is the whole target's), then the free space."""
        self.map = SurfaceMap(size)
        self._origins = [np.concatenate(self._origins)]
        self._directions = [np.concatenate(self._directions)]
        self._ranges = [np.concatenate(self._ranges)]
        self.map.add(self._origins[0], self._directions[0], self._ranges[0],
                     margin=self._margin())

    def _settled(self) -> bool:
        """Whether the least-struck phase has lasted ``GAP_SETTLED_INTERVALS`` intervals (on a
        closed map, whether it has begun: :meth:`_after_interval`)."""
        return (self.residual and
                self._interval - self._residual_from >= self._settle_after)

    def _candidates(self, stored: np.ndarray | None = None,
                    stored_hidden: np.ndarray | None = None, *, block: int = GAP_BLOCK_VOXELS
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The voxels worth a shot: the frontier, and once it is exhausted, the least-struck
        surface voxels too, less those set aside (all re-admitted when ``GAP_ASIDE_INTERVALS``
        intervals have passed since the last time); an even subset of at most
        ``GAP_MAX_CANDIDATES`` (``GAP_SETTLED_MAX_CANDIDATES`` in the settled phase), one per
        cube of ``block`` voxels (one compiled call,
        :meth:`SurfaceMap.candidates`, which first keeps the hidden counts ``stored_hidden``
        of the last plan's candidates ``stored``, if any, in the map's grid).

        Returns
        -------
        keys : (c,) int64; centres : (c, 3) float64, metres, B; hidden : (c,) int64
        """
        if self._interval - self._enclosed >= self._enclose_wait:
            marked = self.map.enclose()
            self._enclosed = self._interval
            self._enclose_wait = (
                GAP_ENCLOSE_INTERVALS if marked > GAP_ENCLOSE_MIN_FRACTION * len(self.map.count)
                else min(2 * self._enclose_wait, GAP_ENCLOSE_MAX_INTERVALS))
        rank, readmit = -1, False
        if self.residual:     # count <= np.quantile(count, GAP_RESIDUAL_QUANTILE), compiled
            rank = math.floor((len(self.map.count) - 1) * GAP_RESIDUAL_QUANTILE)
            readmit = self._interval - self._readmitted >= GAP_ASIDE_INTERVALS
            if readmit:
                self._readmitted = self._interval
        if stored is None:
            stored = stored_hidden = np.zeros(0, dtype=np.int64)
        settled = self._settled()
        return self.map.candidates(
            rank=rank, aside=GAP_SETTLED_ASIDE_WALKS if settled else GAP_ASIDE_WALKS,
            readmit=readmit, most=GAP_SETTLED_MAX_CANDIDATES if settled else GAP_MAX_CANDIDATES,
            block=block, stored=stored, stored_hidden=stored_hidden)

    def _after_interval(self, aimed: bool) -> None:
        """Count intervals with nothing to aim at; after ``GAP_IDLE_INTERVALS`` of them in a
        row the frontier is taken as exhausted and the least-struck surface voxels join it; the
        phase is settled from its start when at most ``GAP_CLOSED_FRONTIER_FRACTION`` frontier
        voxels per occupied voxel are left (the struck surface closed around the frontier)."""
        self._idle = 0 if aimed else self._idle + 1
        if self._idle >= GAP_IDLE_INTERVALS and not self.residual:
            self.residual = True
            self._residual_from = self._interval
            if self.map is not None and (len(self.map.frontier()) <= GAP_CLOSED_FRONTIER_FRACTION
                                         * len(self.map.occupied)):
                self._settle_after, self._settled_wait = 0, GAP_CLOSED_PLAN_INTERVALS

    # ------------------------------------------------------------------ the plan

    def command(self, t: np.ndarray, poses=None) -> np.ndarray:
        """The commanded boresight of each shot at times ``t`` (n,) [s] of the next interval
        (module docstring: a new plan when the last is ``GAP_PLAN_INTERVALS`` old
        (``GAP_LARGE_PLAN_INTERVALS`` while the frontier is larger than a plan weighs;
        ``GAP_SETTLED_PLAN_INTERVALS`` once the least-struck phase has lasted
        ``GAP_SETTLED_INTERVALS``, ``GAP_CLOSED_PLAN_INTERVALS`` from its start on a closed
        map), or while the frontier lasts when the last interval ran short; then this
        interval's sweep of its candidates).

        Parameters
        ----------
        t : (n,) float64, seconds
        poses : tuple, optional
            ``(position, target, nominal)`` at ``t``, as the ``poses`` callable returns them
            (the simulation computes them for its own shots anyway); without it the law calls
            ``poses`` itself.

        Returns
        -------
        (n, 3, 3) float64 matrices sending commanded-sensor vectors to the nominal sensor frame
        (the attitude offset the pipeline applies).
        """
        settled = self._settled()
        wait = (self._settled_wait if settled else GAP_LARGE_PLAN_INTERVALS if self._large
                else GAP_PLAN_INTERVALS)
        if self._age >= wait or (self._short and not self.residual):
            self._plan()
        self._age += 1
        self._interval += 1
        n = len(t)
        if not n or not self._open:     # no candidate open: the sweep would hold every shot
            self._short = True
            self._after_interval(False)
            held = np.empty((n, 3, 3))
            held[:] = self._held()
            return held
        position, target, nominal = (poses if poses is not None else
                                     self._poses(np.asarray(t, dtype=np.float64)))
        solid, lo, hi = self._occupancy
        pick, goal, turn, self._open = self._sweep(
            n, self._centres, self._used, self.map.size, solid, lo, hi, position,
            target.as_matrix(), nominal, self.boresight, self.max_offset, self._reach,
            GAP_BLOCK_VOXELS, self._hidden,
            (_NEVER_ASIDE if not self.residual else
             GAP_SETTLED_ASIDE_WALKS if settled else GAP_ASIDE_WALKS))
        self.boresight = goal[-1]
        first, last = pick[0].item(), pick[-1].item()
        self._short = last < 0
        self._after_interval(first >= 0)
        return turn

    def _plan(self) -> None:
        """Take what was observed into the map and choose the candidates of the next
        ``GAP_PLAN_INTERVALS`` intervals: one per cube of ``GAP_BLOCK_VOXELS`` voxels. The
        last plan's hidden counts are kept in the map's grid (a rebuilt map starts with
        none)."""
        stored, stored_hidden, before = self._keys, self._hidden, self.map
        self._update()
        self._age = 0
        if self.map is not before:
            stored, stored_hidden = stored[:0], stored_hidden[:0]
        self._keys, self._centres = np.zeros(0, dtype=np.int64), np.zeros((0, 3))
        self._hidden = np.zeros(0, dtype=np.int64)
        if self.map is not None:
            self._keys, self._centres, self._hidden = self._candidates(stored, stored_hidden)
            self._large = not self.residual and self.map.frontier_count > GAP_MAX_CANDIDATES
            self._occupancy = self.map.occupancy()      # what the sweeps' walks read
        self._used = np.zeros(len(self._keys), dtype=bool)
        self._open = len(self._keys)

    def _held(self) -> np.ndarray:
        """The rotation (3, 3) of a held shot: :func:`turn_from_boresight`'s matrix of the
        commanded boresight, in Python floats (the same operations; numpy's call overhead on
        one vector cost more than a sweep), made again only when the boresight changed."""
        if self._held_of is not self.boresight:
            x, y, z = self.boresight.tolist()
            k = 1.0 / (1.0 + z)
            self._held_turn = np.array(((1.0 - k * x * x, -k * x * y, x),
                                        (-k * x * y, 1.0 - k * y * y, y), (-x, -y, z)))
            self._held_of = self.boresight
        return self._held_turn
