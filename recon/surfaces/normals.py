"""Per-point normals by local principal component analysis, oriented toward the sensor.

The normal of point ``p`` is the eigenvector of smallest eigenvalue of the covariance of its
``k`` nearest neighbours (Hoppe et al. 1992, "Surface reconstruction from unorganized points").
PCA fixes the normal's line, not its sign. A chaser only ever sees the side of the surface that
faces it, so the sign is set from the view point ingest keeps for every strike (the sensor
position in the body frame): the normal is flipped to point toward it, ``n . (v - p) > 0``.
Unlike a global heuristic this is right on both faces of a thin solar panel and inside concave
regions.

For clouds without view points the documented fallback heuristics are:

``"centroid"`` (default)
    Point away from the cloud's centroid, ``n . (p - c) > 0``. Exact for star-shaped targets seen
    from outside (ellipsoids, most asteroids); wrong wherever the surface faces the centroid
    (concavities, the inner face of a panel).
``"propagate"``
    Start from the centroid rule, then Open3D's ``orient_normals_consistent_tangent_plane``
    (Hoppe's minimum-spanning-tree propagation over a k-nearest-neighbour graph) makes
    neighbouring normals agree. Better on concave shapes, but a single bad hop across a thin
    part flips a whole region.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from formats.errors import InputError
from formats.geometry import check_extent

Fallback = Literal["centroid", "propagate"]
FALLBACKS = ("centroid", "propagate")

# Neighbours per PCA normal: Hoppe et al. 1992 use 10-20; 16 keeps the normal's angular noise
# below ~5 deg at the paper's 0.3 m 3-sigma LRF range noise for the clouds we simulate.
DEFAULT_K = 16
# Adaptive neighbourhoods. A single-beam LRF samples the target along tracks: on the simulated
# asteroid (asteroid-lrf preset) the 16 nearest points of 70% of the points lie on one track
# (0.4 m apart along it, metres between tracks) and fix no plane; their PCA normals are 35 deg
# off on average and 12% point the wrong way. Where the second eigenvalue of a neighbourhood is
# below PLANARITY x the largest (its minor in-plane spread under 22% of its major one) or below
# 4 x the smallest (the in-plane spread is lost in the noise), k doubles, up to MAX_K. Measured
# there: 87.6% / 93.9% / 98.5% / 99.8% of the normals agree in sign with the truth at fixed
# k = 16 / 32 / 64 / 128.
PLANARITY = 0.05
SPREAD_OVER_NOISE = 4.0
MAX_K = 256
# Neighbour entries per vectorised block: (entries, 3) float64 arrays of about 20 MB.
BLOCK_ENTRIES = 800_000


def _check_points(points: np.ndarray, name: str = "points") -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(f"{name} must be (n, 3), got {points.shape}")
    if not np.all(np.isfinite(points)):
        raise InputError(f"{name} contain NaN or Inf")
    check_extent(points, name, error=InputError)
    return points


def _check_k(k: int, n: int) -> int:
    if int(k) != k or k < 3:
        raise InputError(f"k must be an integer >= 3, got {k}")
    if n < k:
        raise InputError(f"need at least k = {k} points for normals, got {n}")
    return int(k)


@dataclass
class LocalPlanes:
    """Least-squares planes of each point's neighbourhood.

    Attributes
    ----------
    normals : (n, 3) float64
        Unit normals, sign arbitrary.
    centroids : (n, 3) float64, metres
        Neighbourhood means (a point of each plane).
    noise : (n,) float64, metres
        Scatter of the smallest (k-point) neighbourhood about its plane, ``sqrt(lambda_0)``, or
        about its line, ``sqrt(lambda_1)``, when it is a single track.
    radius : (n,) float64, metres
        Distance to the farthest neighbour of the final neighbourhood.
    neighbours : (n,) int64
        Size of the final neighbourhood (k, doubled while it was line-like).
    """

    normals: np.ndarray
    centroids: np.ndarray
    noise: np.ndarray
    radius: np.ndarray
    neighbours: np.ndarray

    @property
    def spacing(self) -> np.ndarray:
        """(n,) float64, metres: ``sqrt(area per point)``, ``radius * sqrt(pi / neighbours)``."""
        return self.radius * np.sqrt(np.pi / self.neighbours)


def local_planes(points: np.ndarray, *, k: int = DEFAULT_K, adaptive: bool = True,
                 max_k: int = MAX_K, workers: int = -1) -> LocalPlanes:
    """Fit a least-squares plane to each point's nearest neighbours (the point included).

    Parameters
    ----------
    points : (n, 3) float64, metres, any frame
    k : int
        Starting neighbourhood size.
    adaptive : bool
        Double k for neighbourhoods that do not span a plane (see ``PLANARITY``), up to
        ``max_k``.
    max_k : int
    workers : int
        Threads for the KD-tree queries (-1: all cores).

    Returns
    -------
    LocalPlanes
    """
    points = _check_points(points)
    k = _check_k(k, len(points))
    n = len(points)
    # scipy's spatial package is imported when a tree is made: ``recon reconstruct -m
    # auto`` starts its fit workers before that import
    from scipy.spatial import cKDTree

    tree = cKDTree(points)
    planes = LocalPlanes(np.empty_like(points), np.empty_like(points), np.empty(n),
                         np.empty(n), np.full(n, k, dtype=np.int64))
    todo = np.arange(n)
    size = k
    while len(todo):
        size = min(size, n)
        block = max(1, BLOCK_ENTRIES // size)
        flat = np.empty(len(todo), dtype=bool)
        for start in range(0, len(todo), block):
            rows = todo[start:start + block]
            distance, index = tree.query(points[rows], k=size, workers=workers)
            neigh = points[index]                                       # (b, size, 3)
            mean = neigh.mean(axis=1)
            centred = neigh - mean[:, None, :]
            cov = np.einsum("bki,bkj->bij", centred, centred) / size
            values, vectors = np.linalg.eigh(cov)                        # ascending
            values = np.clip(values, 0.0, None)
            planes.normals[rows] = vectors[:, :, 0]
            planes.centroids[rows] = mean
            planes.radius[rows] = distance[:, -1]
            planes.neighbours[rows] = size
            two_d = ((values[:, 1] >= PLANARITY * values[:, 2])
                     & (values[:, 1] >= SPREAD_OVER_NOISE * values[:, 0]))
            if size == k:
                planes.noise[rows] = np.sqrt(np.where(two_d, values[:, 0], values[:, 1]))
            flat[start:start + block] = two_d
        if not adaptive or size >= max_k or size >= n:
            break
        todo = todo[~flat]
        size *= 2
    return planes


def orient_toward(normals: np.ndarray, points: np.ndarray, view_points: np.ndarray) -> np.ndarray:
    """Flip each normal to point toward its view point, ``n . (v - p) >= 0``.

    Parameters
    ----------
    normals : (n, 3) float64, unit
    points : (n, 3) float64, metres, body frame
    view_points : (n, 3) float64, metres, same frame: the sensor position of each strike

    Returns
    -------
    (n, 3) float64
        Oriented unit normals (a new array).
    """
    view_points = _check_points(view_points, "view_points")
    if view_points.shape != points.shape:
        raise InputError(f"view_points must match points {points.shape}, got "
                           f"{view_points.shape}")
    sign = np.where(np.einsum("ij,ij->i", normals, view_points - points) < 0, -1.0, 1.0)
    return normals * sign[:, None]


def orient_fallback(normals: np.ndarray, points: np.ndarray, *, fallback: Fallback = "centroid",
                    k: int = DEFAULT_K) -> np.ndarray:
    """Orient normals without view points, with one of the heuristics in the module docstring.

    Parameters
    ----------
    normals : (n, 3) float64, unit
    points : (n, 3) float64, metres
    fallback : {"centroid", "propagate"}
    k : int
        Neighbours of the propagation graph (``"propagate"`` only).

    Returns
    -------
    (n, 3) float64
        Oriented unit normals (a new array).
    """
    if fallback not in FALLBACKS:
        raise InputError(f"fallback must be one of {FALLBACKS}, got {fallback!r}")
    outward = points - points.mean(axis=0)
    sign = np.where(np.einsum("ij,ij->i", normals, outward) < 0, -1.0, 1.0)
    oriented = normals * sign[:, None]
    if fallback == "propagate":
        import open3d as o3d

        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        cloud.normals = o3d.utility.Vector3dVector(oriented)
        cloud.orient_normals_consistent_tangent_plane(int(k))
        propagated = np.asarray(cloud.normals)
        # The propagation keeps one global sign of its own choosing: keep the one that agrees
        # with the centroid rule on most points.
        if np.einsum("ij,ij->i", propagated, oriented).mean() < 0:
            propagated = -propagated
        oriented = propagated
    return oriented


def estimate_normals(points: np.ndarray, *, view_points: np.ndarray | None = None,
                     k: int = DEFAULT_K, fallback: Fallback = "centroid") -> np.ndarray:
    """PCA normals oriented toward each point's view point (or by a fallback heuristic).

    Parameters
    ----------
    points : (n, 3) float64, metres, body frame
    view_points : (n, 3) float64, metres, body frame, optional
        Sensor position of each strike (``Cloud.view_points``). Without it the
        ``fallback`` heuristic orients the normals (see the module docstring).
    k : int
        Neighbours per PCA fit.
    fallback : {"centroid", "propagate"}

    Returns
    -------
    (n, 3) float64
        Unit normals pointing out of the surface, toward the side the sensor saw.

    Raises
    ------
    InputError
        Bad shapes, non-finite values, fewer than ``k`` points or an unknown fallback.
    """
    points = _check_points(points)
    if fallback not in FALLBACKS:
        raise InputError(f"fallback must be one of {FALLBACKS}, got {fallback!r}")
    return orient(local_planes(points, k=k).normals, points, view_points=view_points,
                  fallback=fallback, k=k)


def orient(normals: np.ndarray, points: np.ndarray, *, view_points: np.ndarray | None = None,
           fallback: Fallback = "centroid", k: int = DEFAULT_K) -> np.ndarray:
    """Orient unit normals toward the view points, or by the fallback heuristic without them.

    Parameters
    ----------
    normals : (n, 3) float64, unit, sign arbitrary
    points : (n, 3) float64, metres
    view_points : (n, 3) float64, metres, optional
    fallback : {"centroid", "propagate"}
    k : int
        Neighbours of the ``"propagate"`` graph.

    Returns
    -------
    (n, 3) float64
    """
    if view_points is not None:
        return orient_toward(normals, points, view_points)
    return orient_fallback(normals, points, fallback=fallback, k=k)


def point_spacing(points: np.ndarray, *, k: int = DEFAULT_K) -> float:
    """The cloud's typical sample spacing [m]: the median of ``sqrt(area per point)``.

    Each point's area per point is that of the disc its (adaptive, two-dimensional)
    neighbourhood covers divided by the points in it (``LocalPlanes.spacing``). On a uniform
    sampling this is ``1 / sqrt(density)``; on LRF tracks it counts the gaps between tracks,
    which the median nearest-neighbour distance (the along-track step) would hide. Every method
    scales its radii and cells by it.

    Parameters
    ----------
    points : (n, 3) float64, metres, n >= k
    """
    return float(np.median(local_planes(points, k=k).spacing))


def noise_scale(points: np.ndarray, *, k: int = DEFAULT_K) -> float:
    """Robust estimate of the cloud's out-of-surface scatter [m]: median of ``LocalPlanes.noise``.

    The noise standard deviation for noisy flat-ish surfaces, plus a small curvature term.
    """
    return float(np.median(local_planes(points, k=k).noise))
