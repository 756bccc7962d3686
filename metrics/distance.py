"""Exact (float64) distances from points to a triangle mesh, found quickly with Open3D's BVH.

How a query works
-----------------
1. Open3D's ``RaycastingScene.compute_closest_points`` (Embree, float32, both cores) names a
   candidate triangle ``t0`` for every point. Coordinates are re-centred on the mesh's bounding-box
   centre first, so float32 keeps ~7 digits of the mesh's size rather than of its position, and
   the points are queried in Morton order (neighbours share BVH nodes and table rows).
2. The exact float64 distance to ``t0`` is computed, and the triangles sharing a vertex with
   ``t0`` (its ring) are checked for being closer: this is the guard against float32 picking a
   wrong near-tie triangle. A near-tie at a shared edge or vertex is always with a ring face.
   (A near-tie with a triangle sharing no vertex with ``t0``, such as the far side of a plate
   thinner than the float32 error, is not guarded.)
3. Most points need no ring check, by bounds made once per face in a few vectorised passes
   over the faces and vertices (no pass over (face, ring face) pairs). Let p project to p' in
   ``t0``'s interior at height H above its plane; the ring faces are of two kinds.

   *The faces across t0's edges.* The face T across edge k is linear in height above the
   plane, zero on the edge line: ``z = c_k d`` at a distance d beyond the line, with ``c_k``
   fixed by T's far vertex (0 if T never rises on p's side; infinite if T folds back over
   ``t0``, or the edge has more than two faces). If p' lies r_k inside the line, a point x of T
   has ``|p - x|**2 - H**2 >= (r_k + d)**2 - 2 H c_k d >= 2 d (2 r_k - H c_k)``: T cannot be
   closer when ``2 r_k > H c_k``.

   *The faces touching t0 at one corner V only.* Around V, let ``m_V`` be the mean of the unit
   normals of its faces and ``alpha_V`` the largest angle between ``m_V`` and one of them. Every
   face T around V has a normal within ``beta = alpha_V + angle(n_t0, m_V)`` of ``n_t0``, so
   (beta < 90 deg) a point x of T rises at most ``z <= tan(beta) rho`` above ``t0``'s plane, rho
   the distance of its projection x' from V. When the faces around V form one closed,
   consistently oriented fan (every edge at V met once in each direction) whose projection
   along ``m_V`` winds once around V, it winds once along ``n_t0`` too (every face keeps a
   positive orientation on the way, as beta < 90 deg), so the projected faces do not overlap:
   x' lies outside the angle at V covered by ``t0`` and the two faces across its edges at V,
   i.e. at least phi away in angle from the direction of p', phi the smaller angle between
   ``p' - V`` and the directions from V to the far vertices of those two faces. With
   ``e = |p' - V|``, ``|p - x|**2 - H**2 >= rho**2 - 2 rho (e cos(phi) + H tan(beta)) + e**2``,
   positive for every rho when ``H tan(beta) < e (1 - cos(phi))``. Where a fan is open (a
   boundary), not a manifold, holds a degenerate face or turns by 90 deg or more, the bound is
   infinite, unless no ring vertex rises above the plane on p's side (a box's faces, seen
   from outside). A vertex of three faces has no faces of this kind.

   When both hold at the three edges and corners (the fast path: ~99.7 % of the points of a
   reconstruction scored against its truth, in either direction) the distance is H and the
   closest point the projection.
4. The other points (those projecting onto an edge or a corner, and, on a coarse test mesh
   such as a convex hull or a ``planes`` polyhedron, the many truth samples far inside it)
   take the slow path, ``MeshDistance._guarded``. The distance d0 to ``t0`` is computed with
   the closed-form closest point on a triangle (Ericson, *Real-Time Collision Detection*,
   5.1.5). The rings of the block's distinct ``t0`` are listed, each face once, and the points
   are taken one ring position at a time (sorted by ring size, so each position is a prefix of
   them). A ring face is evaluated only if its plane lies within d0, ``|h_t| <= d0`` (a 32-byte
   row ``(n, -n . A)`` and a dot product; it leaves ~1 pair in 10^4 on a convex hull seen from
   inside), and then its lower bound ``sqrt(h_t**2 + e_t**2)`` is within d0 too (e_t: how far
   the projection falls outside it, the largest distance beyond one of its edge lines). Both
   tests allow a slack of ``1e-12 (|p|_1 + max |vertex|_1)``, a hundred times the rounding of
   these forms and of the closed form, so the result is that of evaluating the whole ring. The
   survivors are evaluated with the closed form and the minimum taken; ties go to the lowest
   face index. About 0.4 us of CPU per slow point on a coarse test mesh, 2 us for points far
   from a fine one (where the ring faces around the closest vertex tie and are evaluated).

The set-up is a few vectorised passes over the faces (edge slopes, rays) and, on a second thread,
over the vertices (cones, fans) and then the slow path's tables: about 1.5 us of CPU per face
(0.22 s for a 150k-face surface; docs/decisions.md, "Measurements behind the defaults"),
written with row gathers by ``np.take`` and column-by-column products (numpy's fancy indexing
and its reductions over a length-3 axis cost 4x more). The fast path's test reads a 15-column row
per point and the 6 bounds of the point's side of ``t0`` (a second table, one row per face and
side), with a quick corner test from precomputed coefficients; the full corner
test (a third table) runs for the 1-2 % of points the quick one rejects. At query time nothing is
computed per (point, ring face) pair except for the points off the fast path. ``metrics.score``
sets up a test mesh on a second thread while its samples are scored against the truth.
``benchmarks/bench_score.py`` times the whole score against Open3D's own float32 queries.

Closest points on an edge or a vertex are computed from the edge's endpoints in a canonical order
(lower vertex index first), so two faces sharing the edge give the same bits: results do not
depend on which of two tied triangles Embree returned.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from functools import cached_property

import numpy as np

from metrics import defaults
from metrics.inputs import as_mesh, as_points
from metrics.spatial import bounds, morton_order, row_cross, row_norms

# Barycentric margin of the fast path's "projects into the interior" test. Any value >= 0 is
# exact (points inside the margin take the exact slow path); 1e-12 keeps points whose projection
# lies on an edge, up to float64 rounding, off the fast path.
_INTERIOR_MARGIN = 1e-12
# Columns of the per-face table gathered once per query point (MeshDistance._table): vertex A,
# unit normal, dual basis vectors g_b and g_c, altitudes.
_A, _N, _GB, _GC, _ALT = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)
# Columns of the per-side table (MeshDistance._sides, row 2 face + side: 0 in front of the face,
# 1 behind it), the row of the point's side gathered once per query point: the bounds of the
# fast path (MeshDistance._bounds; module docstring, 3.).
_EDGE, _QUICK = slice(0, 3), slice(3, 6)
# Columns of the second table (MeshDistance._corners), gathered only for the points that fail
# the quick corner test: the full corner test's slopes, ray coefficients and Gram matrix.
_CORNER, _RAYS, _GRAM = slice(0, 6), slice(6, 18), slice(18, 21)
# Added to every cone angle beta (radians): covers the rounding of the unit normals and angles
# (~1e-16 rad each on well-shaped faces). A ring face is then missed only if it rises by more
# than 1e-9 of its distance from V beyond the bound: a distance error below 1e-9 of a face size.
_ANGLE_MARGIN = 1e-9
# The corners of the edges of closest_on_faces' edge regions 3 (AB), 4 (AC) and 5 (BC).
_EDGE_CORNERS = np.array([[0, 1], [0, 2], [1, 2]])


def _lexicographic_order(v: np.ndarray) -> np.ndarray:
    """Permutation sorting rows (n, 3) by x, then y, then z (``np.lexsort(v.T[::-1])``).

    The order of x alone (numpy's SIMD sort, 5x faster than the lexsort), with the rows whose
    x repeats another's (a few % of a reconstruction's vertices) put in order by a lexsort of
    them alone: they fill the same positions, in runs of equal x. The same permutation.
    """
    order = np.argsort(v[:, 0])
    x = v[order, 0]
    same = x[1:] == x[:-1]
    if same.any():
        repeated = np.zeros(len(x), dtype=bool)
        repeated[1:] |= same
        repeated[:-1] |= same
        tied = np.sort(order[repeated])  # equal rows then keep their order, as in the lexsort
        order[repeated] = tied[np.lexsort(v[tied].T[::-1])]
    return order


class MeshDistance:
    """Exact float64 point-to-surface distances to one triangle mesh (reusable across queries).

    Parameters
    ----------
    mesh : Mesh or (vertices, faces)
        Vertices (n, 3) metres, faces (m, 3) int; validated by ``inputs.as_mesh``.

    Notes
    -----
    Faces whose doubled area is below ``defaults.DEGENERATE_AREA_FRACTION`` of the squared
    diagonal (segments and points) have no surface and are ignored. Building is a few
    vectorised passes over the faces; the Open3D scene is built on the first query. See the
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
        lo, hi = bounds(v)
        self.centre = 0.5 * (lo + hi)
        self.scale = max(float(np.linalg.norm(hi - lo)), np.finfo(float).tiny)
        # Weld exactly repeated vertices (STL-style soups), so faces touching in space share
        # vertex indices in the ring; re-centre: all computation happens in _v, _f.
        order = _lexicographic_order(v)
        ordered = v[order]
        new = np.ones(len(v), dtype=bool)
        new[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
        inverse = np.empty(len(v), dtype=np.int64)
        inverse[order] = np.cumsum(new) - 1
        self._v = ordered[new] - self.centre
        self._f = f = np.take(inverse, mesh.faces)
        # np.take: row gathers 4x faster than fancy indexing
        corners = np.take(self._v, f, axis=0)  # (m, 3 corners, 3)
        a = corners[:, 0]
        ab = corners[:, 1] - a
        ac = corners[:, 2] - a
        cross = row_cross(ab, ac)
        double_area = row_norms(cross)
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
        lengths = np.column_stack([row_norms(ac - ab), row_norms(ac), row_norms(ab)])
        altitude = double_area[:, None] / np.where(lengths > 0, lengths, 1.0)
        self.normals = normal
        self._scene_faces = np.flatnonzero(ok)
        self._table = table = np.empty((len(f), 15))
        table[:, _A], table[:, _N], table[:, _GB], table[:, _GC] = a, normal, g_b, g_c
        table[:, _ALT] = altitude
        self._corners = np.empty((len(f), 21))
        self._corners[:, _GRAM] = np.column_stack([bb, bc, cc])
        self._bounds(corners, lengths)
        self._scene = None

    # ------------------------------------------------------------------ set-up

    def _ring(self, faces: np.ndarray, *, unique: bool = False
              ) -> tuple[np.ndarray, np.ndarray]:
        """(face, ring face) pairs of the given faces, ring faces non-degenerate, by row.

        A face sharing an edge appears twice (once per shared corner) unless ``unique``;
        ``faces`` themselves are left out.

        Returns
        -------
        row : (q,) int64, index into ``faces``, non-decreasing
        ring : (q,) int64, face index
        """
        vertex = self._f[faces].ravel()
        first, degree = self._start[vertex], np.diff(self._start)[vertex]
        owner = np.repeat(np.arange(len(vertex)), degree)
        offset = np.arange(len(owner)) - np.repeat(np.cumsum(degree) - degree, degree)
        ring = self._incident[np.repeat(first, degree) + offset]
        row, corner = np.divmod(owner, 3)
        keep = (ring != faces[row]) & ~self.degenerate[ring]
        if unique:  # a face listed at corner k is dropped if it holds an earlier corner too
            corners, ring_vertices = self._f[faces], self._f[ring]
            for j in (0, 1):
                keep &= (corner <= j) | (ring_vertices != corners[row, j, None]).all(axis=1)
        return row[keep], ring[keep]

    def _bounds(self, corners: np.ndarray, lengths: np.ndarray) -> None:
        """Fill the fast path's tests: ``_sides`` and the columns of ``_corners`` (module
        docstring, 3.).

        ``_EDGE``: per side (in front of the face, behind it) and edge k (opposite corner k),
        the slope c of the face across the edge (z <= c * distance beyond the edge line);
        ``_CORNER``: per side and corner, tan(beta) of the cone bound of the faces touching the
        face at that corner only (0 where there are none or none rises); ``_RAYS``: per corner
        j and each edge k != j, the unit in-plane direction from corner j to the vertex across
        edge k, as the coefficients of the weights of corners j + 1 and j + 2 in
        (p' - corner j) . direction. Infinite slopes where nothing is shown. ``_QUICK``: per side
        and corner j, ``tan(beta) / (altitude_j (1 - cos(phi_j)))`` with phi_j the smallest
        angle between the rays and the face's angle at j: a point passes the corner test when
        ``H * quick < 1 - weight_j``, as ``(1 - weight_j) altitude_j <= |p' - V_j|`` and
        ``phi_j`` <= the angle phi of the full test.

        Parameters
        ----------
        corners : (m, 3, 3) float64, the faces' corners
        lengths : (m, 3) float64, per corner the length of the opposite edge
        """
        # The vertices' part on a second thread (numpy releases the GIL in its kernels), then
        # the slow path's tables, which every query of a reconstruction ends up needing.
        with ThreadPoolExecutor(max_workers=1) as pool:
            fans = pool.submit(self._fans, corners)
            pool.submit(lambda: self._affine)
            self._face_bounds(lengths, corners, fans)

    def _face_bounds(self, lengths, corners, fans) -> None:
        """The faces' part of ``_bounds``, joined with the vertices' (``fans``) at the end."""
        f, v = self._f, self._v
        table = self._table
        m, n_vertices = len(f), len(v)
        eta = defaults.COPLANAR_FRACTION * self.scale
        normal, g_b, g_c = self.normals, table[:, _GB], table[:, _GC]

        # Edge k of a face runs from corner k + 1 to corner k + 2. An edge met exactly twice,
        # once in each direction, is manifold, with a face across; one met once is a boundary;
        # any other (met more often, or twice in one direction) is neither.
        start, end = f[:, [1, 2, 0]].ravel(), f[:, [2, 0, 1]].ravel()
        key = np.minimum(start, end) * n_vertices + np.maximum(start, end)
        order = np.argsort(key)
        equal = np.diff(key[order]) == 0
        after, before = np.append(equal, False), np.insert(equal, 0, False)
        first = np.flatnonzero(after & ~before & ~np.append(after[1:], False))  # runs of two
        one, two = order[first], order[first + 1]
        opposite = start[one] == end[two]
        one, two = one[opposite], two[opposite]
        across = np.arange(3 * m)
        across[one], across[two] = two, one
        manifold = across != np.arange(3 * m)
        boundary = np.zeros(3 * m, dtype=bool)
        boundary[order[~after & ~before]] = True
        neighbour = across // 3
        far = np.take(f, across)  # the corner across: edge k's own corner k when none

        # Slopes of the faces across the edges, from their far vertices X (rows 3 face + k).
        rel = np.take(v, far, axis=0).reshape(m, 3, 3) - corners[:, None, 0]
        z = np.einsum("ikj,ij->ik", rel, normal).ravel()
        bv = np.einsum("ikj,ij->ik", rel, g_b).ravel()
        bw = np.einsum("ikj,ij->ik", rel, g_c).ravel()
        weight = np.choose(np.tile([0, 1, 2], m), [1.0 - bv - bw, bv, bw])
        beyond = -weight * table[:, _ALT].ravel()  # distance of X's projection beyond the edge line
        flat = ~manifold | self.degenerate[neighbour]  # nothing across, or no surface
        neither = ~manifold & ~boundary
        edge = np.empty((m, 2, 3))
        for side, rise in enumerate((z, -z)):
            with np.errstate(divide="ignore", invalid="ignore"):
                c = np.where(beyond > 0, rise / beyond, np.inf)
            c[rise <= eta] = 0.0  # the face across never rises on this side
            c[flat] = 0.0
            c[neither] = np.inf
            edge[:, side] = c.reshape(m, 3)

        cone, fan = fans.result()
        fan[start[~manifold]] = fan[end[~manifold]] = False
        vertex = f.ravel()
        cone = np.where(fan[vertex], cone, np.inf)
        cone[fan[vertex] & (np.diff(self._start)[vertex] == 3)] = 0.0  # no vertex-only face

        # Unit in-plane directions r from corner j towards the far vertex X across each edge
        # k != j, as the coefficients of the weights of the other two corners a, b giving
        # (p' - V_j) . r (module docstring, 3.), all from X's barycentric weights (beta) and the
        # Gram matrix: X' - V_j = beta_a (P_a - V_j) + beta_b (P_b - V_j). One contiguous (m,)
        # array per component (strided columns cost twice as much here); both sides alike until
        # the level check below.
        bary = np.stack([1.0 - bv - bw, bv, bw]).reshape(3, m, 3).transpose(2, 0, 1).copy()
        bb, bc, cc = self._corners[:, _GRAM].T
        length = lengths.T.copy()
        squared = length**2
        cones, rays, quick = [], [], []
        for j, between in enumerate((bc, bb - bc, cc - bc)):  # (P_a - V_j) . (P_b - V_j)
            a_, b_ = (j + 1) % 3, (j + 2) % 3
            cone_j = cone[j::3].copy()
            cosine = np.full(m, -np.inf)  # largest cosine between a ray and an edge at j
            for k in (a_, b_):  # bary[k, c]: weight of corner c in X across edge k
                to_a = bary[k, a_] * squared[b_] + bary[k, b_] * between
                to_b = bary[k, a_] * between + bary[k, b_] * squared[a_]
                span = np.sqrt(np.maximum(bary[k, a_] * to_a + bary[k, b_] * to_b, 0.0))
                scale = 1.0 / np.where(span > 0, span, np.inf)
                ray_a, ray_b = to_a * scale, to_b * scale
                rays += [ray_a, ray_b]
                with np.errstate(divide="ignore", invalid="ignore"):  # NaN: no quick test
                    cosine = np.maximum(cosine, np.maximum(ray_a / length[b_],
                                                           ray_b / length[a_]))
                above = span == 0  # X right above V: no direction
                cone_j[above] = np.where(cone_j[above] == 0.0, 0.0, np.inf)
            # Quick test coefficient tan(beta) / (altitude_j (1 - cos(phi_j))).
            room = table[:, 12 + j] * (1.0 - cosine)
            with np.errstate(divide="ignore", invalid="ignore"):
                quick.append(np.where(room > 0, cone_j / room, np.inf))
            cones.append(cone_j)
        corner = np.repeat(np.stack(cones, axis=1)[:, None], 2, axis=1)  # (m, side, corner)
        quick = np.repeat(np.stack(quick, axis=1)[:, None], 2, axis=1)

        # A side on which no ring vertex rises above the plane needs no bound at all: checked
        # where a bound is missing (sharp features such as a box's corners).
        for side, sign in enumerate((1.0, -1.0)):
            missing = np.flatnonzero(~np.isfinite(edge[:, side]).all(axis=1)
                                     | ~np.isfinite(corner[:, side]).all(axis=1))
            row, ring = self._ring(missing)
            rise = np.full(len(missing), -np.inf)
            heights = np.einsum("ikj,ij->ik", v[f[ring]] - corners[missing[row], None, 0],
                                normal[missing[row]])
            np.maximum.at(rise, row, (sign * heights).max(axis=1))
            level = missing[rise <= eta]
            edge[level, side] = corner[level, side] = 0.0
        self._corners[:, _CORNER] = corner.reshape(m, 6)
        self._corners[:, _RAYS] = np.stack(rays, axis=1)
        quick[corner == 0.0] = 0.0
        self._sides = np.concatenate([edge, quick], axis=2).reshape(2 * m, 6)

    def _fans(self, corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The cone bound of the faces around each vertex (module docstring, 3.).

        Also builds the faces-around-vertex index (``_incident``, ``_start``) of ``_ring``.

        Parameters
        ----------
        corners : (m, 3, 3) float64, the faces' corners

        Returns
        -------
        cone : (3 m,) float64, per face and corner (row 3 face + corner), tan(beta); infinite
            where beta >= 90 deg
        fan : (n_vertices,) bool, the faces around the vertex hold no degenerate face and wind
            once around it, projected along their mean normal (edge manifoldness is checked
            by the caller)
        """
        f, normal = self._f, self.normals
        n_vertices = len(self._v)
        vertex = f.ravel()  # rows 3 face + corner
        # Faces around each vertex (CSR): the ring of a face is the faces around its corners.
        # A stable order by vertex, as the argsort of distinct keys (5x numpy's stable sort).
        self._incident = np.argsort(vertex * len(vertex) + np.arange(len(vertex))) // 3
        self._start = np.concatenate([[0], np.cumsum(np.bincount(vertex,
                                                                   minlength=n_vertices))])
        face_normal = np.repeat(normal, 3, axis=0)
        mean = np.stack([np.bincount(vertex, weights=face_normal[:, i], minlength=n_vertices)
                         for i in range(3)], axis=1)
        size = row_norms(mean)[:, None]
        mean /= np.where(size > 0, size, 1.0)
        m_v = np.take(mean, vertex, axis=0)
        tilt = _angle_between(face_normal, m_v)  # angle(n_T, m_V) per corner row
        alpha = np.zeros(n_vertices)
        np.maximum.at(alpha, vertex, tilt)
        # The fan around V winds once when its faces' angles at V, projected along m_V, add up
        # to 2 pi: the m_V component of a face's cross product is that of its projected edges.
        e1 = (np.roll(corners, -1, axis=1) - corners).reshape(-1, 3)
        e2 = (np.roll(corners, -2, axis=1) - corners).reshape(-1, 3)
        det = np.einsum("ij,ij->i", row_cross(e1, e2), m_v)
        dot = (np.einsum("ij,ij->i", e1, e2)
               - np.einsum("ij,ij->i", e1, m_v) * np.einsum("ij,ij->i", e2, m_v))
        turn = np.bincount(vertex, weights=np.arctan2(det, dot), minlength=n_vertices)
        fan = (np.abs(turn - 2 * np.pi) < 1.0) & (size[:, 0] > 0)
        fan[f[self.degenerate].ravel()] = False
        beta = alpha[vertex] + tilt + _ANGLE_MARGIN
        with np.errstate(invalid="ignore"):
            cone = np.where(beta < 0.5 * np.pi, np.tan(beta), np.inf)
        return cone, fan

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

    def query(self, points, *, presorted: bool = False, threads: int = 2
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact distance from each point to the mesh surface.

        Parameters
        ----------
        points : (n, 3) float64, metres, the mesh's frame
        presorted : bool
            The points are already in Morton order (``spatial.morton_order``, e.g. kept by a
            ``metrics.Truth`` for every score against it); else they are ordered here.
        threads : int
            Threads for the float64 post-processing (numpy releases the GIL in its kernels).

        Returns
        -------
        distance : (n,) float64, metres, unsigned
        face : (n,) int64, the face holding the closest point
        closest : (n, 3) float64, metres, the closest point on the surface
        """
        points = as_points(points, "points")
        # Queried in Morton order, so neighbouring queries walk the same BVH nodes and read
        # the same table rows: a third faster on a random-order million, ordering included.
        order = slice(None) if presorted else morton_order(points)
        p = points[order] - self.centre
        t0 = self.candidates(p)
        distance = np.empty(len(p))
        face = np.empty(len(p), dtype=np.int64)
        closest = np.empty_like(p)
        step = defaults.DISTANCE_BLOCK

        def run(lo: int) -> None:
            sl = slice(lo, lo + step)
            rows = sl if presorted else order[sl]
            distance[rows], face[rows], closest[rows] = self._refine(p[sl], t0[sl])

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
        # The bounds of p's side of the face (_EDGE, then _QUICK). The faces across the edges:
        # 2 r_k > H c_k, r_k the in-plane distance from edge k; the faces at one corner: the
        # quick test H * quick_j < 1 - weight_j.
        side = np.take(self._sides, 2 * t0 + (h < 0), axis=0)
        weights = (u, v, w)
        with np.errstate(invalid="ignore"):  # 0 * inf on the plane: the exact path decides
            for k, weight in enumerate(weights):
                fast &= 2.0 * weight * row[:, 12 + k] > height * side[:, k]
            full = fast.copy()
            for j, rest in enumerate((v + w, u + w, u + v)):
                fast &= height * side[:, 3 + j] < rest
        # The full corner test for the others (module docstring, 3.).
        again = np.flatnonzero(full & ~fast)
        if len(again):
            fast[again] = self._corner_test(height[again], h[again] < 0, t0[again],
                                            u[again], v[again], w[again])
        closest = p - h[:, None] * row[:, _N]
        face = t0.copy()
        slow = np.flatnonzero(~fast)
        if len(slow):
            height[slow], face[slow], closest[slow] = self._guarded(p[slow], t0[slow])
        return height, face, closest

    def _corner_test(self, height, behind, t0, u, v, w) -> np.ndarray:
        """The full corner test: ``H tan(beta) < e - max((p' - V_j) . ray)`` at every corner.

        Parameters
        ----------
        height : (r,) float64, H; behind : (r,) bool, p behind the face; t0 : (r,) int64
        u, v, w : (r,) float64, barycentric weights of the projection p'

        Returns
        -------
        (r,) bool, the faces at one corner are farther than H at all three corners
        """
        row = np.take(self._corners, t0, axis=0)
        corner = np.where(behind[:, None], row[:, 3:6], row[:, 0:3])
        rays, gram = row[:, _RAYS], row[:, _GRAM]
        weights = (u, v, w)
        ok = np.ones(len(t0), dtype=bool)
        with np.errstate(invalid="ignore"):
            # e = |p' - V_j| from the Gram matrix of AB, AC and the weights of B and C in
            # p' - V_j.
            for j, (wb, wc) in enumerate(((v, w), (v - 1.0, w), (v, w - 1.0))):
                e = np.sqrt(np.maximum(wb * wb * gram[:, 0] + 2.0 * wb * wc * gram[:, 1]
                                       + wc * wc * gram[:, 2], 0.0))
                la, lb = weights[(j + 1) % 3], weights[(j + 2) % 3]
                along = np.maximum(la * rays[:, 4 * j] + lb * rays[:, 4 * j + 1],
                                   la * rays[:, 4 * j + 2] + lb * rays[:, 4 * j + 3])
                bound = height * corner[:, j]
                ok &= (e - along > bound) | (bound == 0.0)
        return ok

    @cached_property
    def _affine(self) -> tuple[np.ndarray, np.ndarray, float]:
        """The slow path's two per-face tables, built on first use (zero for degenerate faces).

        Returns
        -------
        planes : (m, 4) float64, the row (n, -n . A): its product with (p, 1) is p's height
            above the face's plane
        edges : (m, 3, 4) float64, per edge k (opposite corner k) the row (o, -o . V), o the
            unit in-plane normal pointing out of the face, V an end of the edge: its product
            with (p, 1) is how far p's projection lies beyond the edge's line
        reach : float, the largest |x| + |y| + |z| of a vertex (sets the rounding slack)
        """
        corners = self._v[self._f]
        start, end = corners[:, [1, 2, 0]], corners[:, [2, 0, 1]]
        out = np.cross(end - start, self.normals[:, None])
        length = np.linalg.norm(out, axis=2, keepdims=True)
        out /= np.where(length > 0, length, 1.0)
        edges = np.concatenate([out, -np.einsum("ikj,ikj->ik", out, start)[:, :, None]], axis=2)
        offset = -np.einsum("ij,ij->i", self.normals, corners[:, 0])
        reach = float(np.abs(self._v).sum(axis=1).max())
        return np.column_stack([self.normals, offset]), edges, reach

    def _unique_rings(self, t0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rings of the distinct faces of t0, each ring face once (CSR).

        Returns
        -------
        inverse : (r,) int64, index of t0's face among the distinct ones
        start : (u + 1,) int64, where each distinct face's ring starts in ``ring``
        ring : (q,) int64, ring faces
        """
        faces, inverse = np.unique(t0, return_inverse=True)
        row, ring = self._ring(faces, unique=True)
        start = np.concatenate([[0], np.cumsum(np.bincount(row, minlength=len(faces)))])
        return inverse, start, ring

    def _near_faces(self, p: np.ndarray, t0: np.ndarray, limit: np.ndarray):
        """(point, ring face) pairs whose lower bound ``sqrt(h_t**2 + e_t**2)`` lies within
        ``limit`` of the point, up to rounding: the other ring faces cannot be closer.

        One ring position at a time over all points (sorted by ring size, so each position is a
        prefix of them): first the plane test ``|h_t| <= limit``, a 32-byte row per pair (it
        leaves ~1 pair in 10^4 on a convex hull seen from inside), then the outside distance
        ``e_t`` (the largest distance beyond an edge line) for the survivors. ``slack`` covers
        the rounding of these affine forms (unit normals: ~5 eps (|p|_1 + |V|_1) whatever the
        face's shape) and of the closed form of ``closest_on_faces`` a hundred times over, so a
        pair rejected here cannot come out closer than ``limit`` in the closed form.

        Parameters
        ----------
        p : (r, 3) float64, re-centred points; t0 : (r,) int64, their candidate faces
        limit : (r,) float64, the distance a ring face must not exceed

        Returns
        -------
        row : (q,) int64, index into p; faces : (q,) int64, ring face
        """
        planes, edges, reach = self._affine
        inverse, start, ring = self._unique_rings(t0)
        count = np.diff(start)[inverse]
        order = np.argsort(-count, kind="stable")
        first = start[inverse[order]]
        active = len(p) - np.cumsum(np.bincount(count))  # points with more than j ring faces
        homogeneous = np.column_stack([p[order], np.ones(len(p))])
        slack = limit[order] + 1e-12 * (np.abs(p[order]).sum(axis=1) + reach)
        rows, faces = [np.empty(0, dtype=np.int64)], [np.empty(0, dtype=np.int64)]
        for j, n in enumerate(active[:-1]):
            face = ring[first[:n] + j]
            h = np.einsum("ij,ij->i", np.take(planes, face, axis=0), homogeneous[:n])
            near = np.flatnonzero(np.abs(h) <= slack[:n])
            face, h = face[near], h[near]
            beyond = np.einsum("ikj,ij->ik", np.take(edges, face, axis=0), homogeneous[near])
            outside = np.maximum(beyond.max(axis=1), 0.0)
            keep = h * h + outside * outside <= slack[near] ** 2
            rows.append(order[near[keep]])
            faces.append(face[keep])
        return np.concatenate(rows), np.concatenate(faces)

    def _guarded(self, p: np.ndarray, t0: np.ndarray):
        """Minimum exact distance over t0 and its ring, for points (r, 3) off the fast path.

        A ring face is evaluated exactly unless its lower bound ``sqrt(h_t**2 + e_t**2)`` is
        above the distance to t0 (``_near_faces``).
        """
        distance, closest = closest_on_faces(self._v, self._f, self.normals, self.degenerate,
                                             p, t0)
        limit = distance * (1.0 + 1e-12)  # keep exact ties: the lowest face index wins
        row, faces = self._near_faces(p, t0, limit)
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


def _angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (radians) between unit vectors, rows of a and b (k, 3): accurate near 0 and pi."""
    return 2.0 * np.arctan2(row_norms(a - b), row_norms(a + b))


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
    q = np.empty_like(p)
    inside = region == 6
    n = normals[face_index[inside]]
    h = np.einsum("ij,ij->i", ap[inside], n)
    q[inside] = p[inside] - h[:, None] * n
    vertex = np.flatnonzero(region <= 2)
    q[vertex] = vertices[tri[vertex, region[vertex]]]
    # Edge regions: the closest point on the edge, from its endpoints in canonical order.
    edge = np.flatnonzero((region >= 3) & (region <= 5))
    ends = tri[edge[:, None], _EDGE_CORNERS[region[edge] - 3]]
    q[edge] = _closest_on_segments(vertices, ends.min(axis=1), ends.max(axis=1), p[edge])
    distance = np.empty(len(p))
    outside = np.flatnonzero(~inside)
    distance[outside] = np.linalg.norm(p[outside] - q[outside], axis=1)
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
