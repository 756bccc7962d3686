"""``plane``: least-squares local plane fitting, then meshing of the planes' signed distance.

The paper's conclusion names least-squares plane fitting (its ref. 10, Hoppe et al. 1992) as the
way to reconstruct noisy, non-uniform LRF clouds. Two steps:

1. **Projection.** Each point's ``k`` nearest neighbours get a weighted least-squares plane:
   spatial weights ``(1 - (d / r_k)^2)^2`` (``r_k`` the distance to the k-th neighbour), times
   Tukey biweights of the residuals (iteratively reweighted, ``iterations`` rounds, scale
   1.4826 x the median absolute residual, Tukey's constant 4.685), times zero for neighbours
   whose oriented normal faces the other way (the far side of a thin panel), times (with
   ``weighted``) each neighbour's ``1 / sigma^2``, its recorded uncertainty along the normal
   (``MethodInput.sigma``, ``recon.surfaces.uncertainty``). The point moves
   onto its plane; the plane's normal keeps the input orientation. Noise along the normal
   shrinks roughly by the square root of the effective neighbour count. Where the neighbourhood
   of the normals had to grow to span a plane (LRF tracks, ``MethodInput.neighbours``), the
   plane uses that many neighbours. On curved surfaces a plane of neighbours within r lies
   about r^2 / 4R inside the surface; ``order = 2`` then projects onto a weighted least-squares
   quadratic height field over the plane instead, which removes that bias.
2. **Meshing.** Hoppe's signed distance to the tangent planes, ``f(x) = sum_j w_j n_j . (x -
   q_j) / sum_j w_j`` over the 6 nearest projected points ``q_j`` (Gaussian weights of width
   one cell), is sampled on a grid of ``cell`` x spacing only near the data and contoured by
   surface nets (``recon.surfaces.methods._contour``). Following Hoppe, nodes whose nearest point's
   tangent plane they overhang by more than the local sample gap get no value, so the surface
   stops where the data stop instead of inventing a closed blob. The automatic cell is one
   spacing, or ``CELL_NOISE`` x the noise when that is larger (``_backends.above_noise``): a
   cell finer than the projected points' residual scatter contours that scatter as extra sheets.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from formats.errors import MethodFailed
from recon.surfaces import uncertainty
from recon.surfaces._arrays import unique_sorted
from recon.surfaces.methods import Method, MethodInput, Param, register
from recon.surfaces.methods._backends import above_noise
from recon.surfaces.methods._contour import node_keys, surface_nets

# Tukey's biweight constant (95% efficiency under Gaussian noise; Holland and Welsch 1977) and
# the MAD-to-sigma factor of a Gaussian.
TUKEY_C = 4.685
MAD_TO_SIGMA = 1.4826
# Points per vectorised block: (block, k, 3) float64 arrays of about 30 MB at k = 30.
BLOCK_POINTS = 40_000
# Projected points blended per grid node (Hoppe uses 1; a few smooth the faceting).
BLEND_NEIGHBOURS = 6
# The automatic cell: CELL x spacing, at least CELL_NOISE x noise. 1 x spacing: a cell holds
# about one point (spacing = sqrt(area per point)); finer cells only resample the same planes.
# 2 x noise: on RSO-A's LRF cloud (77,400 points, noise 0.035 m at 0.048 m spacing) cells of
# one spacing gave 519k faces (6.7 per point), of 2 x noise (1.44 spacings) 269k for the same
# F-score (0.891 / 0.890; Chamfer 0.099 / 0.102 m), of 3 x noise 112k but F 0.872; on the
# asteroid LIDAR cloud (336k points, 0.73 m at 0.92 m) 1.2 M faces and 503k at 2 x noise
# (Chamfer 0.380 / 0.377 m, F 0.998 / 0.999). Measured with benchmarks/bench_methods.py's clouds.
CELL, CELL_NOISE = 1.0, 2.0
# Node offsets around each occupied cell: the cell's corners plus one ring.
BAND_OFFSETS = np.stack(np.meshgrid(*[np.arange(-1, 3)] * 3, indexing="ij"), -1).reshape(-1, 3)


def _fit_planes(neigh: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares planes of (b, k, 3) neighbourhoods.

    Returns the centroids (b, 3) and the covariance eigenvectors (b, 3, 3), columns in
    ascending eigenvalue order: column 0 is the unit normal, columns 1 and 2 span the plane.
    """
    total = np.maximum(weights.sum(axis=1), 1e-300)
    centroid = np.einsum("bk,bki->bi", weights, neigh) / total[:, None]
    centred = neigh - centroid[:, None, :]
    cov = np.einsum("bk,bki,bkj->bij", weights, centred, centred) / total[:, None, None]
    _, vectors = np.linalg.eigh(cov)
    return centroid, vectors


