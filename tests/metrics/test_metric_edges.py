"""The edge metric: surface variation, the truth triangulation's weighted edges, and the orderings
the paper reports (on sampled shapes; on simulated paper scenes: test_edge_paper_scenes.py)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from metrics_reference import MESHES, area, box, ellipsoid, load, satellite
from scipy.spatial import cKDTree

from formats.errors import InputError
from metrics import (
    Mesh,
    defaults,
    detect_edges,
    dihedral_edges,
    edge_score,
    feature_edge_score,
    feature_edges,
    sample_surface,
    surface_variation,
)

needs_meshes = pytest.mark.skipif(not (MESHES / "fandisk.obj").exists(),
                                  reason="shared meshes not present")


def cloud(mesh: Mesh, n: int, seed: int = 1, noise_fraction: float = 0.0) -> np.ndarray:
    """n points sampled uniformly on a mesh, with Gaussian noise of a fraction of its diagonal."""
    points, _ = sample_surface(mesh, n, seed=seed)
    sigma = noise_fraction * np.linalg.norm(np.ptp(mesh.vertices, axis=0))
    return points + np.random.default_rng(seed + 1000).normal(scale=sigma, size=points.shape)


@pytest.fixture(scope="module")
def fandisk() -> Mesh:
    if not (MESHES / "fandisk.obj").exists():
        pytest.skip("shared meshes not present")
    return load("fandisk.obj")


# --------------------------------------------------------------------------- building blocks


def test_surface_variation_matches_recomputed_neighbourhoods():
    rng = np.random.default_rng(1)
    xy = rng.uniform(-1, 1, (300, 2))
    points = np.column_stack([xy, 0.3 * np.abs(xy[:, 0]) + 0.02 * rng.normal(size=300)])
    k = 10
    result = surface_variation(points, k=k)
    _, index = cKDTree(points).query(points, k=k)
    for i in range(len(points)):
        hood = points[index[i]]
        eig = np.linalg.eigvalsh(np.cov(hood.T))
        rest = np.linalg.eigvalsh(np.cov(hood[hood_without(index[i], i)].T))
        assert result.sigma[i] == pytest.approx(eig[0] / eig.sum(), abs=1e-12)
        assert result.drop[i] == pytest.approx(eig[0] / eig.sum() - rest[0] / rest.sum(),
                                               abs=1e-12)
    assert result.radius == pytest.approx(cKDTree(points).query(points, k=k)[0][:, -1])


def hood_without(index: np.ndarray, i: int) -> np.ndarray:
    keep = np.ones(len(index), dtype=bool)
    keep[np.flatnonzero(index == i)[0]] = False
    return keep


def test_plane_has_no_variation_and_no_edges():
    rng = np.random.default_rng(2)
    points = np.column_stack([rng.uniform(0, 5, (5000, 2)), np.full(5000, 3.0)])
    is_edge, variation = detect_edges(points)
    assert variation.sigma.max() < 1e-12 and np.abs(variation.drop).max() < 1e-12
    assert not is_edge.any()


def test_closed_form_smallest_eigenvalue_matches_lapack():
    from metrics.edges import _smallest_eigenvalue

    rng = np.random.default_rng(4)
    shapes = [rng.normal(size=(16, 3)) * scale for scale in ([1, 1, 1], [1, 1, 1e-7],
                                                              [1, 1e-7, 1e-7], [5, 1, 0])]
    shapes += [rng.normal(size=(16, 3)) for _ in range(500)]
    matrices = np.stack([(x - x.mean(0)).T @ (x - x.mean(0)) for x in shapes])
    entries = [matrices[:, i, j] for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))]
    expected = np.linalg.eigvalsh(matrices)[:, 0]
    scale = np.trace(matrices, axis1=1, axis2=2)
    assert np.abs(_smallest_eigenvalue(*entries) - expected).max() < 1e-12 * scale.max()
    # A flat neighbourhood: the smallest eigenvalue stays at rounding level of the trace.
    assert abs(_smallest_eigenvalue(*(e[3:4] for e in entries))[0]) < 1e-13 * scale[3]


def test_default_threshold_sees_the_feature_angle_and_not_curvature():
    """The calibration behind defaults.EDGE_K and EDGE_DROP_THRESHOLD (see defaults.py)."""
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-1, 1, (2, 20_000))
    for angle, least in ((30.0, 0.5), (90.0, 0.8)):
        crease = np.column_stack([x, y, -np.abs(x) * np.tan(np.radians(angle) / 2)])
        is_edge, v = detect_edges(crease)
        on = (np.abs(x) < 0.3 * np.median(v.radius)) & (np.abs(y) < 0.8)
        assert is_edge[on].mean() > least
        assert not is_edge[(np.abs(x) > 1.5 * np.median(v.radius)) & (np.abs(x) < 0.8)].any()
    sphere = rng.normal(size=(6_000, 3))
    assert not detect_edges(sphere / np.linalg.norm(sphere, axis=1, keepdims=True))[0].any()
    plane = np.column_stack([rng.uniform(0, 1, (20_000, 2)),
                             rng.normal(scale=0.05 * np.sqrt(1 / 20_000), size=20_000)])
    assert detect_edges(plane)[0].mean() < 0.03
    # Another k scales the default threshold as 1 / k.
    assert edge_score(cloud(box(), 500), box(), k=32).threshold == pytest.approx(
        defaults.EDGE_DROP_THRESHOLD / 2)


def test_feature_edges_of_a_box_are_its_twelve_edges():
    mesh = box((10.0, 6.0, 4.0))
    edges = feature_edges(mesh)
    assert len(edges) == 12
    lengths = sorted(np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]],
                                    axis=1))
    assert lengths == pytest.approx([4.0] * 4 + [6.0] * 4 + [10.0] * 4)
    assert len(feature_edges(ellipsoid(3))) == 0  # facets meet at a few degrees


@needs_meshes
def test_feature_edges_match_trimesh_adjacency_angles(fandisk):
    tm = trimesh.Trimesh(fandisk.vertices, fandisk.faces, process=False)
    for angle in (10.0, 30.0, 60.0):
        sharp = tm.face_adjacency_edges[tm.face_adjacency_angles > np.radians(angle)]
        expected = {tuple(e) for e in np.sort(sharp, axis=1)}
        assert {tuple(e) for e in feature_edges(fandisk, angle_deg=angle)} == expected
        assert len(expected) > 100


def test_score_formula_from_the_report_arrays():
    mesh = box()
    points = cloud(mesh, 20_000, noise_fraction=0.0005)
    report = edge_score(points, mesh)
    far = ~report.near_edge
    assert report.false_edge_rate == pytest.approx((report.is_edge & far).sum() / far.sum())
    assert report.score == pytest.approx(0.5 * (report.false_edge_rate
                                                + report.missed_edge_rate))
    # Missed length, independently: 2000 points along each box edge, found when an edge point
    # lies within the tolerance.
    ends = mesh.vertices[feature_edges(mesh)]
    t = np.linspace(0, 1, 2000)[None, :, None]
    along = (ends[:, 0, None] + t * (ends[:, 1] - ends[:, 0])[:, None]).reshape(-1, 3)
    lengths = np.repeat(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1), 2000)
    found = cKDTree(points[report.is_edge]).query(along)[0] <= report.tolerance_m
    assert report.missed_edge_rate == pytest.approx(lengths[~found].sum() / lengths.sum(),
                                                    abs=0.01)
    assert report.tolerance_m == pytest.approx(
        defaults.EDGE_TOLERANCE_FRACTION * np.linalg.norm(np.ptp(mesh.vertices, axis=0)))


def test_feature_variant_on_a_smooth_body_scores_false_edges_only():
    report = feature_edge_score(cloud(ellipsoid(4), 2_000), ellipsoid(4))
    assert report.variant == "feature"
    assert report.missed_edge_rate is None and report.n_feature_edges == 0
    assert report.score == report.false_edge_rate > 0


def test_dihedral_edges_of_a_box():
    mesh = box((10.0, 6.0, 4.0))
    edges, angle = dihedral_edges(mesh)
    assert len(edges) == 18  # 12 box edges and 6 face diagonals
    assert sorted(np.round(angle, 9)) == [0.0] * 6 + [90.0] * 12


@needs_meshes
def test_dihedral_edges_match_trimesh_adjacency(fandisk):
    tm = trimesh.Trimesh(fandisk.vertices, fandisk.faces, process=False)
    expected = dict(zip(map(tuple, np.sort(tm.face_adjacency_edges, axis=1)),
                        np.degrees(tm.face_adjacency_angles), strict=True))
    edges, angle = dihedral_edges(fandisk)
    assert len(edges) == len(expected)
    assert angle == pytest.approx([expected[tuple(e)] for e in edges], abs=1e-5)  # arccos near 1


def test_dihedral_edges_match_a_per_edge_loop_on_shuffled_non_manifold_meshes():
    """Grouping by edge, written another way: a dict from each sorted vertex pair to its faces
    in face order, the largest angle between the first face and each other one."""
    rng = np.random.default_rng(0)
    sphere = trimesh.creation.icosphere(subdivisions=2)
    faces = np.asarray(sphere.faces, dtype=np.int64)
    faces = rng.permutation(np.concatenate([faces[rng.random(len(faces)) < 0.9], faces[:4],
                                            faces[:2, ::-1]]))
    mesh = trimesh.Trimesh(sphere.vertices, faces, process=False)
    normals = mesh.face_normals
    by_edge: dict[tuple[int, int], list[int]] = {}
    for f, face in enumerate(faces):
        for a, b in ((face[0], face[1]), (face[1], face[2]), (face[2], face[0])):
            by_edge.setdefault((min(a, b), max(a, b)), []).append(f)
    expected = {}
    for edge, owners in sorted(by_edge.items()):
        if len(owners) >= 2:
            cos = [1.0 if g == owners[0] else float(normals[owners[0]] @ normals[g])
                   for g in owners]
            expected[edge] = np.degrees(np.arccos(np.clip(min(cos), -1.0, 1.0)))
    edges, angle = dihedral_edges((np.asarray(sphere.vertices), faces))
    assert [tuple(e) for e in edges] == list(expected)
    assert angle == pytest.approx(list(expected.values()), abs=1e-9)


def weighted_missed_reference(points, mesh, tolerance, edge_points=None, feature_deg=30.0,
                              per_edge=400):
    """MER of the weighted metric, written another way: trimesh's face adjacency for the edges
    and their angles, ``per_edge`` points along each edge, plain cKDTree queries."""
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    ends = mesh.vertices[tm.face_adjacency_edges]
    angle = tm.face_adjacency_angles
    t = ((np.arange(per_edge) + 0.5) / per_edge)[None, :, None]
    along = (ends[:, 0, None] + t * (ends[:, 1] - ends[:, 0])[:, None]).reshape(-1, 3)
    found = cKDTree(points).query(along)[0].reshape(len(angle), -1) <= tolerance
    sharp = np.degrees(angle) > feature_deg
    if sharp.any():
        detected = np.zeros_like(found)
        if edge_points is not None and len(edge_points):
            detected = cKDTree(edge_points).query(along)[0].reshape(found.shape) <= tolerance
        found[sharp] = detected[sharp]
    weight = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1) * angle
    return float(np.sum(weight * (1 - found.mean(axis=1))) / weight.sum())


def test_weighted_score_counts_the_gentle_facet_edges_of_a_smooth_body():
    """Paper: the metric reads "the triangulation of the ellipsoid"; a noise-free cloud of half
    of it misses the other half's facet edges (weighted by length x dihedral angle)."""
    mesh = ellipsoid(4)
    points = cloud(mesh, 60_000)
    half = points[points[:, 2] > 0]
    report = edge_score(half, mesh)
    assert report.variant == "weighted" and report.n_feature_edges == 0
    assert report.n_truth_edges == 7_680 and report.feature_weight_fraction == 0.0
    assert report.false_edge_rate < 1e-3  # a few points on the cut look like edges
    assert report.missed_edge_rate == pytest.approx(
        weighted_missed_reference(half, mesh, report.tolerance_m), abs=0.005)
    assert 0.4 < report.missed_edge_rate < 0.6
    assert report.score == pytest.approx((report.missed_edge_rate + report.false_edge_rate) / 2)
    whole = edge_score(points, mesh)
    assert 0.0 < whole.score < 0.005  # dense and noise-free: nearly every edge sampled
    # Per-edge found fractions: the edges of the lower half (below -t) are missed whole.
    low = (mesh.vertices[report.truth_edges][:, :, 2] < -report.tolerance_m).all(axis=1)
    assert low.sum() > 3_000 and (report.edge_found[low] == 0).all()


