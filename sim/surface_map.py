"""A voxel map of what the beams have struck and the space they crossed, in the body frame.

Built only from what a strike log records (the recorded sensor positions, attitudes and ranges),
never from the truth, and used by the gap-seeking law (sim/gap_seeking.py) to decide where the
next shots should go.

Voxels are cubes of edge ``size`` [m] on a grid of the body frame B; voxel ``(i, j, k)`` holds
the points ``size * ((i, j, k) + [0, 1)^3)``. A voxel is

- **occupied** when a strike fell in it; the map keeps its strike count and the sum of the unit
  vectors from its strikes to the sensor (the side it was seen from);
- **free** when a beam crossed it without striking (each beam marks the voxels along its path
  up to one voxel short of its strike, or through the whole region of interest when it struck
  nothing), unless it is occupied;
- **unknown** otherwise.

Voxel keys are the three integer indices packed into one int64. The occupied voxels are a sorted
key array with their counts and views; the state of every voxel (occupied, crossed, frontier,
enclosed; in its upper bits the planner's count of walks that found the voxel hidden) is a byte
in a dense grid over the box of the occupied voxels grown by the traversal margin, reallocated
larger when that box grows, so that marking a beam's path or looking a voxel up is
one indexing operation. Beams are traversed by sampling every ``size / TRAVERSAL_STEP`` along
them. The update (strikes, carving, the grid's growth: :meth:`SurfaceMap.add`), the planner's
reading of the map (:meth:`SurfaceMap.candidates`) and the visibility walk below are compiled
kernels (sim/planner_kernels.py), one call each.

The **frontier** is the unknown voxels next to (sharing a face with) an occupied voxel: where
the seen surface continues into space no beam has examined. It is kept up to date as voxels are
struck and crossed (a struck voxel marks its unknown neighbours and adds them to a key list; a
struck or crossed voxel leaves the frontier, and the list when it is next read). A thin plate
seen from one side keeps the unknown voxels behind it, so it stays on the frontier until a beam
from its other side strikes it (space behind a plate is joined to the outside around its rim).
A solid body's unknown interior is frontier too until :meth:`SurfaceMap.enclose` finds it
enclosed: once the space outside, filled from the faces of the occupied voxels' box through
voxels not occupied with gaps of up to two voxels between occupied ones taken as closed (a
surface struck voxel by voxel leaves unstruck voxels at its corners), comes nowhere near it
(its struck shell is closed), it is marked ``ENCLOSED`` and is frontier no more, for good. An
unknown voxel in a gap of the struck surface lies next to that outside space and stays
frontier, as does the space behind a plate.

:meth:`SurfaceMap.visible` predicts whether a planned beam from a position reaches a voxel by
walking the beam's line voxel by voxel within the occupied voxels' box, backward from the voxel
toward the position: it is hidden when the beam passes close to the centre of an occupied voxel
nearer than itself (``BLOCK_RADIUS``, ``BLOCK_SLACK``). The walk reads a bit per voxel of the
occupied voxels' box (:meth:`SurfaceMap.occupancy`, kept up to date as voxels are struck for
the first time), not the state grid: a few kilobytes instead of megabytes.
"""

from __future__ import annotations

import numpy as np

# Voxel indices are offset by 2**20 and packed in 21 bits each: +-1e6 voxels per axis.
_BITS = 21
_OFFSET = 1 << (_BITS - 1)
_MASK = (1 << _BITS) - 1
# Samples per voxel edge along a beam: at half a voxel, a beam skips only voxels it clips by
# less than a quarter of their edge.
TRAVERSAL_STEP = 2.0
# A beam toward a voxel is stopped by an occupied voxel it crosses whose centre lies within
# BLOCK_RADIUS edges of the beam's line and nearer than the voxel's by more than BLOCK_SLACK edges:
# the voxel right behind a struck one (one edge) is hidden, one beside it is not, and a beam
# clipping the corner of a struck voxel passes (a struck voxel holds surface somewhere in it, not
# everywhere). Against beams cast at the voxels as boxes (tests/sim/test_surface_map.py) 89 % of
# what these values predict visible is, and 93 % of what is visible is predicted so (radius 0.5:
# 77 % and 100 %; 0.7: 98 % and 79 %), as the depth image they replace (90 % and 90 %).
BLOCK_RADIUS = 0.62
BLOCK_SLACK = 0.5
# The six face neighbours.
FACE_STEPS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
# Bits of a voxel's state in the grid.
OCCUPIED, CROSSED, FRONTIER, ENCLOSED = np.uint8(1), np.uint8(2), np.uint8(4), np.uint8(8)
# The state's upper four bits are the planner's: how many times a walk toward the voxel found it
# hidden (sim/gap_seeking.py, the set-aside candidates), in steps of HIDDEN_STEP up to HIDDEN_MAX.
HIDDEN_STEP, HIDDEN_MAX = 16, 15
# When the grid must grow, it grows by this fraction of its edge on every side beyond what is
# needed, so that a map seen piece by piece is reallocated a few times only.
_GROW = 0.25


