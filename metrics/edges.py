"""The paper's edge metric: how well a point cloud reconstructs the truth triangulation's edges.

What the paper says of its metric (Nayak, Udrea, Marsella and Beck): it "calculates how well the
triangulation of the ellipsoid is reconstructed from the point cloud"; scores lie in [0, 1],
lower is better, and "rough shapes can be reconstructed from point clouds that score below 0.3";
a point is an edge point when, "by removing a point from its neighborhood, the surface variance
of the neighborhood is lowered by some threshold". The authors' earlier paper (Nayak, Beck and
Udrea, IEEE Aerospace Conference 2013) calls it a "weighted edge reconstruction metric". The
formula is not published; what follows builds it from those words, and marks *(ours)* what the
words leave open.

Edge points (Pauly, Gross and Kobbelt, "Efficient simplification of point-sampled surfaces",
2002; the paper's reference 4): for a point and its k nearest neighbours (itself included), the
surface variation is ``sigma = l0 / (l0 + l1 + l2)``, with ``l0 <= l1 <= l2`` the eigenvalues of
the neighbourhood's covariance: 0 on a plane, up to 1/3 for an isotropic blob.

- ``rule="leave_one_out"`` (the paper's rule): a point is an edge point when removing it from its
  own neighbourhood lowers sigma by more than ``threshold``. The covariance without the point is a
  rank-one downdate of the neighbourhood's, ``S' = S - k / (k - 1) d d^T`` with ``d`` the point's
  offset from the neighbourhood mean and ``S`` the scatter matrix, so no neighbourhood is
  recomputed.
- ``rule="pauly"``: a point is an edge point when sigma itself exceeds ``threshold``.

Truth edges ("the triangulation"): every interior edge of the truth mesh, with its dihedral angle
theta, the angle between the unit normals of its two faces (0 where they are coplanar, 90 deg on
a box, 2 to 5 deg between the facets of the paper's 20,480-face ellipsoid). Boundary edges (one
face) have no angle and do not count: surface variation cannot see the rim of a flat sheet.

Weights *(ours: the paper says "weighted", not by what)*: an edge weighs its length times theta
(radians). Half the sum of length x theta over a polyhedron's edges is its integrated mean
curvature (Steiner's formula), and over a finely triangulated smooth surface it converges to
the integral of the mean curvature: a region weighs the turning of the surface there, however
finely the truth was triangulated. A satellite's 90 deg edges outweigh a 5 deg asteroid facet
edge of the same length 18 times; coplanar edges (a box face's diagonal) weigh nothing; on the
smooth asteroid every facet edge counts, the most curved tips most.

Reconstructed *(ours)*: a *feature edge* (theta > ``feature_angle_deg``, 30 deg) is reconstructed
where an edge point lies within t of it: the detector must see it (calibrated in
``metrics.defaults``: at k = 16 it flags 64 % of the points of a 30 deg crease and 88 % of a
90 deg one). A gentler edge is reconstructed where any test point lies within t of it: no
surface-variation threshold separates a 5 deg crease from curvature or noise (a point on a 5 deg
crease lowers sigma by 2e-5 when removed, 25 times less than the threshold; 10 deg: 8e-5), so
what a cloud can do for a gentle edge is to sample it, which lets a surface be rebuilt on both
sides.

The score (``edge_score``), in [0, 1], lower is better::

    t     = tolerance_fraction * (truth bounding-box diagonal)
    w_e   = length_e * theta_e                      weight of truth edge e
    R     = the points of the truth edges that are reconstructed (above)
    MER   = (sum of w over the edge length outside R) / (sum of w over all edges)   missed edges
    near  = the test points within t of a feature edge
    FER   = |edge points that are not near| / |test points that are not near|     false edges
    score = (FER + MER) / 2   the balanced error rate of the point-wise edge classification,
                              with the positive class counted along the weighted truth edges
    score = FER               when no truth edge has weight (a flat sheet)
    score = MER               when every test point is near a feature edge

So on the smooth asteroid the score is half the curvature-weighted share of the triangulation
no point comes within t of, plus half the fraction of false edge points (noise); on a satellite
it is dominated by its sharp edges, which only detected edge points reconstruct. On a body whose
edges are all either coplanar or of one sharp angle (a box) it equals the feature-edge score.

``feature_edge_score`` (``variant="feature"``) is the metric as first built here: only feature
edges count, each by its length, reconstructed where an edge point lies within t. A smooth body
has no feature edge, so it scores the false-edge rate alone: 0 for every noise-free asteroid
cloud.

Defaults (``metrics.defaults``): k = 16; leave-one-out threshold 0.0005 at k = 16 (scaled by
16 / k for other k); Pauly threshold 0.03; feature angle 30 degrees; t = 1 % of the truth's
bounding-box diagonal. "Within t" is decided against points every t / 8 along the truth edges
(to within t / 16).

FER rises with noise (every point of a noisy neighbourhood looks like an outlier), with thin
plates (neighbourhoods straddle both faces, the paper's solar-panel discussion) and with sparse
sampling of curved surfaces; MER rises with holes and with sampling too sparse to place points
(or, on feature edges, edge points) within t of an edge. Neighbourhoods are k nearest points
(their radius follows the local density), t is a fraction of the truth's size and the weights
are ratios, so the score has no length scale: a cloud and truth scaled together score the same.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from formats.errors import InputError
from metrics import defaults
from metrics.inputs import Mesh, as_mesh, as_points, bbox_diagonal, face_normals
from metrics.precision import (
    EDGE_SALT,
    far_sample_fraction,
    far_share_points,
    point_keys,
    proportion_se,
    smallest_keys,
)
from metrics.spatial import (
    PointIndex,
    distinct_points,
    morton_order,
    nearest_distance,
    within,
)

EdgeRule = Literal["leave_one_out", "pauly"]
EdgeVariant = Literal["weighted", "feature"]
_RULES = ("leave_one_out", "pauly")
VARIANTS = ("weighted", "feature")


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
    """Result of ``edge_score`` and ``feature_edge_score``.

    Attributes
    ----------
    score : float
        In [0, 1], lower is better (formula in the module docstring).
    score_se : float
        Its standard error: the false-edge rate's over the number of terms (0 when every far
        point was tested; the missed-edge rate is exact).
    false_edge_rate : float or None
        FER; None when every test point is near a feature edge.
    false_edge_rate_se : float or None
        Its standard error when it is estimated from a sample of the far points (without
        replacement: 0 when all were tested).
    n_far, n_far_tested : int
        Test points not within t of a feature edge, and those of them whose edge test ran
        (all of them unless ``metrics.score`` sampled them to its stated precision).
    missed_edge_rate : float or None
        MER, weighted; None when no truth edge has weight.
    feature_missed_rate : float or None
        Fraction of the feature edges' length not reconstructed (no edge point within t): the
        feature variant's MER; None when the truth has no feature edge.
    variant : {"weighted", "feature"}
    n_points, n_edge_points : int
        Test points, and those classified as edge points (among the points tested: all but
        the far points left out of a sample, ``n_far - n_far_tested``).
    n_truth_edges : int
        Truth edges that count (weighted: every edge that is not coplanar; feature: the
        feature edges).
    n_feature_edges : int
        Truth edges sharper than ``feature_angle_deg``.
    feature_edge_length_m : float
    truth_edge_weight : float
        Sum of the weights, metre-radians (weighted) or metres (feature).
    feature_weight_fraction : float or None
        Share of that weight on feature edges (None when no edge has weight).
    tolerance_m : float
    feature_angle_deg : float
    k : int
    rule : str
    threshold : float
    is_edge : (n,) bool or None
        Edge points of the test cloud (None when it was streamed, ``metrics.edges_stream``).
    near_edge : (n,) bool or None
        Test points within the tolerance of a truth feature edge (None when streamed).
    truth_edges : (e, 2) int64
        Vertex pairs of the truth edges that count.
    edge_angle_deg : (e,) float64, degrees
        Their dihedral angles.
    edge_found : (e,) float64, in [0, 1]
        Fraction of each edge's length that is reconstructed.
    variation : SurfaceVariation or None
        None when streamed.
    """

    score: float
    score_se: float
    false_edge_rate: float | None
    false_edge_rate_se: float | None
    n_far: int
    n_far_tested: int
    missed_edge_rate: float | None
    feature_missed_rate: float | None
    variant: str
    n_points: int
    n_edge_points: int
    n_truth_edges: int
    n_feature_edges: int
    feature_edge_length_m: float
    truth_edge_weight: float
    feature_weight_fraction: float | None
    tolerance_m: float
    feature_angle_deg: float
    k: int
    rule: str
    threshold: float
    is_edge: np.ndarray | None = field(repr=False)
    near_edge: np.ndarray | None = field(repr=False)
    truth_edges: np.ndarray = field(repr=False)
    edge_angle_deg: np.ndarray = field(repr=False)
    edge_found: np.ndarray = field(repr=False)
    variation: SurfaceVariation | None = field(repr=False)

    def to_dict(self) -> dict:
        """The scalar fields, JSON-ready."""
        return {name: getattr(self, name) for name in (
            "score", "score_se", "false_edge_rate", "false_edge_rate_se", "n_far",
            "n_far_tested", "missed_edge_rate", "feature_missed_rate", "variant",
            "n_points", "n_edge_points", "n_truth_edges", "n_feature_edges",
            "feature_edge_length_m", "truth_edge_weight", "feature_weight_fraction",
            "tolerance_m", "feature_angle_deg", "k", "rule", "threshold")}


def _check_k(k, n_points: int) -> int:
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 4:
        raise InputError(f"k must be an integer >= 4, got {k!r}", argument="k")
    if n_points < k:
        raise InputError(f"points has {n_points} rows, fewer than k = {k} neighbours")
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
    Per block of points: k-nearest neighbours (``spatial.PointIndex``, all cores; ties in distance
    broken by the points' coordinates, ``nearest_k``), the six distinct
    entries of each neighbourhood's scatter matrix from coordinate-major offsets, the scatter
    without the point by a rank-one downdate, and the smallest eigenvalue of both in closed form
    (``_smallest_eigenvalue``).
    """
    points = as_points(points, "points")
    return _surface_variation(points, _check_k(k, len(points)))[0]


