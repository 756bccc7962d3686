"""Exact (float64) distances from points to a triangle mesh, found quickly with Open3D's BVH.

How a query works
-----------------
1. Open3D's ``RaycastingScene.compute_closest_points`` (Embree, float32, both cores) names a
   candidate triangle ``t0`` for every point. Coordinates are re-centred on the mesh's bounding-box
   centre first, so float32 keeps ~7 digits of the mesh's size rather than of its position.
2. The exact float64 distance to ``t0`` is computed, and the triangles sharing a vertex with
   ``t0`` (its ring) are checked for being closer: this is the guard against float32 picking a
   wrong near-tie triangle. A near-tie at a shared edge or vertex is always with a ring face.
   (A near-tie with a triangle sharing no vertex with ``t0``, such as the far side of a plate
   thinner than the float32 error, is not guarded.)
3. Most points need no ring check, by bounds computed once per face and side of its plane. Let
   p project into ``t0``'s interior at height H above its plane. Every ring face T touches
   ``t0`` at a corner V; take a line L through V in ``t0``'s plane with ``t0`` on its inner
   side and T's projection reaching beyond it (one of ``t0``'s two edge lines through V, or the
   line through V across the bisector of ``t0``'s angle there), so that T's height above the
   plane is at most ``c_T`` times the in-plane distance beyond L (``z <= c_T d_L``, a linear
   bound fixed by T's corners). If the projection of p lies r_L inside L, a point x of T has
   ``|p - x|**2 - H**2 >= (r_L + d_L)**2 - 2 H c_T d_L >= 2 d_L (2 r_L - H c_T)``, so T cannot
   be closer when ``2 r_L >= H c_T``. The set-up keeps, per face, side and each of its six
   lines (three edge lines, three bisector lines), ``c_L`` = the largest ``c_T`` of the ring
   faces assigned to L (each to the line giving it the smallest ``c_T``; infinite when none
   works, e.g. a ring face folded over ``t0``). Ring faces rising by no more than
   ``defaults.COPLANAR_FRACTION`` of the mesh diagonal are ignored (they can be closer by at
   most that).

   When ``2 r_L > H c_L`` on all six lines (the fast path, most points) the distance is H and
   the closest point the projection. Otherwise every ring face whose lower bound
   ``sqrt(h_t**2 + e_t**2)`` (h_t: distance to its plane, e_t: how far the projection falls
   outside it) is below the distance to ``t0`` is evaluated with the closed-form closest point
   on a triangle (Ericson, *Real-Time Collision Detection*, 5.1.5) and the minimum taken; ties
   go to the lowest face index.

The set-up is a few vectorised passes over (face, ring face) pairs, about 10 us of CPU per face
(2 s for 2e5 faces here): several times an Open3D query of as many points, half the padded
per-neighbour analysis it replaced. At query time nothing is computed per pair except for the
points that need the ring check (about 2 % of points near a noisy surface).

Closest points on an edge or a vertex are computed from the edge's endpoints in a canonical order
(lower vertex index first), so two faces sharing the edge give the same bits: results do not
depend on which of two tied triangles Embree returned.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from metrics import defaults
from metrics.inputs import as_mesh, as_points, bbox_diagonal

# Barycentric margin of the fast path's "projects into the interior" test. Any value >= 0 is
# exact (points inside the margin take the exact slow path); 1e-12 keeps points whose projection
# lies on an edge, up to float64 rounding, off the fast path.
_INTERIOR_MARGIN = 1e-12
# Columns of the per-face table gathered once per query point (MeshDistance._table): vertex A,
# unit normal, dual basis vectors g_b and g_c, altitudes, then the bisector-line coefficients:
# the distance of a projection inside the face from the bisector line at corner j is
# sum_i _BISECT[3 j + i] * weight_i (module docstring, 3.).
_A, _N, _GB, _GC, _ALT, _BISECT = (slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12),
                                   slice(12, 15), slice(15, 24))
# (face, ring face) pairs handled per block at set-up: ~40 float64 temporaries of this length.
_PAIR_BLOCK = 1 << 18


class MeshDistance:
    """Exact float64 point-to-surface distances to one triangle mesh (reusable across queries).

    Parameters
    ----------
    mesh : Mesh or (vertices, faces)
        Vertices (n, 3) metres, faces (m, 3) int; validated by ``inputs.as_mesh``.

    Notes
    -----
    Faces whose doubled area is below ``defaults.DEGENERATE_AREA_FRACTION`` of the squared
    diagonal (segments and points) have no surface and are ignored. Building costs about 10 us
    of CPU per face (the ring slopes); the Open3D scene is built on the first query. See the
    module docstring for the method.

    Examples
    --------
    >>> md = MeshDistance((vertices, faces))                  # doctest: +SKIP
    >>> distance, face, closest = md.query(points)            # doctest: +SKIP
    """

    def __init__(self, mesh):
        mesh = as_mesh(mesh, "mesh")
        self.mesh = mesh
        v = mesh.vertices
        self.centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
        self.scale = max(bbox_diagonal(v), np.finfo(float).tiny)
        # Weld exactly repeated vertices (STL-style soups), so faces touching in space share
        # vertex indices in the ring; re-centre: all computation happens in _v, _f.
        unique, inverse = np.unique(v, axis=0, return_inverse=True)
        self._v = unique - self.centre
        self._f = f = np.ascontiguousarray(inverse.reshape(-1)[mesh.faces])
        a = self._v[f[:, 0]]
        ab = self._v[f[:, 1]] - a
        ac = self._v[f[:, 2]] - a
        cross = np.cross(ab, ac)
        double_area = np.linalg.norm(cross, axis=1)
        self.degenerate = double_area <= defaults.DEGENERATE_AREA_FRACTION * self.scale**2
        ok = ~self.degenerate
        normal = np.zeros_like(cross)
        normal[ok] = cross[ok] / double_area[ok, None]
        # Dual basis of (ab, ac) in the face plane: v = g_b . (p - a), w = g_c . (p - a) are the
        # barycentric weights of B and C of the projection of p (u = 1 - v - w that of A).
        bb = np.einsum("ij,ij->i", ab, ab)
        bc = np.einsum("ij,ij->i", ab, ac)
        cc = np.einsum("ij,ij->i", ac, ac)
        den = np.where(ok, double_area**2, 1.0)[:, None]
        g_b = np.where(ok[:, None], (cc[:, None] * ab - bc[:, None] * ac) / den, 0.0)
        g_c = np.where(ok[:, None], (bb[:, None] * ac - bc[:, None] * ab) / den, 0.0)
        # Altitudes: a point with barycentric weight u (of A) lies u * altitude_A from line BC,
        # and likewise for B (line CA) and C (line AB).
        lengths = np.linalg.norm(np.stack([ac - ab, ac, ab], axis=1), axis=2)
        altitude = double_area[:, None] / np.where(lengths > 0, lengths, 1.0)
        self.normals = normal
        # Faces around each vertex (CSR): the ring of a face is the faces around its corners.
        self._incident = np.argsort(f.ravel(), kind="stable") // 3
        count = np.bincount(f.ravel(), minlength=len(unique))
        self._start = np.concatenate([[0], np.cumsum(count)])
        self._scene_faces = np.flatnonzero(ok)
        # Corner j's bisector line: unit bisector of the angle at j, distances of the corners.
        corners = np.stack([a, a + ab, a + ac], axis=1)  # (m, 3, 3)
        bisect = np.zeros((len(f), 3, 3))
        for j in range(3):
            edge = corners - corners[:, j:j + 1]  # (m, 3 corners, 3), zero at j
            length = np.linalg.norm(edge, axis=2, keepdims=True)
            unit = edge / np.where(length > 0, length, 1.0)
            direction = unit.sum(axis=1)
            direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-300)
            bisect[:, j] = np.einsum("mij,mj->mi", edge, direction)
        self._table = np.hstack([a, normal, g_b, g_c, altitude, bisect.reshape(-1, 9)])
        # Per face and side (row 2 f + side), the ring slope c_L of its six lines.
        self._slope = self._ring_slopes().reshape(-1, 6)
        self._scene = None

    # ------------------------------------------------------------------ set-up

    def _ring(self, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(face, corner, ring face) triples of the given faces, ring faces non-degenerate.

        A face sharing an edge appears twice (once per shared corner); ``faces`` themselves
        are left out.

        Returns
        -------
        row : (q,) int64, index into ``faces``
        corner : (q,) int64, 0..2, the corner of ``faces[row]`` the ring face touches
        ring : (q,) int64, face index
        """
        vertex = self._f[faces].ravel()
        first, degree = self._start[vertex], np.diff(self._start)[vertex]
        owner = np.repeat(np.arange(len(vertex)), degree)
        offset = np.arange(len(owner)) - np.repeat(np.cumsum(degree) - degree, degree)
        ring = self._incident[np.repeat(first, degree) + offset]
        row, corner = owner // 3, owner % 3
        keep = (ring != faces[row]) & ~self.degenerate[ring]
        return row[keep], corner[keep], ring[keep]

    def _ring_slopes(self) -> np.ndarray:
        """Per face, side and line, the largest ring slope c_T (module docstring, 3.).

        Returns
        -------
        (m, 2, 6) float64
            Side 0 is in front of the face (along its normal), side 1 behind it; lines 0..2 are
            the edge lines opposite corners 0..2, lines 3..5 the bisector lines at corners 0..2.
        """
        eta = defaults.COPLANAR_FRACTION * self.scale
        slope = np.zeros((len(self._f), 2, 6))
        table = self._table
        faces = np.flatnonzero(~self.degenerate)
        # Blocks of faces holding about _PAIR_BLOCK pairs each.
        pairs = np.cumsum(np.diff(self._start)[self._f[faces]].sum(axis=1))
        cuts = np.searchsorted(pairs, np.arange(_PAIR_BLOCK, pairs[-1], _PAIR_BLOCK))
        edges = np.unique(np.concatenate([[0], cuts, [len(faces)]]))

        geometry = np.ascontiguousarray(table[:, :15])
        bisectors = np.ascontiguousarray(table[:, _BISECT]).reshape(-1, 3)  # row 3 f + corner
        flat = slope.reshape(-1)  # index (2 f + side) * 6 + line

        def run(lo: int, hi: int) -> None:
            block = faces[lo:hi]
            row, corner, ring = self._ring(block)
            own = block[row]
            q = np.arange(len(row))
            tri = self._f[ring]
            corners = self._f[own]
            touch = corners[q, corner]
            # T's two corners other than the touching one, y1 and y2.
            at = np.where(tri[:, 0] == touch, 0, np.where(tri[:, 1] == touch, 1, 2))
            frame = np.take(geometry, own, axis=0)
            coef = np.take(bisectors, 3 * own + corner, axis=0)
            rises, beyonds = [], []
            for turn in (1, 2):
                y = tri[q, (at + turn) % 3]
                rel = np.take(self._v, y, axis=0) - frame[:, _A]
                z = np.einsum("ij,ij->i", rel, frame[:, _N])
                bv = np.einsum("ij,ij->i", rel, frame[:, _GB])
                bw = np.einsum("ij,ij->i", rel, frame[:, _GC])
                # A corner of f (T shares an edge): exact weights and height.
                is_b, is_c = y == corners[:, 1], y == corners[:, 2]
                corner_of_f = is_b | is_c | (y == corners[:, 0])
                z = np.where(corner_of_f, 0.0, z)
                bv = np.where(corner_of_f, is_b, bv)
                bw = np.where(corner_of_f, is_c, bw)
                bu = 1.0 - bv - bw
                rises.append(z)
                beyonds.append(np.stack([-bu * frame[:, 12], -bv * frame[:, 13],
                                         -bw * frame[:, 14],
                                         -(bu * coef[:, 0] + bv * coef[:, 1] + bw * coef[:, 2])],
                                        axis=1))
            (z1, z2), (d1, d2) = rises, beyonds
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio1, ratio2 = z1[:, None] / d1, z2[:, None] / d2
            for side, sign in ((0, 1.0), (1, -1.0)):
                r1, r2 = (ratio1, ratio2) if side == 0 else (-ratio1, -ratio2)
                # z <= c d at every corner: c >= z / d where d > 0, c <= z / d where d < 0.
                low = np.maximum(np.maximum(np.where(d1 > 0, r1, 0.0), np.where(d2 > 0, r2, 0.0)),
                                 0.0)
                high = np.minimum(np.where(d1 < 0, r1, np.inf), np.where(d2 < 0, r2, np.inf))
                bad = (d1 == 0) & (sign * z1 > 0)[:, None]
                bad |= (d2 == 0) & (sign * z2 > 0)[:, None]
                c = np.where((low <= high) & ~bad, low, np.inf)  # (q, 4 lines)
                c[q, corner] = np.inf  # the edge line opposite the touching corner: unused
                pick = np.argmin(c, axis=1)
                value = c[q, pick]
                value[np.maximum(sign * z1, sign * z2) <= eta] = 0.0  # T never rises
                line = np.where(pick == 3, corner + 3, pick)
                np.maximum.at(flat, (2 * own + side) * 6 + line, value)

        # Blocks on two threads (numpy releases the GIL in its kernels); each writes its faces.
        with ThreadPoolExecutor(max_workers=2) as pool:
            list(pool.map(run, edges[:-1], edges[1:]))
        return slope

    def _get_scene(self):
        if self._scene is None:
            import open3d as o3d  # heavy: imported only when a query runs

            scene = o3d.t.geometry.RaycastingScene()
            scene.add_triangles(self._v.astype(np.float32),
                                self._f[self._scene_faces].astype(np.uint32))
            self._scene = scene
        return self._scene

    # ------------------------------------------------------------------ queries

    def candidates(self, points_centred: np.ndarray) -> np.ndarray:
        """Open3D's (float32) closest triangle for re-centred points (n, 3); (n,) int64."""
        import open3d as o3d

        query = o3d.core.Tensor(points_centred.astype(np.float32))
        result = self._get_scene().compute_closest_points(query)
        return self._scene_faces[result["primitive_ids"].numpy()]

    def query(self, points, *, threads: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact distance from each point to the mesh surface.

        Parameters
        ----------
        points : (n, 3) float64, metres, the mesh's frame
        threads : int
            Threads for the float64 post-processing (numpy releases the GIL in its kernels).

        Returns
        -------
        distance : (n,) float64, metres, unsigned
        face : (n,) int64, the face holding the closest point
        closest : (n, 3) float64, metres, the closest point on the surface
        """
        points = as_points(points, "points")
        p = points - self.centre
        t0 = self.candidates(p)
        distance = np.empty(len(p))
        face = np.empty(len(p), dtype=np.int64)
        closest = np.empty_like(p)
        step = defaults.DISTANCE_BLOCK

        def run(lo: int) -> None:
            sl = slice(lo, lo + step)
            distance[sl], face[sl], closest[sl] = self._refine(p[sl], t0[sl])

        starts = range(0, len(p), step)
        if threads > 1 and len(p) > step:
            with ThreadPoolExecutor(max_workers=threads) as pool:
                list(pool.map(run, starts))
        else:
            for lo in starts:
                run(lo)
        closest += self.centre
        return distance, face, closest

    def _refine(self, p: np.ndarray, t0: np.ndarray):
        """Exact distances for one block of re-centred points (b, 3) given candidates t0 (b,).

        Written column by column: numpy reductions over a length-3 axis cost more than the
        arithmetic here.
        """
        row = np.take(self._table, t0, axis=0)  # np.take: 2x faster than fancy indexing here
        ap = p - row[:, _A]
        h = np.einsum("ij,ij->i", ap, row[:, _N])
        v = np.einsum("ij,ij->i", ap, row[:, _GB])
        w = np.einsum("ij,ij->i", ap, row[:, _GC])
        u = 1.0 - v - w
        height = np.abs(h)
        m = _INTERIOR_MARGIN
        fast = (u > m) & (v > m) & (w > m)
        # The six lines' bounds: 2 r_L > H c_L, with r_L the in-plane distance inside L.
        with np.errstate(invalid="ignore"):  # inf * 0 on the plane: the exact path decides
            half = 0.5 * height[:, None] * np.take(self._slope, 2 * t0 + (h < 0), axis=0)
            fast &= u * row[:, 12] > half[:, 0]
            fast &= v * row[:, 13] > half[:, 1]
            fast &= w * row[:, 14] > half[:, 2]
            fast &= v * row[:, 16] + w * row[:, 17] > half[:, 3]
            fast &= u * row[:, 18] + w * row[:, 20] > half[:, 4]
            fast &= u * row[:, 21] + v * row[:, 22] > half[:, 5]
        closest = p - h[:, None] * row[:, _N]
        face = t0.copy()
        slow = np.flatnonzero(~fast)
        if len(slow):
            height[slow], face[slow], closest[slow] = self._guarded(p[slow], t0[slow])
        return height, face, closest

    def _guarded(self, p: np.ndarray, t0: np.ndarray):
        """Minimum exact distance over t0 and its ring, for points (r, 3) off the fast path.

        A ring face is evaluated exactly unless its lower bound ``sqrt(h_t**2 + e_t**2)`` is not
        below the distance to t0.
        """
        distance, closest = closest_on_faces(self._v, self._f, self.normals, self.degenerate,
                                             p, t0)
        row, _, faces = self._ring(t0)
        plane = np.take(self._table, faces, axis=0)
        ap = p[row] - plane[:, _A]
        v = np.einsum("ij,ij->i", ap, plane[:, _GB])
        w = np.einsum("ij,ij->i", ap, plane[:, _GC])
        bary = np.stack([1.0 - v - w, v, w], axis=1)
        outside = np.maximum((-bary * plane[:, _ALT]).max(axis=1), 0.0)
        bound = np.einsum("ij,ij->i", ap, plane[:, _N]) ** 2 + outside**2
        limit = distance[row] * (1.0 + 1e-12)  # keep exact ties: the lowest face index wins
        keep = bound <= limit**2
        row, faces = row[keep], faces[keep]
        d, q = closest_on_faces(self._v, self._f, self.normals, self.degenerate,
                                p[row], faces)
        # Keep the ring faces that beat t0 (ties: the lower face index), then the best per row.
        better = (d < distance[row]) | ((d == distance[row]) & (faces < t0[row]))
        row, faces, d, q = row[better], faces[better], d[better], q[better]
        order = np.lexsort((faces, d, row))  # by row, then distance, then face index
        first = order[np.flatnonzero(np.diff(row[order], prepend=-1))]
        face = t0.copy()
        distance[row[first]], face[row[first]] = d[first], faces[first]
        closest[row[first]] = q[first]
        return distance, face, closest


def closest_on_faces(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray,
                     degenerate: np.ndarray, p: np.ndarray, face_index: np.ndarray):
    """Closest point on given triangles, float64, vectorised (Ericson's Voronoi-region method).

    Parameters
    ----------
    vertices : (n_vertices, 3) float64
    faces : (n_faces, 3) int64
    normals : (n_faces, 3) float64, unit (zero for degenerate faces)
    degenerate : (n_faces,) bool
    p : (m, 3) float64, query points (same frame as ``vertices``)
    face_index : (m,) int64, the triangle to test for each point

    Returns
    -------
    distance : (m,) float64
    closest : (m, 3) float64
    """
    tri = faces[face_index]
    ia, ib, ic = tri[:, 0], tri[:, 1], tri[:, 2]
    a, b, c = vertices[ia], vertices[ib], vertices[ic]
    ab, ac = b - a, c - a
    ap, bp, cp = p - a, p - b, p - c
    d1 = np.einsum("ij,ij->i", ab, ap)
    d2 = np.einsum("ij,ij->i", ac, ap)
    d3 = np.einsum("ij,ij->i", ab, bp)
    d4 = np.einsum("ij,ij->i", ac, bp)
    d5 = np.einsum("ij,ij->i", ab, cp)
    d6 = np.einsum("ij,ij->i", ac, cp)
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    # Region codes in Ericson's order of tests: 0 A, 1 B, 2 C (vertices), 3 AB, 4 AC, 5 BC, 6 face.
    region = np.select(
        [(d1 <= 0) & (d2 <= 0),
         (d3 >= 0) & (d4 <= d3),
         (vc <= 0) & (d1 >= 0) & (d3 <= 0),
         (d6 >= 0) & (d5 <= d6),
         (vb <= 0) & (d2 >= 0) & (d6 <= 0),
         (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)],
        [0, 1, 3, 2, 4, 5], default=6)
    # Edge regions: the closest point on the edge, from its endpoints in canonical order.
    lo = np.select([region == 4, region == 5], [np.minimum(ia, ic), np.minimum(ib, ic)],
                   np.minimum(ia, ib))
    hi = np.select([region == 4, region == 5], [np.maximum(ia, ic), np.maximum(ib, ic)],
                   np.maximum(ia, ib))
    q = _closest_on_segments(vertices, lo, hi, p)
    vertex = region <= 2
    q[vertex] = vertices[np.choose(region[vertex], [ia[vertex], ib[vertex], ic[vertex]])]
    inside = region == 6
    n = normals[face_index[inside]]
    h = np.einsum("ij,ij->i", ap[inside], n)
    q[inside] = p[inside] - h[:, None] * n
    distance = np.linalg.norm(p - q, axis=1)
    distance[inside] = np.abs(h)
    bad = degenerate[face_index]
    if bad.any():  # a segment or a point: the nearest of its three edges
        best = np.full(int(bad.sum()), np.inf)
        best_q = np.zeros((len(best), 3))
        for i, j in ((ia, ib), (ia, ic), (ib, ic)):
            qe = _closest_on_segments(vertices, np.minimum(i, j)[bad], np.maximum(i, j)[bad],
                                      p[bad])
            de = np.linalg.norm(p[bad] - qe, axis=1)
            better = de < best
            best[better], best_q[better] = de[better], qe[better]
        distance[bad], q[bad] = best, best_q
    return distance, q


def _closest_on_segments(vertices, lo, hi, p):
    """Closest points on segments vertices[lo] -> vertices[hi] to points p; (m, 3)."""
    origin = vertices[lo]
    e = vertices[hi] - origin
    ee = np.einsum("ij,ij->i", e, e)
    t = np.einsum("ij,ij->i", p - origin, e) / np.where(ee > 0, ee, 1.0)
    return origin + np.clip(t, 0.0, 1.0)[:, None] * e


def point_mesh_distance(points, mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact float64 distance from points to a triangle mesh's surface.

    Parameters
    ----------
    points : (n, 3) float64, metres
    mesh : Mesh or (vertices, faces)
        vertices (n_vertices, 3) metres, faces (m, 3) int, same frame as ``points``.

    Returns
    -------
    distance : (n,) float64, metres, unsigned
    face : (n,) int64, index of the face holding the closest point
    closest : (n, 3) float64, metres, closest point on the surface

    Notes
    -----
    See the module docstring for the method. Build a ``MeshDistance`` once to query the same mesh
    repeatedly.
    """
    return MeshDistance(mesh).query(points)
