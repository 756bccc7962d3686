"""Compiled kernels of the gap-seeking planner: the voxel map's update and an interval's aims.

The closed loop (sim/gap_seeking.py) simulates one replanning interval of 30 shots at a time, a
millisecond or so of simulation; a planner of a few dozen numpy calls costs as much again in
call overhead alone. These kernels do each step in one compiled call (numba, ``cache=True``, so
that a process after the first loads them from disk instead of compiling them):

- :func:`recorded_beams`: every beam of the recorded shots, in the body frame;
- :func:`strike_index` and :func:`strike_merge`: the strikes into the occupied voxels and the
  frontier marks around the new ones;
- :func:`carve`: the voxels the beams crossed before their strikes;
- :func:`hidden`: the depth image of the occupied voxels from a few positions;
- :func:`sweep`: one interval's aims (visibility, the sweep's order, the slew limits) and the
  commanded turns.

They do what the numpy code they replaced did, in the same order of operations where it
matters (the same voxel keys, the same sweep order); tests/sim/test_planner_kernels.py holds
that numpy code and checks each kernel against it on small maps. Only the closed loop imports
this module, so the numba import (a few tenths of a second) is paid by closed-loop runs alone.

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
    BLOCK_SLACK,
    CROSSED,
    FRONTIER,
    OCCUPIED,
    PIXEL_EDGES,
    SPLAT,
    TRAVERSAL_STEP,
)

_OCC, _CROSSED, _FRONT = int(OCCUPIED), int(CROSSED), int(FRONTIER)
_KNOWN = _OCC | _CROSSED | _FRONT
_NOT_FRONT = 0xFF ^ _FRONT          # uint8 bit masks, as plain ints


@njit(cache=True)
def _matrix(q):
    """(3, 3) rotation matrix of the quaternion ``q`` (x, y, z, w), normalised first."""
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    x, y, z, w = q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm
    m = np.empty((3, 3))
    m[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    m[0, 1] = 2.0 * (x * y - z * w)
    m[0, 2] = 2.0 * (x * z + y * w)
    m[1, 0] = 2.0 * (x * y + z * w)
    m[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    m[1, 2] = 2.0 * (y * z - x * w)
    m[2, 0] = 2.0 * (x * z - y * w)
    m[2, 1] = 2.0 * (y * z + x * w)
    m[2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return m


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
    for s in range(n):
        to_body[s] = _matrix(target[s]).T
        sensor_m[s] = _matrix(sensor[s])
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
    of ``unique`` not in ``occupied``."""
    o, u = len(occupied), len(unique)
    merged = np.empty(o + u, dtype=np.int64)
    m_count = np.empty(o + u, dtype=np.int64)
    m_view = np.empty((o + u, 3))
    new = np.empty(u, dtype=np.int64)
    a = c = m = n_new = 0
    while a < o or c < u:
        old = c >= u or (a < o and occupied[a] <= unique[c])
        both = old and c < u and occupied[a] == unique[c]
        merged[m] = occupied[a] if old else unique[c]
        m_count[m] = (count[a] if old else 0) + (u_count[c] if both or not old else 0)
        for i in range(3):
            if both:
                m_view[m, i] = occupied_view[a, i] + u_view[c, i]
            else:
                m_view[m, i] = occupied_view[a, i] if old else u_view[c, i]
        if not old:
            new[n_new] = unique[c]
            n_new += 1
        a += old
        c += both or not old
        m += 1
    return merged[:m], m_count[:m], m_view[:m], new[:n_new]


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
    """The sorted union of the sorted, disjoint key arrays ``a`` and ``b``."""
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
def strike_merge(index, view, occupied, count, occupied_view, frontier, state, shape, corner,
                 size):
    """Merge strikes into the occupied voxels and mark the unknown neighbours of new ones.

    Parameters
    ----------
    index : (h, 3) int64; view : (h, 3) float64: from :func:`strike_index`
    occupied : (o,) int64, sorted keys; count : (o,) int64; occupied_view : (o, 3) float64
    frontier : (f,) int64, sorted keys: the frontier list (sim/surface_map.py)
    state : (g,) uint8: the flat state grid, updated in place (it must hold every voxel of
        ``index`` and its face neighbours)
    shape : (3,) int64: the grid's shape; corner : (3,) int64: the voxel index of its first cell
    size : float, metres: the voxel edge

    Returns
    -------
    occupied, count, occupied_view, frontier : the merged arrays (new arrays)
    centres : (o', 3) float64, metres, B: the centres of the merged occupied voxels
    n_new : int: how many voxels were struck for the first time
    """
    keys = np.empty(len(index), dtype=np.int64)
    for k in range(len(index)):
        keys[k] = _pack(index[k, 0], index[k, 1], index[k, 2])
    unique, u_count, u_view = _group(keys, view)
    merged, m_count, m_view, new = _merge_counts(occupied, count, occupied_view, unique,
                                                 u_count, u_view)
    fresh = _mark_new(new, state, shape, corner)
    return merged, m_count, m_view, _join(frontier, fresh), _centres(merged, size), len(new)


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
    the middles of those steps (sim/surface_map.py).
    """
    s1, s2 = shape[1] * shape[2], shape[2]
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
        start = enter / size
        for s in range(samples):
            along = start + (s + 0.5) / TRAVERSAL_STEP
            cell = 0
            for i, stride in ((0, s1), (1, s2), (2, 1)):
                c = np.int64(origins[k, i] / size - corner[i] + along * directions[k, i])
                cell += stride * min(max(c, 0), shape[i] - 1)
            state[cell] = (state[cell] | _CROSSED) & _NOT_FRONT


@njit(cache=True)
def _image_axes(position, centre):
    """Image axes (3, 3) from ``position`` (3,) [m, B]: rows a and b across, w toward ``centre``
    (3,) [m, B]."""
    w = centre - position
    w /= math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    a = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    a -= (a[0] * w[0] + a[1] * w[1] + a[2] * w[2]) * w
    a /= math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    axes = np.empty((3, 3))
    axes[0], axes[2] = a, w
    axes[1, 0] = w[1] * a[2] - w[2] * a[1]
    axes[1, 1] = w[2] * a[0] - w[0] * a[2]
    axes[1, 2] = w[0] * a[1] - w[1] * a[0]
    return axes


@njit(cache=True)
def _project(position, axes, points, local, distance):
    """Fill ``local`` (m, 3) with ``points`` (m, 3) [m, B] in image axes from ``position``
    (3,) [m, B] and ``distance`` (m,) with their distances [m]; return the smallest."""
    a0, a1, a2 = axes[0, 0], axes[0, 1], axes[0, 2]
    b0, b1, b2 = axes[1, 0], axes[1, 1], axes[1, 2]
    w0, w1, w2 = axes[2, 0], axes[2, 1], axes[2, 2]
    p0, p1, p2 = position[0], position[1], position[2]
    nearest = np.inf
    for k in range(len(points)):
        x0, x1, x2 = points[k, 0] - p0, points[k, 1] - p1, points[k, 2] - p2
        la = x0 * a0 + x1 * a1 + x2 * a2
        lb = x0 * b0 + x1 * b1 + x2 * b2
        lw = x0 * w0 + x1 * w1 + x2 * w2
        local[k, 0], local[k, 1], local[k, 2] = la, lb, lw
        d = math.sqrt(la * la + lb * lb + lw * lw)
        distance[k] = d
        nearest = min(nearest, d)
    return nearest


@njit(cache=True)
def _pixels(local, pixel, uv):
    """Fill ``uv`` (m, 2) with the pixel of each point of ``local`` (m, 3) at ``pixel`` [rad]
    (0, 0 behind the position); return the image's first pixel and size (4,) int64: the
    points' pixels and ``2 SPLAT`` around them (room for the neighbourhoods read)."""
    lo0 = lo1 = np.iinfo(np.int64).max
    hi0 = hi1 = np.iinfo(np.int64).min
    for k in range(len(local)):
        if local[k, 2] > 0:
            scale = local[k, 2] * pixel
            uv[k, 0] = np.int64(math.floor(local[k, 0] / scale))
            uv[k, 1] = np.int64(math.floor(local[k, 1] / scale))
        else:
            uv[k, 0] = uv[k, 1] = 0
        lo0, hi0 = min(lo0, uv[k, 0]), max(hi0, uv[k, 0])
        lo1, hi1 = min(lo1, uv[k, 1]), max(hi1, uv[k, 1])
    box = np.empty(4, dtype=np.int64)
    box[0], box[1] = lo0 - 2 * SPLAT, lo1 - 2 * SPLAT
    box[2], box[3] = hi0 + 2 * SPLAT + 1 - box[0], hi1 + 2 * SPLAT + 1 - box[1]
    return box