def _surface_variation(points: np.ndarray, k: int, tested=None):
    """``surface_variation`` of points and k already validated.

    ``tested``, when given, is called with the Morton order of the points and the points in
    that order, and returns which of them (bool, in that order) to compute: the neighbourhoods
    are still the whole cloud's, the others' sigma, drop and radius are NaN.

    Returns
    -------
    variation : SurfaceVariation
    tree : spatial.PointIndex
        Over the distinct points (``spatial.distinct_points``) in Morton order, for later
        nearest-point queries.
    order : (n,) int64
        The Morton order of the points.
    ordered : (n, 3) float64
        ``points[order]``.
    """
    order = morton_order(points)
    ordered = points[order]
    tree, copies = copy_tree(ordered)
    columns = np.ascontiguousarray(tree.data.T)  # (3, d): each coordinate's gathers contiguous
    # The queries coordinate-major too: the offsets' memory layout sets neighbourhood_variation's
    # summation order, hence its last bits.
    rows = None if tested is None else np.flatnonzero(tested(order, ordered))
    chosen = ordered if rows is None else ordered[rows]   # every point: no copy
    queries = np.ascontiguousarray(chosen.T)
    out = np.full((3, len(points)), np.nan)
    step = max(1, defaults.EDGE_BLOCK)
    for lo in range(0, len(chosen), step):  # blocks of points, bounded memory; each vectorised
        sl = slice(lo, lo + step)
        at = sl if rows is None else rows[sl]
        dist, idx = nearest_k(tree, chosen[sl], k, copies)
        out[:2, at] = neighbourhood_variation(neighbour_offsets(columns, idx, queries[:, sl]))
        out[2, at] = dist[:, -1]
    out[:, order] = out.copy()
    return SurfaceVariation(sigma=out[0], drop=out[1], radius=out[2], k=k), tree, order, ordered


