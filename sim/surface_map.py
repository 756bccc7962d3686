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
key array with their counts and views; the state of every voxel (occupied, crossed, frontier)
is a byte in a dense grid over the box of the occupied voxels grown by the traversal margin,
reallocated larger when that box grows, so that marking a beam's path or looking a voxel up is
one indexing operation. Beams are traversed by sampling every ``size / TRAVERSAL_STEP`` along
them, all beams of a batch at once.

The **frontier** is the unknown voxels next to (sharing a face with) an occupied voxel: where
the seen surface continues into space no beam has examined. It is kept up to date as voxels are
struck and crossed (a struck voxel marks its unknown neighbours and adds them to a key list; a
struck or crossed voxel leaves the frontier, and the list when it is next read). A thin plate
seen from one side keeps the unknown voxels behind it, so it stays on the frontier until a beam
from its other side strikes it; a solid body keeps its unknown interior, which
:meth:`SurfaceMap.visible` predicts hidden once the surface around it is struck.

:meth:`SurfaceMap.visible` predicts whether a planned beam from a position reaches a voxel by a
depth image of the occupied voxels seen from there: pixels of half a voxel edge as seen at the
nearest occupied voxel, each holding the distance of the nearest occupied voxel centre that
falls in it or next to it (a beam cast through each pixel against the map, all at once). A
voxel whose pixel holds a centre nearer than its own by more than ``BLOCK_SLACK`` edges is
behind struck surface.
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
# The depth image: pixels of this many voxel edges as seen at the nearest occupied voxel, each
# occupied voxel centre marking its pixel and the SPLAT pixels around it (a voxel's outline is
# 1 to 1.7 edges wide). A voxel is hidden when its pixel holds a centre nearer than its own by
# more than BLOCK_SLACK edges: the voxel right behind a struck one (one edge) is hidden, one beside
# it is not. Against beams cast at the voxels as boxes (tests/sim/test_surface_map.py) 90 % of
# what these values predict visible is, and 90 % of what is visible is predicted so. Measured in
# the closed-loop study (docs/decisions.md): a stricter image (0.5 edge, slack 0.8: 98 % and 80 %)
# reached 95 % sooner on the 60 deg asteroid and later on the spacecraft; a looser one (1 edge, no
# splat) the other way round.
PIXEL_EDGES = 0.35
SPLAT = 1
BLOCK_SLACK = 0.5
# The six face neighbours.
FACE_STEPS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
# Bits of a voxel's state in the grid.
OCCUPIED, CROSSED, FRONTIER = np.uint8(1), np.uint8(2), np.uint8(4)
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


