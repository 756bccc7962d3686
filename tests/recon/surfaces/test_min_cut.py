"""The minimum cut of the visibility and Delaunay-balls methods (``_backends.source_side``,
Boykov-Kolmogorov in ``_min_cut``) against scipy's Dinic maximum flow and a breadth-first search
of its residual graph, the cut it replaced."""

import numpy as np
import pytest

from benchmarks.bench_min_cut import dinic_source_side  # the cut this replaced
from recon.surfaces.methods._backends import source_side


def test_of_two_minimum_cuts_the_side_is_the_smallest():
    # s -> a -> t, both of capacity 1: {s} and {s, a} are minimum cuts; a is not reached
    side = source_side(3, np.array([0, 1]), np.array([1, 2]), np.array([1, 1]), 0, 2)
    assert side.tolist() == [True, False, False]


def test_repeated_edges_add_up():
    rows, cols = np.array([0, 0, 1]), np.array([1, 1, 2])
    # two arcs of 1 into a, 2 out of it: both saturate, a is not reached
    assert source_side(3, rows, cols, np.array([1, 1, 2]), 0, 2).tolist() == [True, False, False]
    # 3 out of a: the arcs into a are the cut, and a is not reached either
    assert source_side(3, rows, cols, np.array([1, 1, 3]), 0, 2).tolist() == [True, False, False]
    # 1 out of a: the arc out of a is the cut; a keeps a unit from the source
    assert source_side(3, rows, cols, np.array([1, 1, 1]), 0, 2).tolist() == [True, True, False]


def test_the_cut_behind_two_paths_into_one_node():
    # s -> a -> b -> t and s -> b: b -> t (3) is the only arc every maximum flow saturates, so
    # the source reaches a and b
    rows, cols = np.array([0, 1, 2, 0]), np.array([1, 2, 3, 2])
    side = source_side(4, rows, cols, np.array([5, 5, 3, 5]), 0, 3)
    assert side.tolist() == [True, True, True, False]


@pytest.mark.parametrize("seed", range(6))
def test_agrees_with_dinic_on_random_graphs(seed):
    rng = np.random.default_rng(seed)
    for _ in range(60):
        n = int(rng.integers(3, 80))
        e = int(rng.integers(1, 6 * n))
        # self loops, terminals at either end
        rows, cols = rng.integers(0, n, e), rng.integers(0, n, e)
        top = int(rng.choice([2, 10, 1000, 2**40]))                 # 2**40: sums capped at int32
        capacity = rng.integers(0, top, e)
        source, sink = rng.choice(n, 2, replace=False)
        np.testing.assert_array_equal(
            source_side(n, rows, cols, capacity, int(source), int(sink)),
            dinic_source_side(n, rows, cols, capacity, int(source), int(sink)))


def test_agrees_with_dinic_on_a_grid_with_long_augmenting_paths():
    # a 30 x 30 grid, the source on the left column and the sink on the right, random capacities
    rng = np.random.default_rng(7)
    side = 30
    node = np.arange(side * side).reshape(side, side)
    right = np.stack([node[:, :-1].ravel(), node[:, 1:].ravel()])
    down = np.stack([node[:-1].ravel(), node[1:].ravel()])
    edges = np.concatenate([right, down, right[::-1], down[::-1]], axis=1)
    s, t = side * side, side * side + 1
    rows = np.concatenate([edges[0], np.full(side, s), node[:, -1]])
    cols = np.concatenate([edges[1], node[:, 0], np.full(side, t)])
    capacity = np.concatenate([rng.integers(1, 50, edges.shape[1]), np.full(2 * side, 1000)])
    np.testing.assert_array_equal(source_side(side * side + 2, rows, cols, capacity, s, t),
                                  dinic_source_side(side * side + 2, rows, cols, capacity, s, t))