@njit(cache=True)
def _mark(local, distance, uv, box, image, stamp, tick):
    """Each point in front marks its own pixel with its distance where nearer (pixels whose
    stamp is not ``tick`` count as empty)."""
    w1 = box[3]
    for k in range(len(local)):
        if local[k, 2] <= 0:
            continue
        cell = (uv[k, 0] - box[0]) * w1 + (uv[k, 1] - box[1])
        if stamp[cell] != tick:
            stamp[cell], image[cell] = tick, distance[k]
        elif distance[k] < image[cell]:
            image[cell] = distance[k]


@njit(cache=True)
def _nearest_around(u, v, box, image, stamp, tick):
    """The smallest distance marked in pixel (u, v) and the ``SPLAT`` pixels around it (inf
    when none is); (u, v) within ``SPLAT`` of the marked pixels' range or beyond it."""
    w0, w1 = box[2], box[3]
    u, v = u - box[0], v - box[1]
    nearest = np.inf
    if u < SPLAT or v < SPLAT or u >= w0 - SPLAT or v >= w1 - SPLAT:
        return nearest
    for du in range(-SPLAT, SPLAT + 1):
        for dv in range(-SPLAT, SPLAT + 1):
            cell = (u + du) * w1 + (v + dv)
            if stamp[cell] == tick and image[cell] < nearest:
                nearest = image[cell]
    return nearest