def copy_tree(points: np.ndarray):
    """Nearest-neighbour index over the distinct points, and how many copies each stands for.

    Parameters
    ----------
    points : (n, 3) float64, best in Morton order (the tree keeps it when none repeats)

    Returns
    -------
    tree : spatial.PointIndex
        Over the distinct points (in Morton order when some repeat; else ``points``).
    copies : (d,) int64 or None
        Copies per row of ``tree.data``; None when there are none (every count 1).
    """
    distinct, copies = distinct_points(points, counts=True)
    if len(distinct) == len(points):
        return PointIndex(points), None
    order = morton_order(distinct)
    return PointIndex(distinct[order]), copies[order]


def nearest_k(tree, queries: np.ndarray, k: int, copies: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
    """The k nearest points of an index to each query, in canonical order.

    Sorted by distance, equal distances by the points' x, then y, then z: the neighbourhood
    and its order depend on the point set alone, not on the tree that holds it (nor on the
    order of its points), so a neighbourhood found among a subset holding every point within
    its k-th distance is the whole cloud's, bit for bit (``metrics.edges_stream``). Points that
    tie in distance and coordinates are copies of one point: which copy is taken changes
    nothing. Rows whose (k + 1)-th distance equals their k-th are asked again for twice as
    many points until every point at the k-th distance is among them (a grid's rows; rare in
    measured clouds).

    Parameters
    ----------
    tree : spatial.PointIndex
        Over n >= k points (with ``copies``: n distinct points standing for ``copies.sum()``
        >= k).
    queries : (m, 3) float64
    k : int
    copies : (n,) int64, optional
        How many copies of the cloud each row of ``tree.data`` stands for (``copy_tree``):
        the neighbours are those of the cloud with its copies, a row repeated once per copy.
        A KD-tree cannot split copies, so one holding them is quadratic in their number.

    Returns
    -------
    dist : (m, k) float64, ascending
    idx : (m, k) int64, rows of ``tree.data``
    """
    if copies is not None:
        dist, idx = nearest_k(tree, queries, min(k, tree.n))
        # Slot j of the cloud's neighbourhood is distinct neighbour i while the copies of
        # neighbours 0..i first exceed j (copies are adjacent in the canonical order).
        reach = np.cumsum(copies[idx], axis=1)
        slot = (reach[:, :, None] <= np.arange(k)).sum(axis=1)
        return np.take_along_axis(dist, slot, axis=1), np.take_along_axis(idx, slot, axis=1)
    n = tree.n
    want = min(k + 1, n)
    dist, idx = tree.knn(queries, want)
    tied = np.flatnonzero((dist[:, 1:] == dist[:, :-1]).any(axis=1))
    out_dist, out_idx = dist[:, :k].copy(), idx[:, :k].copy()
    rows, dist, idx = tied, dist[tied], idx[tied]
    while rows.size:
        # Complete: every point at the k-th distance is a candidate; or that distance is 0,
        # so the k nearest are all copies of the query (a log repeating one strike).
        complete = (dist[:, -1] > dist[:, k - 1]) | (dist[:, k - 1] == 0) | (idx.shape[1] == n)
        near = tree.data[idx[complete]]
        pick = np.lexsort((near[..., 2], near[..., 1], near[..., 0], dist[complete]),
                          axis=-1)[:, :k]
        out_dist[rows[complete]] = np.take_along_axis(dist[complete], pick, axis=1)
        out_idx[rows[complete]] = np.take_along_axis(idx[complete], pick, axis=1)
        rows = rows[~complete]
        if rows.size:
            dist, idx = tree.knn(queries[rows], min(2 * idx.shape[1], n))
    return out_dist, out_idx


def neighbour_offsets(columns: np.ndarray, idx: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """Each neighbourhood's points relative to its query, coordinate-major.

    ``columns[:, idx] - queries[:, :, None]`` bit for bit, one ``np.take`` per coordinate into
    the result (fancy indexing of the (3, n) array cost 2-10x more).

    Parameters
    ----------
    columns : (3, n) float64, metres
        The indexed points, coordinate-major.
    idx : (b, k) int64
        Rows of the neighbours.
    queries : (3, b) float64, metres

    Returns
    -------
    (3, b, k) float64, metres
    """
    offset = np.empty((3, *idx.shape))
    for axis in range(3):  # three coordinates, each a batched gather
        np.take(columns[axis], idx, out=offset[axis])
        offset[axis] -= queries[axis, :, None]
    return offset


def neighbourhood_variation(offset: np.ndarray) -> np.ndarray:
    """Surface variation of neighbourhoods and its leave-one-out drop.

    Parameters
    ----------
    offset : (3, b, k) float64, metres
        Each neighbourhood's points (the point itself among them) relative to the point,
        coordinate-major.

    Returns
    -------
    (2, b) float64
        sigma and drop.
    """
    k = offset.shape[2]
    downdate = k / (k - 1.0)
    pairs = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))
    total = offset.sum(axis=2)
    mean = total / k
    # Scatter entries: sum of products minus the mean term (offsets are small, so the
    # subtraction loses nothing), then the same without the point (at the local origin,
    # offset -mean from the neighbourhood mean).
    scatter = [np.einsum("bk,bk->b", offset[i], offset[j]) - total[i] * mean[j]
               for i, j in pairs]
    without = [s - downdate * mean[i] * mean[j] for s, (i, j) in zip(scatter, pairs,
                                                                    strict=True)]
    sigma = _variation(scatter)
    return np.stack([sigma, sigma - _variation(without)])


