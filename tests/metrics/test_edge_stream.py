"""The edge metric of a streamed cloud (metrics.edges_stream) equals the whole cloud's: same
score, rates and counts, through slabs, halos, set-aside points, ties and duplicate points; and
the canonical k nearest (edges.nearest_k) do not depend on the tree that holds the points."""

from __future__ import annotations

import numpy as np
import pytest
from metrics_reference import box, ellipsoid, satellite

from formats.errors import InputError
from metrics import defaults, sample_surface
from metrics.edges import (
    copy_tree,
    edge_report,
    nearest_k,
    neighbourhood_variation,
    surface_variation,
)
from metrics.edges_stream import EdgeStream
from metrics.spatial import PointIndex


def cloud(mesh, n: int, seed: int, noise: float) -> np.ndarray:
    """n points on a mesh with Gaussian noise (metres) and 1 % of them 3x as far out."""
    points, _ = sample_surface(mesh, n, seed=seed)
    rng = np.random.default_rng(seed + 7)
    points = points + rng.normal(scale=noise, size=points.shape)
    points[rng.random(n) < 0.01] *= 3.0
    return points


def lattice(mesh, spacing: float) -> np.ndarray:
    """Grid points on a box's faces, every point given twice: distances tie everywhere."""
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    axes = [np.arange(a, b + spacing / 2, spacing) for a, b in zip(lo, hi, strict=True)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    on_face = np.isclose(grid, lo).any(axis=1) | np.isclose(grid, hi).any(axis=1)
    return np.repeat(grid[on_face], 2, axis=0)[::-1].copy()


def streamed(points, mesh, step: int, **options):
    stream = EdgeStream(mesh, **options)
    passes = []

    def blocks():
        passes.append(1)
        return (points[i:i + step] for i in range(0, len(points), step))
    for block in blocks():
        stream.add(block)
    return stream.report(blocks), len(passes)


def assert_same(whole, report):
    assert report.to_dict() == whole.to_dict()
    assert np.array_equal(report.edge_found, whole.edge_found)
    assert report.is_edge is None and report.near_edge is None and report.variation is None


CASES = {
    "box": (box(), lambda m: cloud(m, 12_000, 1, 0.01)),
    "ellipsoid": (ellipsoid(3), lambda m: cloud(m, 12_000, 2, 0.5)),
    "satellite": (satellite(0.1), lambda m: cloud(m, 12_000, 3, 0.02)),
    "box lattice": (box(), lambda m: lattice(m, 0.25)),
}


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize(("budget", "halo"), [(10**9, 2.0),    # one slab: no halo at all
                                              (2_000, 2.0),    # slabs, few set aside
                                              (400, 0.05)])    # most set aside, many batches
def test_streamed_edge_report_equals_the_whole_clouds(case, budget, halo, monkeypatch):
    mesh, make = CASES[case]
    points = make(mesh)
    whole = edge_report(points, mesh)
    assert 0 < whole.n_edge_points < len(points)
    monkeypatch.setattr(defaults, "EDGE_SLAB_POINTS", budget)
    monkeypatch.setattr(defaults, "EDGE_HALO_RADII", halo)
    report, passes = streamed(points, mesh, 1_000)
    assert_same(whole, report)
    if budget < 10**9:
        assert passes > len(points) / budget + 1   # slabs and batches of set-aside points
    else:
        assert passes == 1   # held from the first pass


@pytest.mark.parametrize("options", [{"rule": "pauly"}, {"variant": "feature", "k": 8},
                                     {"tolerance_fraction": 0.03, "threshold": 0.001}])
def test_options_reach_the_streamed_metric(options, monkeypatch):
    mesh = satellite(0.1)
    points = cloud(mesh, 6_000, 4, 0.02)
    monkeypatch.setattr(defaults, "EDGE_SLAB_POINTS", 1_000)
    assert_same(edge_report(points, mesh, **options), streamed(points, mesh, 700, **options)[0])


def test_a_cloud_in_one_bin_and_one_point_per_block(monkeypatch):
    """Every point in one slab-bin (a slab over budget), blocks of one point."""
    mesh = box()
    points = cloud(mesh, 600, 5, 0.01)
    points[:, 0] = 0.001 * np.round(points[:, 0], 3)   # a 1 cm sliver across x, the long axis
    monkeypatch.setattr(defaults, "EDGE_SLAB_POINTS", 50)
    assert_same(edge_report(points, mesh), streamed(points, mesh, 1)[0])


def test_a_log_repeating_two_points_scores_the_same(monkeypatch):
    """Copies of two points: every neighbourhood ties at distance 0, which nearest_k settles
    without asking for every copy. A KD-tree cannot split copies (one leaf holds them all, so
    they cost each query their number): the trees hold the two distinct points, 2 x 40,000
    copies take a second (over a minute before)."""
    mesh = box()
    points = np.repeat(np.array([[1.0, 0.5, 0.2], [-2.0, 1.0, 0.0]]), 40_000, axis=0)
    tree, copies = copy_tree(points)
    assert tree.n == 2 and copies.tolist() in ([40_000, 40_000],)
    monkeypatch.setattr(defaults, "EDGE_SLAB_POINTS", 3_000)
    whole = edge_report(points, mesh)
    assert whole.n_edge_points == 0
    assert_same(whole, streamed(points, mesh, 2_000)[0])


def test_fewer_points_than_k_and_a_changing_stream_are_refused(monkeypatch):
    monkeypatch.setattr(defaults, "EDGE_SLAB_POINTS", 50)   # else held: no second pass
    mesh = box()
    points = cloud(mesh, 100, 6, 0.01)
    stream = EdgeStream(mesh)
    stream.add(points[:10])
    with pytest.raises(InputError, match="points has 10 rows, fewer than k = 16"):
        stream.report(lambda: iter([points[:10]]))
    stream = EdgeStream(mesh)
    stream.add(points)
    with pytest.raises(InputError, match="gave 99 points on a second pass, 100 on the "
                                                "first: it changed while it was scored"):
        stream.report(lambda: iter([points[:-1]]))


def canonical_brute_force(data: np.ndarray, queries: np.ndarray, k: int):
    """k nearest by sorting every point by (distance, x, y, z)."""
    dist = np.sqrt(((queries[:, None, :] - data[None, :, :]) ** 2).sum(axis=2))
    keys = np.broadcast_to(data.T[:, None, :], (3, len(queries), len(data)))
    order = np.lexsort((keys[2], keys[1], keys[0], dist), axis=-1)[:, :k]
    return np.take_along_axis(dist, order, axis=1), data[order]


@pytest.mark.parametrize("k", [4, 16])
def test_nearest_k_is_canonical_on_a_lattice_with_copies(k):
    """Integer lattice points (exact distances, ties everywhere), each given 1-3 times, in two
    orders and in a subset: the neighbours are the brute-force canonical ones."""
    rng = np.random.default_rng(0)
    grid = np.stack(np.meshgrid(*[np.arange(6.0)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    data = np.repeat(grid, rng.integers(1, 4, len(grid)), axis=0)
    queries = grid[rng.choice(len(grid), 60, replace=False)] + np.array([0.0, 0.0, 0.5])
    want_dist, want_near = canonical_brute_force(data, queries, k)
    for points in (data, data[rng.permutation(len(data))], data[::-1]):
        dist, idx = nearest_k(PointIndex(points), queries, k)
        assert np.array_equal(dist, want_dist)
        assert np.array_equal(points[idx], want_near)
        tree, copies = copy_tree(points)   # the distinct points, with their copies counted
        assert tree.n == len(grid) and copies.sum() == len(data)
        dist, idx = nearest_k(tree, queries, k, copies)
        assert np.array_equal(dist, want_dist)
        assert np.array_equal(tree.data[idx], want_near)
    few = data[:k]   # exactly k points: every point in every neighbourhood
    dist, idx = nearest_k(PointIndex(few), queries, k)
    assert np.array_equal(few[idx], canonical_brute_force(few, queries, k)[1])


def test_surface_variation_counts_copies_as_points():
    """A noisy cloud with copies (1-30 of some points): each point's variation is that of its
    brute-force canonical neighbourhood, copies included, as if no copy were merged."""
    rng = np.random.default_rng(4)
    base = cloud(ellipsoid(2), 800, 8, 0.05)
    points = np.repeat(base, np.where(rng.random(len(base)) < 0.2,
                                      rng.integers(2, 31, len(base)), 1), axis=0)
    points = points[rng.permutation(len(points))]
    variation = surface_variation(points, k=16)
    _, near = canonical_brute_force(points, points, 16)
    offset = np.ascontiguousarray((near - points[:, None, :]).transpose(2, 0, 1))
    sigma, drop = neighbourhood_variation(offset)
    assert np.array_equal(variation.sigma, sigma)
    assert np.array_equal(variation.drop, drop)
