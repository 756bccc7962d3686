"""score_stream(): the score of a cloud given block by block equals score() of the whole cloud,
its order statistics are exact, and its memory does not grow with the cloud."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
import trimesh
from metrics_reference import as_mesh

from formats.errors import InputError
from metrics import Cloud, Truth, defaults, score
from metrics.score import _RankFinder, score_stream

SPEED = {"n_truth_samples": 5_000, "coverage_points": 5_000}
EXACT = ("accuracy_mean_m", "accuracy_rms_m", "chamfer_m", "normal_consistency")


@pytest.fixture(scope="module")
def sphere():
    return Truth(as_mesh(trimesh.creation.icosphere(3, radius=10.0)))


def noisy_points(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Points within ~0.3 m of the 10 m sphere, some far off, with rough outward normals."""
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    radius = 10.0 + rng.normal(0, 0.1, n)
    radius[rng.random(n) < 0.01] += 5.0   # outliers: a long tail for the 95th percentile
    normals = direction + rng.normal(0, 0.2, (n, 3))
    return direction * radius[:, None], normals


def blocks_of(points, normals, step):
    return lambda: ((points[i:i + step], None if normals is None else normals[i:i + step])
                    for i in range(0, len(points), step))


def assert_same_report(whole, streamed):
    a, b = whole.to_dict(), streamed.to_dict()
    assert a.keys() == b.keys()
    for key, value in a.items():
        if key in EXACT and value is not None:   # sums grouped by block: ~1e-15 apart
            assert b[key] == pytest.approx(value, rel=1e-9, abs=0), key
        else:
            assert b[key] == value, key
    for name, array in whole.arrays().items():
        if name in streamed.arrays():
            assert np.array_equal(streamed.arrays()[name], array), name
    assert streamed.accuracy_distances is None and streamed.test_points is None


@pytest.mark.parametrize("keep", [10**9, 100, 1])   # one pass; radix passes; down to 64 bits
@pytest.mark.parametrize("with_normals", [False, True])
def test_streamed_report_equals_the_whole_clouds(sphere, keep, with_normals, monkeypatch):
    points, normals = noisy_points(6_000, seed=3)
    normals = normals if with_normals else None
    whole = score(Cloud(points, normals=normals), sphere, edges=True, **SPEED)
    monkeypatch.setattr(defaults, "QUANTILE_KEEP", keep)
    monkeypatch.setattr(defaults, "STREAM_BLOCK", 2_500)   # three nearest-distance groups
    monkeypatch.setattr(defaults, "EDGE_SLAB_POINTS", 1_500)   # edge metric: four slabs
    streamed = score_stream(blocks_of(points, normals, 1_000), sphere, edges=True, **SPEED)
    assert_same_report(whole, streamed)
    assert streamed.accuracy_median_m == whole.accuracy_median_m   # exact order statistics
    assert streamed.accuracy_p95_m == whole.accuracy_p95_m


@pytest.mark.parametrize("values", [
    np.zeros(1000),                                            # one value: refined to 64 bits
    np.r_[np.zeros(500), np.full(500, 2.5)],                   # two values, ranks at the seam
    np.random.default_rng(0).lognormal(0, 3, 5001),            # spans many binades
    np.random.default_rng(1).uniform(1.0, 1.0 + 1e-12, 777),  # one top-bits bin
    np.array([3.0]),
    np.array([7.0, 1.0]),
])
@pytest.mark.parametrize("keep", [1, 10, 10**9])
def test_rank_finder_gives_numpys_percentiles(values, keep, monkeypatch):
    monkeypatch.setattr(defaults, "QUANTILE_KEEP", keep)
    finder = _RankFinder()
    blocks = np.array_split(values, 7)
    for block in blocks:
        finder.first_pass(block)
    q = [0, 1, 50, 95, 99.9, 100]
    got = finder.percentiles(len(values), q, lambda: iter(blocks))
    assert got == [float(v) for v in np.percentile(values, q)]


def test_errors_number_rows_across_blocks(sphere):
    points, _ = noisy_points(3_000, seed=4)
    points[2_345] = np.nan
    with pytest.raises(InputError, match=r"^test x points has 1 row\(s\) with NaN or Inf, "
                                                r"first at row 2345$"):
        score_stream(blocks_of(points, None, 1_000), sphere, name="test x", **SPEED)
    with pytest.raises(InputError, match=r"^test x points is empty \(0 rows\)$"):
        score_stream(lambda: iter([np.zeros((0, 3))]), sphere, name="test x", **SPEED)
    with pytest.raises(InputError, match="fewer than the edge metric's k = 16"):
        score_stream(blocks_of(points[:10], None, 4), sphere, **SPEED)
    with pytest.raises(InputError, match="test is in the inertial frame but truth in "
                                                "the body frame"):
        score_stream(blocks_of(points, None, 1_000), sphere, frame="inertial", **SPEED)


def test_a_stream_that_changes_between_passes_is_refused(sphere, monkeypatch):
    monkeypatch.setattr(defaults, "QUANTILE_KEEP", 10)   # the median needs a second pass
    points, _ = noisy_points(3_000, seed=5)
    calls = []

    def blocks():
        calls.append(1)
        return iter([points] if len(calls) == 1 else [points[:-1]])
    with pytest.raises(InputError, match="gave 2999 points on a second pass, 3000 on the "
                                                "first: it changed while it was scored"):
        score_stream(blocks, sphere, edges=False, **SPEED)


def _peak_bytes(n_blocks: int, sphere, edges: bool = False) -> int:
    """tracemalloc's peak (numpy's allocations) of a stream of ``n_blocks`` generated blocks."""
    def blocks():
        for i in range(n_blocks):
            yield noisy_points(20_000, seed=100 + i)[0]
    tracemalloc.start()
    try:
        report = score_stream(blocks, sphere, edges=edges, **SPEED)
        assert (report.edge is not None) == edges
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_memory_does_not_grow_with_the_stream(sphere, monkeypatch):
    monkeypatch.setattr(defaults, "QUANTILE_KEEP", 50_000)   # the 1x stream needs 2 passes too
    monkeypatch.setattr(defaults, "STREAM_BLOCK", 20_000)
    score_stream(lambda: iter([noisy_points(100, 0)[0]]), sphere, edges=False, **SPEED)  # warm
    one, four = _peak_bytes(5, sphere), _peak_bytes(20, sphere)   # 100k and 400k points
    # The whole-cloud score of 400k points holds 40 bytes a point more (16 MB): far outside.
    assert four < 1.1 * one, (one, four)


def test_memory_does_not_grow_with_the_stream_with_the_edge_metric(sphere, monkeypatch):
    monkeypatch.setattr(defaults, "QUANTILE_KEEP", 50_000)
    monkeypatch.setattr(defaults, "STREAM_BLOCK", 20_000)
    monkeypatch.setattr(defaults, "EDGE_SLAB_POINTS", 20_000)   # 5 slabs at 1x, 20 at 4x
    score_stream(lambda: iter([noisy_points(100, 0)[0]]), sphere, **SPEED)  # warm
    one, four = _peak_bytes(5, sphere, edges=True), _peak_bytes(20, sphere, edges=True)
    # Gathering the 400k points for the whole-cloud edge metric holds 24 bytes a point (10 MB)
    # and its neighbourhoods far more: far outside.
    assert four < 1.1 * one, (one, four)