def _variation(entries) -> np.ndarray:
    """l0 / (l0 + l1 + l2) of symmetric 3 x 3 matrices given as their six entries
    (xx, yy, zz, xy, yz, xz), each (b,); 0 where the trace is 0."""
    trace = entries[0] + entries[1] + entries[2]
    smallest = np.maximum(_smallest_eigenvalue(*entries), 0.0)  # rounding can make it < 0
    return np.divide(smallest, trace, out=np.zeros_like(trace), where=trace > 0)


def _smallest_eigenvalue(a, b, c, d, e, f) -> np.ndarray:
    """Smallest eigenvalue of symmetric 3 x 3 matrices [[a, d, f], [d, b, e], [f, e, c]].

    Closed form (O. K. Smith, "Eigenvalues of a symmetric 3 x 3 matrix", CACM 1961): with
    q = trace / 3 and p the scaled Frobenius norm of A - qI, the eigenvalues are
    q + 2 p cos(phi + 2 pi j / 3), phi = acos(det((A - qI) / p) / 2) / 3; the smallest is j = 1.
    Its absolute error is a few float64 epsilons of p (the near-zero eigenvalue of a flat
    neighbourhood sits where the cosine is flat); about 4x faster than batched LAPACK
    ``eigvalsh``.
    """
    q = (a + b + c) / 3.0
    aq, bq, cq = a - q, b - q, c - q
    p = np.sqrt((aq * aq + bq * bq + cq * cq + 2.0 * (d * d + e * e + f * f)) / 6.0)
    det = aq * (bq * cq - e * e) - d * (d * cq - e * f) + f * (d * e - bq * f)
    cube = 2.0 * p**3
    r = np.divide(det, cube, out=np.zeros_like(det), where=cube > 0)
    phi = np.arccos(np.clip(r, -1.0, 1.0)) / 3.0
    return q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)


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
    variation = _surface_variation(points, k)[0]
    return _classify(variation, rule, threshold), variation


