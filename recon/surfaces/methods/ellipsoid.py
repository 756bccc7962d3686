"""``ellipsoid``: a least-squares quadric of 9 parameters, the simplest closed model of a body.

A tri-axial asteroid seen by a noisy sensor may support no more than its three semi-axes, its
orientation and its centre. The quadric

    a x^2 + b y^2 + c z^2 + 2 d xy + 2 e xz + 2 f yz + 2 g x + 2 h y + 2 i z = 1

has 9 parameters (Li and Griffiths 2004, "Least squares ellipsoid specific fitting"). It is
fitted in two steps, on coordinates centred on the points' mean and scaled by their RMS
distance to it (for conditioning):

1. **Algebraic least squares** of the 9 coefficients (``Q(p) = 1`` for every point).
2. **Approximate geometric least squares**: ``iterations`` rounds of iteratively reweighted
   least squares with Sampson's first-order distance ``(Q(p) - 1) / |grad Q(p)|``, i.e. each
   point's equation weighted by ``1 / (|grad Q|^2 sigma^2)``, times Tukey biweights of those
   distances (scale 1.4826 x their median absolute value, Tukey's constant 4.685) so spurious
   returns drop out. ``sigma`` is each strike's uncertainty along the surface normal from the
   recorded error model (``MethodInput.sigma``, ``weighted``), else 1.

The quadric is an ellipsoid when its 3 x 3 matrix is positive definite after normalisation.
On a lumpy natural body seen along a few tracks (a cross or slew of a rangefinder over Bennu,
Ryugu, a comet, Eros) it often is not: the 9 coefficients are barely constrained by points on
a few curves, and the lumps tip the best quadric into a hyperboloid. There the ellipsoid is
fitted by construction instead (``fit_constrained``):

3. **Constrained least squares** (scipy ``least_squares``) of 9 parameters: the centre, the
   logarithms of the three semi-axes (so they stay positive) and a rotation vector (scipy
   ``Rotation``), on each point's radial distance to the ellipsoid,
   ``|p - c| (1 - 1 / |A^-1 R^T (p - c)|)`` (the point's distance from the centre minus the
   ellipsoid's along the same ray; near the geometric distance on a rounded body), divided by
   ``sigma`` when ``weighted``. It starts at the points' mean and principal axes (semi-axis
   ``sqrt(3 x variance)``, a sphere's surface) and is solved twice: plain, then with a soft-L1
   loss at the robust spread of the first solve's residuals (1.4826 x median absolute value).
   No random draw. It fails with too few points, when a semi-axis runs off to ``MAX_AXIS``
   times the points' RMS radius (a patch fitted as a near-plane: no body), or when a solve
   does not settle within ``MAX_EVALUATIONS`` evaluations.

Where the quadric is an ellipsoid, it is kept as it is (the constrained fit is not run). On a
body seen over a small part of its surface either ellipsoid is an extrapolation of that part;
docs/decisions.md has what it is worth against the truth. The surface is an icosphere of
``subdivisions`` levels mapped onto the ellipsoid (level 5: 20,480 faces, the simulator's own
ellipsoid resolution, ~0.01% of the radius off the exact surface). Its model size is 9
parameters whatever the face count (``Method.parameters``).
"""

from __future__ import annotations

import numpy as np

from formats.errors import MethodFailed
from recon.surfaces.methods import Method, MethodInput, Param, register
from recon.surfaces.methods.plane import MAD_TO_SIGMA, TUKEY_C

# Free parameters of a general ellipsoid: centre (3), semi-axes (3), orientation (3).
ELLIPSOID_PARAMETERS = 9
# Fewest points for 9 coefficients with a little redundancy.
MIN_POINTS = 12
# A constrained fit whose semi-axis exceeds this many times the points' RMS distance from
# their mean has run off to fit a patch by a near-plane: no body.
MAX_AXIS = 100.0
# The constrained fit's bounds on the semi-axes in the same unit, and the fraction of MAX_AXIS
# at which a semi-axis counts as having run to the bound.
MIN_AXIS = 1e-3
BOUND_REACHED = 0.99
# Evaluations of the residuals per solve of the constrained fit: the auto suite's natural
# bodies whose quadric is not an ellipsoid need 14-33 (docs/decisions.md); a satellite of
# panels can wander for hundreds without settling on a body.
MAX_EVALUATIONS = 100


