"""``ball-pivoting-meshlab``: MeshLab's ball pivoting (pymeshlab).

The algorithm of ``ball-pivoting`` in MeshLab's implementation, with one ball radius (in units
of the spacing) and MeshLab's clustering of close vertices. With the radius left to
MeshLab's automatic guess it took 155 s on 2e5 points (3.9 s on 5e4 points: 4x the points, 40x
the time; docs/decisions.md, "Measurements behind the defaults"), so the default
radius is ours: 1.5 x spacing, or ``NOISE_RADIUS`` x the noise when that is larger
(``_backends.above_noise``). A ball smaller than the noise band falls into it and pivots
through the scatter: on RSO-A's LRF cloud (77,400 points, noise 0.035 m at 0.048 m spacing) a
1.5 x spacing ball took 46 s (30 x Open3D Poisson) for a 0.41 m Chamfer distance, a 6 x spacing
(8 x noise) ball 3.3 s for 0.24 m; on the 336k-point asteroid LIDAR cloud the first ran past
300 s (``benchmarks/bench_methods.py``).
"""

from __future__ import annotations

import numpy as np

from recon.surfaces.methods import Method, MethodInput, Param, register
from recon.surfaces.methods._backends import (
    above_noise,
    meshlab_arrays,
    meshlab_call,
    meshlab_set,
)

# The automatic radius: RADIUS x spacing, at least NOISE_RADIUS x noise (module docstring).
# 1.5 x spacing: at 1 x the ball fell through a noise-free box's faces (16% of the area missing,
# 20k uniform samples); 1.5 x closed them. 8 x noise: the smallest multiple measured on RSO-A's
# LRF cloud that pivots over the noise band (4 x: 16 s, 0.25 m; 8 x: 3.3 s, 0.24 m).
RADIUS, NOISE_RADIUS = 1.5, 8.0


def ball_radius(cloud: MethodInput, radius: float | None) -> float:
    """The ball radius in metres: ``radius`` x spacing, or when None the automatic one,
    ``max(RADIUS x spacing, NOISE_RADIUS x noise)``."""
    if radius is not None:
        return float(radius) * cloud.spacing
    return above_noise(cloud, RADIUS, NOISE_RADIUS)


def run(cloud: MethodInput, *, radius: float | None, clustering: float, crease_angle: float
        ) -> tuple[np.ndarray, np.ndarray]:
    """Ball-pivoting mesh through the points.

    Parameters
    ----------
    cloud : MethodInput
    radius : float or None
        Ball radius in units of ``cloud.spacing``; None: automatic (``ball_radius``).
    clustering : float
        Percentage of the radius within which vertices are merged.
    crease_angle : float
        Degrees; the ball does not pivot over creases sharper than this.

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64
    """
    import pymeshlab

    ms = meshlab_set(cloud)
    meshlab_call(ms, "generate_surface_reconstruction_ball_pivoting",
                 method="ball-pivoting-meshlab",
                 ballradius=pymeshlab.PureValue(ball_radius(cloud, radius)),
                 clustering=float(clustering), creasethr=float(crease_angle))
    return meshlab_arrays(ms, method="ball-pivoting-meshlab")


METHOD = register(Method(
    name="ball-pivoting-meshlab", run=run, kind="interpolating", preload=("pymeshlab",),
    summary="MeshLab ball pivoting (pymeshlab), one radius in multiples of the spacing",
    params={
        # Up to 50 spacings: a ball that wide touches thousands of points per pivot.
        "radius": Param(None, float, "ball radius / spacing (default: automatic, 1.5, or "
                        "8 x noise when larger)", minimum=0.01, maximum=50.0),
        # 20 % and 90 deg: MeshLab's defaults (print_filter_parameter_list); a percentage and
        # an angle between two faces.
        "clustering": Param(20.0, float, "vertex clustering, percent of the radius",
                            minimum=0.0, maximum=100.0),
        "crease_angle": Param(90.0, float, "maximum crease angle [deg]", minimum=0.0,
                              maximum=180.0),
    },
    grid=({"radius": 1.0}, {"radius": 3.0})))
