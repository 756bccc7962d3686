"""A sparse voxel map of what the beams have struck and the space they crossed, in the body frame.

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

Voxel keys are the three integer indices packed into one int64; each set (occupied, free) is a
sorted key array, looked up with ``np.searchsorted`` (a hash table in numpy arrays). Beams are
traversed by sampling every ``size / TRAVERSAL_STEP`` along them, all beams of a batch at once.

The **frontier** is the unknown voxels next to (sharing a face with) an occupied voxel: where
the seen surface continues into space no beam has examined. A thin plate seen from one side
keeps the unknown voxels behind it, so it stays on the frontier until a beam from its other side
strikes it; a solid body keeps its unknown interior, which :meth:`SurfaceMap.visible` predicts
hidden once the surface around it is struck. :meth:`SurfaceMap.visible` predicts whether a
planned beam reaches a voxel by casting it (Embree, sim/raycast.py) against a mesh of the
exposed faces of the occupied voxels. Building that mesh costs more than the casts it serves, so
it is kept in two parts: the faces of the voxels occupied when the map last grew by
``GAP_MESH_GROWTH`` (sim/defaults.py), and those of the voxels struck since, rebuilt when they
change.
"""

from __future__ import annotations

import numpy as np

from sim.defaults import GAP_MESH_GROWTH