@njit(cache=True)
def hidden(positions, occupied, targets, size, image, stamp, tick):
    """Which ``targets`` lie behind an ``occupied`` centre in the depth image from each of
    ``positions`` (sim/surface_map.py, :meth:`SurfaceMap.visible`).

    Parameters
    ----------
    positions : (p, 3) float64, metres, B
    occupied : (o, 3) float64, metres, B: occupied voxel centres (o >= 1)
    targets : (n, 3) float64, metres, B: voxel centres
    size : float, metres: the voxel edge
    image : (s,) float64; stamp : (s,) int64; tick : int
        Room for the image, reused from call to call: a pixel holds a distance only where
        its stamp is the image's own tick (each image takes the next ticks), so no image is
        ever cleared (clearing or allocating a megabyte costs more than the rest).

    Returns
    -------
    out : (p, n) bool: True where a centre in the target's pixel (or the ``SPLAT`` pixels
        around it) lies nearer than the target by more than ``BLOCK_SLACK`` voxel edges
    image, stamp, tick : the room (larger when an image did not fit) and the last tick used

    Notes
    -----
    Each occupied centre marks its own pixel and each target reads the minimum over its pixel
    and the ``SPLAT`` around it: the same minimum as marking every pixel around each centre and
    reading the target's own (sim/surface_map.py), with one write per centre instead of nine.
    """
    p, o, n = len(positions), len(occupied), len(targets)
    out = np.zeros((p, n), dtype=np.bool_)
    centre = np.empty(3)
    for i in range(3):
        centre[i] = 0.5 * (occupied[:, i].min() + occupied[:, i].max())
    local = np.empty((o, 3))
    distance = np.empty(o)
    uv = np.empty((o, 2), dtype=np.int64)
    t_local = np.empty((n, 3))
    t_distance = np.empty(n)
    t_uv = np.empty((n, 2), dtype=np.int64)
    for q in range(p):
        axes = _image_axes(positions[q], centre)
        nearest = _project(positions[q], axes, occupied, local, distance)
        pixel = PIXEL_EDGES * size / nearest                # rad per pixel
        box = _pixels(local, pixel, uv)
        w0, w1 = box[2], box[3]
        if len(image) < w0 * w1:
            image = np.empty(2 * w0 * w1)
            stamp = np.zeros(2 * w0 * w1, dtype=np.int64)
        tick += 1
        _mark(local, distance, uv, box, image, stamp, tick)
        _project(positions[q], axes, targets, t_local, t_distance)
        _pixels(t_local, pixel, t_uv)
        for k in range(n):
            if t_local[k, 2] > 0:
                near = _nearest_around(t_uv[k, 0], t_uv[k, 1], box, image, stamp, tick)
                out[q, k] = near < t_distance[k] - BLOCK_SLACK * size
    return out, image, stamp, tick