@needs_meshes
def test_weighted_missed_rate_matches_an_independent_computation_on_a_cad_part(fandisk):
    points = cloud(fandisk, 20_000, noise_fraction=0.0005)
    points = points[points[:, 0] > np.median(points[:, 0])]  # half of it: holes too
    report = edge_score(points, fandisk)
    expected = weighted_missed_reference(points, fandisk, report.tolerance_m,
                                         edge_points=points[report.is_edge])
    assert report.missed_edge_rate == pytest.approx(expected, abs=0.01)
    assert report.feature_weight_fraction > 0.5  # feature edges dominate a CAD part


def test_weighted_equals_feature_variant_when_every_edge_is_sharp_or_flat():
    mesh = box()
    points = cloud(mesh, 20_000, noise_fraction=0.0005)
    weighted, feature = edge_score(points, mesh), feature_edge_score(points, mesh)
    assert weighted.n_truth_edges == feature.n_truth_edges == 12  # diagonals weigh nothing
    assert weighted.feature_weight_fraction == 1.0
    assert weighted.score == pytest.approx(feature.score, abs=1e-12)
    assert weighted.feature_missed_rate == pytest.approx(feature.missed_edge_rate, abs=1e-12)
    assert weighted.truth_edge_weight == pytest.approx(np.pi / 2 * feature.truth_edge_weight)


