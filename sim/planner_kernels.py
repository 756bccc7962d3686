"""Compiled kernels of the gap-seeking planner: the voxel map's update and an interval's aims.

The closed loop (sim/gap_seeking.py) simulates one replanning interval of 30 shots at a time, a
millisecond or so of simulation; a planner of a few dozen numpy calls costs as much again in
call overhead alone. These kernels do each step in one compiled call (numba, ``cache=True``, so
that a process after the first loads them from disk instead of compiling them):

- :func:`recorded_beams`: every beam of the recorded shots, in the body frame;
- :func:`add`: a plan's beams into the map in one call: the strikes into the occupied voxels
  and the frontier marks around the new ones (:func:`strike_index`, :func:`strike_merge`), the
  occupancy bits the walks read (:func:`occupancy`), the voxels the beams crossed before their
  strikes (:func:`carve`), handing back to numpy the grid's growth (rare);
- :func:`enclose`: the unknown voxels the struck voxels enclose (a flood fill from outside,
  gaps of two voxels closed);
- :func:`candidates`: a plan's candidates in one call: the frontier, the least-struck voxels
  (:func:`least_struck`), less those set aside (:func:`not_aside`: found hidden too often, or
  all re-admitted), one per cube (:func:`spread`), with their hidden counts;
- :func:`hidden`: which voxels beams from a few positions reach (a walk through the map);
- :func:`sweep`: one interval's aims (the sweep's order, visibility tested in that order until
  the shots are used, the slew limits) and the commanded turns; it counts, per candidate, the
  walks that found it hidden.

They do what the numpy code they replaced did, in the same order of operations where it
matters (the same voxel keys, the same sweep order); tests/sim/test_planner_kernels.py holds
that numpy code (for the visibility walk, a brute-force test of every beam against every
struck voxel) and checks each kernel against it on small maps. Changes made only to be
cheaper keep every decision: the gap-seeking logs of the closed-loop study's scenes stay the
same, byte for byte (benchmarks/bench_planner.py, ``--identical-to``). Only the closed loop
imports this module, so the numba import (a few tenths of a second) is paid by closed-loop runs
alone.

Conventions as in sim/surface_map.py: voxel ``(i, j, k)`` of edge ``size`` [m] holds the points
``size * ((i, j, k) + [0, 1)^3)`` of the body frame B; its key packs the three indices offset by
``2**20`` in 21 bits each; the map's state grid is C-ordered with the voxel index ``corner`` at
its first cell. Quaternions are (x, y, z, w), as the strike log records them.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from sim.surface_map import (
    _BITS,
    _MASK,
    _OFFSET,
    BLOCK_RADIUS,
    BLOCK_SLACK,
    CROSSED,
    ENCLOSED,
    FRONTIER,
    HIDDEN_MAX,
    HIDDEN_STEP,
    OCCUPIED,
    TRAVERSAL_STEP,
)

_OCC, _CROSSED, _FRONT, _ENCLOSED = int(OCCUPIED), int(CROSSED), int(FRONTIER), int(ENCLOSED)
_KNOWN = _OCC | _CROSSED | _FRONT | _ENCLOSED
_NOT_FRONT = 0xFF ^ _FRONT          # uint8 bit masks, as plain ints


@njit(cache=True)
def _matrix(q, m):
    """Write into ``m`` (3, 3) the rotation matrix of the quaternion ``q`` (x, y, z, w),
    normalised first."""
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    x, y, z, w = q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm
    m[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    m[0, 1] = 2.0 * (x * y - z * w)
    m[0, 2] = 2.0 * (x * z + y * w)
    m[1, 0] = 2.0 * (x * y + z * w)
    m[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    m[1, 2] = 2.0 * (y * z - x * w)
    m[2, 0] = 2.0 * (x * z - y * w)
    m[2, 1] = 2.0 * (y * z + x * w)
    m[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@njit(cache=True)
def _pack(i, j, k):
    return ((i + _OFFSET) << (2 * _BITS)) | ((j + _OFFSET) << _BITS) | (k + _OFFSET)


@njit(cache=True)
def _unpack(key):
    return (((key >> (2 * _BITS)) & _MASK) - _OFFSET, ((key >> _BITS) & _MASK) - _OFFSET,
            (key & _MASK) - _OFFSET)


@njit(cache=True)
def recorded_beams(row, beam, ranges, direction, position, sensor, target, beams):
    """Every beam of every recorded shot in B: the strikes in their order, then the misses.

    Parameters
    ----------
    row : (h,) int64: the shot of each strike (row of ``position``)
    beam : (h,) int64: the beam of each strike (row of ``beams``)
    ranges : (h,) float64, metres: recorded ranges
    direction : (h, 3) float64, unit vectors, sensor frame S: measured beam directions
    position : (n, 3) float64, metres, inertial frame I: recorded sensor positions
    sensor : (n, 4) float64, quaternions S->I; target : (n, 4) float64, quaternions B->I
    beams : (b, 3) float64, unit vectors, S: the sensor's beams (a miss goes along its beam)

    Returns
    -------
    origins : (m, 3) float64, metres, B
    directions : (m, 3) float64, unit vectors, B
    beam_ranges : (m,) float64, metres (inf for a miss)
    stats : (9,) float64: the strikes' box low (3) and high (3) corners [m, B], their number,
        the sum of their ranges [m] and their largest distance from the origin of B [m]
        (box corners +-inf when nothing was struck)
    """
    n, b, h = len(position), len(beams), len(row)
    to_body = np.empty((n, 3, 3))
    sensor_m = np.empty((n, 3, 3))
    origin = np.empty((n, 3))
    to_inertial = np.empty((3, 3))
    for s in range(n):
        _matrix(target[s], to_inertial)
        to_body[s] = to_inertial.T
        _matrix(sensor[s], sensor_m[s])
        for i in range(3):
            origin[s, i] = (to_body[s, i, 0] * position[s, 0] + to_body[s, i, 1] * position[s, 1]
                            + to_body[s, i, 2] * position[s, 2])
    struck = np.zeros(n * b, dtype=np.bool_)
    for k in range(h):
        struck[row[k] * b + beam[k]] = True
    misses = n * b - int(struck.sum())
    origins = np.empty((h + misses, 3))
    directions = np.empty((h + misses, 3))
    out_ranges = np.full(h + misses, np.inf)
    m = 0
    for k in range(h + n * b):
        if k < h:
            s, d = row[k], direction[k]
            out_ranges[m] = ranges[k]
        else:
            flat = k - h
            if struck[flat]:
                continue
            s, d = flat // b, beams[flat % b]
        r = sensor_m[s]
        v0 = r[0, 0] * d[0] + r[0, 1] * d[1] + r[0, 2] * d[2]
        v1 = r[1, 0] * d[0] + r[1, 1] * d[1] + r[1, 2] * d[2]
        v2 = r[2, 0] * d[0] + r[2, 1] * d[1] + r[2, 2] * d[2]
        for i in range(3):
            origins[m, i] = origin[s, i]
            directions[m, i] = to_body[s, i, 0] * v0 + to_body[s, i, 1] * v1 + to_body[s, i, 2] * v2
        m += 1
    stats = np.zeros(9)
    for i in range(3):
        stats[i], stats[3 + i] = np.inf, -np.inf
    for k in range(h):
        r2 = 0.0
        for i in range(3):
            e = origins[k, i] + ranges[k] * directions[k, i]
            stats[i] = min(stats[i], e)
            stats[3 + i] = max(stats[3 + i], e)
            r2 += e * e
        stats[8] = max(stats[8], math.sqrt(r2))
        stats[7] += ranges[k]
    stats[6] = h
    return origins, directions, out_ranges, stats


@njit(cache=True)
def strike_index(origins, directions, ranges, size):
    """Voxel indices of the strikes (beams of finite range) and the view they add.

    Parameters
    ----------
    origins, directions : (m, 3) float64, metres and unit vectors, B
    ranges : (m,) float64, metres (inf: no strike)
    size : float, metres: the voxel edge

    Returns
    -------
    index : (h, 3) int64: the voxel of each strike
    view : (h, 3) float64: unit vectors from each strike toward its sensor, B
    lo, hi : (3,) int64: the smallest and largest index on each axis (empty: lo > hi)
    """
    m = len(ranges)
    h = 0
    for k in range(m):
        if math.isfinite(ranges[k]):
            h += 1
    index = np.empty((h, 3), dtype=np.int64)
    view = np.empty((h, 3))
    lo = np.full(3, np.iinfo(np.int64).max)
    hi = np.full(3, np.iinfo(np.int64).min)
    j = 0
    for k in range(m):
        if not math.isfinite(ranges[k]):
            continue
        for i in range(3):
            c = np.int64(math.floor((origins[k, i] + ranges[k] * directions[k, i]) / size))
            index[j, i] = c
            view[j, i] = -directions[k, i]
            lo[i] = min(lo[i], c)
            hi[i] = max(hi[i], c)
        j += 1
    return index, view, lo, hi


@njit(cache=True)
def _group(keys, view):
    """The distinct ``keys`` (h,) sorted, with how often each occurs and the sum of their
    ``view`` rows (h, 3), summed in input order: (u,) int64, (u,) int64, (u, 3) float64."""
    h = len(keys)
    order = np.argsort(keys, kind="mergesort")
    unique = np.empty(h, dtype=np.int64)
    u_count = np.zeros(h, dtype=np.int64)
    u_view = np.zeros((h, 3))
    u = -1
    for k in order:
        if u < 0 or keys[k] != unique[u]:
            u += 1
            unique[u] = keys[k]
        u_count[u] += 1
        for i in range(3):
            u_view[u, i] += view[k, i]
    return unique[:u + 1], u_count[:u + 1], u_view[:u + 1]


@njit(cache=True)
def _merge_counts(occupied, count, occupied_view, unique, u_count, u_view):
    """Sorted keys with counts and views, merged (both sorted): the merged arrays and the keys
    of ``unique`` not in ``occupied``.

    When every key of ``unique`` is occupied already (most plans late in a run), they are found
    by binary search and their counts and views updated in place, without a pass over every
    occupied voxel; otherwise the two are merged into new arrays (:func:`_merge_sorted`)."""
    at = np.searchsorted(occupied, unique)
    if _all_known(occupied, unique, at):
        _add_in_place(count, occupied_view, at, u_count, u_view)
        return occupied, count, occupied_view, np.empty(0, dtype=np.int64)
    return _merge_sorted(occupied, count, occupied_view, unique, u_count, u_view, at)


@njit(cache=True)
def _all_known(occupied, unique, at):
    """Whether every key of ``unique`` is in ``occupied``, at its ``searchsorted`` place ``at``."""
    o = len(occupied)
    for c in range(len(unique)):
        if at[c] >= o or occupied[at[c]] != unique[c]:
            return False
    return True


@njit(cache=True)
def _add_in_place(count, occupied_view, at, u_count, u_view):
    """Add the counts and views of keys already occupied, at their places ``at``."""
    for c in range(len(at)):
        a = at[c]
        count[a] += u_count[c]
        for i in range(3):
            occupied_view[a, i] = occupied_view[a, i] + u_view[c, i]


@njit(cache=True)
def _merge_sorted(occupied, count, occupied_view, unique, u_count, u_view, at):
    """``_merge_counts`` when some key is new (``at``: the ``searchsorted`` places of
    ``unique`` in ``occupied``): new arrays, the occupied voxels between two keys of
    ``unique`` copied as one block (a few new keys among thousands of occupied ones)."""
    o, u = len(occupied), len(unique)
    n_new = 0
    for c in range(u):
        n_new += at[c] >= o or occupied[at[c]] != unique[c]
    merged = np.empty(o + n_new, dtype=np.int64)
    m_count = np.empty(o + n_new, dtype=np.int64)
    m_view = np.empty((o + n_new, 3))
    new = np.empty(n_new, dtype=np.int64)
    a = m = n_new = 0                 # next occupied voxel to copy, next merged entry
    for c in range(u):
        b = at[c]
        merged[m:m + b - a] = occupied[a:b]
        m_count[m:m + b - a] = count[a:b]
        m_view[m:m + b - a] = occupied_view[a:b]
        m += b - a
        if b < o and occupied[b] == unique[c]:
            merged[m] = occupied[b]
            m_count[m] = count[b] + u_count[c]
            for i in range(3):
                m_view[m, i] = occupied_view[b, i] + u_view[c, i]
            a = b + 1
        else:
            merged[m] = unique[c]
            m_count[m] = u_count[c]
            m_view[m] = u_view[c]
            new[n_new] = unique[c]
            n_new += 1
            a = b
        m += 1
    merged[m:] = occupied[a:]
    m_count[m:] = count[a:]
    m_view[m:] = occupied_view[a:]
    return merged, m_count, m_view, new


@njit(cache=True)
def _mark_new(new, state, shape, corner):
    """Mark the voxels ``new`` occupied in the flat ``state`` grid and their unknown face
    neighbours frontier: the keys of those neighbours, sorted."""
    s1, s2 = shape[1] * shape[2], shape[2]
    for key in new:
        i, j, k = _unpack(key)
        cell = (i - corner[0]) * s1 + (j - corner[1]) * s2 + (k - corner[2])
        state[cell] = (state[cell] | _OCC) & _NOT_FRONT
    fresh = np.empty(6 * len(new), dtype=np.int64)
    f = 0
    for key in new:
        i, j, k = _unpack(key)
        for axis in range(3):
            for sign in (1, -1):
                ni = i + sign if axis == 0 else i
                nj = j + sign if axis == 1 else j
                nk = k + sign if axis == 2 else k
                cell = (ni - corner[0]) * s1 + (nj - corner[1]) * s2 + (nk - corner[2])
                if state[cell] & _KNOWN == 0:
                    state[cell] |= _FRONT
                    fresh[f] = _pack(ni, nj, nk)
                    f += 1
    return np.sort(fresh[:f])


@njit(cache=True)
def _join(a, b):
    """The sorted union of the sorted, disjoint key arrays ``a`` and ``b`` (``a`` itself when
    ``b`` is empty)."""
    if not len(b):
        return a
    out = np.empty(len(a) + len(b), dtype=np.int64)
    i = j = 0
    for m in range(len(out)):
        if j >= len(b) or (i < len(a) and a[i] < b[j]):
            out[m] = a[i]
            i += 1
        else:
            out[m] = b[j]
            j += 1
    return out


@njit(cache=True)
def _centres(keys, size):
    """Centres (k, 3) [m, B] of the voxels ``keys`` (k,) of edge ``size`` [m]."""
    centres = np.empty((len(keys), 3))
    for q in range(len(keys)):
        i, j, k = _unpack(keys[q])
        centres[q, 0] = (i + 0.5) * size
        centres[q, 1] = (j + 0.5) * size
        centres[q, 2] = (k + 0.5) * size
    return centres


@njit(cache=True)
def strike_merge(index, view, occupied, count, occupied_view, frontier, state, shape, corner):
    """Merge strikes into the occupied voxels and mark the unknown neighbours of new ones.

    Parameters
    ----------
    index : (h, 3) int64; view : (h, 3) float64: from :func:`strike_index`
    occupied : (o,) int64, sorted keys; count : (o,) int64; occupied_view : (o, 3) float64
    frontier : (f,) int64, sorted keys: the frontier list (sim/surface_map.py)
    state : (g,) uint8: the flat state grid, updated in place (it must hold every voxel of
        ``index`` and its face neighbours)
    shape : (3,) int64: the grid's shape; corner : (3,) int64: the voxel index of its first cell

    Returns
    -------
    occupied, count, occupied_view, frontier : the merged arrays (when no voxel is struck for
        the first time, ``occupied`` and ``frontier`` themselves with ``count`` and
        ``occupied_view`` updated in place; new arrays otherwise)
    new : (n,) int64, sorted: the keys of the voxels struck for the first time
    """
    keys = np.empty(len(index), dtype=np.int64)
    for k in range(len(index)):
        keys[k] = _pack(index[k, 0], index[k, 1], index[k, 2])
    unique, u_count, u_view = _group(keys, view)
    merged, m_count, m_view, new = _merge_counts(occupied, count, occupied_view, unique,
                                                 u_count, u_view)
    fresh = _mark_new(new, state, shape, corner)
    return merged, m_count, m_view, _join(frontier, fresh), new


# What :func:`add` did: everything; nothing yet (the grid must first hold the strikes and
# their neighbours); the strikes but not the carving (the grid must first hold the box).
ADDED, STRIKE, CARVE = 0, 1, 2


@njit(cache=True)
def _holds(shape, corner, lo, hi):
    """Whether the grid of ``shape`` whose first cell is voxel ``corner`` holds the voxel
    indices ``lo`` .. ``hi`` (3,) int64 (inclusive)."""
    for i in range(3):
        if not (corner[i] <= lo[i] and hi[i] < corner[i] + shape[i]):
            return False
    return shape[0] * shape[1] * shape[2] > 0


@njit(cache=True)
def add(origins, directions, ranges, size, margin, occupied, count, occupied_view, frontier,
        state, shape, corner, index_lo, index_hi, solid):
    """Add beams to the map in one call (sim/surface_map.py, :meth:`SurfaceMap.add`): the
    strikes merged (:func:`strike_index`, :func:`strike_merge`) and the occupancy bits kept
    up to date (:func:`occupancy`), then the paths carved (:func:`carve`) within the occupied
    voxels' box grown by ``margin`` [m]. Where the grid must grow first (a copy numpy does
    faster), it stops and says what the grid must hold.

    Parameters
    ----------
    origins, directions : (m, 3) float64, metres and unit vectors, B
    ranges : (m,) float64, metres (inf: no strike)
    size, margin : float, metres: the voxel edge and the traversal margin
    occupied, count, occupied_view, frontier : the map's arrays (:func:`strike_merge`)
    state, shape, corner : the flat state grid (updated in place), its shape and first voxel
    index_lo, index_hi : (3,) int64: the occupied voxels' index box (ignored while none is)
    solid : (ceil(g / 8),) uint8: :func:`occupancy` over that box (ignored while none is)

    Returns
    -------
    occupied, count, occupied_view, frontier, index_lo, index_hi, solid : the map's arrays
        after (new arrays where they changed size; ``solid`` made again when the box changed,
        its new voxels' bits set in place otherwise)
    status : int: ``ADDED``; ``STRIKE``: nothing done, the grid must hold ``lo`` .. ``hi``;
        ``CARVE``: the strikes merged, the grid must hold ``lo`` .. ``hi`` before the carving
    lo, hi : (3,) int64: what the grid must hold (with ``ADDED``, the strikes' index box)
    """
    index, view, lo, hi = strike_index(origins, directions, ranges, size)
    if len(index):
        if not _holds(shape, corner, lo - 1, hi + 1):
            return (occupied, count, occupied_view, frontier, index_lo, index_hi, solid, STRIKE,
                    lo - 1, hi + 1)
        occupied, count, occupied_view, frontier, new = strike_merge(
            index, view, occupied, count, occupied_view, frontier, state, shape, corner)
        if len(new):
            first = len(occupied) == len(new)
            box_lo = lo if first else np.minimum(index_lo, lo)
            box_hi = hi if first else np.maximum(index_hi, hi)
            if first or (box_lo != index_lo).any() or (box_hi != index_hi).any():
                solid = occupancy(occupied, box_lo, box_hi)
            else:
                _set_occupied(solid, new, box_lo, box_hi)
            index_lo, index_hi = box_lo, box_hi
    if len(occupied):
        box_lo = index_lo * size - margin
        box_hi = (index_hi + 1) * size + margin
        lo = np.floor(box_lo / size).astype(np.int64)
        hi = np.floor(box_hi / size).astype(np.int64)
        if not _holds(shape, corner, lo, hi):
            return (occupied, count, occupied_view, frontier, index_lo, index_hi, solid, CARVE,
                    lo, hi)
        carve(origins, directions, ranges, box_lo, box_hi, size, state, shape, corner)
    return occupied, count, occupied_view, frontier, index_lo, index_hi, solid, ADDED, lo, hi


@njit(cache=True)
def carve(origins, directions, ranges, lo, hi, size, state, shape, corner):
    """Mark the voxels each beam crosses inside the box ``lo``..``hi`` before its strike (up to
    one voxel short of it; through the box for a miss) crossed, and no longer frontier.

    Parameters
    ----------
    origins, directions : (m, 3) float64, metres and unit vectors, B
    ranges : (m,) float64, metres (inf: no strike)
    lo, hi : (3,) float64, metres, B: the box traversed (the grid holds it)
    size : float, metres: the voxel edge
    state : (g,) uint8: the flat state grid, updated in place
    shape, corner : (3,) int64: the grid's shape and the voxel index of its first cell

    Notes
    -----
    Samples every ``size / TRAVERSAL_STEP`` along each beam from where it enters the box, at
    the middles of those steps (sim/surface_map.py). A beam's cells are computed first, in a
    loop free of stores to ``state`` (which the compiler vectorises), then marked: about
    twice as fast as marking each as it is computed.
    """
    s1, s2 = shape[1] * shape[2], shape[2]
    n0, n1, n2 = shape[0] - 1, shape[1] - 1, shape[2] - 1
    diagonal = math.sqrt((hi[0] - lo[0]) ** 2 + (hi[1] - lo[1]) ** 2 + (hi[2] - lo[2]) ** 2)
    cells = np.empty(math.ceil(diagonal * (TRAVERSAL_STEP / size)) + 2, dtype=np.int64)
    for k in range(len(ranges)):
        enter, leave = 0.0, np.inf
        for i in range(3):
            inverse = 1.0 / directions[k, i] if directions[k, i] != 0.0 else np.inf
            a = (lo[i] - origins[k, i]) * inverse
            b = (hi[i] - origins[k, i]) * inverse
            near = -np.inf if math.isnan(a) else (math.nan if math.isnan(b) else min(a, b))
            far = np.inf if math.isnan(b) else (math.nan if math.isnan(a) else max(a, b))
            enter = max(enter, near)
            leave = min(leave, far)
        if math.isfinite(ranges[k]):
            leave = min(leave, ranges[k] - size)
        samples = math.ceil(max(leave - enter, 0.0) * (TRAVERSAL_STEP / size))
        if samples > len(cells):     # not within the box's diagonal (rounding): room made
            cells = np.empty(samples, dtype=np.int64)
        _sample_cells(origins[k, 0] / size - corner[0], origins[k, 1] / size - corner[1],
                      origins[k, 2] / size - corner[2], directions[k, 0], directions[k, 1],
                      directions[k, 2], enter / size, samples, s1, s2, n0, n1, n2, cells)
        for s in range(samples):
            cell = cells[s]
            state[cell] = (state[cell] | _CROSSED) & _NOT_FRONT


@njit(cache=True)
def _sample_cells(o0, o1, o2, d0, d1, d2, start, samples, s1, s2, n0, n1, n2, cells):
    """The flat grid cells (written to ``cells[:samples]``) of a beam's samples (:func:`carve`):
    from the origin ``(o0, o1, o2)`` [grid cells] along the unit direction ``(d0, d1, d2)``,
    at ``start + (s + 0.5) / TRAVERSAL_STEP`` [voxel edges] for ``s < samples``, clamped to
    the grid (strides ``s1``, ``s2``, last indices ``n0``, ``n1``, ``n2``)."""
    for s in range(samples):
        along = start + (s + 0.5) / TRAVERSAL_STEP
        cells[s] = (s1 * min(max(np.int64(o0 + along * d0), 0), n0)
                    + s2 * min(max(np.int64(o1 + along * d1), 0), n1)
                    + min(max(np.int64(o2 + along * d2), 0), n2))


@njit(cache=True)
def enclose(state, shape, corner, lo, hi):
    """Mark the unknown voxels enclosed by occupied ones, gaps of up to two voxels closed.

    The occupied voxels grown by one voxel (their 26 neighbours) are walls; the voxels that a
    path of face neighbours through voxels not walls joins to the faces of the occupied voxels'
    box grown by two are reached; the voxels reached or next to one (26 neighbours) are near
    the outside (the space outside, opened by the 3 x 3 x 3 cube). An unknown voxel is
    enclosed unless it or one of its face neighbours not occupied is near the outside (so an
    unknown voxel in a gap of the struck surface stays frontier, the unknown layer behind a
    closed shell does not): it gets ``ENCLOSED`` and loses ``FRONTIER``. Voxels enclosed
    already are walls too (none is reached).

    Parameters
    ----------
    state : (g,) uint8: the flat state grid, updated in place
    shape, corner : (3,) int64: the grid's shape and the voxel index of its first cell (the
        grid holds the box ``lo - 2`` .. ``hi + 2``)
    lo, hi : (3,) int64: the occupied voxels' index box (inclusive)

    Returns
    -------
    int: how many voxels were marked enclosed now.
    """
    s1, s2 = shape[1] * shape[2], shape[2]
    extent = (hi[0] - lo[0] + 5, hi[1] - lo[1] + 5, hi[2] - lo[2] + 5)
    base = (lo[0] - 2 - corner[0]) * s1 + (lo[1] - 2 - corner[1]) * s2 + (lo[2] - 2 - corner[2])
    wall = _walls(state, base, s1, s2, extent)
    near = _grow(_reach(wall, extent), extent)
    return _mark_enclosed(state, base, s1, s2, near, extent)


@njit(cache=True)
def _walls(state, base, s1, s2, extent):
    """The walls of :func:`enclose`, a flat mask over the box of ``extent`` (3,) cells whose
    first cell is ``state[base]`` (strides ``s1``, ``s2`` in ``state``): the occupied voxels
    (none on the box's two outer layers) and their 26 neighbours, and the enclosed voxels."""
    e0, e1, e2 = extent
    f1 = e1 * e2
    wall = np.zeros(e0 * f1, dtype=np.bool_)
    for x in range(1, e0 - 1):
        for y in range(1, e1 - 1):
            for z in range(1, e2 - 1):
                v = state[base + x * s1 + y * s2 + z]
                if v & _ENCLOSED:
                    wall[x * f1 + y * e2 + z] = True
                elif v & _OCC:
                    for a in range(x - 1, x + 2):
                        for b in range(y - 1, y + 2):
                            wall[a * f1 + b * e2 + z - 1:a * f1 + b * e2 + z + 2] = True
    return wall


@njit(cache=True)
def _reach(wall, extent):
    """The cells (flat mask over a box of ``extent`` (3,) cells) that a path of face
    neighbours through cells not ``wall`` joins to the box's faces: raster sweeps forward and
    back over the box, each carrying reach from the three neighbours already swept, until one
    after the first changes nothing (a few, for space outside a body). A sweep leaves the mask
    closed under reach from its three neighbours, so when the next (the other way) adds
    nothing, it is closed both ways: the same mask as sweeping on until a pair adds nothing."""
    e0, e1, e2 = extent
    f1 = e1 * e2
    reached = np.zeros(e0 * f1, dtype=np.bool_)
    for x in range(e0):
        for y in range(e1):
            edge = x == 0 or y == 0 or x == e0 - 1 or y == e1 - 1
            row = x * f1 + y * e2
            for z in range(e2):
                reached[row + z] = edge or z == 0 or z == e2 - 1
    sign, sweeps = 1, 0
    while _raster(reached, wall, extent, sign) or sweeps == 0:
        sign, sweeps = -sign, sweeps + 1
    return reached


@njit(cache=True)
def _raster(reached, wall, extent, sign):
    """One sweep of :func:`_reach` over the box's inner cells, forward (``sign`` 1) or back
    (-1): whether it reached a cell."""
    e0, e1, e2 = extent
    f1 = e1 * e2
    changed = False
    for x in range(1, e0 - 1) if sign > 0 else range(e0 - 2, 0, -1):
        for y in range(1, e1 - 1) if sign > 0 else range(e1 - 2, 0, -1):
            row = x * f1 + y * e2
            for z in range(1, e2 - 1) if sign > 0 else range(e2 - 2, 0, -1):
                c = row + z
                if not reached[c] and not wall[c] and (
                        reached[c - sign] or reached[c - sign * e2] or reached[c - sign * f1]):
                    reached[c] = True
                    changed = True
    return changed


@njit(cache=True)
def _grow(mask, extent):
    """``mask`` (flat, over a box of ``extent`` (3,) cells) grown by one cell toward its 26
    neighbours (the 3 x 3 x 3 cube, one axis at a time): a new array. Every face cell of the box
    must be set already: a step along the flat array that wraps across the box's edge lands on
    one of them."""
    e0, e1, e2 = extent
    n = e0 * e1 * e2
    out = mask.copy()
    for stride in (1, e2, e1 * e2):
        src = out.copy()
        for c in range(stride, n):
            out[c] = out[c] | src[c - stride]
        for c in range(n - stride):
            out[c] = out[c] | src[c + stride]
    return out


@njit(cache=True)
def _mark_enclosed(state, base, s1, s2, near, extent):
    """Mark enclosed (:func:`enclose`) the unknown voxels of the box (as :func:`_walls`) that
    are not ``near`` the outside and have no face neighbour near it and not occupied: how many."""
    e0, e1, e2 = extent
    f1 = e1 * e2
    marked = 0
    for x in range(1, e0 - 1):
        for y in range(1, e1 - 1):
            for z in range(1, e2 - 1):
                local, cell = x * f1 + y * e2 + z, base + x * s1 + y * s2 + z
                if state[cell] & (_OCC | _CROSSED | _ENCLOSED) or near[local]:
                    continue
                outside = False
                for step, stride in ((f1, s1), (-f1, -s1), (e2, s2), (-e2, -s2), (1, 1), (-1, -1)):
                    outside = outside or (near[local + step] and not state[cell + stride] & _OCC)
                if not outside:
                    state[cell] = (state[cell] | _ENCLOSED) & _NOT_FRONT
                    marked += 1
    return marked


@njit(cache=True)
def _axis_walk(p, d, index, size):
    """The walk along one axis from ``p`` [m] in unit direction component ``d`` from voxel
    ``index``: the step (-1, 0, 1), the beam parameter [m] of the next voxel boundary and the
    parameter between boundaries (inf when ``d`` is 0)."""
    if d > 0.0:
        return 1, ((index + 1) * size - p) / d, size / d
    if d < 0.0:
        return -1, (index * size - p) / d, -size / d
    return 0, np.inf, np.inf


@njit(cache=True)
def _slab(p, d, low, high, enter, leave):
    """The beam parameters [m] ``enter`` .. ``leave`` narrowed to the slab ``low`` .. ``high``
    [m] of one axis (empty, enter >= leave, when the beam misses it)."""
    if d == 0.0:
        return (enter, leave) if low <= p <= high else (1.0, 0.0)
    a, b = (low - p) / d, (high - p) / d
    return max(enter, min(a, b)), min(leave, max(a, b))


@njit(cache=True)
def occupancy(occupied, lo, hi):
    """The occupied voxels as a grid over their index box: what a walk reads (:func:`_blocked`).

    Parameters
    ----------
    occupied : (o,) int64: keys of the occupied voxels
    lo, hi : (3,) int64: their index box (inclusive)

    Returns
    -------
    (ceil(g / 8),) uint8: one bit per cell of the flat, C-ordered grid of shape
    ``hi - lo + 1`` (g cells), its first cell voxel ``lo``: cell ``c`` is bit ``c & 7`` of
    byte ``c >> 3``, set where occupied. A few kilobytes for a map whose state grid (a byte
    per voxel, also spanning the traversal margin) is megabytes: the walks' reads stay in the
    cache, however cold the simulation between two plans left it.
    """
    e1, e2 = hi[1] - lo[1] + 1, hi[2] - lo[2] + 1
    solid = np.zeros(((hi[0] - lo[0] + 1) * e1 * e2 + 7) // 8, dtype=np.uint8)
    _set_occupied(solid, occupied, lo, hi)
    return solid


@njit(cache=True)
def _set_occupied(solid, keys, lo, hi):
    """Set the bits of the voxels ``keys`` (k,) int64 in ``solid``, :func:`occupancy`'s grid
    over the box ``lo`` .. ``hi`` (3,) int64, which holds them (in place)."""
    e1, e2 = hi[1] - lo[1] + 1, hi[2] - lo[2] + 1
    for key in keys:
        i, j, k = _unpack(key)
        cell = ((i - lo[0]) * e1 + (j - lo[1])) * e2 + (k - lo[2])
        solid[cell >> 3] |= np.uint8(1 << (cell & 7))


@njit(cache=True)
def _blocked(target, position, size, solid, lo, hi, slack, radius):
    """Whether the beam from ``position`` (3,) toward the voxel centre ``target`` (3,) [m, B]
    crosses, before the target's voxel, an occupied voxel whose centre lies within ``radius``
    [m] of the beam's line and nearer to ``position`` than ``target`` by more than ``slack``
    [m].

    The occupied voxels lie within the voxel index box ``lo`` .. ``hi`` (3,) int64
    (inclusive); ``solid`` is that box's occupancy grid (:func:`occupancy`). Only the part of
    the beam inside that box can meet one (nothing outside it is occupied), and whether it
    does is the same whichever end the voxels are visited from; the walk (voxel by voxel,
    Amanatides and Woo) goes backward, from the target's voxel (or where the beam leaves the
    box before it) toward ``position``, until it leaves the box (measured a little cheaper a
    walk than from ``position``'s side on the closed-loop study's scenes: docs/decisions.md).
    Scalars only: no allocation per beam.
    """
    p0, p1, p2 = position[0], position[1], position[2]
    d0, d1, d2 = target[0] - p0, target[1] - p1, target[2] - p2
    length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if length == 0.0:
        return False
    d0, d1, d2 = d0 / length, d1 / length, d2 / length
    enter, leave = _slab(p0, d0, lo[0] * size, (hi[0] + 1) * size, 0.0, length)
    enter, leave = _slab(p1, d1, lo[1] * size, (hi[1] + 1) * size, enter, leave)
    enter, leave = _slab(p2, d2, lo[2] * size, (hi[2] + 1) * size, enter, leave)
    if enter >= leave:
        return False                 # the beam meets no occupied voxel's box before the target
    limit = max(length - slack, 0.0)     # an occluder's centre must be nearer than this
    gi, gj, gk = (np.int64(math.floor(target[0] / size)), np.int64(math.floor(target[1] / size)),
                  np.int64(math.floor(target[2] / size)))
    if lo[0] <= gi <= hi[0] and lo[1] <= gj <= hi[1] and lo[2] <= gk <= hi[2]:
        i, j, k, own = gi, gj, gk, True
    else:                            # a target outside the box: from where the beam leaves it
        i = min(max(np.int64(math.floor((p0 + leave * d0) / size)), lo[0]), hi[0])
        j = min(max(np.int64(math.floor((p1 + leave * d1) / size)), lo[1]), hi[1])
        k = min(max(np.int64(math.floor((p2 + leave * d2) / size)), lo[2]), hi[2])
        own = i == gi and j == gj and k == gk
    # Beam parameters [m] measured back from the target.
    si, ti, di = _axis_walk(target[0], -d0, i, size)
    sj, tj, dj = _axis_walk(target[1], -d1, j, size)
    sk, tk, dk = _axis_walk(target[2], -d2, k, size)
    back = length - enter            # where the beam enters the box
    s2 = hi[2] - lo[2] + 1
    s1 = (hi[1] - lo[1] + 1) * s2
    cell = (i - lo[0]) * s1 + (j - lo[1]) * s2 + (k - lo[2])
    limit2, radius2 = limit * limit, radius * radius
    while True:
        if not own and solid[cell >> 3] & (1 << (cell & 7)) and _occludes(
                (i + 0.5) * size - p0, (j + 0.5) * size - p1, (k + 0.5) * size - p2,
                d0, d1, d2, limit2, radius2):
            return True
        own = False                  # the target's own voxel never hides it
        if ti <= tj and ti <= tk:
            inside = ti < back and lo[0] <= i + si <= hi[0]
            i, ti, cell = i + si, ti + di, cell + si * s1
        elif tj <= tk:
            inside = tj < back and lo[1] <= j + sj <= hi[1]
            j, tj, cell = j + sj, tj + dj, cell + sj * s2
        else:
            inside = tk < back and lo[2] <= k + sk <= hi[2]
            k, tk, cell = k + sk, tk + dk, cell + sk
        if not inside:
            return False


@njit(cache=True)
def _occludes(c0, c1, c2, d0, d1, d2, limit2, radius2):
    """Whether an occupied voxel whose centre is (``c0``, ``c1``, ``c2``) [m] from the beam's
    start occludes the beam along the unit direction (``d0``, ``d1``, ``d2``): its centre is
    nearer than ``sqrt(limit2)`` and within ``sqrt(radius2)`` of the beam's line."""
    far = c0 * c0 + c1 * c1 + c2 * c2
    along = c0 * d0 + c1 * d1 + c2 * d2
    return far < limit2 and far - along * along < radius2


@njit(cache=True)
def hidden(positions, targets, size, solid, lo, hi):
    """Which beams from ``positions`` (p, 3) toward the voxel centres ``targets`` (n, 3) [m,
    B] are stopped by an occupied voxel nearer than the target by more than ``BLOCK_SLACK``
    edges (sim/surface_map.py, :meth:`SurfaceMap.visible`): (p, n) bool. ``solid``, ``lo``,
    ``hi`` as :func:`_blocked`."""
    out = np.zeros((len(positions), len(targets)), dtype=np.bool_)
    for q in range(len(positions)):
        for k in range(len(targets)):
            out[q, k] = _blocked(targets[k], positions[q], size, solid, lo, hi,
                                 BLOCK_SLACK * size, BLOCK_RADIUS * size)
    return out


@njit(cache=True)
def _turn_toward(b0, b1, b2, g0, g1, g2, angle):
    """The unit vector ``(b0, b1, b2)`` turned toward the unit vector ``(g0, g1, g2)`` by
    ``angle`` [rad] in their plane (the goal itself when within ``angle``): three floats."""
    cos = min(max(b0 * g0 + b1 * g1 + b2 * g2, -1.0), 1.0)
    if math.acos(cos) <= angle:
        return g0, g1, g2
    s0, s1, s2 = g0 - cos * b0, g1 - cos * b1, g2 - cos * b2
    c, k = math.cos(angle), math.sin(angle) / math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    return c * b0 + k * s0, c * b1 + k * s1, c * b2 + k * s2


@njit(cache=True)
def _frames(position, target, nominal):
    """The chaser in B (m, 3) [m] and matrices (m, 3, 3) sending B vectors to the nominal
    sensor frame, from ``position`` (m, 3) [m, I], ``target`` (m, 3, 3) B->I and ``nominal``
    (m, 3, 3) nominal sensor->I."""
    m = len(position)
    chaser = np.empty((m, 3))
    to_nominal = np.empty((m, 3, 3))
    for s in range(m):
        for i in range(3):
            chaser[s, i] = (target[s, 0, i] * position[s, 0] + target[s, 1, i] * position[s, 1]
                            + target[s, 2, i] * position[s, 2])
            for j in range(3):
                to_nominal[s, j, i] = (target[s, 0, i] * nominal[s, 0, j]
                                       + target[s, 1, i] * nominal[s, 1, j]
                                       + target[s, 2, i] * nominal[s, 2, j])
    return chaser, to_nominal


@njit(cache=True)
def _toward(point, origin, r):
    """The unit vector from ``origin`` (3,) toward ``point`` (3,), turned by ``r`` (3, 3):
    three floats."""
    d0, d1, d2 = point[0] - origin[0], point[1] - origin[1], point[2] - origin[2]
    a0 = r[0, 0] * d0 + r[0, 1] * d1 + r[0, 2] * d2
    a1 = r[1, 0] * d0 + r[1, 1] * d1 + r[1, 2] * d2
    a2 = r[2, 0] * d0 + r[2, 1] * d1 + r[2, 2] * d2
    norm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    return a0 / norm, a1 / norm, a2 / norm


@njit(cache=True)
def _aims(points, origin, r):
    """The unit vectors from ``origin`` (3,) toward each of ``points`` (c, 3), turned by ``r``
    (3, 3), as :func:`_toward` computes them: three (c,) arrays. One pass without branches
    over every point (the used ones too), which the compiler vectorises: cheaper than
    :func:`_toward` point by point over the open ones."""
    c = len(points)
    x, y, z = np.empty(c), np.empty(c), np.empty(c)
    for q in range(c):
        d0, d1, d2 = points[q, 0] - origin[0], points[q, 1] - origin[1], points[q, 2] - origin[2]
        a0 = r[0, 0] * d0 + r[0, 1] * d1 + r[0, 2] * d2
        a1 = r[1, 0] * d0 + r[1, 1] * d1 + r[1, 2] * d2
        a2 = r[2, 0] * d0 + r[2, 1] * d1 + r[2, 2] * d2
        norm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        x[q], y[q], z[q] = a0 / norm, a1 / norm, a2 / norm
    return x, y, z


@njit(cache=True)
def _sweep_order(row, now):
    """The aims grouped by their sweep rows ``row`` (c,) int64 in the sweep's order (the
    boresight's row ``now`` and those below it first, then from the top): the aims' indices
    in that order (c,) int64 (a stable counting sort) and the start of each group (g + 1,)."""
    c = len(row)
    low = row.min() if c else 0
    span = (row.max() - low + 1) if c else 0
    start = np.zeros(2 * span + 1, dtype=np.int64)
    for q in range(c):
        start[row[q] - low + (0 if row[q] >= now else span) + 1] += 1
    for g in range(1, len(start)):
        start[g] += start[g - 1]
    fill = start[:-1].copy()
    order = np.empty(c, dtype=np.int64)
    for q in range(c):
        g = row[q] - low + (0 if row[q] >= now else span)
        order[fill[g]] = q
        fill[g] += 1
    return order, start


@njit(cache=True)
def _goals(pick, centres, chaser, to_nominal, boresight, max_offset):
    """The goal (n, 3) of each shot, nominal sensor frame: toward ``centres[pick]`` from the
    chaser, within ``max_offset`` [rad] of +z (onto the cone's edge toward it), the last goal
    held where ``pick`` is -1 (``boresight`` before any)."""
    n = len(pick)
    goal = np.empty((n, 3))
    cos_max, sin_max = math.cos(max_offset), math.sin(max_offset)
    for s in range(n):
        if pick[s] < 0:
            goal[s] = goal[s - 1] if s else boresight
            continue
        g0, g1, g2 = _toward(centres[pick[s]], chaser[s], to_nominal[s])
        if g2 < cos_max:
            side = math.sqrt(g0 * g0 + g1 * g1)
            g0, g1, g2 = sin_max * (g0 / side), sin_max * (g1 / side), cos_max
        goal[s, 0], goal[s, 1], goal[s, 2] = g0, g1, g2
    return goal


@njit(cache=True)
def _rate_limit(goal, boresight, reach):
    """From the first goal (n, 3) beyond ``reach`` [rad] of the one before (``boresight`` (3,)
    before the first), turn toward each goal by at most ``reach`` (in place)."""
    started = False
    b0 = b1 = b2 = 0.0
    for s in range(len(goal)):
        if not started:
            before = goal[s - 1] if s else boresight
            dot = goal[s, 0] * before[0] + goal[s, 1] * before[1] + goal[s, 2] * before[2]
            if math.acos(min(max(dot, -1.0), 1.0)) > reach:
                started, b0, b1, b2 = True, before[0], before[1], before[2]
        if started:
            b0, b1, b2 = _turn_toward(b0, b1, b2, goal[s, 0], goal[s, 1], goal[s, 2], reach)
            goal[s, 0], goal[s, 1], goal[s, 2] = b0, b1, b2


@njit(cache=True)
def _turns(goal):
    """The smallest rotations (n, 3, 3) taking +z onto each unit vector of ``goal`` (n, 3)
    (sim/gap_seeking.py, :func:`turn_from_boresight`)."""
    turn = np.empty((len(goal), 3, 3))
    for s in range(len(goal)):
        x, y, z = goal[s, 0], goal[s, 1], goal[s, 2]
        k = 1.0 / (1.0 + z)
        turn[s, 0, 0], turn[s, 0, 1], turn[s, 0, 2] = 1.0 - k * x * x, -k * x * y, x
        turn[s, 1, 0], turn[s, 1, 1], turn[s, 1, 2] = -k * x * y, 1.0 - k * y * y, y
        turn[s, 2, 0], turn[s, 2, 1], turn[s, 2, 2] = -x, -y, z
    return turn


@njit(cache=True)
def not_aside(keys, state, shape, corner, aside, readmit):
    """The ``keys`` (k,) int64 whose voxels' hidden count (the upper bits of the flat ``state``
    grid, shape and first voxel ``shape``, ``corner`` (3,) int64) is below ``aside``, in their
    order; with ``readmit``, every key, its count cleared (in place)."""
    keep = np.empty(len(keys), dtype=np.int64)
    m = 0
    s1, s2 = shape[1] * shape[2], shape[2]
    for key in keys:
        i, j, k = _unpack(key)
        cell = (i - corner[0]) * s1 + (j - corner[1]) * s2 + (k - corner[2])
        if readmit:
            state[cell] &= HIDDEN_STEP - 1
        if state[cell] < aside * HIDDEN_STEP:
            keep[m] = key
            m += 1
    return keep[:m]


@njit(cache=True)
def hidden_counts(keys, state, shape, corner):
    """The hidden count of each voxel of ``keys`` (k,) int64 (the upper bits of the flat
    ``state`` grid, shape and first voxel ``shape``, ``corner`` (3,) int64): (k,) int64."""
    out = np.empty(len(keys), dtype=np.int64)
    s1, s2 = shape[1] * shape[2], shape[2]
    for q in range(len(keys)):
        i, j, k = _unpack(keys[q])
        out[q] = state[(i - corner[0]) * s1 + (j - corner[1]) * s2 + (k - corner[2])] // HIDDEN_STEP
    return out


@njit(cache=True)
def store_hidden(keys, hidden, state, shape, corner):
    """Write the hidden counts ``hidden`` (k,) int64 of the voxels ``keys`` (k,) int64 into the
    upper bits of the flat ``state`` grid (at most ``HIDDEN_MAX``; in place)."""
    s1, s2 = shape[1] * shape[2], shape[2]
    for q in range(len(keys)):
        i, j, k = _unpack(keys[q])
        cell = (i - corner[0]) * s1 + (j - corner[1]) * s2 + (k - corner[2])
        state[cell] = (state[cell] & (HIDDEN_STEP - 1)) + min(hidden[q], HIDDEN_MAX) * HIDDEN_STEP


@njit(cache=True)
def _sort_run(order, start, stop, key):
    """Sort ``order[start:stop]`` in place by ``key[order]``, stably (insertion: a sweep row
    holds a few dozen aims)."""
    for a in range(start + 1, stop):
        q = order[a]
        b = a
        while b > start and key[order[b - 1]] > key[q]:
            order[b] = order[b - 1]
            b -= 1
        order[b] = q


@njit(cache=True)
def sweep(n, centres, used, size, solid, lo, hi, position, target, nominal, boresight,
          max_offset, reach, block, hidden, aside):
    """One interval's aims (sim/gap_seeking.py, :meth:`GapSeeker.command`): the open
    candidates within ``max_offset`` from the interval's middle shot, in a sweep of rows
    ``block`` voxels wide across the view from the boresight's row on, each taken when
    predicted visible from there (:func:`_blocked`), until every shot has one; each shot
    turned toward its aim within ``reach``.

    Parameters
    ----------
    n : int: shots in the interval
    centres : (c, 3) float64, metres, B: the plan's candidates
    used : (c,) bool: candidates already aimed at or set aside; those aimed at or set aside
        now are set (in place)
    size : float, metres: the voxel edge
    solid, lo, hi : the occupied voxels' grid over their index box, and that box
        (:func:`occupancy`, :func:`_blocked`)
    position : (n, 3) float64, metres, I: the chaser at the interval's shots
    target : (n, 3, 3) float64: matrices sending B vectors to I, at the same times
    nominal : (n, 3, 3) float64: matrices sending nominal-sensor vectors to I
    boresight : (3,) float64, unit vector, nominal sensor frame: the commanded one so far
    max_offset : float, rad: largest angle from the nominal boresight
    reach : float, rad: the largest turn between consecutive shots
    block : int: sweep rows are this many voxels wide
    hidden : (c,) int64: how many walks found each candidate hidden; one found hidden now
        counts one more (in place)
    aside : int: a candidate whose hidden count reaches this is set aside: marked used (in
        place), not walked again

    Returns
    -------
    pick : (n,) int64: the open candidate (index among those not used before) each shot aims
        at, or -1 (held)
    goal : (n, 3) float64, unit vectors, nominal sensor frame: the commanded boresights
    turn : (n, 3, 3) float64: the smallest rotations taking ``+z`` onto each ``goal``
        (sim/gap_seeking.py, :func:`turn_from_boresight`)
    left : int: the candidates still open after (not in ``used``): the law then knows,
        without a pass over ``used``, when an interval has nothing left to sweep

    Notes
    -----
    Visibility is tested in the sweep's order and only until the shots are used up: a few
    dozen walks through the map per interval, whatever its size.
    """
    chaser, to_nominal = _frames(position, target, nominal)
    middle = n // 2
    ch = chaser[middle]
    band = block * size / math.sqrt(ch[0] * ch[0] + ch[1] * ch[1] + ch[2] * ch[2])
    now = math.floor(boresight[1] / band)
    # The open candidates within the offset cone from the middle shot: each one's index in
    # ``centres`` and among the open ones, its sweep row and its key along the row
    # (alternately left and right).
    cos_max = math.cos(max_offset)
    cand = np.empty(len(centres), dtype=np.int64)
    rank = np.empty(len(centres), dtype=np.int64)
    row = np.empty(len(centres), dtype=np.int64)
    across = np.empty(len(centres))
    x, y, z = _aims(centres, ch, to_nominal[middle])
    c = n_open = 0
    for q in range(len(centres)):
        if used[q]:
            continue
        if z[q] >= cos_max:
            r = np.int64(math.floor(y[q] / band))
            cand[c], rank[c], row[c] = q, n_open, r
            across[c] = x[q] if r & 1 == 0 else -x[q]
            c += 1
        n_open += 1
    order, start = _sweep_order(row[:c], now)
    pick = np.full(n, -1, dtype=np.int64)
    aimed = np.full(n, -1, dtype=np.int64)
    m = 0
    for g in range(len(start) - 1):
        if m == n:
            break
        _sort_run(order, start[g], start[g + 1], across)
        for q in order[start[g]:start[g + 1]]:
            k = cand[q]
            if _blocked(centres[k], ch, size, solid, lo, hi, BLOCK_SLACK * size,
                        BLOCK_RADIUS * size):
                hidden[k] += 1
                if hidden[k] >= aside:
                    used[k] = True
                    n_open -= 1
            else:
                pick[m], aimed[m] = rank[q], k
                used[k] = True
                m += 1
                if m == n:
                    break
    goal = _goals(aimed, centres, chaser, to_nominal, boresight, max_offset)
    _rate_limit(goal, boresight, reach)
    return pick, goal, _turns(goal), n_open - m


@njit(cache=True)
def frontier_keep(frontier, state, shape, corner):
    """The keys of ``frontier`` (f,) int64 whose voxels still hold the frontier mark in the
    flat ``state`` grid (shape and first voxel ``shape``, ``corner`` (3,) int64): (k,) int64,
    in their order."""
    keep = np.empty(len(frontier), dtype=np.int64)
    m = 0
    s1, s2 = shape[1] * shape[2], shape[2]
    for key in frontier:
        i, j, k = _unpack(key)
        if state[(i - corner[0]) * s1 + (j - corner[1]) * s2 + (k - corner[2])] & _FRONT:
            keep[m] = key
            m += 1
    return keep[:m]


@njit(cache=True)
def spread(keys, block, size):
    """The first of ``keys`` (sorted) in each cube of ``block`` voxels on a side, and their
    centres.

    Parameters
    ----------
    keys : (k,) int64, sorted voxel keys
    block : int: the cube's edge in voxels
    size : float, metres: the voxel edge

    Returns
    -------
    chosen : (c,) int64: the chosen keys, in their order
    centres : (c, 3) float64, metres, B: their voxel centres

    Notes
    -----
    A mark per cube of the keys' own index box (a few thousand cubes: it stays in the cache);
    two passes over the keys (the box, then the marks), nothing else allocated.
    """
    if not len(keys):
        return keys.copy(), np.empty((0, 3))
    # A cube of 2**s voxels: its index by an arithmetic shift (a floor division, as `//`,
    # without the integer divide: three per key would cost more than the rest of the pass).
    shift = -1
    if block & (block - 1) == 0:
        shift = 0
        while (1 << shift) < block:
            shift += 1
    f0 = f1 = f2 = np.iinfo(np.int64).max
    l0 = l1 = l2 = np.iinfo(np.int64).min
    for key in keys:
        c0, c1, c2 = _cube(key, block, shift)
        f0, f1, f2 = min(f0, c0), min(f1, c1), min(f2, c2)
        l0, l1, l2 = max(l0, c0), max(l1, c1), max(l2, c2)
    e1, e2 = l1 - f1 + 1, l2 - f2 + 1
    taken = np.zeros((l0 - f0 + 1) * e1 * e2, dtype=np.bool_)
    chosen = np.empty(len(keys), dtype=np.int64)
    centres = np.empty((len(keys), 3))
    c = 0
    for key in keys:
        c0, c1, c2 = _cube(key, block, shift)
        cell = ((c0 - f0) * e1 + (c1 - f1)) * e2 + (c2 - f2)
        if not taken[cell]:
            taken[cell] = True
            i, j, k = _unpack(key)
            chosen[c] = key
            centres[c, 0] = (i + 0.5) * size
            centres[c, 1] = (j + 0.5) * size
            centres[c, 2] = (k + 0.5) * size
            c += 1
    return chosen[:c].copy(), centres[:c].copy()


@njit(cache=True)
def _cube(key, block, shift):
    """The index (three ints) of the cube of ``block`` voxels on a side holding the voxel
    ``key``: by ``>> shift`` when ``shift`` >= 0 (``block`` is ``2**shift``), else by ``//``."""
    i, j, k = _unpack(key)
    if shift >= 0:
        return i >> shift, j >> shift, k >> shift
    return i // block, j // block, k // block


@njit(cache=True)
def candidates(stored, stored_hidden, frontier, state, shape, corner, occupied, count, rank,
               aside, readmit, most, block, size):
    """A plan's candidates in one call (sim/gap_seeking.py, ``GapSeeker._plan``): the last
    plan's hidden counts stored (:func:`store_hidden`), the frontier list read
    (:func:`frontier_keep`), with ``rank`` >= 0 the least-struck voxels joined
    (:func:`least_struck`) and those set aside left out (:func:`not_aside`), an even subset of
    at most ``most``, one per cube (:func:`spread`) and their hidden counts
    (:func:`hidden_counts`).

    Parameters
    ----------
    stored : (s,) int64; stored_hidden : (s,) int64: keys and hidden counts to store first
    frontier : (f,) int64, sorted keys: the map's frontier list
    state, shape, corner : the flat state grid (updated in place), its shape and first voxel
        (sim/surface_map.py)
    occupied : (o,) int64, sorted keys; count : (o,) int64: their strike counts
    rank : int: the least-struck voxels' rank (:func:`least_struck`), or -1: the frontier only
    aside : int; readmit : bool: as :func:`not_aside`
    most : int: at most this many keys go to the spread (every ``ceil(k / most)``-th)
    block : int: the spread's cube edge in voxels; size : float, metres: the voxel edge

    Returns
    -------
    frontier : (f',) int64: the frontier list, voxels no longer frontier left out
    keys : (c,) int64: the candidates; centres : (c, 3) float64, metres, B
    hidden : (c,) int64: their hidden counts
    """
    store_hidden(stored, stored_hidden, state, shape, corner)
    if len(frontier):
        frontier = frontier_keep(frontier, state, shape, corner)
    keys = frontier
    if rank >= 0:
        keys = not_aside(least_struck(frontier, occupied, count, rank), state, shape, corner,
                         aside, readmit)
    if len(keys) > most:
        keys = keys[::(len(keys) + most - 1) // most].copy()
    chosen, centres = spread(keys, block, size)
    return frontier, chosen, centres, hidden_counts(chosen, state, shape, corner)


# Strike counts below this are ranked by a histogram (the least-struck quantile's count is a
# few strikes); a rank among larger counts falls back to a partition.
_HISTOGRAM_COUNTS = 64


@njit(cache=True)
def _kth_smallest(count, rank):
    """The ``rank``-th (0-based) smallest of the non-negative integers ``count`` (o,), as
    ``np.partition(count, rank)[rank]``: from a histogram of the counts below
    ``_HISTOGRAM_COUNTS`` when the rank falls among them (one pass, no copy)."""
    histogram = np.zeros(_HISTOGRAM_COUNTS, dtype=np.int64)
    for c in count:
        if c < _HISTOGRAM_COUNTS:
            histogram[c] += 1
    below = 0
    for value in range(_HISTOGRAM_COUNTS):
        below += histogram[value]
        if below > rank:
            return np.int64(value)
    return np.partition(count, rank)[rank]


@njit(cache=True)
def least_struck(frontier, occupied, count, rank):
    """The sorted union of ``frontier`` and the occupied voxels struck at most as often as the
    ``rank``-th least-struck one.

    Parameters
    ----------
    frontier : (f,) int64, sorted keys
    occupied : (o,) int64, sorted keys; count : (o,) int64: their strike counts
    rank : int: 0-based rank in the sorted counts (0 <= rank < o)

    Returns
    -------
    (k,) int64, sorted, each key once.

    Notes
    -----
    ``count <= np.quantile(count, q)`` selects exactly the counts up to the one at rank
    ``floor((o - 1) * q)``: the quantile lies between that count and the next larger one in
    sorted order, and counts are integers with none between those two.
    """
    threshold = _kth_smallest(count, rank)
    m = len(frontier)
    out = np.empty(m + len(occupied), dtype=np.int64)
    a = k = 0
    for c in range(len(occupied)):
        if count[c] > threshold:
            continue
        key = occupied[c]
        while a < m and frontier[a] < key:
            out[k] = frontier[a]
            a += 1
            k += 1
        if a < m and frontier[a] == key:
            a += 1
        out[k] = key
        k += 1
    while a < m:
        out[k] = frontier[a]
        a += 1
        k += 1
    return out[:k]
