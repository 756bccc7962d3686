"""``screened-poisson``: MeshLab's screened Poisson reconstruction (pymeshlab), density-trimmed.

The same algorithm as ``poisson`` (Kazhdan and Hoppe 2013) in MeshLab's build, with its point
weight (the screening term that pulls the surface onto the points) exposed. MeshLab stores the
per-vertex sampling density in the vertex quality; the trimming rule is ``poisson``'s.

With ``weighted`` (and a recorded error model, ``MethodInput.sigma``) each point's confidence is
its ``1 / sigma^2`` normalised to mean 1: MeshLab's ``confidence`` option scales each normal by
the vertex quality, so a grazing, uncertain strike pulls on the indicator function less than a
head-on one.

MeshLab's solver runs ``OMP_NUM_THREADS`` threads (default 1): with its default of 2 it took 10 s
instead of 1.2 s on 6000 points while another process kept a core busy (OpenMP threads
spin-waiting on a busy core; docs/decisions.md, "Measurements behind the defaults").
"""

from __future__ import annotations

import math
import os

import numpy as np

from recon.surfaces.methods import Method, MethodInput, Param, register
from recon.surfaces.methods._backends import meshlab_arrays, meshlab_call, meshlab_set
from recon.surfaces.methods.poisson import MAX_DEPTH, trim_low_density
from recon.surfaces.uncertainty import weights


def run(cloud: MethodInput, *, depth: int, point_weight: float, samples_per_node: float,
        trim: float, weighted: bool) -> tuple[np.ndarray, np.ndarray]:
    """Screened Poisson surface of the oriented points, trimmed where the data are sparse.

    Parameters
    ----------
    cloud : MethodInput
    depth : int
        Octree depth.
    point_weight : float
        Screening weight (0: plain Poisson).
    samples_per_node : float
        Minimum samples per octree node (higher smooths noisy data).
    trim : float
        Density drop below the median at which vertices are removed (see ``poisson``).
    weighted : bool
        Per-point confidence from the recorded uncertainty (``MethodInput.sigma``) when known.

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64
    """
    confident = weighted and cloud.sigma is not None
    ms = meshlab_set(cloud, quality=weights(cloud.sigma, len(cloud.points)) if confident
                     else None)
    meshlab_call(ms, "generate_surface_reconstruction_screened_poisson", method="screened-poisson",
                 depth=int(depth), pointweight=float(point_weight),
                 samplespernode=float(samples_per_node), preclean=False, confidence=confident,
                 threads=max(1, int(os.environ.get("OMP_NUM_THREADS", "1"))))
    density = np.asarray(ms.current_mesh().vertex_scalar_array(), dtype=np.float64)
    vertices, faces = meshlab_arrays(ms, method="screened-poisson")
    return trim_low_density(vertices, faces, density, trim)


METHOD = register(Method(
    name="screened-poisson", run=run, kind="smooth", preload=("pymeshlab",),
    summary="MeshLab screened Poisson (pymeshlab), low-density vertices trimmed",
    params={
        # depth 8: best Chamfer of the methods measured (0.086 m at 5e4 points of the paper's
        # ellipsoid, 0.3 m noise; docs/decisions.md, "Measurements behind the defaults").
        "depth": Param(8, int, "octree depth", minimum=1, maximum=MAX_DEPTH),
        # 4 and 1.5: MeshLab's defaults (print_filter_parameter_list). The bounds: a weight of
        # 1000 already makes the surface interpolate the points (250 x the default), and nodes
        # of 100 samples are coarser than the surfaces our clouds resolve.
        "point_weight": Param(4.0, float, "screening weight (0 = plain Poisson)", minimum=0.0,
                              maximum=1000.0),
        "samples_per_node": Param(1.5, float, "minimum samples per node", minimum=1.0,
                                  maximum=100.0),
        "trim": Param(1.0, float, "density drop below the median that trims a vertex",
                      minimum=0.0, maximum=math.inf),
        "weighted": Param(True, bool, "per-point confidence from the recorded error model"),
    },
    grid=({"depth": 6}, {"depth": 10}, {"samples_per_node": 5.0})))