def test_edge_weights_are_the_integrated_mean_curvature_whatever_the_triangulation():
    """Sum of length x dihedral angle is twice the integrated mean curvature: 8 pi R for a
    sphere, however finely it is triangulated; a cloud missing a cap misses the cap's share."""
    radius = 50.0
    rng = np.random.default_rng(5)
    u = rng.normal(size=(80_000, 3))
    points = radius * u / np.linalg.norm(u, axis=1, keepdims=True)
    kept = points[points[:, 2] < 0.5 * radius]  # no cap above z = R / 2: a quarter of the area
    missed = []
    for subdivisions in (3, 4, 5):
        tm = trimesh.creation.icosphere(subdivisions, radius=radius)
        report = edge_score(kept, Mesh(np.asarray(tm.vertices), np.asarray(tm.faces)))
        assert report.truth_edge_weight == pytest.approx(8 * np.pi * radius, rel=0.03)
        missed.append(report.missed_edge_rate)
    assert max(missed) - min(missed) < 0.03
    assert missed == pytest.approx([0.25] * 3, abs=0.04)  # a little less: the rim within t


# --------------------------------------------------------------------------- the paper's orderings


def scores(mesh, sizes, **kw):
    return [edge_score(cloud(mesh, n, **kw), mesh).score for n in sizes]


