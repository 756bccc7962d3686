"""Exact point-to-mesh distance against a brute force over all triangles."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from metrics_reference import MESHES, as_mesh, box, brute_force_distance, load

from formats.errors import InputError, ReconError
from metrics import MeshDistance, point_mesh_distance
from metrics.distance import _CORNER, _EDGE, _QUICK, closest_on_faces
from metrics.inputs import Mesh, bbox_diagonal

RTOL = 1e-9  # the brief's agreement
ATOL_FRACTION = 1e-12  # of the mesh diagonal: points lying on the surface have d ~ 1e-15


def probe_points(mesh: Mesh, n: int, seed: int) -> np.ndarray:
    """Points on, inside, outside, near edges and near vertices of a mesh."""
    rng = np.random.default_rng(seed)
    v, f = mesh.vertices, mesh.faces
    size = bbox_diagonal(v)
    lo, hi = v.min(axis=0) - 0.2 * size, v.max(axis=0) + 0.2 * size
    tri = v[f[rng.integers(0, len(f), n)]]
    bary = rng.dirichlet(np.ones(3), n)
    on_surface = np.einsum("nk,nkj->nj", bary, tri)
    ends = rng.integers(0, 3, n)
    edge_start, edge_end = tri[np.arange(n), ends], tri[np.arange(n), (ends + 1) % 3]
    t = rng.uniform(0, 1, (n, 1))
    on_edge = edge_start + t * (edge_end - edge_start)
    vertex = v[rng.integers(0, len(v), n)]
    jitter = rng.normal(scale=1e-3 * size, size=(n, 3))
    tiny = rng.normal(scale=1e-9 * size, size=(n, 3))
    return np.concatenate([
        rng.uniform(lo, hi, (n, 3)),  # inside and outside
        on_surface, on_surface + jitter,
        on_edge, on_edge + jitter, on_edge + tiny,
        vertex, vertex + jitter, vertex + tiny,
        rng.normal(scale=10 * size, size=(n // 4, 3)),  # far away
    ])


def assert_agrees(mesh: Mesh, points: np.ndarray):
    distance, face, closest = point_mesh_distance(points, mesh)
    expected = brute_force_distance(points, mesh.vertices, mesh.faces, skip_degenerate=True)
    atol = ATOL_FRACTION * bbox_diagonal(mesh.vertices)
    np.testing.assert_allclose(distance, expected, rtol=RTOL, atol=atol)
    # The closest point is at that distance and lies on the reported face.
    np.testing.assert_allclose(np.linalg.norm(points - closest, axis=1), distance,
                               rtol=RTOL, atol=atol)
    on_face = np.array([brute_force_distance(q[None], mesh.vertices, mesh.faces[[fi]])[0]
                        for q, fi in zip(closest[:200], face[:200], strict=True)])
    np.testing.assert_array_less(on_face, 1e-9 * bbox_diagonal(mesh.vertices))


def test_icosphere_far_from_origin_matches_brute_force():
    sphere = trimesh.creation.icosphere(2)
    mesh = Mesh(sphere.vertices * 300.0 + [2.0e4, -1.0e4, 5.0e3], sphere.faces)
    assert_agrees(mesh, probe_points(mesh, 200, seed=1))


def test_box_inside_and_outside_matches_brute_force():
    mesh = box()
    assert_agrees(mesh, probe_points(mesh, 200, seed=2))


def test_unwelded_soup_matches_brute_force():
    sphere = trimesh.creation.icosphere(2)
    soup = Mesh(sphere.vertices[sphere.faces].reshape(-1, 3) * 50.0,
                np.arange(3 * len(sphere.faces)).reshape(-1, 3))
    assert_agrees(soup, probe_points(soup, 200, seed=9))


def test_concave_torus_matches_brute_force():
    mesh = as_mesh(trimesh.creation.torus(major_radius=3.0, minor_radius=1.0,
                                          major_sections=24, minor_sections=12))
    assert_agrees(mesh, probe_points(mesh, 200, seed=3))


def test_triangle_soup_with_degenerate_faces_matches_brute_force():
    """Zero-area faces (segments, points) have no surface and are ignored by convention."""
    rng = np.random.default_rng(4)
    vertices = rng.uniform(-1, 1, (60, 3))
    faces = rng.integers(0, 60, (40, 3))
    faces[0] = [5, 5, 7]  # a segment
    faces[1] = [9, 9, 9]  # a point
    vertices[12] = 0.5 * (vertices[10] + vertices[11])
    faces[2] = [10, 11, 12]  # collinear
    mesh = Mesh(vertices, faces)
    assert_agrees(mesh, probe_points(mesh, 150, seed=5))


@pytest.mark.skipif(not (MESHES / "fandisk.obj").exists(), reason="shared meshes not present")
def test_real_cad_mesh_matches_brute_force():
    mesh = load("fandisk.obj")
    assert_agrees(mesh, probe_points(mesh, 60, seed=6))


def test_guard_corrects_float32_near_ties():
    """Points a hair off the bisector of concave creases: Embree's float32 pick is often wrong.

    A fan of faces meeting at shallow concave creases; each probe sits above a crease, on the
    side of one face by 1e-9 of the mesh size (far below float32 resolution), so the true closest
    triangle is decided by that offset. The raw candidate must be wrong for some probes (so this
    test can fail) and the guarded result exact for all.
    """
    # A corrugated sheet: valleys along y, faces tilted by +-5 degrees.
    xs = np.arange(0.0, 21.0)
    zs = np.where(np.arange(len(xs)) % 2 == 0, 0.0, np.tan(np.radians(5.0)))
    grid_x, grid_y = np.meshgrid(xs, np.array([0.0, 10.0]), indexing="ij")
    vertices = np.column_stack([grid_x.ravel(), grid_y.ravel(), np.repeat(zs, 2)]) + 1000.0
    n = len(xs)
    quads = np.arange(n - 1) * 2
    faces = np.concatenate([np.column_stack([quads, quads + 2, quads + 1]),
                            np.column_stack([quads + 1, quads + 2, quads + 3])])
    mesh = Mesh(vertices, faces)
    rng = np.random.default_rng(7)
    valley = np.arange(2, n - 2, 2)  # x of the valley lines (z = 0 at even x)
    x = rng.choice(valley, 4000).astype(float)
    height = rng.uniform(0.05, 0.4, 4000)
    side = rng.choice([-1.0, 1.0], 4000)
    probes = np.column_stack([x + side * 1e-9 * bbox_diagonal(vertices), rng.uniform(2, 8, 4000),
                              height]) + 1000.0
    md = MeshDistance(mesh)
    t0 = md.candidates(probes - md.centre)
    raw, _ = closest_on_faces(md._v, md._f, md.normals, md.degenerate,
                              probes - md.centre, t0)
    expected = brute_force_distance(probes, vertices, faces)
    raw_wrong = np.abs(raw - expected) > RTOL * expected
    assert raw_wrong.sum() > 10, "the probes no longer provoke float32 near-tie errors"
    distance, _, _ = md.query(probes)
    np.testing.assert_allclose(distance, expected, rtol=RTOL, atol=0)
    # The same sheet as an unwelded soup (every face with its own vertex copies, as in STL).
    soup = Mesh(vertices[faces].reshape(-1, 3), np.arange(3 * len(faces)).reshape(-1, 3))
    distance, _, _ = MeshDistance(soup).query(probes)
    np.testing.assert_allclose(distance, expected, rtol=RTOL, atol=0)


def test_guard_corrects_float32_near_ties_at_a_shared_vertex():
    """A flat floor meeting a wall at one vertex only: probes above the floor that are (nearly)
    as close to the wall, which touches the floor face under them at the vertex alone.

    Twelve faces fan around the origin; those spanning 15..165 degrees lie on z = 0, the rest rise
    to z = -2 y, and the one spanning 255..285 degrees lies exactly in that plane. A point
    (0, s, H) is H from the floor face under it (75..105 degrees, whose edge neighbours are flat)
    and (H + 2 s) / sqrt(5) from the wall: equidistant at s = 0.618 H. Probes sit 1e-8 to either
    side, below float32 resolution.
    """
    angle = np.radians(15.0 + 30.0 * np.arange(12))
    rim = np.column_stack([np.cos(angle), np.sin(angle), np.maximum(0.0, -2 * np.sin(angle))])
    vertices = np.vstack([[0.0, 0.0, 0.0], rim]) + 500.0
    faces = np.column_stack([np.zeros(12, int), 1 + np.arange(12), 1 + (np.arange(12) + 1) % 12])
    mesh = Mesh(vertices, faces)
    rng = np.random.default_rng(10)
    height = rng.uniform(0.2, 1.0, 4000)
    s = height * (np.sqrt(5.0) - 1.0) / 2.0 * (1.0 + rng.choice([-1e-8, 1e-8], 4000))
    probes = np.column_stack([np.zeros(4000), s, height]) + 500.0
    md = MeshDistance(mesh)
    t0 = md.candidates(probes - md.centre)
    raw, _ = closest_on_faces(md._v, md._f, md.normals, md.degenerate, probes - md.centre, t0)
    expected = brute_force_distance(probes, vertices, faces)
    assert (np.abs(raw - expected) > RTOL * expected).sum() > 10
    np.testing.assert_allclose(md.query(probes)[0], expected, rtol=RTOL, atol=0)


def test_results_do_not_depend_on_threads_or_blocks():
    mesh = box()
    points = probe_points(mesh, 30000, seed=8)
    md = MeshDistance(mesh)
    one = md.query(points, threads=1)
    two = md.query(points, threads=2)
    for a, b in zip(one, two, strict=True):
        assert np.array_equal(a, b)


@pytest.mark.parametrize(("points", "match"), [
    (np.zeros((0, 3)), "points is empty"),
    (np.zeros((4, 2)), r"points must be \(n, 3\), got shape \(4, 2\)"),
    (np.array([[0.0, np.nan, 0.0]]), "points has 1 row.* NaN or Inf"),
    (np.array([[0.0, 0.0, np.inf]]), "points has 1 row.* NaN or Inf"),
    ([["a", "b", "c"]], r"points must be an \(n, 3\) array of numbers"),
])
def test_bad_points_raise(points, match):
    with pytest.raises(InputError, match=match):
        point_mesh_distance(points, box())


@pytest.mark.parametrize(("mesh", "match"), [
    ((np.zeros((3, 3)), np.zeros((0, 3), dtype=int)), "mesh has no faces"),
    ((np.eye(3), np.array([[0, 1, 3]])), r"faces index vertices 0\.\.3, outside 0\.\.2"),
    ((np.eye(3), np.array([[0.0, 1.0, 2.0]])), "faces must be integers"),
    ((np.eye(3), np.array([[0, 1]])), r"faces must be \(m, 3\)"),
    ((np.zeros((3, 3)), np.array([[0, 1, 2]])), "zero total area"),
    ("not a mesh", "mesh must be a Mesh"),
])
def test_bad_meshes_raise(mesh, match):
    with pytest.raises(InputError, match=match):
        MeshDistance(mesh)


def test_error_is_a_recon_error_and_value_error():

    assert issubclass(InputError, ReconError)
    assert issubclass(InputError, ValueError)


def ring_checked_everywhere(md: MeshDistance) -> MeshDistance:
    """The same mesh with every point sent through the exact ring check (no fast path)."""
    md._sides[:, _EDGE] = md._sides[:, _QUICK] = md._corners[:, _CORNER] = np.inf
    return md


@pytest.mark.parametrize("name", ["icosphere", "box", "torus", "soup", "fandisk"])
def test_fast_path_equals_the_ring_checked_path(name):
    """The per-face bounds only skip work: every point's distance, face and closest point are
    those of the exact ring check of every point, on the meshes of the tests above."""
    if name == "fandisk":
        if not (MESHES / "fandisk.obj").exists():
            pytest.skip("shared meshes not present")
        mesh = load("fandisk.obj")
    elif name == "icosphere":
        sphere = trimesh.creation.icosphere(2)
        mesh = Mesh(sphere.vertices * 300.0 + [2.0e4, -1.0e4, 5.0e3], sphere.faces)
    elif name == "box":
        mesh = box()
    elif name == "torus":
        mesh = as_mesh(trimesh.creation.torus(major_radius=3.0, minor_radius=1.0,
                                              major_sections=24, minor_sections=12))
    else:
        sphere = trimesh.creation.icosphere(2)
        mesh = Mesh(sphere.vertices[sphere.faces].reshape(-1, 3) * 50.0,
                    np.arange(3 * len(sphere.faces)).reshape(-1, 3))
    points = probe_points(mesh, 400, seed=11)
    fast = MeshDistance(mesh)
    assert np.isfinite(fast._sides[:, _EDGE]).mean() > 0.5  # the fast path is in use
    distance, face, closest = fast.query(points)
    d_ref, f_ref, q_ref = ring_checked_everywhere(MeshDistance(mesh)).query(points)
    np.testing.assert_allclose(distance, d_ref, rtol=1e-9, atol=ATOL_FRACTION * fast.scale)
    np.testing.assert_allclose(closest, q_ref, rtol=0, atol=1e-9 * fast.scale)
    tied = face != f_ref  # a different face only where the two are equally close
    np.testing.assert_allclose(distance[tied], d_ref[tied], rtol=1e-12, atol=1e-15 * fast.scale)


def test_distinct_points_drops_exact_copies_only():
    """Copies go (counted); points sharing x but not y or z stay; no copy: the input itself."""
    from metrics.spatial import distinct_points

    points = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [2.0, 0.0, 0.0],
                       [0.0, 0.0, 1e-300], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    distinct, copies = distinct_points(points, counts=True)
    got = sorted(zip(map(tuple, distinct), copies.tolist(), strict=True))
    assert got == [((0.0, 0.0, 0.0), 3), ((0.0, 0.0, 1e-300), 1), ((0.0, 1.0, 0.0), 2),
                   ((2.0, 0.0, 0.0), 1)]
    unique = np.random.default_rng(0).normal(size=(100, 3))
    assert distinct_points(unique) is unique