@njit(cache=True)
def _turn_toward(b, goal, angle):
    """Unit vector ``b`` (3,) turned toward ``goal`` (3,) by ``angle`` [rad] in their plane
    (``goal`` itself when within ``angle``)."""
    cos = min(max(b[0] * goal[0] + b[1] * goal[1] + b[2] * goal[2], -1.0), 1.0)
    if math.acos(cos) <= angle:
        return goal.copy()
    s = goal - cos * b
    c, k = math.cos(angle), math.sin(angle) / math.sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2])
    return c * b + k * s


@njit(cache=True)
def _stable_by(order, key):
    """``order`` (m,) int64 re-sorted, stably, by ``key[order]``."""
    return order[np.argsort(key[order], kind="mergesort")]


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
def _unit(points, origin, rotation):
    """Unit vectors (c, 3) from ``origin`` (3,) toward ``points`` (c, 3), turned by
    ``rotation`` (3, 3)."""
    out = np.empty((len(points), 3))
    for k in range(len(points)):
        d0, d1, d2 = (points[k, 0] - origin[0], points[k, 1] - origin[1],
                      points[k, 2] - origin[2])
        for i in range(3):
            out[k, i] = rotation[i, 0] * d0 + rotation[i, 1] * d1 + rotation[i, 2] * d2
        out[k] /= math.sqrt(out[k, 0] * out[k, 0] + out[k, 1] * out[k, 1]
                            + out[k, 2] * out[k, 2])
    return out


@njit(cache=True)
def _sweep_order(aim, seen_later, band, boresight):
    """The order of the aims (c, 3) (nominal sensor frame) in the sweep: those not seen at the
    look-ahead (``seen_later`` (c,) bool) first, then rows ``band`` [rad] wide from the
    boresight's (3,) row on (the rows below it first, then from the top), alternately left and
    right along each row; ties kept in their order (a stable sort by each key in turn)."""
    c = len(aim)
    now = math.floor(boresight[1] / band)
    row = np.empty(c)
    across = np.empty(c)
    earlier = np.empty(c)
    later_seen = np.empty(c)
    for q in range(c):
        r = math.floor(aim[q, 1] / band)
        row[q] = r
        across[q] = aim[q, 0] if np.int64(r) & 1 == 0 else -aim[q, 0]
        earlier[q] = 0.0 if r >= now else 1.0
        later_seen[q] = 1.0 if seen_later[q] else 0.0
    order = np.arange(c)
    for key in (across, row, earlier, later_seen):
        order = _stable_by(order, key)
    return order


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
        g = _unit(centres[pick[s]:pick[s] + 1], chaser[s], to_nominal[s])[0]
        if g[2] < cos_max:
            side = math.sqrt(g[0] * g[0] + g[1] * g[1])
            g[0], g[1], g[2] = sin_max * (g[0] / side), sin_max * (g[1] / side), cos_max
        goal[s] = g
    return goal


