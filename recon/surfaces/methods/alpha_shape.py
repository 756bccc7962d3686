"""``alpha-shape``: Open3D's alpha shape (Edelsbrunner and Mücke 1994).

The boundary of the union of the Delaunay tetrahedra whose circumsphere radius is below
``alpha``. It ignores normals and interpolates the points. Open3D keeps tetrahedra only, so on
noise-free samples of smooth surfaces, whose near-surface tetrahedra are flat slivers with the
surface's curvature radius as circumradius (every tetrahedron of points on a sphere has the
sphere as circumsphere), small alphas return nothing; on noisy clouds they leave a second, inner
layer. Hence the automatic alpha: the smallest of 1.5, 3, 6, ... x spacing whose shape uses at
least ``min_used`` of the points as vertices (a surface through the samples uses nearly all of
them). The Delaunay step runs in qhull, which can crash the process (a failure reported
upstream) and stalls on noise-free planar or spherical samples unless they are perturbed first
(``_backends.general_position``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from recon.surfaces.methods import Method, MethodInput, Param, register
from recon.surfaces.methods._backends import (
    general_position,
    open3d_arrays,
    open3d_cloud,
    with_triangles,
)

# First automatic alpha, in spacings, doubled each step: 3 x the nearest-neighbour distance (the
# alpha measured on the paper's ellipsoid: 0.29 m Chamfer at 5e4 points; docs/decisions.md), which
# is ~1.5 x our area spacing on uniform samples.
AUTO_START = 1.5


def run(cloud: MethodInput, *, alpha: float | None, min_used: float
        ) -> tuple[np.ndarray, np.ndarray]:
    """Alpha-shape boundary of the points.

    Parameters
    ----------
    cloud : MethodInput
    alpha : float or None
        Alpha radius in units of ``cloud.spacing``; None picks it (module docstring).
    min_used : float
        Fraction of the points the automatic alpha's shape must use as vertices.

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64
    """
    import open3d as o3d

    points = general_position(cloud.points, cloud.spacing, cloud.seed)
    pcd = open3d_cloud(replace(cloud, points=points))
    tetra, index = o3d.geometry.TetraMesh.create_from_point_cloud(pcd)
    diagonal = float(np.linalg.norm(np.ptp(cloud.points, axis=0)))
    if alpha is None:
        ladder = AUTO_START * 2.0 ** np.arange(64)
        ladder = ladder[: int(np.searchsorted(ladder * cloud.spacing, diagonal)) + 1]
    else:
        ladder = np.array([float(alpha)])
    for factor in ladder:
        mesh = o3d.geometry.TriangleMesh.create_from_point_cloud_alpha_shape(
            pcd, float(factor) * cloud.spacing, tetra, index)
        vertices, faces = open3d_arrays(mesh)
        if alpha is not None or len(vertices) >= min_used * len(cloud.points):
            break
    return with_triangles(vertices, faces,
                          f"alpha-shape: no triangles with alpha = {factor:g} x spacing")


METHOD = register(Method(
    name="alpha-shape", run=run, kind="interpolating", preload=("open3d",),
    summary="Open3D alpha shape; alpha automatic or in multiples of the spacing",
    params={
        # Up to 1000 spacings: the shape is the convex hull long before.
        "alpha": Param(None, float, "alpha radius / spacing (default: automatic)",
                       minimum=0.01, maximum=1000.0),
        # 0.9: a surface through the samples uses nearly every one of them as a vertex; a
        # fraction.
        "min_used": Param(0.9, float, "points the automatic alpha's shape must use",
                          minimum=0.0, maximum=1.0),
    },
    grid=({"alpha": 1.5}, {"alpha": 6.0})))
