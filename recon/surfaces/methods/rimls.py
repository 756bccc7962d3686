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
from recon.surfaces.methods._mls import GRID, mls_params, mls_surface


def run(cloud: MethodInput, *, filter_scale: float, sigma_n: float, resolution: int
        ) -> tuple[np.ndarray, np.ndarray]:
    """RIMLS surface of the oriented points: ``(vertices, faces)`` as ``mls_surface`` returns.

    Parameters
    ----------
    cloud : MethodInput
    filter_scale : float
        Kernel support in units of the local point spacing (MeshLab's "MLS - Filter scale").
    sigma_n : float
        Normal-reweighting width (smaller keeps sharper features).
    resolution : int or None
        Marching-cubes cells per side; None: one per spacing (``mls_surface``).
    """
    return mls_surface(cloud, "generate_marching_cubes_rimls", method="rimls",
                       filter_scale=filter_scale, resolution=resolution, sigman=sigma_n)


METHOD = register(Method(
    name="rimls", run=run, kind="smooth", preload=("pymeshlab",),
    summary="robust implicit MLS (pymeshlab), marching cubes",
    # 0.75: MeshLab's default (print_filter_parameter_list); a width of 10 weighs every normal
    # alike (the weights are exp(-(difference / sigma_n)**2) of unit-normal differences <= 2).
    params=mls_params("sigma_n", Param(0.75, float, "normal reweighting width", minimum=0.0,
                                       maximum=10.0)),
    grid=GRID))
