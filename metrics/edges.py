"""The paper's edge metric: how well a point cloud shows the truth's feature edges.

Edge points (Pauly, Gross and Kobbelt, "Efficient simplification of point-sampled surfaces",
2002; the paper's reference 4): for a point and its k nearest neighbours (itself included),
the surface variation is ``sigma = l0 / (l0 + l1 + l2)``, with ``l0 <= l1 <= l2`` the eigenvalues
of the neighbourhood's covariance: 0 on a plane, up to 1/3 for an isotropic blob.

- ``rule="leave_one_out"`` (the paper's rule): a point is an edge point when removing it from its
  own neighbourhood lowers sigma by more than ``threshold``. The covariance without the point is a
  rank-one downdate of the neighbourhood's, ``S' = S - k / (k - 1) d d^T`` with ``d`` the point's
  offset from the neighbourhood mean and ``S`` the scatter matrix, so no neighbourhood is
  recomputed.
- ``rule="pauly"``: a point is an edge point when sigma itself exceeds ``threshold``.

Truth edges are the feature edges of the truth mesh: interior edges whose two faces' normals
differ by more than ``feature_angle_deg``.

The score (``edge_score``), in [0, 1], lower is better::

    t     = tolerance_fraction * (truth bounding-box diagonal)
    near  = the test points within t of a truth feature edge
    FER   = |edge points that are not near| / |test points that are not near|   false edges
    MER   = (length of truth feature edges with no edge point within t)
            / (total length of truth feature edges)                            missed edges
    score = (FER + MER) / 2   the balanced error rate of the point-wise edge classification,
                              with the positive class counted along the truth edges
    score = FER               when the truth has no feature edges (a smooth body)
    score = MER               when every test point is near a feature edge

Defaults (``metrics.defaults``): k = 16; leave-one-out threshold 0.0005 at k = 16 (scaled by
16 / k for other k); Pauly threshold 0.03; feature angle 30 degrees; t = 1 % of the truth's
bounding-box diagonal. "Within t" is decided against points every t / 8 along the feature edges
(to within t / 16).

FER rises with noise (every point of a noisy neighbourhood looks like an outlier), with thin
plates (neighbourhoods straddle both faces, paper's solar-panel discussion) and with sparse
sampling of curved surfaces; MER rises with holes and with sampling too sparse to place edge
points within t of an edge. Neighbourhoods are k nearest points (their radius follows the local
density) and t is a fraction of the truth's size, so the score has no length scale: a cloud and
truth scaled together score the same.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from metrics import defaults
from metrics.errors import MetricsInputError
from metrics.inputs import Mesh, as_mesh, as_points, bbox_diagonal, face_normals
from metrics.spatial import morton_order, nearest_distance

EdgeRule = Literal["leave_one_out", "pauly"]
_RULES = ("leave_one_out", "pauly")


@dataclass(frozen=True)
class SurfaceVariation:
    """Per-point surface variation of k-nearest neighbourhoods.

    Attributes
    ----------
    sigma : (n,) float64, dimensionless, in [0, 1/3]
        ``l0 / (l0 + l1 + l2)`` of the neighbourhood covariance (0 when all k points coincide).
    drop : (n,) float64, dimensionless
        ``sigma`` minus the surface variation of the neighbourhood without the point.
    radius : (n,) float64, metres
        Distance to the k-th nearest point (the neighbourhood radius).
    k : int
    """

    sigma: np.ndarray
    drop: np.ndarray
    radius: np.ndarray
    k: int


@dataclass(frozen=True)
class EdgeReport:
    """Result of ``edge_score``.

    Attributes
    ----------
    score : float
        In [0, 1], lower is better (formula in the module docstring).
    false_edge_rate : float or None
        FER; None when every test point is near a truth edge.
    missed_edge_rate : float or None
        MER; None when the truth has no feature edges.
    n_points, n_edge_points : int
        Test points, and those classified as edge points.
    n_feature_edges : int
    feature_edge_length_m : float
    tolerance_m : float
    k : int
    rule : str
    threshold : float
    is_edge : (n,) bool
        Edge points of the test cloud.
    near_edge : (n,) bool
        Test points within the tolerance of a truth feature edge.
    variation : SurfaceVariation
    """

    score: float
    false_edge_rate: float | None
    missed_edge_rate: float | None
    n_points: int
    n_edge_points: int
    n_feature_edges: int
    feature_edge_length_m: float
    tolerance_m: float
    k: int
    rule: str
    threshold: float
    is_edge: np.ndarray = field(repr=False)
    near_edge: np.ndarray = field(repr=False)
    variation: SurfaceVariation = field(repr=False)

    def to_dict(self) -> dict:
        """The scalar fields, JSON-ready."""
        return {name: getattr(self, name) for name in (
            "score", "false_edge_rate", "missed_edge_rate", "n_points", "n_edge_points",
            "n_feature_edges", "feature_edge_length_m", "tolerance_m", "k", "rule", "threshold")}


def _check_k(k, n_points: int) -> int:
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 4:
        raise MetricsInputError(f"k must be an integer >= 4, got {k!r}")
    if n_points < k:
        raise MetricsInputError(f"points has {n_points} rows, fewer than k = {k} neighbours")
    return int(k)


def surface_variation(points, *, k: int = defaults.EDGE_K) -> SurfaceVariation:
    """Surface variation and its leave-one-out drop for every point, vectorised.

    Parameters
    ----------
    points : (n, 3) float64, metres
    k : int, >= 4
        Neighbourhood size, the point itself included.

    Returns
    -------
    SurfaceVariation

    Notes
    -----
    The points are put in Morton (Z-curve) order before the KD-tree is built and queried, so
    consecutive queries touch the same tree nodes and memory: 2-3x faster on a million points.
    Per block of points: k-nearest neighbours (scipy cKDTree, all cores), neighbourhood scatter
    matrices by one einsum, eigenvalues by ``np.linalg.eigvalsh`` on the (b, 3, 3) stack, and the
    scatter without the point by a rank-one downdate.
    """
    points = as_points(points, "points")
    return _surface_variation(points, _check_k(k, len(points)))


def _surface_variation(points: np.ndarray, k: int) -> SurfaceVariation:
    """``surface_variation`` of points and k already validated."""
    from scipy.spatial import cKDTree

    order = morton_order(points)
    ordered = points[order]
    tree = cKDTree(ordered)
    n = len(points)
    sigma = np.empty(n)
    drop = np.empty(n)
    radius = np.empty(n)
    step = max(1, defaults.EDGE_BLOCK)
    for lo in range(0, n, step):  # blocks of points, bounded memory; each block is vectorised
        sl = slice(lo, lo + step)
        dist, idx = tree.query(ordered[sl], k=k, workers=-1)
        local = ordered[idx] - ordered[sl, None, :]  # neighbours relative to the point (b, k, 3)
        mean = local.mean(axis=1)
        centred = local - mean[:, None, :]
        scatter = np.einsum("bki,bkj->bij", centred, centred, optimize=True)
        # Without the point (at the local origin): offset d = 0 - mean, rank-one downdate.
        without = scatter - (k / (k - 1.0)) * (mean[:, :, None] * mean[:, None, :])
        sigma[sl] = _variation(scatter)
        drop[sl] = sigma[sl] - _variation(without)
        radius[sl] = dist[:, -1]
    out = np.empty((3, n))
    out[:, order] = np.stack([sigma, drop, radius])
    return SurfaceVariation(sigma=out[0], drop=out[1], radius=out[2], k=k)


def _variation(scatter: np.ndarray) -> np.ndarray:
    """l0 / (l0 + l1 + l2) of symmetric (b, 3, 3) matrices; 0 where the trace is 0."""
    eig = np.linalg.eigvalsh(scatter)
    total = eig.sum(axis=1)
    smallest = np.maximum(eig[:, 0], 0.0)  # rounding can make a planar neighbourhood's l0 < 0
    return np.divide(smallest, total, out=np.zeros_like(total), where=total > 0)


def detect_edges(points, *, k: int = defaults.EDGE_K, rule: EdgeRule = "leave_one_out",
                 threshold: float | None = None) -> tuple[np.ndarray, SurfaceVariation]:
    """Classify the points of a cloud as edge points by surface variation.

    Parameters
    ----------
    points : (n, 3) float64, metres
    k : int
        Neighbourhood size, the point itself included (default ``defaults.EDGE_K``).
    rule : {"leave_one_out", "pauly"}
        ``leave_one_out``: edge when removing the point lowers sigma by more than ``threshold``
        (default ``defaults.EDGE_DROP_THRESHOLD * defaults.EDGE_K / k``, 0.0005 at k = 16).
        ``pauly``: edge when sigma exceeds ``threshold`` (default
        ``defaults.EDGE_SIGMA_THRESHOLD`` = 0.03).
    threshold : float, optional

    Returns
    -------
    is_edge : (n,) bool
    variation : SurfaceVariation
    """
    points = as_points(points, "points")
    k = _check_k(k, len(points))
    rule, threshold = _check_rule(rule, threshold, k)
    return _detect_edges(points, k, rule, threshold)


def _detect_edges(points: np.ndarray, k: int, rule: str, threshold: float
                  ) -> tuple[np.ndarray, SurfaceVariation]:
    """``detect_edges`` of arguments already validated."""
    variation = _surface_variation(points, k)
    value = variation.drop if rule == "leave_one_out" else variation.sigma
    return value > threshold, variation


def _check_rule(rule, threshold, k) -> tuple[str, float]:
    if rule not in _RULES:
        raise MetricsInputError(f"rule must be one of {_RULES}, got {rule!r}")
    if threshold is None:
        threshold = default_threshold(rule, k)
    if not (isinstance(threshold, int | float | np.integer | np.floating)
            and not isinstance(threshold, bool) and np.isfinite(threshold) and threshold >= 0):
        raise MetricsInputError(f"threshold must be a finite number >= 0, got {threshold!r}")
    return rule, float(threshold)


def default_threshold(rule: EdgeRule, k: int) -> float:
    """Default threshold of an edge rule for neighbourhood size k (see ``metrics.defaults``).

    ``leave_one_out``: ``EDGE_DROP_THRESHOLD * EDGE_K / k`` (a crease point's drop scales as
    about 1 / k); ``pauly``: ``EDGE_SIGMA_THRESHOLD``.
    """
    if rule == "leave_one_out":
        return defaults.EDGE_DROP_THRESHOLD * defaults.EDGE_K / k
    return defaults.EDGE_SIGMA_THRESHOLD


def feature_edges(truth, *, angle_deg: float = defaults.FEATURE_ANGLE_DEG) -> np.ndarray:
    """Feature edges of a triangle mesh: interior edges with a dihedral angle above a threshold.

    The angle of an edge is the angle between the unit normals of its two faces (0 where the
    faces are coplanar, 90 degrees on a box). Boundary edges (one face) are not feature edges:
    surface variation cannot see the rim of a flat sheet. Non-manifold edges (three or more faces)
    are feature edges when any two of their faces exceed the angle.

    Parameters
    ----------
    truth : Mesh or (vertices, faces)
    angle_deg : float, degrees, in [0, 180)

    Returns
    -------
    (e, 2) int64
        Vertex index pairs (lower index first), sorted, unique.
    """
    return _feature_edges(as_mesh(truth, "truth"), angle_deg)


def _feature_edges(mesh: Mesh, angle_deg: float) -> np.ndarray:
    """``feature_edges`` of a mesh already validated; the angle is checked."""
    if not (0.0 <= angle_deg < 180.0):
        raise MetricsInputError(f"angle_deg must be in [0, 180), got {angle_deg!r}")
    normals = face_normals(mesh.vertices, mesh.faces)
    edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    owner = np.repeat(np.arange(len(mesh.faces)), 3)
    _, inverse, counts = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    order = np.argsort(inverse, kind="stable")
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    cos_limit = np.cos(np.radians(angle_deg))
    # Compare every face of an edge with the first face of that edge: exact for manifold edges
    # (two faces); for non-manifold ones it checks the pairs involving the first face.
    first_face = owner[order][np.repeat(start, counts)]
    other_face = owner[order]
    cos = np.einsum("ij,ij->i", normals[first_face], normals[other_face])
    sharp_pair = (cos < cos_limit) & (first_face != other_face)
    sharp = np.zeros(len(counts), dtype=bool)
    np.logical_or.at(sharp, inverse[order], sharp_pair)
    sharp &= counts >= 2
    unique_edges = edges[order][start]
    return unique_edges[sharp]


def _edge_samples(mesh: Mesh, edges: np.ndarray, spacing: float):
    """Points every ``spacing`` (at most) along edges, at sub-segment midpoints, with lengths.

    Returns
    -------
    points : (s, 3) float64
    weight : (s,) float64, metres of edge each point stands for
    """
    a = mesh.vertices[edges[:, 0]]
    b = mesh.vertices[edges[:, 1]]
    length = np.linalg.norm(b - a, axis=1)
    count = np.maximum(np.ceil(length / spacing), 1).astype(np.int64)
    which = np.repeat(np.arange(len(edges)), count)
    position = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    t = (position + 0.5) / count[which]
    points = a[which] + t[:, None] * (b - a)[which]
    return points, (length / count)[which]


def edge_score(points, truth, *, k: int = defaults.EDGE_K, rule: EdgeRule = "leave_one_out",
               threshold: float | None = None,
               feature_angle_deg: float = defaults.FEATURE_ANGLE_DEG,
               tolerance: float | None = None,
               tolerance_fraction: float | None = None) -> EdgeReport:
    """The paper's edge metric of a point cloud against a truth mesh (formula in module docs).

    Parameters
    ----------
    points : (n, 3) float64, metres, the truth's frame
        The test cloud; n >= k.
    truth : Mesh or (vertices, faces)
        vertices (n_v, 3) float64 metres, faces (m, 3) int.
    k : int
        Neighbourhood size (default ``defaults.EDGE_K`` = 16), the point itself included.
    rule : {"leave_one_out", "pauly"}
        Edge-point rule; see ``detect_edges``.
    threshold : float, optional
        Threshold of the rule (defaults in ``metrics.defaults``).
    feature_angle_deg : float, degrees
        Dihedral angle above which a truth edge is a feature edge (default 30).
    tolerance : float, optional, metres
        Edge tolerance t. Give at most one of ``tolerance`` and ``tolerance_fraction``.
    tolerance_fraction : float, optional
        t as a fraction of the truth's bounding-box diagonal (default
        ``defaults.EDGE_TOLERANCE_FRACTION`` = 0.01).

    Returns
    -------
    EdgeReport
    """
    return edge_report(as_points(points, "points"), as_mesh(truth, "truth"), k=k, rule=rule,
                       threshold=threshold, feature_angle_deg=feature_angle_deg,
                       tolerance=tolerance, tolerance_fraction=tolerance_fraction)


def edge_report(points: np.ndarray, mesh: Mesh, *, k: int = defaults.EDGE_K,
                rule: EdgeRule = "leave_one_out", threshold: float | None = None,
                feature_angle_deg: float = defaults.FEATURE_ANGLE_DEG,
                tolerance: float | None = None,
                tolerance_fraction: float | None = None) -> EdgeReport:
    """``edge_score`` of points and a mesh already validated (``inputs.as_points`` and
    ``inputs.as_mesh``), as ``metrics.score`` passes them; the options are still checked."""
    diagonal = bbox_diagonal(mesh.vertices)
    t = resolve_length(tolerance, tolerance_fraction, defaults.EDGE_TOLERANCE_FRACTION,
                       diagonal, "tolerance")
    k = _check_k(k, len(points))
    rule, threshold = _check_rule(rule, threshold, k)
    is_edge, variation = _detect_edges(points, k, rule, threshold)
    edges = _feature_edges(mesh, feature_angle_deg)
    length = float(np.linalg.norm(mesh.vertices[edges[:, 1]] - mesh.vertices[edges[:, 0]],
                                  axis=1).sum())
    if len(edges):
        samples, weight = _edge_samples(mesh, edges, t / defaults.EDGE_SAMPLES_PER_TOLERANCE)
        near = nearest_distance(samples, points) <= t
        if is_edge.any():
            found = nearest_distance(points[is_edge], samples) <= t
        else:
            found = np.zeros(len(samples), dtype=bool)
        missed = float(weight[~found].sum() / weight.sum())
    else:
        near = np.zeros(len(points), dtype=bool)
        missed = None
    far = ~near
    false_rate = float((is_edge & far).sum() / far.sum()) if far.any() else None
    terms = [x for x in (false_rate, missed) if x is not None]
    score = float(np.mean(terms)) if terms else 0.0
    return EdgeReport(
        score=score, false_edge_rate=false_rate, missed_edge_rate=missed,
        n_points=len(points), n_edge_points=int(is_edge.sum()), n_feature_edges=len(edges),
        feature_edge_length_m=length, tolerance_m=t, k=variation.k, rule=rule,
        threshold=threshold, is_edge=is_edge, near_edge=near, variation=variation)


def check_options(n_points: int, diagonal: float, *, k: int = defaults.EDGE_K,
                  rule: EdgeRule = "leave_one_out", threshold: float | None = None,
                  feature_angle_deg: float = defaults.FEATURE_ANGLE_DEG,
                  tolerance: float | None = None,
                  tolerance_fraction: float | None = None) -> None:
    """Validate ``edge_score`` options for a cloud of ``n_points`` before any work is done.

    Raises
    ------
    MetricsInputError
        The first bad option, named.
    """
    _check_rule(rule, threshold, _check_k(k, n_points))
    if not (isinstance(feature_angle_deg, int | float) and 0.0 <= feature_angle_deg < 180.0):
        raise MetricsInputError(
            f"feature_angle_deg must be in [0, 180), got {feature_angle_deg!r}")
    resolve_length(tolerance, tolerance_fraction, defaults.EDGE_TOLERANCE_FRACTION, diagonal,
                   "tolerance")


def resolve_length(value, fraction, default_fraction: float, diagonal: float, name: str) -> float:
    """A length given in metres (``value``) or as a fraction of the truth diagonal.

    Raises
    ------
    MetricsInputError
        Both given, or a value that is not a finite positive number.
    """
    if value is not None and fraction is not None:
        raise MetricsInputError(f"give {name} or {name}_fraction, not both")
    if value is not None:
        if not _positive_finite(value):
            raise MetricsInputError(f"{name} must be a finite length > 0 metres, got {value!r}")
        return float(value)
    fraction = default_fraction if fraction is None else fraction
    if not _positive_finite(fraction):
        raise MetricsInputError(f"{name}_fraction must be a finite number > 0, got {fraction!r}")
    return float(fraction) * diagonal


def _positive_finite(value) -> bool:
    return (isinstance(value, int | float | np.integer | np.floating)
            and not isinstance(value, bool) and bool(np.isfinite(value)) and value > 0)