# Voxel indices are offset by 2**20 and packed in 21 bits each: +-1e6 voxels per axis.
_BITS = 21
_OFFSET = 1 << (_BITS - 1)
_MASK = (1 << _BITS) - 1
# Samples per voxel edge along a beam: at half a voxel, a beam skips only voxels it clips by
# less than a quarter of their edge.
TRAVERSAL_STEP = 2.0
# A beam enters a voxel at most half its diagonal, sqrt(3) / 2 edges, before the voxel's centre:
# a struck face nearer than that blocks it.
BLOCK_SLACK = 0.8660254037844386
# The six face neighbours.
FACE_STEPS = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])


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
    """Occupied and free voxels of edge ``size`` [m] (see the module docstring).

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
        self.free = np.zeros(0, dtype=np.int64)          # sorted keys (may include occupied)
        self._mesh = None                                # faces of the voxels in _built
        self._built = np.zeros(0, dtype=np.int64)
        self._recent = None                              # faces of the voxels struck since
        self._recent_voxels = 0

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
        at = np.searchsorted(self.occupied, keys[~known])
        self.occupied = np.insert(self.occupied, at, keys[~known])
        self.count = np.insert(self.count, at, count[~known])
        self.view = np.insert(self.view, at, view[~known], axis=0)

    def carve(self, origins: np.ndarray, directions: np.ndarray, ranges: np.ndarray, *,
              margin: float) -> None:
        """Mark the voxels the beams crossed before their strikes free (arguments as
        :meth:`add`)."""
        if not len(self.occupied):
            return
        hit = np.isfinite(ranges)
        lo, hi = self.bounds(margin)
        enter, leave = clip_to_box(origins, directions, lo, hi)
        leave = np.where(hit, np.minimum(leave, ranges - self.size), leave)
        length = np.maximum(leave - enter, 0.0)
        spacing = self.size / TRAVERSAL_STEP
        samples = np.ceil(length / spacing).astype(np.int64)
        if not samples.sum():
            return
        ray = np.repeat(np.arange(len(origins)), samples)
        first = np.cumsum(samples) - samples
        along = enter[ray] + (np.arange(samples.sum()) - first[ray] + 0.5) * spacing
        points = origins[ray] + along[:, None] * directions[ray]
        crossed = np.unique(self.keys_of(points))
        crossed = crossed[~member(crossed, self.free)]
        self.free = np.insert(self.free, np.searchsorted(self.free, crossed), crossed)

    def frontier(self) -> np.ndarray:
        """Sorted keys (m,) of the unknown voxels sharing a face with an occupied voxel."""
        if not len(self.occupied):
            return np.zeros(0, dtype=np.int64)
        steps = pack(FACE_STEPS) - pack(np.zeros((1, 3), dtype=np.int64))
        around = np.unique((self.occupied[:, None] + steps[None, :]).ravel())
        return around[~member(around, self.occupied) & ~member(around, self.free)]

    def surface_frontier(self) -> np.ndarray:
        """Sorted keys (m,) of the occupied voxels sharing a face with a frontier voxel: seen
        surface next to unknown space (a plate seen from one side among them)."""
        frontier = self.frontier()
        index = unpack(self.occupied)
        near = np.zeros(len(self.occupied), dtype=bool)
        for step in FACE_STEPS:
            near |= member(pack(index + step), frontier)
        return self.occupied[near]

    def _mesh_of(self, keys: np.ndarray):
        """Embree caster of the faces of the voxels ``keys`` (sorted, occupied) that no
        occupied voxel covers, with each triangle's axis (t,) and plane coordinate (t,)
        [m, B]; None when there is no such face."""
        from sim.raycast import EmbreeBackend

        index = unpack(keys)
        quads, axes, planes = [], [], []
        unit = np.eye(3, dtype=np.int64)
        for step in FACE_STEPS:
            cell = index[~member(pack(index + step), self.occupied)]
            axis = int(np.flatnonzero(step)[0])
            side = cell[:, axis] + (step[axis] > 0)
            u, v = unit[(axis + 1) % 3], unit[(axis + 2) % 3]
            corner = cell.copy()
            corner[:, axis] = side
            quads.append(np.stack([corner, corner + u, corner + u + v, corner + v], axis=1))
            axes.append(np.full(len(cell), axis))
            planes.append(side * self.size)
        quad = np.concatenate(quads)                                    # (q, 4, 3) corners
        if not len(quad):
            return None
        # Faces share their corners (embreex copies a scene element by element).
        corner, faces = np.unique(pack(quad.reshape(-1, 3)), return_inverse=True)
        faces = faces.reshape(-1, 4)
        triangles = np.concatenate([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]])
        return (EmbreeBackend(unpack(corner) * self.size, triangles),
                np.tile(np.concatenate(axes), 2), np.tile(np.concatenate(planes), 2))

    def _casters(self) -> list:
        """The meshes that together hold every exposed face of the occupied voxels: one built
        when the map last grew by ``GAP_MESH_GROWTH`` (rebuilding a BVH costs more than the
        casts it serves) and one of the voxels struck since, rebuilt when they change. A face
        of the first that a later strike covered lies between two occupied voxels, so it blocks
        only beams that one of them blocks anyway."""
        if self._mesh is None or len(self.occupied) > (1 + GAP_MESH_GROWTH) * len(self._built):
            self._built = self.occupied
            self._mesh = self._mesh_of(self.occupied)
            self._recent, self._recent_voxels = None, len(self.occupied)
        if self._recent_voxels != len(self.occupied):
            self._recent = self._mesh_of(self.occupied[~member(self.occupied, self._built)])
            self._recent_voxels = len(self.occupied)
        return [m for m in (self._mesh, self._recent) if m is not None]

    def visible(self, origins: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """Predict which beams from ``origins`` reach the voxels centred at ``targets`` before
        striking an occupied voxel.

        Parameters
        ----------
        origins : (n, 3) or (3,) float64, metres, B
        targets : (n, 3) float64, metres, B: voxel centres

        Returns
        -------
        (n,) bool: True when no occupied voxel's face lies on the beam before it can have
        entered the target voxel (``BLOCK_SLACK`` voxel edges short of the centre).
        """
        if not len(self.occupied):
            return np.ones(len(targets), dtype=bool)
        origins = np.broadcast_to(origins, targets.shape)
        line = targets - origins
        length = np.linalg.norm(line, axis=1)
        direction = line / length[:, None]
        rows = np.arange(len(targets))
        seen = np.ones(len(targets), dtype=bool)
        for caster, axis, plane in self._casters():
            face = caster.first_hit(origins.astype(np.float32), direction.astype(np.float32))
            hit = face >= 0
            f = np.where(hit, face, 0)
            a = axis[f]
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (plane[f] - origins[rows, a]) / direction[rows, a]
            seen &= ~hit | ~(t < length - BLOCK_SLACK * self.size)
        return seen