def pack(index: np.ndarray) -> np.ndarray:
    """Keys (n,) int64 of voxel indices (n, 3) int."""
    i = np.asarray(index, dtype=np.int64) + _OFFSET
    return (i[:, 0] << (2 * _BITS)) | (i[:, 1] << _BITS) | i[:, 2]


def unpack(keys: np.ndarray) -> np.ndarray:
    """Voxel indices (n, 3) int64 of keys (n,) int64."""
    k = np.asarray(keys, dtype=np.int64)
    return np.stack([(k >> (2 * _BITS)) & _MASK, (k >> _BITS) & _MASK, k & _MASK],
                    axis=1) - _OFFSET


def member(keys: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Which ``keys`` (n,) are in the sorted unique array ``table``: (n,) bool."""
    if not len(table):
        return np.zeros(len(keys), dtype=bool)
    at = np.minimum(np.searchsorted(table, keys), len(table) - 1)
    return table[at] == keys


class SurfaceMap:
    """Occupied, crossed and frontier voxels of edge ``size`` [m] (see the module docstring).

    Parameters
    ----------
    size : float, metres
        Voxel edge.
    """

    def __init__(self, size: float):
        if not size > 0:
            raise ValueError(f"size must be positive, got {size!r}")
        self.size = float(size)
        self.occupied = np.zeros(0, dtype=np.int64)      # sorted keys
        self.count = np.zeros(0, dtype=np.int64)         # strikes per occupied voxel
        self.view = np.zeros((0, 3))                     # sum of unit vectors strike -> sensor
        self._state = np.zeros((0, 0, 0), dtype=np.uint8)   # OCCUPIED | CROSSED | FRONTIER
        self._corner = np.zeros(3, dtype=np.int64)      # voxel index of _state[0, 0, 0]
        self._shape = np.zeros(3, dtype=np.int64)       # _state.shape
        self._frontier = np.zeros(0, dtype=np.int64)    # sorted keys, each once a frontier
        self._index_lo = np.zeros(3, dtype=np.int64)    # the occupied voxels' index box
        self._index_hi = np.zeros(3, dtype=np.int64)
        self._enclosed_at = 0                           # occupied voxels at the last enclose
        self._solid = np.zeros(1, dtype=np.uint8)       # occupancy over the index box

    @property
    def occupied_centres(self) -> np.ndarray:
        """Centres (o, 3) [m, B] of the occupied voxels, in the order of ``occupied``."""
        return self.centres(self.occupied)

    def keys_of(self, points: np.ndarray) -> np.ndarray:
        """Keys (n,) of the voxels holding ``points`` (n, 3) [m, B]."""
        return pack(np.floor(points / self.size).astype(np.int64))

    def centres(self, keys: np.ndarray) -> np.ndarray:
        """Centres (n, 3) [m, B] of the voxels ``keys`` (n,)."""
        return (unpack(keys) + 0.5) * self.size

    def bounds(self, margin: float) -> tuple[np.ndarray, np.ndarray]:
        """Box of the occupied voxels grown by ``margin`` [m] on every side."""
        return (self._index_lo * self.size - margin, (self._index_hi + 1) * self.size + margin)

    # ------------------------------------------------------------------ the grid

    def _cover(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Grow the grid to hold the voxel indices ``lo`` .. ``hi`` (3,) (inclusive)."""
        shape, corner = self._shape, self._corner
        (c0, c1, c2), (s0, s1, s2) = corner.tolist(), shape.tolist()
        (l0, l1, l2), (h0, h1, h2) = lo.tolist(), hi.tolist()
        if (self._state.size and c0 <= l0 and c1 <= l1 and c2 <= l2 and h0 < c0 + s0
                and h1 < c1 + s1 and h2 < c2 + s2):
            return
        old_hi = corner + shape - 1
        if self._state.size:
            lo, hi = np.minimum(lo, self._corner), np.maximum(hi, old_hi)
        pad = np.ceil(_GROW * (hi - lo + 1)).astype(np.int64)
        corner, new_shape = lo - pad, hi - lo + 1 + 2 * pad
        state = np.zeros(tuple(int(n) for n in new_shape), dtype=np.uint8)
        if self._state.size:
            at = self._corner - corner
            state[at[0]:at[0] + shape[0], at[1]:at[1] + shape[1],
                  at[2]:at[2] + shape[2]] = self._state
        self._state, self._corner = state, corner
        self._shape = np.array(state.shape, dtype=np.int64)

    def _cells(self, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Flat grid positions (n,) of voxel indices (n, 3), and which of them the grid holds."""
        local = index - self._corner
        shape = np.array(self._state.shape)
        inside = ((local >= 0) & (local < shape)).all(axis=1)
        local = np.where(inside[:, None], local, 0)
        return np.ravel_multi_index(local.T, self._state.shape), inside

    def _keys_of_cells(self, flat: np.ndarray) -> np.ndarray:
        """Keys (n,) of the flat grid positions ``flat`` (n,)."""
        return pack(np.column_stack(np.unravel_index(flat, self._state.shape)) + self._corner)

    # ------------------------------------------------------------------ adding beams

    def add(self, origins: np.ndarray, directions: np.ndarray, ranges: np.ndarray, *,
            margin: float) -> None:
        """Add beams: each struck at ``origins + ranges * directions`` or, where ``ranges`` is
        inf, struck nothing. The strikes' voxels become occupied (their unknown face
        neighbours frontier), then the voxels each beam crossed before its strike free
        (compiled, one call: sim/planner_kernels.py, ``add``).

        Parameters
        ----------
        origins : (n, 3) float64, metres, B: sensor position of each beam
        directions : (n, 3) float64, unit vectors, B
        ranges : (n,) float64, metres (inf: no strike)
        margin : float, metres
            Misses and the paths of strikes are traversed within the box of the occupied voxels
            grown by this much (space far from the target holds nothing to plan for).
        """
        from sim import planner_kernels as kernels

        margin = float(margin)
        while True:
            (self.occupied, self.count, self.view, self._frontier, self._index_lo,
             self._index_hi, self._solid, status, lo, hi) = kernels.add(
                origins, directions, ranges, self.size, margin, self.occupied, self.count,
                self.view, self._frontier, self._state.reshape(-1), self._shape,
                self._corner, self._index_lo, self._index_hi, self._solid)
            if status == kernels.ADDED:
                return
            self._cover(lo, hi)         # the grid grows (rarely), then the step left is done
            if status == kernels.CARVE:
                box_lo, box_hi = self.bounds(margin)
                kernels.carve(origins, directions, ranges, box_lo, box_hi, self.size,
                              self._state.reshape(-1), self._shape, self._corner)
                return

    # ------------------------------------------------------------------ reading the map

    @property
    def free(self) -> np.ndarray:
        """Sorted keys (m,) of the voxels a beam crossed (some may be occupied too)."""
        return self._keys_of_cells(np.flatnonzero(self._state.reshape(-1) & CROSSED))

    def frontier(self) -> np.ndarray:
        """Sorted keys (m,) of the unknown voxels sharing a face with an occupied voxel."""
        from sim import planner_kernels as kernels

        if len(self._frontier):
            self._frontier = kernels.frontier_keep(
                self._frontier, self._state.reshape(-1),
                self._shape, self._corner)
        return self._frontier

    @property
    def frontier_count(self) -> int:
        """How many keys the frontier list holds as the last :meth:`frontier` or
        :meth:`candidates` left it (voxels struck or enclosed since then still counted)."""
        return len(self._frontier)

    def candidates(self, *, rank: int, aside: int, readmit: bool, most: int, block: int,
                   stored: np.ndarray, stored_hidden: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The planner's candidates (sim/gap_seeking.py) in one compiled call: the hidden
        counts ``stored_hidden`` (s,) of the voxels ``stored`` (s,) kept in the grid first;
        then the frontier (:meth:`frontier`), with ``rank`` >= 0 joined by the occupied voxels
        struck at most as often as the ``rank``-th least-struck one and less the voxels whose
        hidden count reaches ``aside`` (with ``readmit``, none: every count cleared); an even
        subset of at most ``most``; the first in each cube of ``block`` voxels on a side
        (sim/planner_kernels.py, ``candidates``).

        Returns
        -------
        keys : (c,) int64; centres : (c, 3) float64, metres, B; hidden : (c,) int64: the
        chosen voxels, their centres and hidden counts.
        """
        from sim import planner_kernels as kernels

        self._frontier, keys, centres, hidden = kernels.candidates(
            stored, stored_hidden, self._frontier, self._state.reshape(-1), self._shape,
            self._corner, self.occupied, self.count, rank, aside, readmit, most, block,
            self.size)
        return keys, centres, hidden

    def enclose(self) -> int:
        """Mark the unknown voxels the occupied ones enclose (a body's interior behind its
        struck shell; gaps of up to two voxels in the shell taken as closed, an unknown voxel
        in such a gap kept: sim/planner_kernels.py, ``enclose``) as no frontier, for good
        (voxels only ever become occupied, so an enclosed voxel stays enclosed; with no voxel
        struck for the first time since the last call there is nothing new to mark). A flood
        fill over the occupied voxels' box, compiled. Returns how many voxels were marked now."""
        from sim import planner_kernels as kernels

        if len(self.occupied) == self._enclosed_at:     # nothing struck since: nothing new
            return 0
        self._enclosed_at = len(self.occupied)
        self._cover(self._index_lo - 2, self._index_hi + 2)
        return int(kernels.enclose(self._state.reshape(-1), self._shape, self._corner,
                                   self._index_lo, self._index_hi))

    def surface_frontier(self) -> np.ndarray:
        """Sorted keys (m,) of the occupied voxels sharing a face with a frontier voxel: seen
        surface next to unknown space (a plate seen from one side among them)."""
        frontier = self.frontier()
        index = unpack(self.occupied)
        near = np.zeros(len(self.occupied), dtype=bool)
        for step in FACE_STEPS:
            near |= member(pack(index + step), frontier)
        return self.occupied[near]

    def grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The flat state grid (g,) uint8, its shape and the voxel index of its first cell
        (3,) int64: what the planner's kernels index by voxel (sim/planner_kernels.py)."""
        return self._state.reshape(-1), self._shape, self._corner

    def occupancy(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What a walk through the map reads (sim/planner_kernels.py, ``_blocked``): a bit
        per voxel of the occupied voxels' index box, set where occupied ((ceil(g / 8),) uint8
        for the box's g voxels: ``occupancy`` there), and that box's low and high corners (3,)
        int64. Kept by :meth:`add`: made again when the box grows, the bits of new voxels set
        in place otherwise."""
        return self._solid, self._index_lo, self._index_hi

    def visible(self, positions: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """Predict which beams from ``positions`` reach the voxels centred at ``targets``
        before entering an occupied voxel (a walk through the map: module docstring).

        Parameters
        ----------
        positions : (p, 3) or (3,) float64, metres, B
        targets : (n, 3) float64, metres, B: voxel centres

        Returns
        -------
        (p, n) bool, or (n,) for one position given as (3,): False where the beam from the
        position toward the target's centre enters an occupied voxel other than the target's
        own before reaching it.
        """
        from sim import planner_kernels as kernels

        one = np.ndim(positions) == 1
        positions = np.atleast_2d(np.asarray(positions, dtype=np.float64))
        seen = np.ones((len(positions), len(targets)), dtype=bool)
        if len(self.occupied) and len(targets):
            seen = ~kernels.hidden(positions, np.asarray(targets, dtype=np.float64), self.size,
                                   *self.occupancy())
        return seen[0] if one else seen