def _design(x: np.ndarray) -> np.ndarray:
    """(n, 9) rows of the quadric's monomials at ``x`` (n, 3)."""
    X, Y, Z = x.T
    return np.column_stack([X * X, Y * Y, Z * Z, 2 * X * Y, 2 * X * Z, 2 * Y * Z,
                            2 * X, 2 * Y, 2 * Z])


def _gradient(x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n, 3) gradient of the quadric ``v`` (9,) at ``x`` (n, 3)."""
    a, b, c, d, e, f, g, h, i = v
    A = np.array([[a, d, e], [d, b, f], [e, f, c]])
    return 2.0 * (x @ A + np.array([g, h, i]))


def _solve(design: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Weighted least squares of ``design @ v = 1``."""
    w = np.sqrt(weights)[:, None]
    v, *_ = np.linalg.lstsq(design * w, w[:, 0], rcond=None)
    return v


def fit_quadric(points: np.ndarray, *, sigma: np.ndarray | None = None, iterations: int = 20
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares ellipsoid of points (module docstring).

    Parameters
    ----------
    points : (n, 3) float64, metres
    sigma : (n,) float64, metres, optional
        1-sigma uncertainty of each point along the surface normal (weights ``1 / sigma^2``).
    iterations : int
        Sampson-reweighted rounds after the algebraic fit.

    Returns
    -------
    centre : (3,) float64, metres
    axes : (3,) float64, metres
        Semi-axes, ascending.
    rotation : (3, 3) float64
        Columns are the unit directions of ``axes`` (sends ellipsoid-frame vectors to the
        points' frame).

    Raises
    ------
    MethodFailed
        Too few points, or the best quadric is not an ellipsoid.
    """
    points = np.asarray(points, dtype=np.float64)
    if len(points) < MIN_POINTS:
        raise MethodFailed(f"ellipsoid: need at least {MIN_POINTS} points, got {len(points)}")
    mean = points.mean(axis=0)
    scale = float(np.sqrt(np.mean(np.sum((points - mean) ** 2, axis=1)))) or 1.0
    x = (points - mean) / scale
    prior = np.ones(len(x)) if sigma is None else 1.0 / np.maximum(
        np.asarray(sigma, dtype=np.float64) / scale, 1e-12) ** 2
    prior = prior / prior.mean()
    design = _design(x)
    v = _solve(design, prior)
    for _ in range(int(iterations)):
        grad2 = np.maximum(np.sum(_gradient(x, v) ** 2, axis=1), 1e-12)
        distance = (design @ v - 1.0) / np.sqrt(grad2)
        spread = MAD_TO_SIGMA * np.median(np.abs(distance))
        u = distance / (TUKEY_C * max(spread, 1e-9))
        robust = np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)
        v = _solve(design, prior * robust / grad2)
    a, b, c, d, e, f, g, h, i = v
    A = np.array([[a, d, e], [d, b, f], [e, f, c]])
    try:
        centre = -np.linalg.solve(A, np.array([g, h, i]))
    except np.linalg.LinAlgError:
        raise MethodFailed("ellipsoid: the fitted quadric has no centre (a cylinder or a "
                           "plane, not an ellipsoid)") from None
    k = 1.0 + centre @ A @ centre
    values, vectors = np.linalg.eigh(A / k)
    if not np.all(values > 0):
        raise MethodFailed("ellipsoid: the best quadric is not an ellipsoid (eigenvalues "
                           f"{np.array2string(values, precision=3)}); the points do not "
                           "enclose a convex body")
    axes = scale / np.sqrt(values)
    order = np.argsort(axes)
    return mean + scale * centre, axes[order], vectors[:, order]


def _radial(x: np.ndarray, centre: np.ndarray, axes: np.ndarray, rotation: np.ndarray
            ) -> np.ndarray:
    """(n,) signed radial distance of ``x`` (n, 3) to the ellipsoid (``fit_quadric``'s
    returns): along the ray from the centre through each point, the point's distance from the
    centre minus the ellipsoid's, positive outside."""
    d = x - centre
    r = np.linalg.norm(d, axis=1)
    q = np.linalg.norm((d @ rotation) / axes, axis=1)
    return r * (1.0 - 1.0 / np.maximum(q, 1e-12))


def fit_constrained(points: np.ndarray, *, sigma: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares ellipsoid by construction (module docstring): centre, three positive
    semi-axes and a rotation by robust nonlinear least squares of the radial distance.

    Parameters
    ----------
    points : (n, 3) float64, metres
    sigma : (n,) float64, metres, optional
        1-sigma uncertainty of each point along the surface normal (residuals ``/ sigma``).

    Returns
    -------
    centre : (3,) float64, metres
    axes : (3,) float64, metres
        Semi-axes, ascending.
    rotation : (3, 3) float64
        Columns are the unit directions of ``axes`` (sends ellipsoid-frame vectors to the
        points' frame), a proper rotation.

    Raises
    ------
    MethodFailed
        Too few points, or no bounded ellipsoid fits them (a semi-axis runs to ``MAX_AXIS``
        times the points' RMS distance from their mean, or a solve does not converge within
        ``MAX_EVALUATIONS`` evaluations).
    """
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    points = np.asarray(points, dtype=np.float64)
    if len(points) < MIN_POINTS:
        raise MethodFailed(f"ellipsoid: need at least {MIN_POINTS} points, got {len(points)}")
    mean = points.mean(axis=0)
    scale = float(np.sqrt(np.mean(np.sum((points - mean) ** 2, axis=1)))) or 1.0
    x = (points - mean) / scale
    weight = np.ones(len(x)) if sigma is None else 1.0 / np.maximum(
        np.asarray(sigma, dtype=np.float64) / scale, 1e-12)
    weight = weight / np.sqrt(np.mean(weight ** 2))
    # The start: the points' mean and principal axes; on a sphere's surface the variance
    # along an axis is a^2 / 3.
    values, vectors = np.linalg.eigh(np.cov(x.T))
    if np.linalg.det(vectors) < 0:
        vectors[:, 0] = -vectors[:, 0]
    start = np.concatenate([np.zeros(3), 0.5 * np.log(3.0 * np.maximum(values, 1e-6)),
                            Rotation.from_matrix(vectors).as_rotvec()])

    def residual(params: np.ndarray, w: np.ndarray) -> np.ndarray:
        rotation = Rotation.from_rotvec(params[6:]).as_matrix()
        return w * _radial(x, params[:3], np.exp(params[3:6]), rotation)

    # Plain least squares, then a soft-L1 loss (a smooth Huber: quadratic below f_scale,
    # linear above) at the robust spread of its residuals (1.4826 x their median absolute
    # value), so spurious returns and lumps the ellipsoid cannot follow count linearly.
    # The semi-axes are bounded (MIN_AXIS, MAX_AXIS) so that a patch's fit stops at the bound
    # rather than overflowing; one at the upper bound is no body.
    bounds = (np.r_[np.full(3, -np.inf), np.full(3, np.log(MIN_AXIS)), np.full(3, -np.inf)],
              np.r_[np.full(3, np.inf), np.full(3, np.log(MAX_AXIS)), np.full(3, np.inf)])
    start[3:6] = np.clip(start[3:6], np.log(MIN_AXIS) + 1e-9, np.log(MAX_AXIS) - 1e-9)
    solve = {"x_scale": "jac", "method": "trf", "bounds": bounds, "max_nfev": MAX_EVALUATIONS,
             "args": (weight,)}
    fit = least_squares(residual, start, **solve)
    spread = MAD_TO_SIGMA * float(np.median(np.abs(fit.fun)))
    if fit.status > 0 and spread > 0:
        fit = least_squares(residual, fit.x, loss="soft_l1", f_scale=spread, **solve)
    if fit.status <= 0:
        raise MethodFailed(f"ellipsoid: the constrained fit did not converge in "
                           f"{MAX_EVALUATIONS} evaluations; the points do not determine an "
                           "ellipsoid")
    axes = np.exp(fit.x[3:6])
    if axes.max() > BOUND_REACHED * MAX_AXIS:
        raise MethodFailed("ellipsoid: no bounded ellipsoid fits the points (semi-axes "
                           f"{np.array2string(scale * axes, precision=3)} m for points "
                           f"{scale:.3g} m RMS from their mean); they do not enclose a body")
    order = np.argsort(axes)
    rotation = Rotation.from_rotvec(fit.x[6:]).as_matrix()
    return mean + scale * fit.x[:3], scale * axes[order], rotation[:, order] * np.array(
        [1.0, 1.0, np.linalg.det(rotation[:, order])])


def fit_ellipsoid(points: np.ndarray, *, sigma: np.ndarray | None = None, iterations: int = 20
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The least-squares ellipsoid of points: the quadric's (``fit_quadric``, unchanged) where
    it is an ellipsoid, else the constrained fit's (``fit_constrained``). Parameters and
    returns as ``fit_quadric``'s.

    Raises
    ------
    MethodFailed
        Too few points, or the constrained fit finds no bounded ellipsoid (its reasons).
    """
    try:   # too few points: both raise the same error
        return fit_quadric(points, sigma=sigma, iterations=iterations)
    except MethodFailed:
        return fit_constrained(points, sigma=sigma)


def ellipsoid_mesh(centre: np.ndarray, axes: np.ndarray, rotation: np.ndarray,
                   subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """An icosphere of ``subdivisions`` levels mapped onto the ellipsoid, faces outward."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=int(subdivisions))
    vertices = (np.asarray(sphere.vertices) * axes) @ rotation.T + centre
    faces = np.asarray(sphere.faces, dtype=np.int64)
    if np.linalg.det(rotation) < 0:  # a reflection turns the faces inside out
        faces = faces[:, ::-1]
    return vertices, faces


def run(cloud: MethodInput, *, subdivisions: int, iterations: int, weighted: bool
        ) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares ellipsoid of the points as a triangle mesh.

    Parameters
    ----------
    cloud : MethodInput
    subdivisions : int
        Icosphere levels of the mesh (20 * 4**n faces).
    iterations : int
        Sampson-reweighted rounds (``fit_quadric``; ``fit_ellipsoid``).
    weighted : bool
        Weight each point by its recorded uncertainty (``MethodInput.sigma``) when known.

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64, counter-clockwise seen from outside
    """
    sigma = cloud.sigma if weighted else None
    centre, axes, rotation = fit_ellipsoid(cloud.points, sigma=sigma, iterations=iterations)
    return ellipsoid_mesh(centre, axes, rotation, subdivisions)


METHOD = register(Method(
    name="ellipsoid", run=run, kind="primitive",
    summary="least-squares ellipsoid (9-parameter quadric, Sampson-reweighted, robust; fitted "
            "by construction where the quadric is not an ellipsoid)",
    parameters=lambda vertices, faces: ELLIPSOID_PARAMETERS,
    params={
        # 5: the simulator's ellipsoid resolution (sim/defaults.py target.subdivisions).
        "subdivisions": Param(5, int, "icosphere levels of the mesh (20 * 4**n faces)",
                              minimum=0, choices=tuple(range(8))),
        # 20 rounds: from an algebraic start biased by 5% uniform outliers (short axis 2.4 x
        # too long), 5 rounds leave it 1.2% off and 20 rounds 0.04%, as without outliers
        # (measured on a 1 x 2 x 3.5 ellipsoid, 4000 points, noise 0.01); at most 1000.
        "iterations": Param(20, int, "Sampson-reweighted robust rounds", minimum=0,
                            maximum=1000),
        "weighted": Param(True, bool, "weight points by the recorded sensor error model"),
    }))