def _classify(variation: SurfaceVariation, rule: str, threshold: float) -> np.ndarray:
    value = variation.drop if rule == "leave_one_out" else variation.sigma
    return value > threshold


def _check_rule(rule, threshold, k) -> tuple[str, float]:
    if rule not in _RULES:
        raise InputError(f"rule must be one of {_RULES}, got {rule!r}")
    if threshold is None:
        threshold = default_threshold(rule, k)
    if not (isinstance(threshold, int | float | np.integer | np.floating)
            and not isinstance(threshold, bool) and np.isfinite(threshold) and threshold >= 0):
        raise InputError(f"threshold must be a finite number >= 0, got {threshold!r}",
                         argument="threshold")
    return rule, float(threshold)


def _check_variant(variant) -> str:
    if variant not in VARIANTS:
        raise InputError(f"variant must be one of {VARIANTS}, got {variant!r}",
                         argument="variant")
    return variant


def _check_angle(angle_deg) -> float:
    if not (isinstance(angle_deg, int | float | np.integer | np.floating)
            and not isinstance(angle_deg, bool) and 0.0 <= angle_deg < 180.0):
        raise InputError(f"feature_angle_deg must be in [0, 180), got {angle_deg!r}",
                         argument="feature_angle_deg")
    return float(angle_deg)


def default_threshold(rule: EdgeRule, k: int) -> float:
    """Default threshold of an edge rule for neighbourhood size k (see ``metrics.defaults``).

    ``leave_one_out``: ``EDGE_DROP_THRESHOLD * EDGE_K / k`` (a crease point's drop scales as
    about 1 / k); ``pauly``: ``EDGE_SIGMA_THRESHOLD``.
    """
    if rule == "leave_one_out":
        return defaults.EDGE_DROP_THRESHOLD * defaults.EDGE_K / k
    return defaults.EDGE_SIGMA_THRESHOLD


def dihedral_edges(truth) -> tuple[np.ndarray, np.ndarray]:
    """Interior edges of a triangle mesh and their dihedral angles.

    The angle of an edge is the angle between the unit normals of its two faces (0 where the
    faces are coplanar, 90 degrees on a box). Boundary edges (one face) are left out.
    Non-manifold edges (three or more faces) take the largest angle between their first face
    and each other face. A degenerate face (zero normal) meets its neighbours at 90 degrees.

    Parameters
    ----------
    truth : Mesh or (vertices, faces)

    Returns
    -------
    edges : (e, 2) int64
        Vertex index pairs (lower index first), sorted, unique.
    angle_deg : (e,) float64, degrees, in [0, 180]
    """
    return _dihedral_edges(as_mesh(truth, "truth"))


