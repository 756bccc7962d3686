"""``apss``: algebraic point set surfaces (Guennebaud and Gross 2007), MeshLab's marching cubes.

Moving least squares with algebraic spheres instead of planes, so it follows curvature with
fewer points; pymeshlab's ``generate_marching_cubes_apss`` extracts the zero set on a grid of
``resolution`` cells per side (default: one per spacing). Faces on NaN vertices (where the
projection diverged) are dropped, as in ``rimls``.
"""

from __future__ import annotations

import numpy as np

from recon.surfaces.methods import Method, MethodInput, Param, register
from recon.surfaces.methods._mls import GRID, mls_params, mls_surface


def run(cloud: MethodInput, *, filter_scale: float, spherical: float, resolution: int
        ) -> tuple[np.ndarray, np.ndarray]:
    """APSS surface of the oriented points: ``(vertices, faces)`` as ``mls_surface`` returns.

    Parameters
    ----------
    cloud : MethodInput
    filter_scale : float
        Kernel support in units of the local point spacing.
    spherical : float
        Blend between plane fit (0) and pure sphere fit (1).
    resolution : int or None
        Marching-cubes cells per side; None: one per spacing (``mls_surface``).
    """
    return mls_surface(cloud, "generate_marching_cubes_apss", method="apss",
                       filter_scale=filter_scale, resolution=resolution,
                       sphericalparameter=spherical)


METHOD = register(Method(
    name="apss", run=run, kind="smooth", preload=("pymeshlab",),
    summary="algebraic point set surfaces (pymeshlab), marching cubes",
    # 1: MeshLab's default (print_filter_parameter_list).
    params=mls_params("spherical", Param(1.0, float, "0 = planes, 1 = spheres", minimum=0.0,
                                                   maximum=1.0)),
    grid=GRID))
