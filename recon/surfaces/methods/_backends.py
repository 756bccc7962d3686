"""Conversions between ``MethodInput``/mesh arrays and Open3D or pymeshlab objects, and the
check that a method's mesh has triangles."""

from __future__ import annotations

import numpy as np

from recon.surfaces.methods import MethodFailed, MethodInput


def open3d_cloud(cloud: MethodInput):
    """An ``open3d.geometry.PointCloud`` with the cloud's points and oriented normals."""
    import open3d as o3d

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.points))
    pcd.normals = o3d.utility.Vector3dVector(cloud.normals)
    return pcd


def with_triangles(vertices: np.ndarray, faces: np.ndarray, failure: str
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, faces)`` unchanged, unless there are no faces.

    Parameters
    ----------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64
    failure : str
        Message of the ``MethodFailed`` raised when ``faces`` is empty, naming the method and
        the setting that gave nothing (``"ball-pivoting: no triangles with radii [...] m"``).

    Returns
    -------
    vertices, faces : as given
    """
    if len(faces) == 0:
        raise MethodFailed(failure)
    return vertices, faces


def open3d_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, faces)`` of an ``open3d.geometry.TriangleMesh``."""
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.triangles, dtype=np.int64)


# Fewest faces that must survive dropping NaN vertices (``meshlab_arrays``): below half, the
# surface is more hole than surface.
MIN_FINITE_FRACTION = 0.5
# Bounds of the automatic marching-cubes resolution (cells along the longest side): below 32 a
# target is a handful of voxels; MeshLab documents values "up to 1000 or even more".
AUTO_RESOLUTION_RANGE = (32, 1000)


def auto_resolution(cloud: MethodInput, resolution: int | None) -> int:
    """``resolution`` or, when None, one grid cell per spacing along the longest side."""
    if resolution is not None:
        return int(resolution)
    extent = float(np.ptp(cloud.points, axis=0).max())
    low, high = AUTO_RESOLUTION_RANGE
    return int(np.clip(np.ceil(extent / cloud.spacing), low, high))


def meshlab_set(cloud: MethodInput, *, quality: np.ndarray | None = None):
    """A ``pymeshlab.MeshSet`` holding the cloud (vertices with normals, no faces) and, when
    given, a per-vertex quality ((n,) float64, e.g. a confidence)."""
    import pymeshlab

    extra = {} if quality is None else {"v_scalar_array": np.ascontiguousarray(quality)}
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.ascontiguousarray(cloud.points),
                               v_normals_matrix=np.ascontiguousarray(cloud.normals), **extra),
                "cloud")
    return ms


def meshlab_arrays(ms, *, method: str, drop_nan: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, faces)`` of the current mesh of a ``pymeshlab.MeshSet``.

    ``drop_nan`` removes the faces touching non-finite vertices (MeshLab's MLS marching cubes
    writes NaN where its projection diverged, on noisy clouds) instead of failing; a mesh that
    is mostly NaN still fails.
    """
    mesh = ms.current_mesh()
    if mesh.face_number() == 0:
        raise MethodFailed(f"{method}: produced no triangles")
    vertices = np.asarray(mesh.vertex_matrix(), dtype=np.float64)
    faces = np.asarray(mesh.face_matrix(), dtype=np.int64)
    if drop_nan:
        bad = ~np.all(np.isfinite(vertices), axis=1)
        if bad.any():
            keep = ~bad[faces].any(axis=1)
            if keep.mean() < MIN_FINITE_FRACTION:
                raise MethodFailed(f"{method}: {bad.mean():.0%} of the vertices are NaN (the MLS "
                                   "projection diverged)")
            faces = faces[keep]
            vertices = np.where(bad[:, None], 0.0, vertices)  # unreferenced now
    return vertices, faces


def meshlab_call(ms, filter_name: str, *, method: str, **params) -> None:
    """Apply a pymeshlab filter, turning its exceptions into ``MethodFailed``."""
    import pymeshlab

    try:
        getattr(ms, filter_name)(**params)
    except pymeshlab.PyMeshLabException as exc:
        raise MethodFailed(f"{method}: pymeshlab {filter_name} failed: "
                           f"{str(exc).strip().splitlines()[0]}") from None
