"""Points on a mesh's surface: seeded uniform sampling and a deterministic quadrature lattice."""

from __future__ import annotations

import numpy as np

from formats.errors import InputError
from metrics.inputs import Mesh, face_areas


def sample_surface(mesh: Mesh, n: int, *, seed: int | None) -> tuple[np.ndarray, np.ndarray]:
    """Sample ``n`` points uniformly by area on a mesh's surface.

    A face is drawn with probability proportional to its area, then a point uniformly inside it
    (barycentric ``(1 - sqrt(r1), sqrt(r1) (1 - r2), sqrt(r1) r2)`` with ``r1, r2 ~ U[0, 1)``).

    Parameters
    ----------
    mesh : Mesh
        A validated mesh (``inputs.as_mesh``), metres.
    n : int
        Number of points, >= 1.
    seed : int or None
        Seed of ``np.random.default_rng``; the same seed gives the same points, bit for bit.

    Returns
    -------
    points : (n, 3) float64, metres, the mesh's frame
    face_index : (n,) int64, the face each point lies on
    """
    n = _positive_int(n, "n")
    rng = np.random.default_rng(seed)
    cumulative = np.cumsum(face_areas(mesh.vertices, mesh.faces))
    # Looked up in ascending order (numpy's binary search starts from the last key's place:
    # 4x faster than random keys, the sort included), each key's face put back in its place.
    key = rng.random(n) * cumulative[-1]
    ascending = np.argsort(key)
    face_index = np.empty(n, dtype=np.int64)
    face_index[ascending] = np.searchsorted(cumulative, key[ascending], side="right")
    face_index = np.minimum(face_index, len(cumulative) - 1)  # guards r * total == total rounding
    r1, r2 = rng.random((2, n))
    s = np.sqrt(r1)
    tri = np.take(mesh.faces, face_index, axis=0)
    v = mesh.vertices
    points = ((1.0 - s)[:, None] * np.take(v, tri[:, 0], axis=0)
              + (s * (1.0 - r2))[:, None] * np.take(v, tri[:, 1], axis=0)
              + (s * r2)[:, None] * np.take(v, tri[:, 2], axis=0))
    return points, face_index


def subdivision_levels(mesh: Mesh, n_points: int, max_level: int) -> np.ndarray:
    """Per-face subdivision level s of the coverage lattice (``coverage_lattice``).

    s is the smallest integer with ``area_f / s**2 <= total_area / n_points``, clipped to
    ``1..max_level``; the lattice then has about ``n_points + n_faces`` points.

    Returns
    -------
    (n_faces,) int64
    """
    areas = face_areas(mesh.vertices, mesh.faces)
    cell = areas.sum() / _positive_int(n_points, "n_points")
    level = np.ceil(np.sqrt(areas / cell) - 1e-9)
    return np.clip(level, 1, max_level).astype(np.int64)


def _unit_lattice(s: int) -> np.ndarray:
    """Barycentric (v, w) of the centroids of the s**2 congruent sub-triangles of a triangle.

    The triangle is cut by lines parallel to its sides into s**2 copies of itself scaled by 1/s:
    s (s + 1) / 2 upright ones with corners (i, j), (i+1, j), (i, j+1) (in units of 1/s, i + j <=
    s - 1) and s (s - 1) / 2 inverted ones with corners (i+1, j), (i, j+1), (i+1, j+1).

    Returns
    -------
    (s**2, 2) float64, weights of vertices B and C (A's weight is 1 - v - w)
    """
    i, j = np.meshgrid(np.arange(s), np.arange(s), indexing="ij")
    up = (i + j) <= s - 1
    down = (i + j) <= s - 2
    upright = np.column_stack([i[up] + 1.0 / 3.0, j[up] + 1.0 / 3.0])
    inverted = np.column_stack([i[down] + 2.0 / 3.0, j[down] + 2.0 / 3.0])
    return np.concatenate([upright, inverted]) / s


def coverage_lattice(mesh: Mesh, levels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature points for per-face coverage: centroids of each face's equal-area sub-triangles.

    Face f is split into ``levels[f]**2`` congruent sub-triangles; each centroid stands for
    ``area_f / levels[f]**2`` of the surface. A face's covered fraction is then the fraction of its
    centroids that pass a test (midpoint-rule quadrature, exact as the level grows).

    Parameters
    ----------
    mesh : Mesh
    levels : (n_faces,) int, >= 1 (``subdivision_levels``)

    Returns
    -------
    points : (sum(levels**2), 3) float64, metres
    face_index : (sum(levels**2),) int64, sorted: all of face 0's points, then face 1's, ...
    """
    v = mesh.vertices
    a = v[mesh.faces[:, 0]]
    ab = v[mesh.faces[:, 1]] - a
    ac = v[mesh.faces[:, 2]] - a
    chunks_points, chunks_faces = [], []
    for s in np.unique(levels):  # a handful of distinct levels, not a loop over points
        faces = np.flatnonzero(levels == s)
        uv = _unit_lattice(int(s))
        pts = (a[faces, None, :] + uv[None, :, 0:1] * ab[faces, None, :]
               + uv[None, :, 1:2] * ac[faces, None, :])
        chunks_points.append(pts.reshape(-1, 3))
        chunks_faces.append(np.repeat(faces, len(uv)))
    face_index = np.concatenate(chunks_faces)
    order = np.argsort(face_index, kind="stable")
    return np.concatenate(chunks_points)[order], face_index[order]


def _positive_int(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise InputError(f"{name} must be a positive integer, got {value!r}")
    return int(value)
