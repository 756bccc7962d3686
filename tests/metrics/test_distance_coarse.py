"""Coarse test meshes (convex hulls, `planes`-like polyhedra, a box, a cone) seen from far
away: most points take the slow path of metrics.distance, whose answer must equal the minimum
of the exact closed form over *all* faces, bit for bit, ties to the lowest face index."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from metrics_reference import as_mesh, box, brute_force_distance, ellipsoid
from scipy.spatial import ConvexHull, HalfspaceIntersection

from metrics import Mesh, MeshDistance
from metrics.distance import closest_on_faces
from metrics.inputs import bbox_diagonal

RTOL = 1e-9  # issue #10: agreement with the independent reference


def outward(points: np.ndarray, *, orient: bool = True) -> Mesh:
    """The convex hull of the points; faces counter-clockwise from outside (as the
    ``convex-hull`` and ``planes`` methods return them) unless ``orient`` is False (qhull's own
    order: mixed orientations)."""
    qhull = ConvexHull(points)
    used, faces = np.unique(qhull.simplices, return_inverse=True)
    faces = faces.reshape(-1, 3)
    if orient:
        a, b, c = (points[used][faces[:, i]] for i in range(3))
        flip = np.einsum("ij,ij->i", np.cross(b - a, c - a), qhull.equations[:, :3]) < 0
        faces[flip] = faces[flip][:, ::-1]
    return Mesh(points[used], faces)


def cloud_hull(n: int, seed: int, *, orient: bool = True) -> Mesh:
    """The convex hull of a noisy cloud on the paper's ellipsoid (noise 0.5 m)."""
    truth = ellipsoid(3)
    rng = np.random.default_rng(seed)
    tri = truth.vertices[truth.faces[rng.integers(0, truth.n_faces, n)]]
    points = np.einsum("nk,nkj->nj", rng.dirichlet(np.ones(3), n), tri)
    return outward(points + rng.normal(scale=0.5, size=points.shape), orient=orient)


def polyhedron(planes: int, seed: int) -> Mesh:
    """A `planes`-like polyhedron: the intersection of the half-spaces below the tangent planes
    of the paper's ellipsoid at random points, triangulated by qhull (many coplanar faces)."""
    axes = np.array([143.75, 86.25, 287.5])
    direction = np.random.default_rng(seed).normal(size=(planes, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    normal = direction / axes  # the ellipsoid's normal at axes * direction
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    offset = np.einsum("ij,ij->i", normal, direction * axes)
    corners = HalfspaceIntersection(np.column_stack([normal, -offset]), np.zeros(3))
    return outward(corners.intersections)


MESHES = {"hull": lambda: cloud_hull(400, seed=1),
          "hull (qhull order)": lambda: cloud_hull(400, seed=1, orient=False),
          "hull (40 points)": lambda: cloud_hull(40, seed=2),
          "polyhedron": lambda: polyhedron(120, seed=3),
          "box": box,
          "cone": lambda: as_mesh(trimesh.creation.cone(5.0, 12.0, sections=64))}


def probes(mesh: Mesh, n: int, seed: int) -> np.ndarray:
    """Points far inside and outside, just off the surface, and above edges and vertices
    (where faces tie exactly)."""
    rng = np.random.default_rng(seed)
    v, f = mesh.vertices, mesh.faces
    size = bbox_diagonal(v)
    lo, hi = v.min(axis=0), v.max(axis=0)
    tri = v[f[rng.integers(0, len(f), n)]]
    on = np.einsum("nk,nkj->nj", rng.dirichlet(np.ones(3), n), tri)
    corner = v[rng.integers(0, len(v), n)]
    ends = rng.integers(0, 3, n)
    middle = 0.5 * (tri[np.arange(n), ends] + tri[np.arange(n), (ends + 1) % 3])
    away = 0.05 * size * (corner - v.mean(axis=0))
    return np.concatenate([
        rng.uniform(lo, hi, (n, 3)),  # inside (far from a coarse surface) and just outside
        lo + (hi - lo) * rng.uniform(-3.0, 4.0, (n, 3)),  # far outside
        on + rng.normal(scale=1e-3 * size, size=(n, 3)),
        corner + away / np.linalg.norm(away, axis=1, keepdims=True),  # beyond a vertex
        middle + rng.normal(scale=0.1 * size, size=(n, 3)),
        # Ties within 1e-7 of the size: rounding (~1e-16 of the size) is 1e-9 of the distance.
        corner + 1e-7 * size * away / np.linalg.norm(away, axis=1, keepdims=True),
        middle + rng.normal(scale=1e-7 * size, size=(n, 3)),
    ])


def all_faces(md: MeshDistance, points: np.ndarray, chunk: int = 64):
    """The exact closed form (``closest_on_faces``) over every face; the smallest distance,
    ties to the lowest face index. Same frame and arithmetic as the query's."""
    p = points - md.centre
    faces = np.flatnonzero(~md.degenerate)
    distance, face = np.empty(len(p)), np.empty(len(p), dtype=np.int64)
    closest = np.empty_like(p)
    for lo in range(0, len(p), chunk):
        block = p[lo:lo + chunk]
        d, q = closest_on_faces(md._v, md._f, md.normals, md.degenerate,
                                np.repeat(block, len(faces), axis=0), np.tile(faces, len(block)))
        d = d.reshape(len(block), len(faces))
        best = d.argmin(axis=1)  # the first minimum: the lowest face index
        rows = np.arange(len(block))
        distance[lo:lo + chunk], face[lo:lo + chunk] = d[rows, best], faces[best]
        closest[lo:lo + chunk] = q.reshape(len(block), len(faces), 3)[rows, best]
    return distance, face, closest + md.centre


@pytest.mark.parametrize("name", list(MESHES))
def test_coarse_meshes_match_the_minimum_over_all_faces(name):
    """Distances, faces and closest points equal the minimum over all faces bit for bit (ties
    to the lowest face index), and the distances the independent reference to 1e-9."""
    mesh = MESHES[name]()
    points = probes(mesh, 400, seed=4)
    md = MeshDistance(mesh)
    slow = []
    guarded = md._guarded
    md._guarded = lambda p, t0: (slow.append(len(p)), guarded(p, t0))[1]
    distance, face, closest = md.query(points)
    assert sum(slow) > 0.2 * len(points)  # the slow path is what is tested here
    d_all, f_all, q_all = all_faces(md, points)
    np.testing.assert_array_equal(distance, d_all)
    np.testing.assert_array_equal(face, f_all)
    np.testing.assert_array_equal(closest, q_all)
    expected = brute_force_distance(points, mesh.vertices, mesh.faces, skip_degenerate=True)
    np.testing.assert_allclose(distance, expected, rtol=RTOL, atol=1e-12 * md.scale)


@pytest.mark.parametrize("name", ["hull (40 points)", "polyhedron", "box", "cone"])
def test_slow_path_for_every_point_matches_all_faces(name):
    """``_guarded`` on every point, near ones included (not only those the fast path leaves):
    the same answer as the minimum over all faces."""
    mesh = MESHES[name]()
    points = probes(mesh, 200, seed=5)
    md = MeshDistance(mesh)
    p = points - md.centre
    distance, face, closest = md._guarded(p, md.candidates(p))
    d_all, f_all, q_all = all_faces(md, points)
    np.testing.assert_array_equal(distance, d_all)
    np.testing.assert_array_equal(face, f_all)
    np.testing.assert_array_equal(closest + md.centre, q_all)
