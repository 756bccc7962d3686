"""score(): agreement with Open3D and independent computations, defaults, coverage, errors."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import trimesh
from metrics_reference import area, as_mesh, box, brute_force_distance, ellipsoid
from scipy.spatial import cKDTree

from formats.errors import InputError
from metrics import Cloud, Mesh, ScaleMismatchWarning, ScoreReport, defaults, sample_surface, score

SPEED = {"n_truth_samples": 20_000, "coverage_points": 20_000}  # small but exact-enough


@pytest.fixture(scope="module")
def sphere() -> Mesh:
    return as_mesh(trimesh.creation.icosphere(3, radius=10.0))


def offset_cloud(truth: Mesh, report: ScoreReport, n: int, max_offset: float, seed: int):
    """Truth samples pushed outward along their face normal: on a convex truth the exact
    distance to the surface, and the distance to the nearest truth sample, are both the offset."""
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(report.truth_points), n, replace=False)
    a, b, c = (truth.vertices[truth.faces[report.truth_point_faces[pick], i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    offset = rng.uniform(0.0, max_offset, n)
    return report.truth_points[pick] + offset[:, None] * normal, offset


def test_chamfer_hausdorff_fscore_agree_with_open3d(sphere):
    import open3d as o3d

    tau = 0.2
    first = score(np.zeros((1, 3)) + 10.0, sphere, tau=tau, edges=False, **SPEED)
    points, offset = offset_cloud(sphere, first, 3000, 2.5 * tau, seed=1)
    report = score(points, sphere, tau=tau, edges=False, **SPEED)
    np.testing.assert_allclose(report.accuracy_distances, offset, rtol=1e-9, atol=1e-12)
    assert np.array_equal(report.truth_points, first.truth_points)

    # Open3D's metrics run in float32 only: agreement to float32 precision.
    test_pcd = o3d.t.geometry.PointCloud(o3d.core.Tensor(points.astype(np.float32)))
    truth_pcd = o3d.t.geometry.PointCloud(
        o3d.core.Tensor(report.truth_points.astype(np.float32)))
    metric = o3d.t.geometry.Metric
    params = o3d.t.geometry.MetricParameters(fscore_radius=[tau])
    chamfer_sum, hausdorff, fscore_percent = test_pcd.compute_metrics(
        truth_pcd, [metric.ChamferDistance, metric.HausdorffDistance, metric.FScore],
        params).numpy()
    # Open3D's Chamfer is the sum of the two means; ours is their mean. F is in percent.
    np.testing.assert_allclose(2 * report.chamfer_m, chamfer_sum, rtol=1e-5)
    np.testing.assert_allclose(report.hausdorff_m, hausdorff, rtol=1e-5)
    np.testing.assert_allclose(100 * report.fscore, fscore_percent, rtol=1e-5)
    assert 0.05 < report.precision < 0.95 and 0.05 < report.recall < 0.95  # not trivially 0/1


def test_every_scalar_matches_an_independent_computation():
    truth = box((4.0, 3.0, 2.0))
    rng = np.random.default_rng(2)
    cloud = rng.uniform([-2.5, -2, -1.5], [2.5, 2, 1.5], (400, 3))
    report = score(cloud, truth, tau=0.3, edges=False, **SPEED)
    accuracy = brute_force_distance(cloud, truth.vertices, truth.faces)
    completeness = cKDTree(cloud).query(report.truth_points)[0]
    np.testing.assert_allclose(report.accuracy_distances, accuracy, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(report.completeness_distances, completeness, rtol=1e-12)
    for name, values in (("accuracy", accuracy), ("completeness", completeness)):
        d = report.to_dict()
        assert d[f"{name}_mean_m"] == pytest.approx(values.mean(), rel=1e-9)
        assert d[f"{name}_rms_m"] == pytest.approx(np.sqrt(np.mean(values**2)), rel=1e-9)
        assert d[f"{name}_median_m"] == pytest.approx(np.median(values), rel=1e-9)
        assert d[f"{name}_p95_m"] == pytest.approx(np.quantile(values, 0.95), rel=1e-9)
        assert d[f"{name}_max_m"] == pytest.approx(values.max(), rel=1e-9)
    p = np.mean(accuracy < 0.3)
    r = np.mean(completeness < 0.3)
    assert report.precision == p and report.recall == r
    assert report.fscore == pytest.approx(2 * p * r / (p + r))
    assert report.chamfer_m == pytest.approx(0.5 * (accuracy.mean() + completeness.mean()))
    assert report.hausdorff_m == pytest.approx(max(accuracy.max(), completeness.max()))
    # Truth samples lie on the truth and are spread uniformly by area (face area shares).
    assert brute_force_distance(report.truth_points[:500], truth.vertices, truth.faces).max() \
        < 1e-12
    counts = np.bincount(report.truth_point_faces, minlength=len(truth.faces))
    share = trimesh.Trimesh(truth.vertices, truth.faces).area_faces / area(truth)
    np.testing.assert_allclose(counts / counts.sum(), share, atol=0.01)


def test_dense_sampling_of_the_truth_scores_perfectly():
    truth = ellipsoid(3)
    points, _ = sample_surface(truth, 200_000, seed=3)
    report = score(points, truth, **SPEED)
    assert report.fscore == 1.0 and report.coverage == 1.0
    assert report.accuracy_max_m < 1e-9
    # Chamfer is then half the completeness: the mean nearest-neighbour distance of a Poisson
    # sampling of density n / A on a surface, 0.5 sqrt(A / n) (0.69 m here, tau is 6.7 m).
    expected = 0.5 * 0.5 * np.sqrt(area(truth) / len(points))
    assert report.chamfer_m == pytest.approx(expected, rel=0.05)
    assert report.edge_score < 0.02


def test_default_tau_is_one_percent_of_the_truth_diagonal(sphere):
    report = score(sphere.vertices, sphere, edges=False, **SPEED)
    diagonal = np.linalg.norm(np.ptp(sphere.vertices, axis=0))
    assert report.tau_m == pytest.approx(defaults.TAU_FRACTION * diagonal)
    assert defaults.TAU_FRACTION == 0.01
    fraction = score(sphere.vertices, sphere, tau_fraction=0.05, edges=False, **SPEED)
    assert fraction.tau_m == pytest.approx(0.05 * diagonal)


def test_coverage_of_a_half_seen_box_maps_the_blind_faces():
    """Only the top face (z = +1) is seen: coverage = (top + a tau-wide band) / total area."""
    truth = box((4.0, 4.0, 2.0))
    top = np.flatnonzero(np.isclose(truth.vertices[truth.faces][:, :, 2], 1.0).all(axis=1))
    top_mesh = Mesh(truth.vertices, truth.faces[top])
    points, _ = sample_surface(top_mesh, 400_000, seed=4)
    tau = 0.1
    report = score(points, truth, tau=tau, edges=False, n_truth_samples=50_000,
                   coverage_points=200_000)
    expected = (16.0 + 4 * 4.0 * tau) / area(truth)  # top face + a band tau high on 4 sides
    assert report.coverage == pytest.approx(expected, abs=0.004)
    assert report.recall == pytest.approx(expected, abs=0.01)
    bottom = np.isclose(truth.vertices[truth.faces][:, :, 2], -1.0).all(axis=1)
    assert np.all(report.face_coverage[top] == 1.0)
    assert np.all(report.face_coverage[bottom] == 0.0)
    sides = ~bottom & ~np.isin(np.arange(len(truth.faces)), top)
    assert np.all((report.face_coverage[sides] > 0) & (report.face_coverage[sides] < 0.2))
    assert report.face_coverage.shape == (len(truth.faces),)


def test_normal_consistency(sphere):
    points, faces = sample_surface(sphere, 5000, seed=5)
    a, b, c = (sphere.vertices[sphere.faces[faces, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    assert score(points, sphere, edges=False, **SPEED).normal_consistency is None
    same = score(Cloud(points, normals=-3.0 * normal), sphere, edges=False, **SPEED)
    assert same.normal_consistency == pytest.approx(1.0)
    # Tilt every normal by 60 degrees about an in-plane axis: |cos| = 0.5.
    axis = np.cross(normal, [0.0, 0.0, 1.0]) + np.cross(normal, [1.0, 0.0, 0.0])
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    unit = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    axis -= np.einsum("ij,ij->i", axis, unit)[:, None] * unit
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    tilted = np.cos(np.radians(60)) * unit + np.sin(np.radians(60)) * np.cross(axis, unit)
    assert score(Cloud(points, normals=tilted), sphere, edges=False,
                 **SPEED).normal_consistency == pytest.approx(0.5)


def test_test_mesh_is_sampled_and_scored_exactly(sphere):
    bigger = Mesh(sphere.vertices * 1.01, sphere.faces)
    report = score(bigger, sphere, n_test_samples=3000, edges=False, **SPEED)
    assert report.test_kind == "mesh" and report.n_points == 3000
    expected = brute_force_distance(report.test_points, sphere.vertices, sphere.faces)
    np.testing.assert_allclose(report.accuracy_distances, expected, rtol=1e-9)
    back = brute_force_distance(report.truth_points[:2000], bigger.vertices, bigger.faces)
    np.testing.assert_allclose(report.completeness_distances[:2000], back, rtol=1e-9)
    # Same normals, except near edges where the nearest truth face is the neighbour.
    assert 0.999 < report.normal_consistency < 1.0
    assert 0.09 < report.accuracy_mean_m < 0.1  # the 1 % offset of a 10 m sphere, less the chords
    # A trimesh object works as well as a Mesh.
    same = score(trimesh.Trimesh(bigger.vertices, bigger.faces, process=False), sphere,
                 n_test_samples=3000, edges=False, **SPEED)
    assert same.to_dict() == report.to_dict()


def test_same_seed_same_report_bytes(sphere):
    bigger = (sphere.vertices * 1.02, sphere.faces)
    one = score(bigger, sphere, n_test_samples=4000, seed=11, **SPEED)
    two = score(bigger, sphere, n_test_samples=4000, seed=11, **SPEED)
    other = score(bigger, sphere, n_test_samples=4000, seed=12, **SPEED)
    assert json.dumps(one.to_dict()) == json.dumps(two.to_dict())
    for name, array in one.arrays().items():
        assert array.tobytes() == two.arrays()[name].tobytes(), name
    assert other.accuracy_mean_m != one.accuracy_mean_m


def test_report_dict_has_the_documented_keys(sphere):
    d = score(sphere.vertices, sphere, **SPEED).to_dict()
    for key in ("n_points", "tau_m", "chamfer_m", "hausdorff_m", "precision", "recall",
                "fscore", "coverage", "normal_consistency", "edge_score"):
        assert key in d
    for side in ("accuracy", "completeness"):
        for stat in ("mean", "rms", "median", "p95", "max"):
            assert f"{side}_{stat}_m" in d
    json.dumps(d)  # JSON-ready: no arrays
    assert not any(isinstance(v, np.ndarray) for v in d.values())


def test_km_against_m_warns(sphere):
    with pytest.warns(ScaleMismatchWarning, match=r"differ by 1000x.*probably km against m"):
        score(sphere.vertices / 1000.0, sphere, edges=False, **SPEED)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        score(sphere.vertices * 50.0, sphere, edges=False, **SPEED)  # 50x: no warning


@pytest.mark.parametrize(("test", "kwargs", "match"), [
    (np.zeros((0, 3)), {}, "test is empty"),
    (np.zeros((5, 2)), {}, r"test must be \(n, 3\)"),
    (np.array([[0.0, 0.0, np.nan]]), {}, "test has 1 row.*NaN or Inf"),
    (np.array([[np.inf, 0.0, 0.0]]), {}, "test has 1 row.*NaN or Inf"),
    (Cloud(np.zeros((2, 3)), normals=np.zeros((2, 3))), {}, "test normals has 2 zero vector"),
    ((np.zeros((3, 3)), np.zeros((0, 3), dtype=int)), {}, "test has no faces"),
    (np.zeros((5, 3)), {"tau": -1.0}, "tau must be a finite length > 0"),
    (np.zeros((5, 3)), {"tau": float("nan")}, "tau must be a finite length > 0"),
    (np.zeros((5, 3)), {"tau": 1.0, "tau_fraction": 0.1}, "give tau or tau_fraction"),
    (np.zeros((5, 3)), {"tau_fraction": 0.0}, "tau_fraction must be a finite number > 0"),
    (np.zeros((5, 3)), {"n_truth_samples": 0}, "n_truth_samples must be a positive integer"),
    (np.zeros((5, 3)), {"coverage_points": 2.5}, "coverage_points must be a positive integer"),
    (np.zeros((5, 3)), {"seed": -3}, "seed must be a non-negative integer or None"),
    (np.zeros((5, 3)), {"edge_options": {"k": 2}}, "k must be an integer >= 4"),
    (np.zeros((5, 3)), {}, r"test has 5 points, fewer than the edge metric's k = 16"),
    (np.zeros((50, 3)), {"edge_options": {"radius": 2}}, r"edge_options has unknown key\(s\)"),
    (np.zeros((50, 3)), {"edge_options": {"rule": "magic"}}, "rule must be one of"),
])
def test_bad_input_raises_one_clear_error(sphere, test, kwargs, match):
    with pytest.raises(InputError, match=match):
        score(test, sphere, **kwargs)


def test_cloud_with_mismatched_normals_cannot_be_built():
    # formerly scored and refused there; the one Cloud type refuses it on construction
    with pytest.raises(InputError, match="cloud normals must match its points"):
        Cloud(np.zeros((3, 3)), normals=np.zeros((2, 3)))


@pytest.mark.parametrize(("truth", "match"), [
    ((np.eye(3), np.zeros((0, 3), dtype=int)), "truth has no faces"),
    ((np.eye(3), np.array([[0, 1, 5]])), "truth faces index vertices"),
    ((np.full((3, 3), np.nan), np.array([[0, 1, 2]])), "truth vertices has 3 row"),
    ((np.zeros((3, 3)), np.array([[0, 1, 2]])), "truth has zero total area"),
    (42, "truth must be a Mesh"),
])
def test_bad_truth_raises(truth, match):
    with pytest.raises(InputError, match=match):
        score(np.zeros((5, 3)), truth)


def test_progress_reports_each_stage_once_in_order():
    solid = trimesh.creation.box(extents=(2.0, 1.0, 1.0))
    points = trimesh.sample.sample_surface(solid, 2000, seed=0)[0]
    stages = []
    score(points, (solid.vertices, solid.faces), progress=stages.append, n_truth_samples=5000,
          coverage_points=5000)
    assert stages == ["accuracy", "completeness", "edges"]
    stages.clear()
    score(points, (solid.vertices, solid.faces), progress=stages.append, edges=False,
          n_truth_samples=5000, coverage_points=5000)
    assert stages == ["accuracy", "completeness"]


def test_frames_must_agree(sphere):
    inertial = Cloud(sphere.vertices, frame="inertial")
    with pytest.raises(InputError, match="test is in the inertial frame but truth in the "
                                                "body frame"):
        score(inertial, sphere, edges=False, **SPEED)


@pytest.mark.parametrize("kind", ["cloud", "mesh"])
def test_a_truth_built_once_gives_the_same_reports_as_a_fresh_one(sphere, kind):
    from metrics import Truth

    rng = np.random.default_rng(12)
    if kind == "mesh":
        tests = [(sphere.vertices * s, sphere.faces) for s in (0.98, 1.0, 1.03)]
    else:
        tests = [rng.normal(size=(500, 3)) * 10.0 / np.sqrt(3) for _ in range(3)]
    truth = Truth(sphere)
    for test in tests:
        for options in ({}, {"n_truth_samples": 3000, "seed": 4}):
            reused = score(test, truth, **SPEED | options, edges=False)
            fresh = score(test, sphere, **SPEED | options, edges=False)
            assert reused.to_dict() == fresh.to_dict()
            for name, array in fresh.arrays().items():
                assert np.array_equal(reused.arrays()[name], array), name
    assert len(truth._samples) == 2 and len(truth._lattices) == 1  # built once, reused
    assert len(truth._queries) == 2  # the samples and lattice in Morton order, once per seed
    assert not truth.samples(3000, [4, 1])[0].flags.writeable  # shared: read-only
    assert not truth.queries(3000, [4, 1], SPEED["coverage_points"])[0].flags.writeable


@pytest.mark.parametrize("kind", ["cloud", "mesh"])
def test_unseeded_scores_report_the_truth_samples_they_measured(sphere, kind):
    """seed=None draws fresh truth samples each call: the completeness distances are those of
    the truth points the report holds (one draw per score, kept by a Truth or not)."""
    from metrics import Truth

    test = ((sphere.vertices + np.array([3.0, 0.0, 0.0]), sphere.faces) if kind == "mesh"
            else np.random.default_rng(3).normal(size=(400, 3)) * 6.0)
    for truth in (sphere, Truth(sphere)):
        report = score(test, truth, seed=None, edges=False, n_truth_samples=2000,
                       coverage_points=2000, n_test_samples=2000)
        expected = (brute_force_distance(report.truth_points, *test)
                    if kind == "mesh" else cKDTree(test).query(report.truth_points)[0])
        np.testing.assert_allclose(report.completeness_distances, expected, rtol=1e-9,
                                   atol=1e-12)


def test_copies_of_points_score_as_the_points(sphere):
    """A cloud of 2 x 40,000 copies of two points (a log repeating two strikes) scores as the
    two points: copies change no distance, and the KD-tree holds the two distinct points (a
    tree cannot split copies: they took over a minute before)."""
    two = np.array([[10.0, 0.0, 0.0], [0.0, 10.5, 0.0]])
    copies = score(np.repeat(two, 40_000, axis=0), sphere, edges=False, **SPEED)
    alone = score(two, sphere, edges=False, **SPEED)
    for key in ("completeness_mean_m", "completeness_p95_m", "accuracy_mean_m", "recall",
                "coverage"):
        assert getattr(copies, key) == pytest.approx(getattr(alone, key), rel=1e-12), key