def _robust(residual: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Tukey biweights of (b, k) residuals, scale 1.4826 x their median absolute value."""
    scale = MAD_TO_SIGMA * np.median(np.abs(residual), axis=1, keepdims=True)
    u = residual / (TUKEY_C * np.maximum(scale, 1e-12 * radius))
    return np.where(np.abs(u) < 1, (1 - u * u) ** 2, 0.0)


def _quadric(u, v, h, weights, radius):
    """Weighted least-squares height fields h = a + b u + c v + d u^2 + e u v + f v^2.

    Coordinates are scaled by ``radius`` for conditioning; returns the (b, 6) coefficients in
    those scaled units.
    """
    s, t = u / radius, v / radius
    design = np.stack([np.ones_like(s), s, t, s * s, s * t, t * t], axis=2)   # (b, k, 6)
    normal = np.einsum("bk,bki,bkj->bij", weights, design, design)
    normal += 1e-9 * np.eye(6) * np.trace(normal, axis1=1, axis2=2)[:, None, None]
    rhs = np.einsum("bk,bki,bk->bi", weights, design, h)
    return np.linalg.solve(normal, rhs[..., None])[..., 0]


def project_to_planes(points: np.ndarray, normals: np.ndarray, *, k: int, iterations: int,
                      neighbours: np.ndarray | None = None, order: int = 1,
                      weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Move each point onto its robust weighted least-squares local plane.

    Parameters
    ----------
    points : (n, 3) float64, metres, body frame
    normals : (n, 3) float64
        Oriented unit normals (they only select neighbours on the same side and give signs).
    k : int
        Neighbours per plane (the point included).
    iterations : int
        Robust reweighting rounds after the first, spatially weighted fit.
    neighbours : (n,) int, optional
        Per-point neighbourhood sizes that span a plane (``MethodInput.neighbours``); each point
        uses ``max(k, neighbours)``.
    order : {1, 2}
        1: project onto the plane. 2: then onto a weighted least-squares quadratic height field
        over that plane, which removes the plane's curvature bias (on a sphere of radius R the
        plane of neighbours within r lies ~r^2 / 4R inside the surface).
    weights : (n,) float64, optional
        Per-point weights (``1 / sigma^2``, ``recon.surfaces.uncertainty.weights``).

    Returns
    -------
    projected : (n, 3) float64, metres
    plane_normals : (n, 3) float64
        Unit normals of the fitted planes, oriented like ``normals``.
    """
    n = len(points)
    sizes = np.full(n, min(int(k), n)) if neighbours is None else \
        np.minimum(np.maximum(int(k), neighbours), n)
    weights = np.ones(n) if weights is None else np.asarray(weights, dtype=np.float64)
    tree = cKDTree(points)
    projected = np.empty_like(points)
    plane_normals = np.empty_like(points)
    for size in np.unique(sizes):  # a few sizes (k doubled): one vectorised pass each
        group = np.flatnonzero(sizes == size)
        block = max(1, BLOCK_POINTS * 30 // int(size))
        for start in range(0, len(group), block):
            rows = group[start:start + block]
            d, idx = tree.query(points[rows], k=int(size), workers=-1)
            projected[rows], plane_normals[rows] = _project(points, normals, rows, d, idx,
                                                            iterations, order, weights)
    return projected, plane_normals


def _project(points, normals, rows, d, idx, iterations, order, weights
             ) -> tuple[np.ndarray, np.ndarray]:
    """Robust local fits of the neighbourhoods ``idx`` (b, k) of ``rows``; projections, normals."""
    neigh = points[idx]                                               # (b, k, 3)
    radius = np.maximum(d[:, -1:], 1e-300)
    spatial = (1.0 - np.clip(d / (radius * 1.0001), 0, 1) ** 2) ** 2
    same_side = np.einsum("bki,bi->bk", normals[idx], normals[rows]) > 0
    base = spatial * same_side * weights[idx]
    centroid, frame = _fit_planes(neigh, base)
    for _ in range(int(iterations)):
        residual = np.einsum("bki,bi->bk", neigh - centroid[:, None, :], frame[:, :, 0])
        centroid, frame = _fit_planes(neigh, base * _robust(residual, radius))
    normal = frame[:, :, 0]
    sign = np.where(np.einsum("bi,bi->b", normal, normals[rows]) < 0, -1.0, 1.0)
    normal = normal * sign[:, None]
    offset = np.einsum("bi,bi->b", points[rows] - centroid, normal)
    if order == 1:
        return points[rows] - offset[:, None] * normal, normal
    e1, e2 = frame[:, :, 1], frame[:, :, 2]
    local = neigh - centroid[:, None, :]
    u = np.einsum("bki,bi->bk", local, e1)
    v = np.einsum("bki,bi->bk", local, e2)
    h = np.einsum("bki,bi->bk", local, normal)
    weights = base
    coef = _quadric(u, v, h, weights, radius)
    for _ in range(int(iterations)):
        s, t = u / radius, v / radius
        fit = (coef[:, :1] + coef[:, 1:2] * s + coef[:, 2:3] * t + coef[:, 3:4] * s * s
               + coef[:, 4:5] * s * t + coef[:, 5:6] * t * t)
        weights = base * _robust(h - fit, radius)
        coef = _quadric(u, v, h, weights, radius)
    own = points[rows] - centroid
    s = np.einsum("bi,bi->b", own, e1) / radius[:, 0]
    t = np.einsum("bi,bi->b", own, e2) / radius[:, 0]
    a, b, c, dd, e, f = coef.T
    height = a + b * s + c * t + dd * s * s + e * s * t + f * t * t
    slope_u = (b + 2 * dd * s + e * t) / radius[:, 0]  # dh/du in metres per metre
    slope_v = (c + e * s + 2 * f * t) / radius[:, 0]
    moved = centroid + (s * radius[:, 0])[:, None] * e1 + (t * radius[:, 0])[:, None] * e2 \
        + height[:, None] * normal
    curved = normal - slope_u[:, None] * e1 - slope_v[:, None] * e2
    return moved, curved / np.linalg.norm(curved, axis=1, keepdims=True)


def signed_distance_mesh(points: np.ndarray, normals: np.ndarray, *, cell: float
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Contour Hoppe's signed distance to the tangent planes ``(points, normals)``.

    Parameters
    ----------
    points : (n, 3) float64, metres
        Points on their tangent planes (``project_to_planes``).
    normals : (n, 3) float64
        Outward unit plane normals.
    cell : float, metres
        Grid spacing.

    Returns
    -------
    (vertices, faces)
        The zero set of the signed distance to the planes, as ``_contour.surface_nets`` gives it.
    """
    origin = points.min(axis=0) - 3 * cell
    shape = tuple(int(s) for s in np.ceil((points.max(axis=0) - origin) / cell).astype(int) + 4)
    occupied = np.unique(np.floor((points - origin) / cell).astype(np.int64), axis=0)
    nodes = (occupied[:, None, :] + BAND_OFFSETS[None, :, :]).reshape(-1, 3)
    keys = unique_sorted(node_keys(nodes, shape))
    xyz = origin + cell * np.stack([keys // (shape[1] * shape[2]),
                                    (keys // shape[2]) % shape[1], keys % shape[2]], axis=1)
    tree = cKDTree(points)
    blend = min(BLEND_NEIGHBOURS, len(points))
    d, j = tree.query(xyz, k=blend, workers=-1)
    delta = xyz[:, None, :] - points[j]                                # (m, blend, 3)
    along = np.einsum("mki,mki->mk", delta, normals[j])
    weights = np.exp(-(d / cell) ** 2) + 1e-300
    values = (weights * along).sum(axis=1) / weights.sum(axis=1)
    # Hoppe's validity test: the node's foot on the nearest tangent plane must lie within the
    # local sample gap (distance to the 4th neighbour, at least a cell) of that point.
    gap, _ = tree.query(points, k=min(5, len(points)), workers=-1)
    reach = np.maximum(cell, 2.0 * gap[:, -1])
    lateral = np.linalg.norm(delta[:, 0] - along[:, :1] * normals[j[:, 0]], axis=1)
    values[lateral > reach[j[:, 0]]] = np.nan
    return surface_nets(keys, values, shape, origin, cell)


def cell_size(cloud: MethodInput, cell: float | None) -> float:
    """The grid cell in metres: ``cell`` x spacing, or when None the automatic one,
    ``max(CELL x spacing, CELL_NOISE x noise)``."""
    if cell is not None:
        return float(cell) * cloud.spacing
    return above_noise(cloud, CELL, CELL_NOISE)


def run(cloud: MethodInput, *, k: int, iterations: int, cell: float | None, order: int,
        weighted: bool) -> tuple[np.ndarray, np.ndarray]:
    """Project onto robust local planes, then mesh the planes' signed distance.

    Parameters
    ----------
    cloud : MethodInput
    k : int
        Neighbours per local plane.
    iterations : int
        Robust reweighting rounds.
    cell : float or None
        Grid cell in units of ``cloud.spacing``; None: automatic (``cell_size``).
    order : {1, 2}
        1: the plane (the paper's least-squares plane fitting); 2: plus a quadratic height
        correction (``project_to_planes``).
    weighted : bool
        Weight neighbours by their recorded uncertainty (``MethodInput.sigma``) when known.

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64
    """
    if len(cloud.points) < 3:
        raise MethodFailed(f"plane: need at least 3 points, got {len(cloud.points)}")
    projected, normals = project_to_planes(cloud.points, cloud.normals, k=k,
                                           iterations=iterations, neighbours=cloud.neighbours,
                                           order=order, weights=uncertainty.weights(
                                               cloud.sigma if weighted else None,
                                               len(cloud.points)))
    size = cell_size(cloud, cell)
    if not size > 0:
        raise MethodFailed("plane: zero point spacing (all points identical?)")
    extent = np.ptp(projected, axis=0).max()
    if extent / size > 4000:
        raise MethodFailed(f"plane: cell {size:.3g} m gives {extent / size:.0f} cells across "
                           f"the cloud (at most 4000); raise cell")
    vertices, faces = signed_distance_mesh(projected, normals, cell=size)
    if len(faces) == 0:
        raise MethodFailed("plane: the signed distance has no zero crossing")
    return vertices, faces


METHOD = register(Method(
    name="plane", run=run, kind="smooth",
    summary="robust least-squares local planes (Hoppe 1992), signed distance, surface nets",
    params={
        # 30 neighbours: the biweight spatial kernel leaves about a third effective, enough to
        # cut normal-direction noise by ~3x while following the RSO's 5 m bus faces.
        # At most 1000 neighbours: the neighbour table holds k indices per point.
        "k": Param(30, int, "neighbours per local plane", minimum=3, maximum=1000),
        # 2 rounds: the Tukey weights settle after two rounds on our clouds (at most 100).
        "iterations": Param(2, int, "robust reweighting rounds", minimum=0, maximum=100),
        # 0.01 to 100 spacings (run refuses more than 4000 cells across the cloud as well).
        "cell": Param(None, float, "grid cell / spacing (default: automatic, 1, or 2 x noise "
                      "when larger)", minimum=0.01, maximum=100.0),
        # 1: the paper's plane. Order 2 removes the curvature bias (measured on a noise-free
        # unit sphere, 5000 points, k = 30: mean vertex error 0.0023 -> 0.0004) but follows
        # noise more (sigma 0.005: 0.0013 -> 0.0017 at 20000 points), so it is a grid option.
        "order": Param(1, int, "1: plane; 2: plane plus quadratic height correction",
                       choices=(1, 2)),
        "weighted": Param(True, bool, "weight points by the recorded sensor error model"),
    },
    grid=({"cell": 0.5}, {"cell": 2.0}, {"k": 60}, {"order": 2})))
