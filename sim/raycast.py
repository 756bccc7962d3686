"""First-hit ray casting: Embree finds the triangle, float64 arithmetic finds the point.

Both backends wrap Intel Embree, which computes in float32: at 750 m a hit distance can be off by
centimetres. The backend is therefore asked only *which* triangle each ray hits first; the hit is
then recomputed in float64 as the intersection of the exact ray with that triangle's plane, and
checked to lie inside the triangle. The check uses the backend's float32 barycentric coordinates
where they are far from the triangle's edges (nearly every hit) and float64 ones near them; a ray
that float32 placed on a triangle it misses in exact arithmetic is re-intersected, exactly, with
the triangles around that one, and if none is hit there it is a miss (a grazing ray at a
silhouette). So every hit returned lies on the mesh to float64 rounding.

Backends, measured on the paper's asteroid in benchmarks/bench_simulate.py:

- ``embree`` (embreex): one thread per call, releasing the GIL, so the simulator runs one call per
  core on its worker threads; imports in microseconds and builds the BVH in ~20 ms;
- ``open3d`` (``RaycastingScene``): uses every core within a call; importing open3d takes ~0.5 s.
"""

from __future__ import annotations

import numpy as np

# Barycentric slack for "inside the triangle" in exact arithmetic, in units of the triangle's
# size: points within 1e-9 of a triangle's edge, on its plane, are on the mesh for any purpose.
INSIDE_TOLERANCE = 1e-9
# Bound on a float32 hit's position error, relative to the largest coordinate of the scene (the
# sensor's distance from the body origin): 1e-6 is ~17 float32 ulps. A float32 hit at least this
# far from every edge of its triangle is inside it in exact arithmetic too.
FLOAT32_POSITION_SLACK = 1e-6