def test_dense_noise_free_sampling_scores_near_zero():
    assert edge_score(cloud(box(), 100_000), box()).score < 0.01
    assert edge_score(cloud(ellipsoid(4), 100_000), ellipsoid(4)).score < 0.01


@needs_meshes
def test_dense_noise_free_real_cad_part_scores_near_zero(fandisk):
    assert edge_score(cloud(fandisk, 100_000), fandisk).score < 0.02


@pytest.mark.parametrize("shape", ["box", "ellipsoid", "fandisk"])
def test_denser_scores_below_sparser(shape, request):
    mesh = {"box": box, "ellipsoid": lambda: ellipsoid(4)}.get(
        shape, lambda: request.getfixturevalue("fandisk"))()
    dense, medium, sparse = scores(mesh, (50_000, 8_000, 1_500))
    assert dense <= medium < sparse
    assert dense < sparse - 0.02


@pytest.mark.parametrize("shape", ["box", "ellipsoid", "fandisk"])
def test_noise_free_scores_below_noisy(shape, request):
    mesh = {"box": box, "ellipsoid": lambda: ellipsoid(4)}.get(
        shape, lambda: request.getfixturevalue("fandisk"))()
    clean, noisy, noisier = (edge_score(cloud(mesh, 30_000, noise_fraction=f), mesh).score
                             for f in (0.0, 0.001, 0.003))
    assert clean < noisy < noisier
    assert noisier > clean + 0.1


