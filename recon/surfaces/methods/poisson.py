"""``poisson``: Open3D's (screened) Poisson reconstruction with low-density trimming.

Poisson (Kazhdan and Hoppe 2013) solves for an indicator function whose gradient matches the
oriented normals and extracts its level set on an octree of ``depth`` levels. It always returns a
closed surface, so where the points stop (an unseen side) it invents a smooth "blob"; those
vertices have low sampling density. Trimming removes every vertex whose density is more than
``trim`` below the median density (the density is Open3D's per-vertex estimate, on a log2 scale
of samples per octree node; measured on a half-observed sphere, ``trim = 1`` cuts the invented
cap and keeps the observed part to within 0.6% of the radius).

The solver runs ``OMP_NUM_THREADS`` threads (default 1): with several, Open3D's sums run in a
varying order and the same input gives meshes that differ in the last bits (measured), against
"same seed, same bytes".
"""

from __future__ import annotations

import math
import os

import numpy as np

from formats.errors import MethodFailed
from recon.surfaces.methods import Method, MethodInput, Param, register
from recon.surfaces.methods._backends import open3d_arrays

# Deepest octree accepted (Poisson and screened Poisson). A depth-d octree fills its finest level
# on a surface with about 4**d samples (4**14 = 2.7e8, beyond any cloud recon makes): deeper
# levels add memory, not detail. Open3D's Poisson on 20,000 points of a unit sphere peaked at
# 0.38 GB at depth 10, 0.63 GB at 12 and 0.92 GB at 14 (docs/decisions.md); depth 100 ran out of
# memory (23 GB) before returning.
MAX_DEPTH = 14


def trim_low_density(vertices: np.ndarray, faces: np.ndarray, density: np.ndarray, trim: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Drop faces touching a vertex whose density is below ``median(density) - trim``.

    Parameters
    ----------
    vertices : (v, 3) float64
    faces : (f, 3) int64
    density : (v,) float64, log2 samples per node (Poisson's per-vertex estimate)
    trim : float
        Allowed drop below the median; ``inf`` keeps everything.
    """
    if not np.isfinite(trim):
        return vertices, faces
    low = density < np.median(density) - trim
    return vertices, faces[~low[faces].any(axis=1)]


def solve(points: np.ndarray, normals: np.ndarray, *, depth: int, scale: float,
          linear_fit: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Open3D's Poisson surface of oriented points, untrimmed, on ``OMP_NUM_THREADS`` threads
    (module docstring).

    Parameters
    ----------
    points : (n, 3) float64, metres, body frame
    normals : (n, 3) float64, unit, outward
    depth, scale, linear_fit
        As ``run``'s.

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64
    density : (v,) float64, log2 samples per octree node
    """
    import open3d as o3d

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.normals = o3d.utility.Vector3dVector(normals)
    mesh, density = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
        cloud, depth=int(depth), scale=float(scale), linear_fit=bool(linear_fit),
        n_threads=max(1, int(os.environ.get("OMP_NUM_THREADS", "1"))))
    vertices, faces = open3d_arrays(mesh)
    return vertices, faces, np.asarray(density)


def run(cloud: MethodInput, *, depth: int, scale: float, trim: float, linear_fit: bool
        ) -> tuple[np.ndarray, np.ndarray]:
    """Poisson surface of the oriented points, trimmed where the data are sparse.

    Parameters
    ----------
    cloud : MethodInput
    depth : int
        Octree depth: the grid has up to ``2**depth`` cells along the bounding box.
    scale : float
        Ratio of the reconstruction cube to the points' bounding cube.
    trim : float
        Density drop (log2 units) below the median at which vertices are removed.
    linear_fit : bool
        Place iso-vertices by linear interpolation (sharper, noisier).

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64
    """
    vertices, faces, density = solve(cloud.points, cloud.normals, depth=depth, scale=scale,
                                     linear_fit=linear_fit)
    if len(faces) == 0:
        raise MethodFailed("poisson: produced no triangles")
    return trim_low_density(vertices, faces, density, trim)


METHOD = register(Method(
    name="poisson", run=run, kind="smooth", preload=("open3d",),
    summary="Open3D Poisson reconstruction, low-density vertices trimmed",
    params={
        # depth 8: best Chamfer at 5e4-2e5 points of the paper's ellipsoid with 0.3 m noise
        # (0.092 / 0.058 m; depth 10 fits the noise there: 0.094 / 0.089 m; docs/decisions.md,
        # "Measurements behind the defaults").
        "depth": Param(8, int, "octree depth (grid of up to 2**depth cells)", minimum=1,
                       maximum=MAX_DEPTH),
        # 1.1: Kazhdan's and Open3D's default; at 4 the points span a quarter of the cube and
        # three quarters of the depth's resolution are spent on empty space.
        "scale": Param(1.1, float, "reconstruction cube / bounding cube", minimum=1.0,
                       maximum=4.0),
        # 1.0: see the module docstring (half-sphere measurement); inf keeps every vertex.
        "trim": Param(1.0, float, "density drop below the median that trims a vertex",
                      minimum=0.0, maximum=math.inf),
        "linear_fit": Param(False, bool, "linear interpolation of iso-vertices"),
    },
    grid=({"depth": 6}, {"depth": 7}, {"depth": 9}, {"depth": 10})))