def _dihedral_edges(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """``dihedral_edges`` of a mesh already validated.

    Each edge is one int64 key (``low * n + high``, n vertices); one stable sort of the keys
    groups an edge's faces, in face order (the row-wise ``np.unique`` it replaces gave the same
    groups and order at twice the cost).
    """
    normals = face_normals(mesh.vertices, mesh.faces)
    edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    key = edges[:, 0] * (int(edges.max(initial=0)) + 1) + edges[:, 1]
    order = np.argsort(key, kind="stable")
    owner = order // 3  # the face of each sorted edge
    key = key[order]
    first = np.concatenate([[True], key[1:] != key[:-1]])
    start = np.flatnonzero(first)
    counts = np.diff(np.append(start, len(key)))
    # Compare every face of an edge with the first face of that edge: exact for manifold edges
    # (two faces); for non-manifold ones it takes the pairs involving the first face.
    first_face = owner[start][np.cumsum(first) - 1]
    cos = np.einsum("ij,ij->i", normals[first_face], normals[owner])
    cos = np.where(first_face != owner, cos, 1.0)
    least = np.minimum.reduceat(cos, start) if len(start) else cos[:0]
    interior = counts >= 2
    angle = np.degrees(np.arccos(np.clip(least[interior], -1.0, 1.0)))
    return edges[order[start]][interior], angle


def feature_edges(truth, *, angle_deg: float = defaults.FEATURE_ANGLE_DEG) -> np.ndarray:
    """Feature edges of a triangle mesh: interior edges with a dihedral angle above a threshold.

    Parameters
    ----------
    truth : Mesh or (vertices, faces)
    angle_deg : float, degrees, in [0, 180)

    Returns
    -------
    (e, 2) int64
        Vertex index pairs (lower index first), sorted, unique (see ``dihedral_edges``).
    """
    angle_deg = _check_angle(angle_deg)
    edges, angle = _dihedral_edges(as_mesh(truth, "truth"))
    return edges[angle > angle_deg]


def _edge_samples(vertices: np.ndarray, edges: np.ndarray, spacing: float):
    """Points every ``spacing`` (at most) along edges, at sub-segment midpoints.

    Returns
    -------
    points : (s, 3) float64
    length : (s,) float64, metres of edge each point stands for
    which : (s,) int64, the edge of each point
    """
    a = vertices[edges[:, 0]]
    b = vertices[edges[:, 1]]
    length = np.linalg.norm(b - a, axis=1)
    count = np.maximum(np.ceil(length / spacing), 1).astype(np.int64)
    which = np.repeat(np.arange(len(edges)), count)
    position = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    t = (position + 0.5) / count[which]
    points = a[which] + t[:, None] * (b - a)[which]
    return points, (length / count)[which], which


def edge_score(points, truth, *, k: int = defaults.EDGE_K, rule: EdgeRule = "leave_one_out",
               threshold: float | None = None,
               feature_angle_deg: float = defaults.FEATURE_ANGLE_DEG,
               tolerance: float | None = None,
               tolerance_fraction: float | None = None,
               variant: EdgeVariant = "weighted") -> EdgeReport:
    """The paper's weighted edge metric of a point cloud against a truth mesh (module docs).

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
        Dihedral angle above which a truth edge is a feature edge (default 30): reconstructed
        only by edge points, and the edges false edge points are counted against.
    tolerance : float, optional, metres
        Edge tolerance t. Give at most one of ``tolerance`` and ``tolerance_fraction``.
    tolerance_fraction : float, optional
        t as a fraction of the truth's bounding-box diagonal (default
        ``defaults.EDGE_TOLERANCE_FRACTION`` = 0.01).
    variant : {"weighted", "feature"}
        ``weighted``: every edge of the triangulation, weighted by length x dihedral angle
        (the paper's metric). ``feature``: feature edges only, by length
        (``feature_edge_score``).

    Returns
    -------
    EdgeReport
    """
    return edge_report(as_points(points, "points"), as_mesh(truth, "truth"), k=k, rule=rule,
                       threshold=threshold, feature_angle_deg=feature_angle_deg,
                       tolerance=tolerance, tolerance_fraction=tolerance_fraction,
                       variant=variant)


def feature_edge_score(points, truth, **options) -> EdgeReport:
    """The feature-edge variant: ``edge_score(points, truth, variant="feature", **options)``.

    Only truth edges sharper than ``feature_angle_deg`` count, each by its length; a smooth body
    has none and scores its false-edge rate alone.
    """
    return edge_score(points, truth, variant="feature", **options)


def edge_report(points: np.ndarray, mesh: Mesh, *, k: int = defaults.EDGE_K,
                rule: EdgeRule = "leave_one_out", threshold: float | None = None,
                feature_angle_deg: float = defaults.FEATURE_ANGLE_DEG,
                tolerance: float | None = None,
                tolerance_fraction: float | None = None,
                variant: EdgeVariant = "weighted", precision: float | None = None,
                seed: int = 0) -> EdgeReport:
    """``edge_score`` of points and a mesh already validated (``inputs.as_points`` and
    ``inputs.as_mesh``), as ``metrics.score`` passes them; the options are still checked.
    A cloud given block by block: ``metrics.edges_stream.EdgeStream`` (the same report in
    memory that does not grow with the cloud).

    With a ``precision``, only a sample of the points far from feature edges is tested (those
    whose ``precision.point_keys`` under ``seed`` fall below ``precision.far_sample_fraction``
    of the share of far points among the ``far_share_points`` smallest keys) and every point
    near one: the missed-edge rates stay exact (they depend on the near points alone), the
    false-edge rate is that of the sample, with its standard error; the per-point ``is_edge``
    and ``variation`` are then None unless every point was tested."""
    t = resolve_length(tolerance, tolerance_fraction, defaults.EDGE_TOLERANCE_FRACTION,
                       bbox_diagonal(mesh.vertices), "tolerance")
    k = _check_k(k, len(points))
    rule, threshold = _check_rule(rule, threshold, k)
    variant = _check_variant(variant)
    feature_angle_deg = _check_angle(feature_angle_deg)
    side = TruthEdges.of(mesh, t, feature_angle_deg, variant)
    samples, on_sharp = side.samples, side.on_sharp
    near = np.zeros(len(points), dtype=bool)

    def tested(order: np.ndarray, ordered: np.ndarray) -> np.ndarray:
        """Near points (all of them marked in ``near``) and the sample of the far ones."""
        if on_sharp.any():
            near[order] = within(side.sharp_tree(), ordered, t, presorted=True)
        if precision is None:
            return np.ones(len(ordered), dtype=bool)
        keys = point_keys(points, seed, EDGE_SALT)
        share = float(np.mean(~near[smallest_keys(keys, far_share_points(precision))]))
        fraction = far_sample_fraction(len(points), share, precision)
        return (near | (keys < fraction))[order]

    variation, tree = _surface_variation(points, k, tested)[:2]
    checked = ~np.isnan(variation.drop)
    is_edge = _classify(variation, rule, threshold)
    # Reconstructed: feature-edge samples need an edge point within t, the others any point.
    found = np.zeros(len(samples), dtype=bool)
    if is_edge.any() and on_sharp.any():
        found[on_sharp] = nearest_distance(points[is_edge], samples[on_sharp]) <= t
    if (~on_sharp).any():
        found[~on_sharp] = within(tree, samples[~on_sharp], t)
    far = ~near
    whole = bool(checked.all())
    return side.report(found, n_points=len(points), n_edge_points=int(is_edge.sum()),
                       n_far=int(far.sum()), n_false_edges=int((is_edge & far).sum()), k=k,
                       rule=rule, threshold=threshold, is_edge=is_edge if whole else None,
                       near_edge=near, variation=variation if whole else None,
                       n_far_tested=int((far & checked).sum()))


@dataclass(frozen=True)
class TruthEdges:
    """The truth side of the edge metric: its counted edges and their samples every t / 8.

    Attributes
    ----------
    tolerance_m, feature_angle_deg : float
    variant : str
    edges : (e, 2) int64
        The counted truth edges (vertex pairs).
    angle : (e,) float64, degrees
    sharp : (e,) bool
        Feature edges.
    lengths : (e,) float64, metres
    samples : (s, 3) float64, metres
        Points along the edges (``_edge_samples``).
    sample_length : (s,) float64, metres of edge each sample stands for
    which : (s,) int64, the edge of each sample
    on_sharp : (s,) bool, samples on feature edges
    """

    tolerance_m: float
    feature_angle_deg: float
    variant: str
    edges: np.ndarray
    angle: np.ndarray
    sharp: np.ndarray
    lengths: np.ndarray
    samples: np.ndarray
    sample_length: np.ndarray
    which: np.ndarray
    on_sharp: np.ndarray

    @classmethod
    def of(cls, mesh: Mesh, t: float, feature_angle_deg: float, variant: str) -> TruthEdges:
        """The counted edges of a validated mesh at tolerance t (metres), options checked."""
        edges, angle = _dihedral_edges(mesh)
        sharp = angle > feature_angle_deg
        counted = sharp if variant == "feature" else angle > defaults.FLAT_EDGE_DEG
        edges, angle, sharp = edges[counted], angle[counted], sharp[counted]
        lengths = np.linalg.norm(mesh.vertices[edges[:, 1]] - mesh.vertices[edges[:, 0]],
                                 axis=1)
        samples, sample_length, which = _edge_samples(
            mesh.vertices, edges, t / defaults.EDGE_SAMPLES_PER_TOLERANCE)
        return cls(tolerance_m=t, feature_angle_deg=feature_angle_deg, variant=variant,
                   edges=edges, angle=angle, sharp=sharp, lengths=lengths, samples=samples,
                   sample_length=sample_length, which=which, on_sharp=sharp[which])

    def sharp_tree(self):
        """``PointIndex`` over the feature-edge samples (Morton order), for ``near`` queries."""
        return _tree(self.samples[self.on_sharp])

    def report(self, found: np.ndarray, *, n_points: int, n_edge_points: int, n_far: int,
               n_false_edges: int, k: int, rule: str, threshold: float,
               is_edge: np.ndarray | None = None, near_edge: np.ndarray | None = None,
               variation: SurfaceVariation | None = None,
               n_far_tested: int | None = None) -> EdgeReport:
        """The report from what the test cloud gave.

        Parameters
        ----------
        found : (s,) bool
            The samples reconstructed.
        n_points, n_edge_points : int
            Test points, and those that are edge points.
        n_far, n_false_edges : int
            Test points not within t of a feature edge, and the edge points among them.
        k, rule, threshold
            The edge rule's options, validated.
        is_edge, near_edge, variation
            Per-point results, when the cloud was held whole (None when streamed).
        n_far_tested : int, optional
            The far points whose edge test ran (default ``n_far``: all of them); the
            false-edge rate is that of these, with the standard error of a sample drawn
            without replacement from the ``n_far``.
        """
        variant, on_sharp, sample_length = self.variant, self.on_sharp, self.sample_length
        weight = (sample_length if variant == "feature"
                  else sample_length * np.radians(self.angle[self.which]))
        total_weight = float(weight.sum())
        missed = float(weight[~found].sum() / total_weight) if total_weight > 0 else None
        feature_length = float(sample_length[on_sharp].sum())
        feature_missed = (float(sample_length[on_sharp & ~found].sum() / feature_length)
                          if feature_length > 0 else None)
        edge_found = np.divide(np.bincount(self.which, weights=sample_length * found,
                                           minlength=len(self.edges)),
                               self.lengths, out=np.ones(len(self.edges)),
                               where=self.lengths > 0)
        tested = n_far if n_far_tested is None else n_far_tested
        false_rate = n_false_edges / tested if tested else None
        false_se = (None if false_rate is None
                    else proportion_se(false_rate, tested, population=n_far))
        terms = [x for x in (false_rate, missed) if x is not None]
        return EdgeReport(
            score=float(np.mean(terms)) if terms else 0.0,
            score_se=0.0 if false_se is None else false_se / len(terms),
            false_edge_rate=false_rate, false_edge_rate_se=false_se, n_far=n_far,
            n_far_tested=tested,
            missed_edge_rate=missed, feature_missed_rate=feature_missed, variant=variant,
            n_points=n_points, n_edge_points=n_edge_points, n_truth_edges=len(self.edges),
            n_feature_edges=int(self.sharp.sum()),
            feature_edge_length_m=float(self.lengths[self.sharp].sum()),
            truth_edge_weight=total_weight,
            feature_weight_fraction=(float(weight[on_sharp].sum() / total_weight)
                                     if total_weight > 0 else None),
            tolerance_m=self.tolerance_m, feature_angle_deg=self.feature_angle_deg, k=k,
            rule=rule, threshold=threshold, is_edge=is_edge, near_edge=near_edge,
            truth_edges=self.edges, edge_angle_deg=self.angle, edge_found=edge_found,
            variation=variation)


def _tree(points: np.ndarray):
    """``PointIndex`` over points in Morton order (faster queries; its data is reordered)."""
    return PointIndex(points[morton_order(points)])


def check_options(n_points: int, diagonal: float, *, k: int = defaults.EDGE_K,
                  rule: EdgeRule = "leave_one_out", threshold: float | None = None,
                  feature_angle_deg: float = defaults.FEATURE_ANGLE_DEG,
                  tolerance: float | None = None,
                  tolerance_fraction: float | None = None,
                  variant: EdgeVariant = "weighted") -> None:
    """Validate ``edge_score`` options for a cloud of ``n_points`` before any work is done.

    Raises
    ------
    InputError
        The first bad option, named.
    """
    _check_rule(rule, threshold, _check_k(k, n_points))
    _check_angle(feature_angle_deg)
    _check_variant(variant)
    resolve_length(tolerance, tolerance_fraction, defaults.EDGE_TOLERANCE_FRACTION, diagonal,
                   "tolerance")


def resolve_length(value, fraction, default_fraction: float, diagonal: float, name: str) -> float:
    """A length given in metres (``value``) or as a fraction of the truth diagonal.

    Raises
    ------
    InputError
        Both given, or a value that is not a finite positive number.
    """
    if value is not None and fraction is not None:
        raise InputError(f"give {name} or {name}_fraction, not both")
    if value is not None:
        if not _positive_finite(value):
            raise InputError(f"{name} must be a finite length > 0 metres, got {value!r}")
        return float(value)
    fraction = default_fraction if fraction is None else fraction
    if not _positive_finite(fraction):
        raise InputError(f"{name}_fraction must be a finite number > 0, got {fraction!r}")
    return float(fraction) * diagonal


def _positive_finite(value) -> bool:
    return (isinstance(value, int | float | np.integer | np.floating)
            and not isinstance(value, bool) and bool(np.isfinite(value)) and value > 0)
