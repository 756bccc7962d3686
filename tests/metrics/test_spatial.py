"""The fast forms of the scoring's helpers equal the plain numpy they replace, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from metrics_reference import as_mesh

from metrics import Mesh, MeshDistance, sample_surface
from metrics.distance import _lexicographic_order
from metrics.inputs import face_areas
from metrics.spatial import bounds, morton_order, row_cross, row_norms


def clouds():
    rng = np.random.default_rng(0)
    ties = rng.integers(-2, 3, (600, 3)).astype(float)
    ties[ties == 0] = -0.0  # -0.0 and 0.0 compare equal
    return {"random": rng.normal(size=(5000, 3)) * 1e3 + [4e5, -2e5, 7e4],
            "ties": np.concatenate([ties, np.abs(ties)]),
            "flat": np.column_stack([rng.random(300), rng.random(300), np.zeros(300)]),
            "one": rng.random((1, 3)), "same": np.ones((7, 3))}


def interleaved_code(cell: np.ndarray) -> list[int]:
    """Morton codes bit by bit in Python: bit b of axis a goes to bit 3 b + a."""
    return [sum(((int(c[a]) >> b) & 1) << (3 * b + a) for a in range(3) for b in range(21))
            for c in cell]


@pytest.mark.parametrize("name", ["random", "ties", "flat", "one", "same"])
def test_row_helpers_equal_numpy(name):
    x = clouds()[name]
    y = np.roll(x, 1, axis=0) * 0.7 - 3.0
    lo, hi = bounds(x)
    assert np.array_equal(lo, x.min(axis=0)) and np.array_equal(hi, x.max(axis=0))
    assert np.array_equal(row_norms(x), np.linalg.norm(x, axis=1))
    assert np.array_equal(row_cross(x, y), np.cross(x, y))


@pytest.mark.parametrize("name", ["random", "ties", "flat", "one", "same"])
def test_morton_order_sorts_by_the_interleaved_cell_bits(name):
    points = clouds()[name][:800]
    lo, hi = points.min(axis=0), points.max(axis=0)
    extent = max(float((hi - lo).max()), np.finfo(float).tiny)
    cell = np.minimum((points - lo) / extent * (2**21 - 1), 2**21 - 1).astype(np.int64)
    codes = interleaved_code(cell)
    order = morton_order(points)
    assert sorted(order.tolist()) == list(range(len(points)))
    ordered = [codes[i] for i in order]
    assert ordered == sorted(codes)


@pytest.mark.parametrize("name", ["random", "ties", "flat", "one", "same"])
def test_lexicographic_order_is_the_lexsort(name):
    v = clouds()[name]
    assert np.array_equal(_lexicographic_order(v), np.lexsort(v.T[::-1]))


def test_sampling_and_areas_equal_the_plain_formulas():
    """sample_surface looks faces up in sorted key order: the same faces and points as the
    definition (a binary search per key, in draw order)."""
    mesh = as_mesh(trimesh.creation.icosphere(3, radius=10.0))
    mesh = Mesh(mesh.vertices * [1.0, 2.0, 0.5], mesh.faces)
    v, f = mesh.vertices, mesh.faces
    areas = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]),
                                 axis=1)
    assert np.array_equal(face_areas(v, f), areas)
    points, faces = sample_surface(mesh, 5000, seed=9)
    rng = np.random.default_rng(9)
    cumulative = np.cumsum(areas)
    expected = np.minimum(np.searchsorted(cumulative, rng.random(5000) * cumulative[-1],
                                          side="right"), len(f) - 1)
    r1, r2 = rng.random((2, 5000))
    s = np.sqrt(r1)[:, None]
    tri = f[expected]
    assert np.array_equal(faces, expected)
    assert np.array_equal(points, (1.0 - s) * v[tri[:, 0]] + (s * (1.0 - r2[:, None]))
                          * v[tri[:, 1]] + (s * r2[:, None]) * v[tri[:, 2]])


def test_presorted_query_is_the_query_in_that_order():
    mesh = as_mesh(trimesh.creation.icosphere(3, radius=10.0))
    points = np.random.default_rng(4).normal(size=(3000, 3)) * 8.0
    md = MeshDistance(mesh)
    order = morton_order(points)
    unsorted = md.query(points)
    presorted = md.query(points[order], presorted=True)
    for a, b in zip(unsorted, presorted, strict=True):
        assert np.array_equal(a[order], b)
