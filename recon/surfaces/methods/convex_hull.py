"""``convex-hull``: the convex hull of the points, the floor every method should beat.

Exact for convex targets sampled without noise; on noisy clouds it wraps the outermost points
(biased outward by about two noise sigmas) and it bridges every concavity.
"""

from __future__ import annotations

import numpy as np

from formats.errors import MethodFailed
from recon.surfaces.methods import Method, MethodInput, register


def run(cloud: MethodInput) -> tuple[np.ndarray, np.ndarray]:
    """Convex hull by qhull (scipy), faces oriented outward.

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64, counter-clockwise seen from outside
    """
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(cloud.points)
    except QhullError as exc:
        raise MethodFailed(f"convex-hull: qhull failed ({str(exc).strip().splitlines()[0]})"
                           ) from None
    faces = hull.simplices.astype(np.int64)
    a, b, c = (cloud.points[faces[:, i]] for i in range(3))
    # hull.equations[:, :3] are outward unit normals of each facet, in simplices order.
    flip = np.einsum("ij,ij->i", np.cross(b - a, c - a), hull.equations[:, :3]) < 0
    faces[flip] = faces[flip][:, ::-1]
    return cloud.points, faces


METHOD = register(Method(
    name="convex-hull", run=run, params={}, kind="baseline",
    summary="convex hull of the points (qhull): the floor baseline"))