@pytest.mark.parametrize("shape", ["box", "fandisk"])
def test_full_coverage_scores_below_a_cloud_with_holes(shape, request):
    mesh = box() if shape == "box" else request.getfixturevalue("fandisk")
    points = cloud(mesh, 40_000)
    full = edge_score(points, mesh)
    # Blind spots: balls around three feature-edge midpoints, a tenth of the diagonal across.
    edges = feature_edges(mesh)
    centres = mesh.vertices[edges[[0, len(edges) // 2, -1]]].mean(axis=1)
    radius = 0.1 * np.linalg.norm(np.ptp(mesh.vertices, axis=0))
    seen = cKDTree(centres).query(points)[0] > radius
    holed = edge_score(points[seen], mesh)
    assert full.score < holed.score
    assert full.missed_edge_rate < holed.missed_edge_rate


def test_thin_solar_panels_raise_false_edges():
    """Paper: neighbourhoods on thin panels straddle both faces, marking panel points as edges."""
    density = 400.0  # points per square metre, the same on every body
    result, points = {}, {}
    for name, thickness in (("bus", None), ("thick", 1.0), ("thin", 0.05)):
        mesh = satellite(thickness)
        points[name] = cloud(mesh, int(density * area(mesh)))
        result[name] = edge_score(points[name], mesh)
    thin = result["thin"]
    assert thin.false_edge_rate > 5 * max(result["bus"].false_edge_rate,
                                          result["thick"].false_edge_rate, 0.01)
    assert thin.score > result["thick"].score and thin.score > result["bus"].score
    # The false edges are on the panels (|x| > 2.5 m), not on the bus.
    false = thin.is_edge & ~thin.near_edge
    on_panel = np.abs(points["thin"][:, 0]) > 2.5
    assert false[on_panel].mean() > 10 * max(false[~on_panel].mean(), 1e-3)


def test_denser_lidar_cloud_sees_fewer_false_edges_on_thin_panels():
    """Paper, Figure 19: the LIDAR cloud is dense enough that few panel points are false edges."""
    mesh = satellite(0.1)
    lrf, lidar = (edge_score(cloud(mesh, int(d * area(mesh))), mesh) for d in (75.0, 400.0))
    assert lidar.false_edge_rate < 0.5 * lrf.false_edge_rate


def test_scale_invariant_asteroid_against_satellite_size():
    """The same shape and sampling at 300 m and at 20 m (and moved) scores the same."""
    shape = box((1.0, 0.6, 0.4))
    points = cloud(shape, 5_000, noise_fraction=0.001)
    scores_ = []
    for size, shift in ((300.0, 0.0), (20.0, 7.0e3)):
        mesh = Mesh(shape.vertices * size + shift, shape.faces)
        scores_.append(edge_score(points * size + shift, mesh).score)
    assert scores_[0] > 0.01
    assert scores_[0] == pytest.approx(scores_[1], rel=1e-6)


def test_pauly_rule_variant():
    mesh = box()
    clean = edge_score(cloud(mesh, 30_000), mesh, rule="pauly")
    noisy = edge_score(cloud(mesh, 30_000, noise_fraction=0.003), mesh, rule="pauly")
    assert clean.rule == "pauly" and clean.threshold == defaults.EDGE_SIGMA_THRESHOLD
    assert clean.score < 0.05 < noisy.score
    is_edge, variation = detect_edges(cloud(mesh, 30_000), rule="pauly", threshold=0.05)
    assert np.array_equal(is_edge, variation.sigma > 0.05)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"k": 3}, "k must be an integer >= 4"),
    ({"k": 2.5}, "k must be an integer >= 4"),
    ({"k": 500}, "points has 200 rows, fewer than k = 500"),
    ({"rule": "sobel"}, "rule must be one of"),
    ({"threshold": -0.1}, "threshold must be a finite number >= 0"),
    ({"tolerance": 0.1, "tolerance_fraction": 0.01}, "give tolerance or tolerance_fraction"),
    ({"tolerance": 0.0}, "tolerance must be a finite length > 0"),
    ({"feature_angle_deg": 190.0}, r"angle_deg must be in \[0, 180\)"),
    ({"variant": "sharp"}, "variant must be one of"),
])
def test_bad_edge_options_raise(kwargs, match):
    with pytest.raises(InputError, match=match):
        edge_score(cloud(box(), 200), box(), **kwargs)
