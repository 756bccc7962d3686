"""The fast path of metrics.distance is exact: scores and distances equal the ring-checked path
and a brute-force reference to 1e-9, on the meshes and clouds the metric tests use and on rough
reconstruction-like meshes that strain the per-face bounds."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from metrics_reference import MESHES, as_mesh, box, brute_force_distance, ellipsoid, load, satellite

from metrics import Mesh, MeshDistance, Truth, score
from metrics.distance import _CORNER, _EDGE, _QUICK
from metrics.inputs import bbox_diagonal

RTOL = 1e-9  # issue #10: the fast path equals the exact path to 1e-9 relative
ATOL_FRACTION = 1e-12  # of the diagonal, for points on the surface (distances ~1e-15)
SMALL = {"n_truth_samples": 600, "n_test_samples": 600, "coverage_points": 600}


def rough(mesh: Mesh, roughness: float, seed: int) -> Mesh:
    """The mesh with every vertex moved at random by ``roughness`` x the mean edge length: a
    noisy reconstruction at small roughness, folded fans and creases at large."""
    edges = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).edges_unique_length
    rng = np.random.default_rng(seed)
    jitter = rng.normal(scale=roughness * edges.mean(), size=mesh.vertices.shape)
    return Mesh(mesh.vertices + jitter, mesh.faces)


def near_points(mesh: Mesh, n: int, seed: int) -> np.ndarray:
    """Points on the surface and at heights from 1e-9 to 30 % of the diagonal off it."""
    rng = np.random.default_rng(seed)
    tri = mesh.vertices[mesh.faces[rng.integers(0, mesh.n_faces, n)]]
    on = np.einsum("nk,nkj->nj", rng.dirichlet(np.ones(3), n), tri)
    height = bbox_diagonal(mesh.vertices) * 10.0 ** rng.uniform(-9, np.log10(0.3), (n, 1))
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return np.concatenate([on, on + height * direction])


def ring_checked(mesh: Mesh) -> MeshDistance:
    """The exact path for every point: the ring of every candidate is checked."""
    md = MeshDistance(mesh)
    md._sides[:, _EDGE] = md._sides[:, _QUICK] = md._corners[:, _CORNER] = np.inf
    return md


def fast_fraction(md: MeshDistance, points: np.ndarray) -> float:
    """Fraction of the points answered by the fast path (no ring check)."""
    slow = []
    guarded = md._guarded
    md._guarded = lambda p, t0: (slow.append(len(p)), guarded(p, t0))[1]
    md.query(points)
    md._guarded = guarded
    return 1.0 - sum(slow) / len(points)


def truths() -> dict[str, Mesh]:
    out = {"sphere": as_mesh(trimesh.creation.icosphere(3, radius=10.0)),
           "box": box(), "ellipsoid": ellipsoid(3), "satellite": satellite(0.1),
           "torus": as_mesh(trimesh.creation.torus(major_radius=3.0, minor_radius=1.0,
                                                   major_sections=24, minor_sections=12))}
    if (MESHES / "fandisk.obj").exists():
        out["fandisk"] = load("fandisk.obj")
    return out


@pytest.mark.parametrize("name", ["sphere", "box", "ellipsoid", "satellite", "torus",
                                  "fandisk"])
def test_scores_of_a_mesh_and_a_cloud_match_brute_force(name):
    """Accuracy of a test mesh's samples and of a cloud, and completeness to a test mesh:
    every distance in the report equals the brute-force distance to 1e-9."""
    shapes = truths()
    if name not in shapes:
        pytest.skip("shared meshes not present")
    truth = shapes[name]
    diagonal = bbox_diagonal(truth.vertices)
    test = rough(truth, 0.05, seed=1)  # a reconstruction: every vertex a little off
    prepared = Truth(truth)
    report = score(test, prepared, edges=False, **SMALL)
    atol = ATOL_FRACTION * diagonal
    np.testing.assert_allclose(
        report.accuracy_distances,
        brute_force_distance(report.test_points, truth.vertices, truth.faces,
                             skip_degenerate=True), rtol=RTOL, atol=atol)
    np.testing.assert_allclose(
        report.completeness_distances,
        brute_force_distance(report.truth_points, test.vertices, test.faces,
                             skip_degenerate=True), rtol=RTOL, atol=atol)
    cloud = near_points(truth, 200, seed=2)
    report = score(cloud, prepared, edges=False, **SMALL)
    np.testing.assert_allclose(
        report.accuracy_distances,
        brute_force_distance(cloud, truth.vertices, truth.faces, skip_degenerate=True),
        rtol=RTOL, atol=atol)


@pytest.mark.parametrize("roughness", [0.0, 0.02, 0.1, 0.3, 1.0])
def test_fast_path_equals_ring_check_on_rough_meshes(roughness):
    """From a smooth sphere to crumpled folds: the per-face bounds only ever skip work.

    The distances, faces and closest points of the fast path equal those of the ring check of
    every point and the brute-force distances, and the fast path is in use where it should be.
    """
    sphere = as_mesh(trimesh.creation.icosphere(3, radius=100.0))
    mesh = rough(sphere, roughness, seed=3)
    points = near_points(mesh, 1000, seed=4)
    md = MeshDistance(mesh)
    distance, face, closest = md.query(points)
    d_ref, f_ref, q_ref = ring_checked(mesh).query(points)
    atol = ATOL_FRACTION * md.scale
    np.testing.assert_allclose(distance, d_ref, rtol=RTOL, atol=atol)
    np.testing.assert_allclose(closest, q_ref, rtol=0, atol=RTOL * md.scale)
    tied = face != f_ref  # a different face only where the two are equally close
    np.testing.assert_allclose(distance[tied], d_ref[tied], rtol=1e-12, atol=atol)
    expected = brute_force_distance(points, mesh.vertices, mesh.faces, skip_degenerate=True)
    np.testing.assert_allclose(distance, expected, rtol=RTOL, atol=atol)
    if roughness <= 0.1:
        assert fast_fraction(md, points) > 0.7  # so the comparison above tests the bounds


def test_bounds_where_the_fan_is_open_or_not_a_manifold():
    """No cone bound at a boundary or a non-manifold edge (those points take the ring check),
    and no bound needed where nothing rises (a box seen from outside)."""
    sphere = as_mesh(trimesh.creation.icosphere(2, radius=10.0))
    upper = sphere.faces[sphere.vertices[sphere.faces].mean(axis=1)[:, 2] > 0]
    open_mesh = Mesh(sphere.vertices, upper)
    edges = trimesh.Trimesh(sphere.vertices, upper, process=False).edges_sorted
    rim = np.unique(edges[trimesh.grouping.group_rows(edges, require_count=1)])
    at_rim = np.isin(upper, rim)  # (faces, corners)
    behind = MeshDistance(open_mesh)._corners[:, _CORNER.start + 3:_CORNER.stop]  # inside
    assert at_rim.any() and np.isinf(behind[at_rim]).all()
    assert np.isfinite(behind[~at_rim]).all()
    # A fin on one edge of a sheet: three faces on one edge.
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1.0]])
    fin = MeshDistance(Mesh(vertices, np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])))
    assert np.isinf(fin._sides[:, _EDGE]).any()
    outside = MeshDistance(box())
    assert (outside._sides[0::2, _EDGE] == 0).all()  # in front: no rise
    assert (outside._corners[:, _CORNER.start:_CORNER.start + 3] == 0).all()
