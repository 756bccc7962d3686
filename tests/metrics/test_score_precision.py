"""Scores sized from the precision they state: agreement with many-sample references, seeding,
the same sample held whole or streamed, and explicit counts keeping the fixed path."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
import trimesh
from metrics_reference import ellipsoid, satellite

from formats.errors import InputError, ParameterError
from metrics import defaults, sample_surface, score
from metrics.inputs import as_mesh
from metrics.precision import KeySample, point_keys, smallest_keys
from metrics.score import Truth, score_stream

# The reference: counts well above what the stated precision needs (its own standard errors
# are in the comparison too). With n_test_samples at the default draw size, a test mesh's
# edge metric runs on the very points the precision-sized score draws, every far one tested.
REFERENCE = {"n_truth_samples": 300_000, "n_test_samples": defaults.TEST_MESH_SAMPLES,
             "coverage_points": 600_000}


def _noisy_cloud(mesh, n: int, noise: float, seed: int, hole=None) -> np.ndarray:
    points = sample_surface(mesh, n, seed=seed)[0]
    points += np.random.default_rng(seed).normal(0.0, noise, points.shape)
    if hole is not None:   # drop the points beyond a plane: a gap in the cover
        points = points[points @ np.asarray(hole[0]) < hole[1]]
    return points


def _bumpy_ellipsoid() -> tuple[np.ndarray, np.ndarray]:
    sphere = trimesh.creation.icosphere(3)
    vertices = np.asarray(sphere.vertices) * (143.75, 86.25, 287.5)
    vertices *= 1 + 0.01 * np.sin(7 * sphere.vertices[:, :1])
    return vertices, np.asarray(sphere.faces)


CASES = {
    "mesh on the ellipsoid": (ellipsoid(4), _bumpy_ellipsoid),
    "noisy cloud of the satellite": (
        satellite(0.3), lambda: _noisy_cloud(satellite(0.3), 60_000, 0.02, 1)),
    "cloud of the ellipsoid with a hole": (
        ellipsoid(4), lambda: _noisy_cloud(ellipsoid(4), 50_000, 0.5, 2,
                                           hole=((0.0, 0.0, 1.0), 200.0))),
}


def _within(a: float, b: float, se_a: float, se_b: float, floor: float = 0.0) -> bool:
    """a and b agree within three standard errors of their difference."""
    return abs(a - b) <= 3 * np.hypot(se_a, se_b) + floor


@pytest.mark.parametrize("case", list(CASES))
def test_precision_score_agrees_with_a_many_sample_reference(case):
    truth_mesh, make_test = CASES[case]
    truth = Truth(truth_mesh)
    test = make_test()
    sized = score(test, truth)
    ref = score(test, truth, **REFERENCE)
    assert sized.target_precision == defaults.PRECISION
    assert ref.target_precision is None
    # The stated precision is met (a pilot's spread is an estimate: 5 % to spare).
    assert sized.chamfer_se_m <= 1.05 * defaults.PRECISION * sized.chamfer_m
    assert sized.fscore_se <= 1.05 * defaults.PRECISION / 2
    assert sized.coverage_se <= defaults.PRECISION / 2
    assert sized.edge.score_se <= defaults.PRECISION / 2
    assert _within(sized.chamfer_m, ref.chamfer_m, sized.chamfer_se_m, ref.chamfer_se_m)
    assert _within(sized.accuracy_mean_m, ref.accuracy_mean_m, sized.accuracy_mean_se_m,
                   ref.accuracy_mean_se_m)
    assert _within(sized.completeness_mean_m, ref.completeness_mean_m,
                   sized.completeness_mean_se_m, ref.completeness_mean_se_m)
    assert _within(sized.precision, ref.precision, sized.precision_se, ref.precision_se)
    assert _within(sized.recall, ref.recall, sized.recall_se, ref.recall_se)
    assert _within(sized.fscore, ref.fscore, sized.fscore_se, ref.fscore_se)
    assert _within(sized.coverage, ref.coverage, sized.coverage_se, ref.coverage_se)
    # The missed-edge rate is exact either way; the false-edge rate is a sample's.
    assert sized.edge.missed_edge_rate == ref.edge.missed_edge_rate
    assert sized.edge.n_far == ref.edge.n_far
    assert sized.edge.n_far_tested < sized.edge.n_far
    assert _within(sized.edge_score, ref.edge_score, sized.edge.score_se, ref.edge.score_se,
                   floor=1e-12)
    assert ref.edge.score_se == 0.0


def test_a_cloud_sample_is_smaller_than_the_cloud_and_its_error_says_so():
    truth = ellipsoid(4)
    cloud = _noisy_cloud(truth, 80_000, 3.0, 3)   # some points beyond tau (6.7 m)
    sized = score(cloud, truth, edges=False)
    assert defaults.PILOT_SAMPLES <= sized.n_points < len(cloud)
    assert 0 < sized.accuracy_mean_se_m
    assert 0 < sized.precision_se
    # Every point: no sampling error on the accuracy side.
    whole = score(cloud[:5000], truth, edges=False)
    assert whole.n_points == 5000
    assert whole.accuracy_mean_se_m == 0.0 and whole.precision_se == 0.0


def test_same_seed_same_report_and_another_seed_another():
    truth = satellite(0.3)
    cloud = _noisy_cloud(truth, 30_000, 0.02, 4)
    first, again = score(cloud, truth), score(cloud, truth)
    assert first.to_dict() == again.to_dict()
    assert np.array_equal(first.accuracy_distances, again.accuracy_distances)
    other = score(cloud, truth, seed=5)
    assert other.chamfer_m != first.chamfer_m


def test_a_streamed_cloud_gives_the_report_of_the_whole_cloud():
    truth = satellite(0.3)
    cloud = _noisy_cloud(truth, 40_000, 0.02, 6)
    whole = score(cloud, truth)
    step = 7_000
    streamed = score_stream(lambda: (cloud[i:i + step] for i in range(0, len(cloud), step)),
                            truth)
    assert streamed.to_dict() == whole.to_dict()


def test_key_sample_of_a_stream_is_the_smallest_keys_of_the_whole():
    rng = np.random.default_rng(7)
    points = rng.normal(size=(50_000, 3))
    points[1000:1100] = points[:100]   # copies: equal keys, taken in row order
    keys = point_keys(points, 3, 1)
    assert np.all((keys >= 0) & (keys < 1))
    assert 0.45 < keys.mean() < 0.55
    # A function of the coordinates and the seed only.
    assert np.array_equal(point_keys(points[::-1], 3, 1), keys[::-1])
    assert not np.array_equal(point_keys(points, 4, 1), keys)
    sample = KeySample(3000, 3, 1)
    for lo in range(0, len(points), 4_321):
        sample.add(points[lo:lo + 4_321], None)
    kept, normals = sample.sample()
    assert normals is None
    assert np.array_equal(kept, points[smallest_keys(keys, 3000)])


def test_explicit_counts_keep_the_fixed_path():
    truth = ellipsoid(3)
    cloud = _noisy_cloud(truth, 20_000, 0.5, 8)
    fixed = score(cloud, truth, n_truth_samples=5000, coverage_points=5000)
    assert fixed.target_precision is None
    assert fixed.n_points == len(cloud) and fixed.n_truth_samples == 5000
    assert fixed.edge.n_far_tested == fixed.edge.n_far
    assert fixed.edge.is_edge is not None
    with pytest.raises(InputError, match="precision or sample counts"):
        score(cloud, truth, n_truth_samples=5000, precision=0.02)
    with pytest.raises(InputError, match="precision must be"):
        score(cloud, truth, precision=0.0)


def test_a_lattice_beyond_the_memory_budget_is_refused_before_it_is_built(monkeypatch):
    """A precision of 1e-9 asks 512**2 coverage points on every face (20 GB on 320 faces):
    refused at once, naming the argument, before the lattice exists."""
    def never(*args):
        raise AssertionError("the coverage lattice was built")

    monkeypatch.setattr(importlib.import_module("metrics.score"), "coverage_lattice", never)
    truth = ellipsoid(2)
    cloud = sample_surface(truth, 2000, seed=0)[0]
    with pytest.raises(ParameterError, match=r"^precision 1e-09 asks a coverage lattice of "
                                             r"83,886,080 points on the truth's 320 faces, "
                                             r"about 20\.1 GB of memory, more than the 4\.3 GB "
                                             r"allowed; give at least 0\.00048$") as info:
        score(cloud, truth, precision=1e-9, edges=False)
    assert info.value.argument == "precision"
    with pytest.raises(ParameterError, match=r"^coverage_points 1,000,000,000 asks") as info:
        score_stream(lambda: [cloud], truth, coverage_points=10**9, edges=False)
    assert info.value.argument == "coverage_points"


def test_the_values_a_lattice_refusal_suggests_fit(monkeypatch):
    monkeypatch.setattr(defaults, "COVERAGE_MAX_BYTES", 20_000 * defaults.LATTICE_BYTES_PER_POINT)
    truth = Truth(ellipsoid(2))
    cloud = sample_surface(truth.mesh, 2000, seed=0)[0]
    with pytest.raises(ParameterError, match=r"^precision 0\.001 asks .* give at least") as info:
        score(cloud, truth, precision=1e-3, edges=False)
    least = float(str(info.value).rsplit(" ", 1)[1])
    assert score(cloud, truth, precision=least, edges=False).target_precision == least
    with pytest.raises(ParameterError, match=r"^coverage_points 100,000 asks .* give at "
                                             r"most") as info:
        score(cloud, truth, coverage_points=100_000, edges=False)
    most = int(str(info.value).rsplit(" ", 1)[1].replace(",", ""))
    assert len(score(cloud, truth, coverage_points=most, n_truth_samples=1000,
                     edges=False).face_coverage) == 320


def test_a_coarser_precision_takes_fewer_samples():
    truth = Truth(ellipsoid(4))
    test = _bumpy_ellipsoid()
    fine, coarse = score(test, truth, edges=False), score(test, truth, edges=False,
                                                          precision=0.05)
    assert coarse.target_precision == 0.05
    assert coarse.n_truth_samples <= fine.n_truth_samples
    assert coarse.chamfer_se_m <= 1.05 * 0.05 * coarse.chamfer_m


def test_within_is_the_bounded_nearest_query():
    from metrics.spatial import PointIndex, query_distance, within

    rng = np.random.default_rng(9)
    points = rng.uniform(0, 10, size=(3000, 3))
    queries = np.concatenate([rng.uniform(-1, 11, size=(20_000, 3)),
                              points[:500] + 0.3,        # near a point, maybe another cell
                              np.round(points[:500], 1)])   # on cell-like round numbers
    index = PointIndex(points)
    for t in (0.05, 0.3, 1.0):
        want = query_distance(index, queries, upper=t) <= t
        assert np.array_equal(within(index, queries, t), want)
        assert 0 < want.sum() < len(want)


def test_samples_beyond_the_first_draw_come_from_further_seeded_draws(monkeypatch):
    monkeypatch.setattr(defaults, "TEST_MESH_SAMPLES", 3000)
    monkeypatch.setattr(defaults, "TRUTH_SAMPLES", 3000)
    monkeypatch.setattr(defaults, "PILOT_SAMPLES", 1000)
    truth = ellipsoid(3)
    test = _bumpy_ellipsoid()
    first = score(test, truth, edges=False, precision=0.004)
    assert first.n_points > 3000 and first.n_truth_samples > 3000
    assert len(first.test_points) == first.n_points == len(first.accuracy_distances)
    assert len(first.truth_points) == first.n_truth_samples
    # The first draw is a prefix of what was scored.
    assert np.array_equal(first.test_points[:3000],
                          sample_surface(as_mesh(test, "test"), 3000, seed=0)[0])
    again = score(test, truth, edges=False, precision=0.004)
    assert np.array_equal(first.test_points, again.test_points)
    assert first.to_dict() == again.to_dict()