class EmbreeBackend:
    """Embree through embreex: ``first_hit`` runs on the calling thread without the GIL.

    Parameters
    ----------
    vertices : (n, 3) float64, metres, body frame B
    faces : (m, 3) int
    """

    name = "embree"

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        from embreex import mesh_construction, rtcore_scene

        self._scene = rtcore_scene.EmbreeScene()
        mesh_construction.TriangleMesh(self._scene, np.ascontiguousarray(vertices, np.float32),
                                       np.ascontiguousarray(faces, np.int32))
        # Build the BVH now, on one thread, rather than racing to it in the first calls.
        self.first_hit(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32))

    def first_hit(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Index of the first triangle each ray hits, -1 for a miss.

        Parameters
        ----------
        origins, directions : (n, 3) float32, body frame B; directions unit vectors

        Returns
        -------
        (n,) int32
        """
        return self._scene.run(origins, directions, query="INTERSECT")

    def first_hit_uv(self, origins: np.ndarray, directions: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As :meth:`first_hit`, plus the float32 barycentric weights ``u``, ``v`` (n,) of the
        hit triangle's second and third vertices."""
        out = self._scene.run(origins, directions, output=1)
        return out["primID"], out["u"], out["v"]


class Open3DBackend:
    """Open3D's ``RaycastingScene`` (Embree inside), multi-threaded within each call."""

    name = "open3d"

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        import open3d as o3d

        self._o3d = o3d
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(o3d.core.Tensor(np.ascontiguousarray(vertices, np.float32)),
                                  o3d.core.Tensor(np.ascontiguousarray(faces, np.uint32)))
        self.first_hit(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32))

    def first_hit(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """As :meth:`EmbreeBackend.first_hit`."""
        return self.first_hit_uv(origins, directions)[0]

    def first_hit_uv(self, origins: np.ndarray, directions: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As :meth:`EmbreeBackend.first_hit_uv`."""
        rays = self._o3d.core.Tensor(np.hstack([origins, directions]))
        out = self._scene.cast_rays(rays)
        ids = out["primitive_ids"].numpy().view(np.int32)  # INVALID_ID, 2**32 - 1, reads -1
        uv = out["primitive_uvs"].numpy()
        return ids, uv[:, 0], uv[:, 1]


# Backends by name; DEFAULT_BACKEND is the faster on the benchmark scenes.
BACKENDS = {"embree": EmbreeBackend, "open3d": Open3DBackend}
DEFAULT_BACKEND = "embree"


class ExactHits:
    """Float64 ray-triangle intersection with known triangles.

    Parameters
    ----------
    vertices : (n, 3) float64, metres, body frame B
    faces : (m, 3) int

    Attributes
    ----------
    normals : (m, 3) float64, unit outward normals (zero for degenerate triangles)
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.vertices = np.asarray(vertices, np.float64)
        self.faces = np.asarray(faces, np.int64)
        v0, v1, v2 = (self.vertices[self.faces[:, k]] for k in range(3))
        e1, e2 = v1 - v0, v2 - v0
        cross = np.cross(e1, e2)
        norm = np.linalg.norm(cross, axis=1, keepdims=True)
        normals = np.divide(cross, norm, out=np.zeros_like(cross), where=norm > 0)
        d11 = np.einsum("ij,ij->i", e1, e1)
        d12 = np.einsum("ij,ij->i", e1, e2)
        d22 = np.einsum("ij,ij->i", e2, e2)
        det = d11 * d22 - d12 * d12
        inv = np.divide(1.0, det, out=np.zeros_like(det), where=det > 0)[:, None]
        # Dual basis: barycentric weights of v1 and v2 are g1.(p - v0) and g2.(p - v0).
        g1 = (d22[:, None] * e1 - d12[:, None] * e2) * inv
        g2 = (d11[:, None] * e2 - d12[:, None] * e1) * inv
        offset = np.einsum("ij,ij->i", normals, v0)[:, None]
        # One row per face, gathered once per hit: v0, normal, plane offset, g1, g2.
        self._table = np.hstack([v0, normals, offset, g1, g2])
        self.normals = normals
        # 1 / (smallest altitude) of each face: a distance d from an edge is a barycentric
        # weight of at least d / altitude. Degenerate faces get inf: always checked exactly.
        longest = np.sqrt(np.max([d11, d22, np.einsum("ij,ij->i", v2 - v1, v2 - v1)], axis=0))
        inv_altitude = np.divide(longest, norm[:, 0], out=np.full(len(norm), np.inf),
                                 where=norm[:, 0] > 0)
        # What the float32 hits need, per face: normal and plane offset in one row of four
        # (32-byte rows: numpy's take copies them with its fast fixed-size path, where 40-byte
        # rows go through memmove), 1 / altitude apart.
        self._plane = np.hstack([normals, offset])
        self._inv_altitude = inv_altitude
        self._ring: tuple[np.ndarray, np.ndarray] | None = None

    def _intersect(self, origins, directions, face):
        row = np.take(self._table, face, axis=0)
        v0, normal, offset, g1, g2 = (row[:, 0:3], row[:, 3:6], row[:, 6], row[:, 7:10],
                                      row[:, 10:13])
        denom = np.einsum("ij,ij->i", normal, directions)
        # A ray parallel to the plane gives t = inf or nan; it is rejected below.
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (offset - np.einsum("ij,ij->i", normal, origins)) / denom
            rel = origins + t[:, None] * directions - v0
            b1 = np.einsum("ij,ij->i", g1, rel)
            b2 = np.einsum("ij,ij->i", g2, rel)
        inside = ((b1 >= -INSIDE_TOLERANCE) & (b2 >= -INSIDE_TOLERANCE)
                  & (b1 + b2 <= 1.0 + INSIDE_TOLERANCE) & (denom != 0) & (t > 0) & (t < np.inf))
        return t, inside

    def _faces_around(self, face: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For each face, the faces sharing a vertex with it: (owner index, face) pairs."""
        if self._ring is None:
            order = np.argsort(self.faces.ravel(), kind="stable")
            counts = np.bincount(self.faces.ravel(), minlength=len(self.vertices))
            self._ring = (np.concatenate([[0], np.cumsum(counts)]), order // 3)
        indptr, vertex_faces = self._ring
        corners = self.faces[face].ravel()
        counts = indptr[corners + 1] - indptr[corners]
        owner = np.repeat(np.repeat(np.arange(len(face)), 3), counts)
        start = np.repeat(indptr[corners] - np.concatenate([[0], np.cumsum(counts)[:-1]]),
                          counts)
        return owner, vertex_faces[start + np.arange(counts.sum())]

    def refine(self, origins: np.ndarray, directions: np.ndarray, face: np.ndarray,
               u: np.ndarray | None = None, v: np.ndarray | None = None, *,
               scale: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact first hits of rays on the triangles a float32 caster reported.

        Parameters
        ----------
        origins : (h, 3) float64, metres, body frame B
        directions : (h, 3) float64, unit vectors, B
        face : (h,) int, triangle hit according to the caster
        u, v : (h,) float32, optional
            The caster's barycentric weights of the triangle's second and third vertices. Without
            them every hit is checked in float64.
        scale : float, metres
            Largest coordinate magnitude of the rays (the sensor's distance from the origin);
            sets how close to an edge a float32 hit must be to be checked in float64.

        Returns
        -------
        t : (h,) float64, metres along the ray (undefined where not ``hit``)
        face : (h,) int64, triangle hit (possibly a neighbour of the one reported)
        hit : (h,) bool, False for rays that miss in exact arithmetic
        """
        face = np.array(face, np.int64)   # a copy: repaired rays get a neighbouring face
        if u is None or v is None:
            t, hit = self._intersect(origins, directions, face)
            check = np.flatnonzero(~hit)
        else:
            # np.take: row gathers several times faster than fancy indexing.
            plane = np.take(self._plane, face, axis=0)
            normal = plane[:, :3]
            denom = np.einsum("ij,ij->i", normal, directions)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (plane[:, 3] - np.einsum("ij,ij->i", normal, origins)) / denom
            margin = np.take(self._inv_altitude, face) * (FLOAT32_POSITION_SLACK * scale)
            edge = np.minimum(np.minimum(u, v), 1.0 - u - v)
            check = np.flatnonzero((edge < margin) | ~(t > 0) | (t == np.inf))
            hit = np.ones(len(face), bool)
            if len(check):
                t[check], hit[check] = self._intersect(origins[check], directions[check],
                                                       face[check])
                check = check[~hit[check]]
        if len(check):
            owner, candidate = self._faces_around(face[check])
            ct, cin = self._intersect(origins[check][owner], directions[check][owner], candidate)
            ct = np.where(cin, ct, np.inf)
            order = np.lexsort((ct, owner))           # nearest candidate first, per ray
            first = order[np.flatnonzero(np.r_[True, np.diff(owner[order]) != 0])]
            rows = check[owner[first]]
            t[rows] = ct[first]
            face[rows] = candidate[first]
            hit[rows] = np.isfinite(ct[first])
        return t, face, hit
