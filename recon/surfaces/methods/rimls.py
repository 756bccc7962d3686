"""``rimls``: robust implicit moving least squares (Öztireli et al. 2009), MeshLab's marching cubes.

The surface is the zero set of a moving-least-squares fit of the oriented points, made robust to
outliers and sharp features by iterative reweighting of both residuals and normals; pymeshlab's
``generate_marching_cubes_rimls`` extracts it on a grid of ``resolution`` cells per side
(default: one per spacing). On noisy clouds MeshLab writes NaN vertices where the projection
diverges; their faces are dropped (the run fails if that is more than half of them).
"""

from __future__ import annotations

import numpy as np

from recon.surfaces.methods import Method, MethodInput, Param, register
from recon.surfaces.methods._backends import (
    auto_resolution,
    meshlab_arrays,
    meshlab_call,
    meshlab_set,
)


def run(cloud: MethodInput, *, filter_scale: float, sigma_n: float, resolution: int
        ) -> tuple[np.ndarray, np.ndarray]:
    """RIMLS surface of the oriented points.

    Parameters
    ----------
    cloud : MethodInput
    filter_scale : float
        Kernel support in units of the local point spacing (MeshLab's "MLS - Filter scale").
    sigma_n : float
        Normal-reweighting width (smaller keeps sharper features).
    resolution : int or None
        Marching-cubes grid cells along the bounding box; None: one cell per spacing
        (``auto_resolution``).

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64
    """
    ms = meshlab_set(cloud)
    meshlab_call(ms, "generate_marching_cubes_rimls", method="rimls",
                 filterscale=float(filter_scale), sigman=float(sigma_n),
                 resolution=auto_resolution(cloud, resolution))
    return meshlab_arrays(ms, method="rimls", drop_nan=True)


METHOD = register(Method(
    name="rimls", run=run, kind="smooth", preload=("pymeshlab",),
    summary="robust implicit MLS (pymeshlab), marching cubes",
    params={
        # 2, 0.75 and 200: MeshLab's defaults (print_filter_parameter_list).
        "filter_scale": Param(2.0, float, "kernel support / local spacing", minimum=0.0),
        "sigma_n": Param(0.75, float, "normal reweighting width", minimum=0.0),
        # None: one cell per spacing; MeshLab's default 200 gave 26x the faces for the same
        # accuracy on a 6000-point unit sphere (0.028% vs 0.016% of the diagonal, Chamfer).
        "resolution": Param(None, int, "marching-cubes cells per side (default: automatic)",
                            minimum=8),
    },
    grid=({"resolution": 200}, {"filter_scale": 4.0})))
