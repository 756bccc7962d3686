"""Validation of the geometry the metrics take: ``formats.geometry``'s ``Cloud`` and ``Mesh``.

A test reconstruction is a point cloud (``Cloud``, or a bare ``(n, 3)`` array) or a triangle mesh
(``Mesh``, a ``(vertices, faces)`` tuple, or any object with ``vertices`` and ``faces`` attributes
such as ``trimesh.Trimesh``). A truth is always a triangle mesh. Everything is in metres, in one
frame (for recon, the target body frame B).
"""

from __future__ import annotations

import numpy as np

from formats.errors import InputError
from formats.geometry import Cloud, Mesh, xyz_array
from metrics.spatial import bounds, row_cross, row_norms

# Largest coordinate accepted [m], about 7 au: beyond any target imaged from nearby. The
# distance queries run in float32 (Open3D) and square coordinates: at 1e20 m the square
# overflows and no closest triangle is found.
MAX_COORDINATE_M = 1e12


def _finite_xyz(array, what: str, *, first_row: int = 0, allow_empty: bool = False
                ) -> np.ndarray:
    """``array`` as a C-contiguous (n, 3) float64 array of finite values within
    ``MAX_COORDINATE_M`` of the origin, n >= 1 (or 0 with ``allow_empty``). Rows are numbered
    from ``first_row`` in messages (a block of a streamed input)."""
    arr = xyz_array(array, what, error=InputError)
    if len(arr) == 0:
        if allow_empty:
            return np.ascontiguousarray(arr)
        raise InputError(f"{what} is empty (0 rows)")
    if not np.isfinite(arr).all():  # one flat reduction; rows only when something is wrong
        bad = ~np.isfinite(arr).all(axis=1)
        raise InputError(f"{what} has {int(bad.sum())} row(s) with NaN or Inf, first at "
                                f"row {first_row + int(np.argmax(bad))}")
    if np.abs(arr).max() > MAX_COORDINATE_M:
        bad = (np.abs(arr) > MAX_COORDINATE_M).any(axis=1)
        raise InputError(f"{what} has {int(bad.sum())} row(s) farther than "
                                f"{MAX_COORDINATE_M:g} m from the origin, first at row "
                                f"{first_row + int(np.argmax(bad))} "
                                f"({np.abs(arr[np.argmax(bad)]).max():g} m)")
    return np.ascontiguousarray(arr)


def as_points(points, name: str = "points") -> np.ndarray:
    """Validate a point array.

    Parameters
    ----------
    points : array-like (n, 3), metres
    name : str
        Argument name used in error messages.

    Returns
    -------
    (n, 3) float64, C-contiguous

    Raises
    ------
    InputError
        Wrong shape, no points, or NaN/Inf coordinates.
    """
    return _finite_xyz(points, name)


def as_cloud(cloud, name: str = "cloud", *, first_row: int = 0, allow_empty: bool = False
             ) -> Cloud:
    """Validate a ``Cloud`` or an (n, 3) array; normals are checked and scaled to unit length.

    ``first_row`` numbers the rows in messages (a block of a streamed cloud starting there);
    ``allow_empty`` accepts a block of no points.
    """
    rows = {"first_row": first_row, "allow_empty": allow_empty}
    if isinstance(cloud, Cloud):
        points = _finite_xyz(cloud.points, f"{name} points", **rows)
        normals = cloud.normals
    else:
        points = _finite_xyz(cloud, name, **rows)
        normals = None
    if normals is not None:
        normals = _finite_xyz(normals, f"{name} normals", **rows)
        if normals.shape != points.shape:
            raise InputError(
                f"{name} normals must match its points, got {normals.shape} for {points.shape}")
        length = np.linalg.norm(normals, axis=1)
        if (length == 0).any():
            raise InputError(f"{name} normals has {int((length == 0).sum())} zero vector(s)")
        normals = normals / length[:, None]
    return Cloud(points, normals=normals, frame=getattr(cloud, "frame", "body"))


def as_mesh(mesh, name: str = "mesh") -> Mesh:
    """Validate a triangle mesh.

    Parameters
    ----------
    mesh : Mesh, (vertices, faces) tuple, or object with ``vertices`` and ``faces`` attributes
        vertices (n, 3) metres; faces (m, 3) integer rows of vertices.
    name : str
        Argument name used in error messages.

    Returns
    -------
    Mesh
        vertices (n, 3) float64 and faces (m, 3) int64, both C-contiguous.

    Raises
    ------
    InputError
        Wrong shapes, no faces, NaN/Inf vertices, non-integer or out-of-range face indices, or zero
        total area.
    """
    if isinstance(mesh, tuple | list) and len(mesh) == 2:
        vertices, faces = mesh
    elif hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        vertices, faces = mesh.vertices, mesh.faces
    else:
        raise InputError(
            f"{name} must be a Mesh, a (vertices, faces) tuple or an object with vertices and "
            f"faces, got {type(mesh).__name__}")
    vertices = _finite_xyz(vertices, f"{name} vertices")
    faces_arr = np.asarray(faces)
    if faces_arr.size == 0:
        raise InputError(f"{name} has no faces")
    if faces_arr.ndim != 2 or faces_arr.shape[1] != 3:
        raise InputError(f"{name} faces must be (m, 3), got shape {faces_arr.shape}")
    if not np.issubdtype(faces_arr.dtype, np.integer):
        raise InputError(f"{name} faces must be integers, got dtype {faces_arr.dtype}")
    lo, hi = int(faces_arr.min()), int(faces_arr.max())
    if lo < 0 or hi >= len(vertices):
        raise InputError(
            f"{name} faces index vertices {lo}..{hi}, outside 0..{len(vertices) - 1}")
    faces_arr = np.ascontiguousarray(faces_arr, dtype=np.int64)
    if not face_areas(vertices, faces_arr).sum() > 0:
        raise InputError(f"{name} has zero total area (all faces degenerate)")
    return Mesh(vertices, faces_arr, frame=getattr(mesh, "frame", "body"))


def as_test(test, name: str = "test") -> Cloud | Mesh:
    """Validate a test reconstruction: a ``Cloud``, an (n, 3) array, or a mesh (see ``as_mesh``).

    A tuple is read as ``(vertices, faces)``; pass a cloud with normals as
    ``Cloud(points, normals=normals)``.
    """
    if isinstance(test, Cloud):
        return as_cloud(test, name)
    if isinstance(test, Mesh | tuple) or (
            hasattr(test, "vertices") and hasattr(test, "faces")):
        return as_mesh(test, name)
    return as_cloud(test, name)


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Areas of the faces.

    Parameters
    ----------
    vertices : (n, 3) float64, metres
    faces : (m, 3) int

    Returns
    -------
    (m,) float64, square metres
    """
    a, b, c = (np.take(vertices, faces[:, i], axis=0) for i in range(3))
    return 0.5 * row_norms(row_cross(b - a, c - a))


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit normals of the faces (right-hand rule on the vertex order); zero for degenerate faces.

    Returns
    -------
    (m, 3) float64
    """
    a, b, c = (np.take(vertices, faces[:, i], axis=0) for i in range(3))
    n = row_cross(b - a, c - a)
    length = row_norms(n)
    out = np.zeros_like(n)
    ok = length > 0
    out[ok] = n[ok] / length[ok, None]
    return out


def bbox_diagonal(points: np.ndarray) -> float:
    """Length of the diagonal of the axis-aligned bounding box of ``points`` (n, 3), metres."""
    lo, hi = bounds(points)
    return float(np.linalg.norm(hi - lo))