def clip_to_box(origins: np.ndarray, directions: np.ndarray, lo: np.ndarray, hi: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Where each ray enters and leaves the box ``lo``..``hi`` (slab method).

    Parameters
    ----------
    origins, directions : (n, 3) float64, B; directions unit vectors
    lo, hi : (3,) float64, metres, B

    Returns
    -------
    enter, leave : (n,) float64, metres along each ray (``enter >= leave`` when it misses)
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = 1.0 / directions
        a = (lo - origins) * inverse
        b = (hi - origins) * inverse
    near = np.where(np.isnan(a), -np.inf, np.minimum(a, b))
    far = np.where(np.isnan(b), np.inf, np.maximum(a, b))
    return np.maximum(near.max(axis=1), 0.0), far.min(axis=1)


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
        self._frontier = np.zeros(0, dtype=np.int64)    # sorted keys, each once a frontier

    def keys_of(self, points: np.ndarray) -> np.ndarray:
        """Keys (n,) of the voxels holding ``points`` (n, 3) [m, B]."""
        return pack(np.floor(points / self.size).astype(np.int64))

    def centres(self, keys: np.ndarray) -> np.ndarray:
        """Centres (n, 3) [m, B] of the voxels ``keys`` (n,)."""
        return (unpack(keys) + 0.5) * self.size

    def bounds(self, margin: float) -> tuple[np.ndarray, np.ndarray]:
        """Box of the occupied voxels grown by ``margin`` [m] on every side."""
        index = unpack(self.occupied)
        return (index.min(axis=0) * self.size - margin,
                (index.max(axis=0) + 1) * self.size + margin)

    # ------------------------------------------------------------------ the grid

    def _cover(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Grow the grid to hold the voxel indices ``lo`` .. ``hi`` (3,) (inclusive)."""
        shape = np.array(self._state.shape)
        old_hi = self._corner + shape - 1
        if self._state.size and (lo >= self._corner).all() and (hi <= old_hi).all():
            return
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
        inf, struck nothing (:meth:`strike`, then :meth:`carve`).

        Parameters
        ----------
        origins : (n, 3) float64, metres, B: sensor position of each beam
        directions : (n, 3) float64, unit vectors, B
        ranges : (n,) float64, metres (inf: no strike)
        margin : float, metres
            Misses and the paths of strikes are traversed within the box of the occupied voxels
            grown by this much (space far from the target holds nothing to plan for).
        """
        self.strike(origins, directions, ranges)
        self.carve(origins, directions, ranges, margin=margin)

    def strike(self, origins: np.ndarray, directions: np.ndarray, ranges: np.ndarray) -> None:
        """Mark the voxels of the strikes occupied (arguments as :meth:`add`; misses ignored)."""
        hit = np.isfinite(ranges)
        if not hit.any():
            return
        end = origins[hit] + ranges[hit, None] * directions[hit]
        keys, inverse = np.unique(self.keys_of(end), return_inverse=True)
        count = np.bincount(inverse, minlength=len(keys))
        view = np.stack([np.bincount(inverse, weights=-directions[hit, i],
                                     minlength=len(keys)) for i in range(3)], axis=1)
        known = member(keys, self.occupied)
        row = np.searchsorted(self.occupied, keys[known])
        self.count[row] += count[known]
        self.view[row] += view[known]
        new = keys[~known]
        at = np.searchsorted(self.occupied, new)
        self.occupied = np.insert(self.occupied, at, new)
        self.count = np.insert(self.count, at, count[~known])
        self.view = np.insert(self.view, at, view[~known], axis=0)
        if not len(new):
            return
        index = unpack(new)
        self._cover(index.min(axis=0) - 1, index.max(axis=0) + 1)
        state = self._state.reshape(-1)
        cell = self._cells(index)[0]
        state[cell] = (state[cell] | OCCUPIED) & ~FRONTIER
        around = self._cells((index[:, None, :] + FACE_STEPS[None]).reshape(-1, 3))[0]
        fresh = np.unique(around[(state[around] & (OCCUPIED | CROSSED | FRONTIER)) == 0])
        state[fresh] |= FRONTIER
        fresh = self._keys_of_cells(fresh)
        self._frontier = np.insert(self._frontier, np.searchsorted(self._frontier, fresh), fresh)

    def carve(self, origins: np.ndarray, directions: np.ndarray, ranges: np.ndarray, *,
              margin: float) -> None:
        """Mark the voxels the beams crossed before their strikes free (arguments as
        :meth:`add`)."""
        if not len(self.occupied):
            return
        hit = np.isfinite(ranges)
        lo, hi = self.bounds(margin)
        self._cover(np.floor(lo / self.size).astype(np.int64),
                    np.floor(hi / self.size).astype(np.int64))
        enter, leave = clip_to_box(origins, directions, lo, hi)
        leave = np.where(hit, np.minimum(leave, ranges - self.size), leave)
        samples = np.ceil(np.maximum(leave - enter, 0.0) * (TRAVERSAL_STEP / self.size)
                          ).astype(np.int64)
        total = int(samples.sum())
        if not total:
            return
        # In grid units (voxel edges from the grid's corner), where truncation is the cell.
        ray = np.repeat(np.arange(len(origins)), samples)
        first = np.cumsum(samples) - samples
        along = (enter[ray] / self.size + (np.arange(total) - first[ray] + 0.5)
                 / TRAVERSAL_STEP)
        start = origins / self.size - self._corner
        shape = self._state.shape
        cell = np.zeros(total, dtype=np.int64)
        for axis, stride in enumerate((shape[1] * shape[2], shape[2], 1)):
            cell += stride * np.clip((start[ray, axis] + along * directions[ray, axis]
                                      ).astype(np.int64), 0, shape[axis] - 1)
        state = self._state.reshape(-1)
        state[cell] = (state[cell] | CROSSED) & ~FRONTIER

    # ------------------------------------------------------------------ reading the map

    @property
    def free(self) -> np.ndarray:
        """Sorted keys (m,) of the voxels a beam crossed (some may be occupied too)."""
        return self._keys_of_cells(np.flatnonzero(self._state.reshape(-1) & CROSSED))

    def frontier(self) -> np.ndarray:
        """Sorted keys (m,) of the unknown voxels sharing a face with an occupied voxel."""
        if len(self._frontier):
            cell = self._cells(unpack(self._frontier))[0]
            self._frontier = self._frontier[(self._state.reshape(-1)[cell] & FRONTIER) > 0]
        return self._frontier

    def surface_frontier(self) -> np.ndarray:
        """Sorted keys (m,) of the occupied voxels sharing a face with a frontier voxel: seen
        surface next to unknown space (a plate seen from one side among them)."""
        frontier = self.frontier()
        index = unpack(self.occupied)
        near = np.zeros(len(self.occupied), dtype=bool)
        for step in FACE_STEPS:
            near |= member(pack(index + step), frontier)
        return self.occupied[near]

    def visible(self, positions: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """Predict which beams from ``positions`` reach the voxels centred at ``targets``
        before striking an occupied voxel (a depth image per position: module docstring).

        Parameters
        ----------
        positions : (p, 3) or (3,) float64, metres, B
        targets : (n, 3) float64, metres, B: voxel centres

        Returns
        -------
        (p, n) bool, or (n,) for one position given as (3,): False where an occupied voxel
        centre in the target's pixel lies nearer than the target by more than ``BLOCK_SLACK``
        edges.
        """
        one = np.ndim(positions) == 1
        positions = np.atleast_2d(np.asarray(positions, dtype=np.float64))
        seen = np.ones((len(positions), len(targets)), dtype=bool)
        if len(self.occupied) and len(targets):
            seen = ~self._hidden(positions, self.centres(self.occupied), targets)
        return seen[0] if one else seen

    def _hidden(self, positions: np.ndarray, occupied: np.ndarray, targets: np.ndarray
                ) -> np.ndarray:
        """(p, n) bool: ``targets`` (n, 3) behind one of the ``occupied`` centres (o, 3) in
        the depth image from each of ``positions`` (p, 3) [m, B]."""
        o = len(occupied)
        # Image axes per position: w toward the occupied voxels' box centre, a and b across.
        w = 0.5 * (occupied.min(axis=0) + occupied.max(axis=0)) - positions
        w /= np.sqrt((w * w).sum(axis=1))[:, None]
        a = np.where(np.abs(w[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
        a -= (a * w).sum(axis=1)[:, None] * w
        a /= np.sqrt((a * a).sum(axis=1))[:, None]
        frame = np.stack([a, np.cross(w, a), w], axis=1)                 # (p, 3, 3)
        local = np.matmul(np.concatenate([occupied, targets])[None] - positions[:, None],
                          frame.transpose(0, 2, 1))                       # (p, o + n, 3)
        distance = np.sqrt(np.einsum("pni,pni->pn", local, local))
        depth = local[:, :, 2]
        front = depth > 0
        pixel = PIXEL_EDGES * self.size / distance[:, :o].min(axis=1)    # rad per pixel
        scale = np.where(front, depth, 1.0) * pixel[:, None]
        uv = np.floor(local[:, :, :2] / scale[:, :, None]).astype(np.int64)
        uv[~front] = 0
        # Each image spans its occupied voxels' pixels and the splat around them.
        lo = uv[:, :o].min(axis=1) - SPLAT                               # (p, 2)
        width = uv[:, :o].max(axis=1) + SPLAT + 1 - lo
        uv -= lo[:, None]
        u, v = uv[:, :, 0], uv[:, :, 1]
        inside = front & (u >= 0) & (v >= 0) & (u < width[:, :1]) & (v < width[:, 1:])
        start = np.concatenate([[0], np.cumsum(width[:, 0] * width[:, 1])[:-1]])
        flat = start[:, None] + u * width[:, 1:] + v                       # (p, o + n)
        keep = front[:, :o]
        spot, near = flat[:, :o][keep], distance[:, :o][keep]
        row = np.broadcast_to(width[:, 1:], keep.shape)[keep]
        span = np.arange(-SPLAT, SPLAT + 1)
        shift = (span[:, None, None] * row + span[None, :, None]).reshape(-1, len(spot))
        image = np.full(int((width[:, 0] * width[:, 1]).sum()), np.inf)
        np.minimum.at(image, (spot + shift).ravel(), np.tile(near, len(shift)))
        nearest = np.where(inside[:, o:], image[np.where(inside[:, o:], flat[:, o:], 0)],
                           np.inf)
        return nearest < distance[:, o:] - BLOCK_SLACK * self.size
