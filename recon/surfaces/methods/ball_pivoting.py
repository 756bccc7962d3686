"""``ball-pivoting``: Open3D's ball-pivoting algorithm (Bernardini et al. 1999).

A ball of radius ``r`` rolls over the oriented points; every three points it rests on become a
triangle. The mesh interpolates the points (no smoothing) and leaves holes wherever the gaps are
wider than the largest ball. Radii are multiples of the cloud's spacing (``MethodInput.spacing``);
several radii run in turn, small to large, filling what the smaller balls missed. Known failure
mode, reported upstream: runs lasting hours on millions of points, hence the isolation in
``recon compare``.
"""

from __future__ import annotations

import numpy as np

from recon.surfaces.methods import Method, MethodInput, Param, register
from recon.surfaces.methods._backends import open3d_arrays, open3d_cloud, with_triangles


def run(cloud: MethodInput, *, radii: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Ball-pivoting mesh through the points.

    Parameters
    ----------
    cloud : MethodInput
    radii : tuple of float
        Ball radii in units of ``cloud.spacing``, used in increasing order.

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame (the input points)
    faces : (f, 3) int64
    """
    import open3d as o3d

    metres = sorted(float(r) * cloud.spacing for r in radii)
    mesh = o3d.geometry.TriangleMesh.create_from_point_cloud_ball_pivoting(
        open3d_cloud(cloud), o3d.utility.DoubleVector(metres))
    vertices, faces = open3d_arrays(mesh)
    return with_triangles(vertices, faces, f"ball-pivoting: no triangles with radii {metres} m")


METHOD = register(Method(
    name="ball-pivoting", run=run, kind="interpolating", preload=("open3d",),
    summary="Open3D ball pivoting through the points, radii in multiples of the spacing",
    params={
        # 0.5, 1, 2 x spacing: 1, 2, 4 x the nearest-neighbour distance, which ran in 0.8 s on 5e4
        # points (docs/decisions.md); on uniform samples our area spacing is ~2 x that
        # distance.
        # Up to 50 spacings: a ball that wide touches thousands of points per pivot.
        "radii": Param((0.5, 1.0, 2.0), float, "ball radii / spacing", minimum=0.01,
                       maximum=50.0, sequence=True),
    },
    grid=({"radii": (1.0,)}, {"radii": (0.5, 1.0, 2.0, 4.0)})))
