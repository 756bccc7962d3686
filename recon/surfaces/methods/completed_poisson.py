"""``completed-poisson``: Poisson where the strikes are, their ellipsoid where none is.

A body seen over part of its surface (a pole never in view, a side that never turned to the
sensor) has an unseen rest that every closed surface must guess. ``poisson`` guesses a smooth
blob of its own, which follows the trend of the strikes' edge and can swell far from the body;
``ellipsoid`` is the better guess of a rounded body's unseen side but smooths away the detail the
strikes resolve (craters, ridges, a flattened pole). This method takes each where it is right:

1. the least-squares ellipsoid of the strikes (``ellipsoid.fit_ellipsoid``: the quadric, or the
   constrained fit where the quadric is not an ellipsoid; weighted by the recorded error model
   with ``weighted``);
2. the vertices of its mesh (an icosphere of ``subdivisions`` levels) farther than ``reach``
   times its mean semi-axis from every strike's radial projection onto it (the directions from
   its centre no strike covers), with the ellipsoid's outward normals: oriented points standing
   for the unseen surface;
3. Poisson (Open3D, octree ``depth``) on the strikes and those points together, untrimmed: a
   closed surface that follows the strikes where they are and passes over the ellipsoid where
   nothing was seen, with Poisson's smooth blend between the two across the ``reach``.

It fails, as ``ellipsoid`` does, where no bounded ellipsoid fits the strikes (a flat patch).
The completion is only as good as the ellipsoid is a guess of the unseen side: on a contact
binary, or a satellite of plates and booms, it is not (``-m auto`` lets the missed beams and
the held-out passes decide; ``recon.surfaces.auto``).

Measured on the auto suite's natural bodies against the truth, at the defaults: the Chamfer
distance and the F-score over the best of every other method's runs, where the strikes cover a
fifth to a half of the body: cratered asteroids 0.44-0.95 and 0.91-1.11 (eight clouds), Psyche
under the slew 0.66 and 1.14, Bennu under the LIDAR 0.90 and 1.00, Ryugu under the slew 0.77
and 1.05. On a body that is an ellipsoid the bare ellipsoid stays the better model (the
generated asteroid under the cross: 1.95 and 0.97). docs/decisions.md has the table.
"""

from __future__ import annotations

import numpy as np

from formats.errors import MethodFailed
from recon.surfaces.methods import Method, MethodInput, Param, ellipsoid, poisson, register
from recon.surfaces.methods.ellipsoid import ellipsoid_mesh, fit_ellipsoid
from recon.surfaces.methods.poisson import MAX_DEPTH, solve

# The ellipsoid fit's rounds and Poisson's reconstruction cube are those methods' defaults.
ELLIPSOID_ITERATIONS = ellipsoid.METHOD.params["iterations"].default
SCALE = poisson.METHOD.params["scale"].default


def unseen_points(points: np.ndarray, centre: np.ndarray, axes: np.ndarray,
                  rotation: np.ndarray, *, reach: float, subdivisions: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The ellipsoid's mesh vertices farther than ``reach`` times its mean semi-axis from every
    strike's radial projection onto it (the part of the ellipsoid no strike's direction from
    its centre covers: where the body is not seen, not where the ellipsoid departs from a body
    that is), and their outward unit normals.

    Parameters
    ----------
    points : (n, 3) float64, metres, body frame
        The strikes.
    centre : (3,) float64, metres; axes : (3,) float64, metres; rotation : (3, 3) float64
        The ellipsoid (``ellipsoid.fit_ellipsoid``): body = rotation @ (axes * unit) + centre.
    reach : float
        Distance from the strikes, as a fraction of the mean semi-axis, beyond which the
        ellipsoid stands for the surface.
    subdivisions : int
        Icosphere levels of the ellipsoid's mesh (10 * 4**n + 2 vertices).

    Returns
    -------
    vertices : (m, 3) float64, metres, body frame
    normals : (m, 3) float64, unit, outward
    """
    from scipy.spatial import cKDTree

    vertices, _ = ellipsoid_mesh(centre, axes, rotation, subdivisions)
    unit = (points - centre) @ rotation / axes          # the ellipsoid's frame, unit sphere
    norm = np.linalg.norm(unit, axis=1, keepdims=True)
    shadows = (axes * unit / np.where(norm > 0, norm, 1.0)) @ rotation.T + centre
    distance, _ = cKDTree(shadows).query(vertices)
    far = vertices[distance > reach * float(np.mean(axes))]
    # The gradient of |R^T (p - c) / axes|^2 is the outward normal.
    normals = ((far - centre) @ rotation / axes ** 2) @ rotation.T
    return far, normals / np.linalg.norm(normals, axis=1, keepdims=True)


def run(cloud: MethodInput, *, depth: int, reach: float, subdivisions: int, weighted: bool
        ) -> tuple[np.ndarray, np.ndarray]:
    """The Poisson surface of the strikes completed by their ellipsoid (module docstring).

    Parameters
    ----------
    cloud : MethodInput
    depth : int
        Poisson's octree depth.
    reach : float
        Distance from every strike, as a fraction of the ellipsoid's mean semi-axis, beyond
        which the ellipsoid stands for the unseen surface.
    subdivisions : int
        Icosphere levels of the ellipsoid whose vertices complete the strikes.
    weighted : bool
        Weight the ellipsoid fit by the recorded uncertainty (``MethodInput.sigma``) when known.

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64
    """
    try:
        centre, axes, rotation = fit_ellipsoid(cloud.points,
                                               sigma=cloud.sigma if weighted else None,
                                               iterations=ELLIPSOID_ITERATIONS)
    except MethodFailed as error:
        raise MethodFailed(f"completed-poisson: no ellipsoid to complete with: {error}") from None
    prior, prior_normals = unseen_points(cloud.points, centre, axes, rotation, reach=reach,
                                         subdivisions=subdivisions)
    vertices, faces, _ = solve(np.vstack([cloud.points, prior]),
                               np.vstack([cloud.normals, prior_normals]), depth=depth,
                               scale=SCALE, linear_fit=False)
    if len(faces) == 0:
        raise MethodFailed("completed-poisson: Poisson produced no triangles")
    return vertices, faces


METHOD = register(Method(
    name="completed-poisson", run=run, kind="smooth", preload=("open3d",),
    summary="Poisson of the strikes, completed by their ellipsoid where nothing was seen",
    params={
        # depth 6: the natural bodies' best Poisson depth in the auto suite (docs/auto-suite.md).
        "depth": Param(6, int, "Poisson octree depth (grid of up to 2**depth cells)", minimum=1,
                       maximum=MAX_DEPTH),
        # 0.3 of the mean semi-axis: on the auto suite's natural bodies, from 0.2 to 0.5, 0.3 was
        # within 5 % of the best of 0.2 and 0.3 in Chamfer everywhere (0.2 presses the ellipsoid
        # against the seen edge, where it is wrong on a cratered body; 0.5 is better on the
        # bodies least like an ellipsoid and brings Poisson's blob back on those most like one);
        # docs/decisions.md.
        "reach": Param(0.3, float, "distance from the strikes, as a fraction of the "
                       "ellipsoid's mean semi-axis, beyond which the ellipsoid completes them",
                       minimum=0.0, maximum=10.0),
        # 5: 10,242 vertices, the ellipsoid method's own mesh.
        "subdivisions": Param(5, int, "icosphere levels of the completing ellipsoid",
                              minimum=0, choices=tuple(range(8))),
        "weighted": Param(True, bool, "weight the ellipsoid fit by the recorded sensor error "
                          "model"),
    },
    grid=({"reach": 0.2}, {"depth": 7})))