@njit(cache=True)
def _rate_limit(goal, boresight, reach):
    """From the first goal (n, 3) beyond ``reach`` [rad] of the one before (``boresight`` (3,)
    before the first), turn toward each goal by at most ``reach`` (in place)."""
    started = False
    b = boresight.copy()
    for s in range(len(goal)):
        if not started:
            before = goal[s - 1] if s else boresight
            dot = goal[s, 0] * before[0] + goal[s, 1] * before[1] + goal[s, 2] * before[2]
            if math.acos(min(max(dot, -1.0), 1.0)) > reach:
                started, b = True, before.copy()
        if started:
            b = _turn_toward(b, goal[s], reach)
            goal[s] = b


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
def sweep(n, centres, used, occupied, size, position, target, nominal, boresight, max_offset,
          reach, block, image, stamp, tick):
    """One interval's aims (sim/gap_seeking.py, :meth:`GapSeeker.command`): the open
    candidates predicted visible from the interval's middle shot and within ``max_offset``,
    those hidden at the look-ahead first, then in a sweep of rows ``block`` voxels wide across
    the view from the boresight's row on; each shot turned toward its aim within ``reach``.

    Parameters
    ----------
    n : int: shots in the interval
    centres : (c, 3) float64, metres, B: the plan's candidates
    used : (c,) bool: candidates already aimed at; those aimed at now are set (in place)
    occupied : (o, 3) float64, metres, B: occupied voxel centres
    size : float, metres: the voxel edge
    position : (n + 1, 3) float64, metres, I: the chaser at the interval's shots and at the
        look-ahead time
    target : (n + 1, 3, 3) float64: matrices sending B vectors to I, at the same times
    nominal : (n + 1, 3, 3) float64: matrices sending nominal-sensor vectors to I
    boresight : (3,) float64, unit vector, nominal sensor frame: the commanded one so far
    max_offset : float, rad: largest angle from the nominal boresight
    reach : float, rad: the largest turn between consecutive shots
    block : int: sweep rows are this many voxels wide
    image, stamp, tick : room for the depth images (:func:`hidden`)

    Returns
    -------
    pick : (n,) int64: the open candidate (index among those not used before) each shot aims
        at, or -1 (held)
    goal : (n, 3) float64, unit vectors, nominal sensor frame: the commanded boresights
    turn : (n, 3, 3) float64: the smallest rotations taking ``+z`` onto each ``goal``
        (sim/gap_seeking.py, :func:`turn_from_boresight`)
    image, stamp, tick : the room after (:func:`hidden`)
    """
    chaser, to_nominal = _frames(position, target, nominal)
    open_ = np.flatnonzero(~used)
    cent = centres[open_]
    middle = n // 2
    if len(occupied) and len(cent):
        views = np.empty((2, 3))
        views[0], views[1] = chaser[middle], chaser[n]
        behind, image, stamp, tick = hidden(views, occupied, cent, size, image, stamp, tick)
        seen = ~behind
    else:
        seen = np.ones((2, len(cent)), dtype=np.bool_)
    aim = _unit(cent, chaser[middle], to_nominal[middle])
    ok_ = np.flatnonzero(seen[0] & (aim[:, 2] >= math.cos(max_offset)))
    ch = chaser[middle]
    band = block * size / math.sqrt(ch[0] * ch[0] + ch[1] * ch[1] + ch[2] * ch[2])
    chosen = ok_[_sweep_order(aim[ok_], seen[1][ok_], band, boresight)[:n]]
    for k in chosen:
        used[open_[k]] = True
    pick = np.full(n, -1, dtype=np.int64)
    pick[:len(chosen)] = chosen
    goal = _goals(pick, cent, chaser, to_nominal, boresight, max_offset)
    _rate_limit(goal, boresight, reach)
    return pick, goal, _turns(goal), (image, stamp, tick)


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
def spread(keys, block, size, shape, corner):
    """The first of ``keys`` (sorted) in each cube of ``block`` voxels on a side, and their
    centres.

    Parameters
    ----------
    keys : (k,) int64, sorted voxel keys, all within the map's grid
    block : int: the cube's edge in voxels
    size : float, metres: the voxel edge
    shape, corner : (3,) int64: the grid's shape and the voxel index of its first cell

    Returns
    -------
    chosen : (c,) int64: the chosen keys, in their order
    centres : (c, 3) float64, metres, B: their voxel centres
    """
    # A grid of the cubes, from the cube holding the grid's first voxel.
    first = np.empty(3, dtype=np.int64)
    extent = np.empty(3, dtype=np.int64)
    for i in range(3):
        first[i] = corner[i] // block
        extent[i] = (corner[i] + shape[i] - 1) // block - first[i] + 1
    taken = np.zeros(extent[0] * extent[1] * extent[2], dtype=np.bool_)
    keep = np.zeros(len(keys), dtype=np.bool_)
    for q in range(len(keys)):
        i, j, k = _unpack(keys[q])
        cell = (((i // block - first[0]) * extent[1] + (j // block - first[1])) * extent[2]
                + (k // block - first[2]))
        if not taken[cell]:
            taken[cell] = keep[q] = True
    chosen = keys[keep]
    return chosen, _centres(chosen, size)


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
    threshold = np.partition(count, rank)[rank]
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
