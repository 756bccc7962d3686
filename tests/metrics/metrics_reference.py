"""Independent reference implementations the metrics tests compare against.

Deliberately written differently from metrics/: point-to-triangle distance by plane projection
with same-side tests plus the three segment distances, over *all* triangles (no acceleration),
and plain shapes built with trimesh.
"""

from __future__ import annotations

import numpy as np
import trimesh

from metrics.inputs import Mesh
from tests.conftest import SHARED_MESHES as MESHES


def brute_force_distance(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray,
                         chunk: int = 64, skip_degenerate: bool = False) -> np.ndarray:
    """Exact unsigned distance from each point to the union of all triangles, float64.

    ``skip_degenerate`` drops zero-area triangles (doubled area below 1e-14 of the squared
    bounding-box diagonal), the convention of metrics.distance.
    """
    if skip_degenerate:
        a, b, c = (vertices[faces[:, i]] for i in range(3))
        size = np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))
        faces = faces[np.linalg.norm(np.cross(b - a, c - a), axis=1) > 1e-14 * size**2]
    a, b, c = (vertices[faces[:, i]][None] for i in range(3))  # (1, m, 3)
    normal = np.cross(b - a, c - a)
    length = np.linalg.norm(normal, axis=-1, keepdims=True)
    unit = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)
    out = np.empty(len(points))
    for lo in range(0, len(points), chunk):
        p = points[lo:lo + chunk, None, :]  # (c, 1, 3)
        best = np.minimum(np.minimum(_segment(p, a, b), _segment(p, b, c)), _segment(p, c, a))
        h = np.sum((p - a) * unit, axis=-1)
        q = p - h[..., None] * unit
        inside = ((np.sum(np.cross(b - a, q - a) * normal, axis=-1) >= 0)
                  & (np.sum(np.cross(c - b, q - b) * normal, axis=-1) >= 0)
                  & (np.sum(np.cross(a - c, q - c) * normal, axis=-1) >= 0)
                  & (length[..., 0] > 0))
        best = np.where(inside, np.minimum(best, np.abs(h)), best)
        out[lo:lo + chunk] = best.min(axis=1)
    return out


def _segment(p, s, e):
    d = e - s
    dd = np.sum(d * d, axis=-1)
    t = np.clip(np.sum((p - s) * d, axis=-1) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    return np.linalg.norm(p - (s + t[..., None] * d), axis=-1)


def as_mesh(tm: trimesh.Trimesh) -> Mesh:
    return Mesh(np.asarray(tm.vertices, dtype=np.float64), np.asarray(tm.faces, dtype=np.int64))


def box(extents=(10.0, 6.0, 4.0)) -> Mesh:
    return as_mesh(trimesh.creation.box(extents))


def ellipsoid(subdivisions: int = 4, axes=(143.75, 86.25, 287.5)) -> Mesh:
    """The paper's tri-axial ellipsoid (semi-axes in metres) as a triangulated icosphere."""
    sphere = trimesh.creation.icosphere(subdivisions)
    return Mesh(np.asarray(sphere.vertices) * np.asarray(axes), np.asarray(sphere.faces))


def satellite(panel_thickness: float | None, panel=(7.5, 3.0)) -> Mesh:
    """A 5 m cube bus with two solar panels along x (none when ``panel_thickness`` is None)."""
    parts = [trimesh.creation.box((5.0, 5.0, 5.0))]
    if panel_thickness is not None:
        for sign in (-1.0, 1.0):
            wing = trimesh.creation.box((panel[0], panel[1], panel_thickness))
            wing.apply_translation((sign * (2.5 + panel[0] / 2), 0.0, 0.0))
            parts.append(wing)
    return as_mesh(trimesh.util.concatenate(parts))


def load(name: str) -> Mesh:
    return as_mesh(trimesh.load(MESHES / name, process=False))


def area(mesh: Mesh) -> float:
    return float(trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).area)
