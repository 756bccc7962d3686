"""What a method's mesh must be before it counts: not empty, not degenerate; and whether it is
watertight (``recon.surfaces.methods.watertight``, which methods use too). Applied to every run,
isolated or not (``recon.surfaces.isolation``, ``recon.surfaces.reconstruct``)."""

from __future__ import annotations

import numpy as np

from formats.errors import MethodFailed
from recon.surfaces.methods import check_mesh_arrays

# Degenerate-mesh tests, relative to the points' bounding-box diagonal: a mesh whose own
# diagonal is below the first collapsed to a point or a line; above the second it extends far
# beyond the data (a Poisson blow-up); total area below the third squared is zero.
COLLAPSED_FRACTION = 1e-3
EXPLODED_FACTOR = 10.0
ZERO_AREA_FRACTION = 1e-9


class SurfaceRejected(MethodFailed):
    """A method returned an empty or degenerate mesh (``kind`` says which)."""

    def __init__(self, kind: str, reason: str):
        super().__init__(reason)
        self.kind = kind


def check_surface(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray, *, method: str
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Reject an empty or degenerate mesh (raises ``SurfaceRejected`` with the reason).

    Parameters
    ----------
    vertices : (v, 3) float64, metres
    faces : (f, 3) int64
    points : (n, 3) float64, metres
        The input points: the scale the mesh is judged against.
    """
    vertices, faces = check_mesh_arrays(vertices, faces, method=method)
    if len(faces) == 0:
        raise SurfaceRejected("empty", f"{method}: empty mesh (no triangles)")
    scale = float(np.linalg.norm(np.ptp(points, axis=0))) or 1.0
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
    if not area > ZERO_AREA_FRACTION * scale**2:
        raise SurfaceRejected("degenerate", f"{method}: degenerate mesh (zero area)")
    size = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    if size < COLLAPSED_FRACTION * scale:
        raise SurfaceRejected("degenerate",
                              f"{method}: degenerate mesh (collapsed to {size:.3g} m)")
    if size > EXPLODED_FACTOR * scale:
        raise SurfaceRejected("degenerate", f"{method}: degenerate mesh ({size:.3g} m across "
                                            f"for points {scale:.3g} m across)")
    return vertices, faces
