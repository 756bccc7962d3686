"""Reconstruct a surface from a point cloud: preprocessing, normals, one registered method.

The pipeline of ``recon reconstruct``:

1. read the input (a cloud, or a strike log registered on the fly; ``recon.inputs``);
2. optionally remove statistical outliers and downsample on a voxel grid (view points are
   averaged with their points, so normals can still be oriented by them);
3. estimate PCA normals oriented toward each point's view point (``recon.surfaces.normals``), the
   median spacing and the noise scale: a ``MethodInput``;
4. run the method, in this process (``reconstruct``) or isolated in a child process with time
   and memory limits (``reconstruct(..., isolate=True)``, what the CLI does), and check the mesh.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from formats.errors import ReconError
from formats.geometry import Cloud
from recon.surfaces import methods
from recon.surfaces.isolation import (
    DEFAULT_MEMORY_MB,
    DEFAULT_TIMEOUT_S,
    check_surface,
    run_isolated,
)
from recon.surfaces.methods import MethodFailed, MethodInput
from recon.surfaces.normals import DEFAULT_K, Fallback, local_planes, orient

# Statistical outlier removal (Rusu et al. 2008, PCL's StatisticalOutlierRemoval): a point is an
# outlier when its mean distance to its OUTLIER_K neighbours exceeds the cloud's mean of that
# distance by OUTLIER_STD standard deviations. 20 and 2.0 are PCL's and Open3D's tutorial values.
OUTLIER_K = 20
OUTLIER_STD = 2.0
# Fewest points any method is given.
MIN_POINTS = 16


class InputError(ReconError, ValueError):
    """A cloud or a preprocessing option that cannot be reconstructed from."""


@dataclass
class Surface:
    """A reconstructed triangle mesh and how it was made.

    Attributes
    ----------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64, counter-clockwise seen from outside
    method : str
    params : dict
        The resolved parameters.
    info : dict
        ``wall_time_s``, ``watertight``, and for isolated runs ``peak_memory_mb``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    method: str
    params: dict[str, Any]
    info: dict[str, Any] = field(default_factory=dict)


def remove_statistical_outliers(points: np.ndarray, *, k: int = OUTLIER_K,
                                std_ratio: float = OUTLIER_STD) -> np.ndarray:
    """Mask of the points kept by statistical outlier removal.

    Parameters
    ----------
    points : (n, 3) float64, metres
    k : int
        Neighbours whose mean distance is tested.
    std_ratio : float
        Standard deviations above the mean at which a point is dropped.

    Returns
    -------
    (n,) bool
        True for inliers.
    """
    if k < 1:
        raise InputError(f"outlier k must be >= 1, got {k}")
    if not std_ratio > 0:
        raise InputError(f"outlier std_ratio must be positive, got {std_ratio}")
    if len(points) <= k:
        return np.ones(len(points), dtype=bool)
    distance, _ = cKDTree(points).query(points, k=k + 1, workers=-1)
    mean = distance[:, 1:].mean(axis=1)
    return mean <= mean.mean() + std_ratio * mean.std()


def voxel_downsample(points: np.ndarray, voxel: float, *, view_points: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray | None]:
    """Replace the points of each voxel by their mean (and their view points' mean).

    Parameters
    ----------
    points : (n, 3) float64, metres
    voxel : float, metres
        Edge of the cubic voxels (grid anchored at the points' minimum corner).
    view_points : (n, 3) float64, optional

    Returns
    -------
    points : (m, 3) float64
    view_points : (m, 3) float64 or None
    """
    if not voxel > 0:
        raise InputError(f"voxel must be a positive size in metres, got {voxel}")
    cells = np.floor((points - points.min(axis=0)) / voxel).astype(np.int64)
    _, inverse, count = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()

    def mean(values):
        return np.stack([np.bincount(inverse, weights=values[:, i]) for i in range(3)],
                        axis=1) / count[:, None]

    return mean(points), (None if view_points is None else mean(view_points))


def preprocess(cloud: Cloud, *, remove_outliers: bool = False, outlier_k: int = OUTLIER_K,
               outlier_std: float = OUTLIER_STD, voxel: float | None = None) -> Cloud:
    """Statistical outlier removal, then voxel downsampling (each optional).

    Parameters
    ----------
    cloud : Cloud
        Points in metres; ``view_x/y/z`` attributes, when present, follow their points.
    remove_outliers : bool
    outlier_k, outlier_std
        See ``remove_statistical_outliers``.
    voxel : float, metres, optional
        Voxel edge of the downsampling.

    Returns
    -------
    Cloud
        Points and (when the input had them) view points; other attributes are dropped.
    """
    points = cloud.points
    view = cloud.view_points
    if remove_outliers:
        keep = remove_statistical_outliers(points, k=outlier_k, std_ratio=outlier_std)
        points = points[keep]
        view = None if view is None else view[keep]
    if voxel is not None:
        points, view = voxel_downsample(points, voxel, view_points=view)
    attributes = {} if view is None else {"view_x": view[:, 0], "view_y": view[:, 1],
                                          "view_z": view[:, 2]}
    return Cloud(points, attributes)


def prepare(points: np.ndarray, *, view_points: np.ndarray | None = None,
            normals: np.ndarray | None = None, k: int = DEFAULT_K,
            fallback: Fallback = "centroid", seed: int = 0) -> MethodInput:
    """Everything a method needs: oriented normals, spacing and noise scale.

    Parameters
    ----------
    points : (n, 3) float64, metres, body frame
    view_points : (n, 3) float64, metres, optional
        Sensor position of each point; orients the normals (``recon.surfaces.normals``).
    normals : (n, 3) float64, optional
        Oriented normals to use as they are (skips the estimation).
    k : int
        Neighbours of the PCA normals and of the noise scale.
    fallback : {"centroid", "propagate"}
        Orientation heuristic when there are no view points.
    seed : int

    Returns
    -------
    MethodInput
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(f"points must be (n, 3), got {points.shape}")
    if len(points) < MIN_POINTS:
        raise InputError(f"need at least {MIN_POINTS} points to reconstruct, got {len(points)}")
    if not np.all(np.isfinite(points)):
        raise InputError("points contain NaN or Inf")
    planes = local_planes(points, k=k)
    if normals is None:
        normals = orient(planes.normals, points, view_points=view_points, fallback=fallback, k=k)
    else:
        normals = np.asarray(normals, dtype=np.float64)
        if normals.shape != points.shape:
            raise InputError(f"normals must match points {points.shape}, got {normals.shape}")
        normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    spacing = float(np.median(planes.spacing))
    if not spacing > 0:
        raise InputError("all points coincide: nothing to reconstruct")
    return MethodInput(points=points, normals=normals, spacing=spacing,
                       noise=float(np.median(planes.noise)), seed=int(seed),
                       neighbours=planes.neighbours)


def reconstruct(cloud: MethodInput, *, method: str = "poisson", params: dict | None = None,
                isolate: bool = False, timeout_s: float = DEFAULT_TIMEOUT_S,
                memory_mb: int | None = DEFAULT_MEMORY_MB, on_wait=None) -> Surface:
    """Run one registered method on a prepared cloud.

    Parameters
    ----------
    cloud : MethodInput
        From ``prepare``.
    method : str
        A name from ``recon.surfaces.methods.available()``.
    params : dict, optional
        Overrides of the method's defaults.
    isolate : bool
        Run in a child process with ``timeout_s`` and ``memory_mb`` limits (crashes and hangs
        become ``MethodFailed``) instead of in this process.
    timeout_s, memory_mb
        Limits of the isolated run.
    on_wait : callable, optional
        For an isolated run, called with the child's stage while waiting (``run_isolated``).

    Returns
    -------
    Surface

    Raises
    ------
    UnknownMethod, ParameterError
        Bad method name or parameter.
    MethodFailed
        The method failed, crashed, timed out, or returned an empty or degenerate mesh.
    """
    spec = methods.get(method)
    resolved = spec.resolve(params)
    if isolate:
        result = run_isolated(method, cloud, resolved, timeout_s=timeout_s, memory_mb=memory_mb,
                              on_wait=on_wait)
        if result["status"] != "ok":
            raise MethodFailed(f"{method} failed ({result['failure']}): {result['reason']}")
        info = {k: result[k] for k in ("wall_time_s", "peak_memory_mb", "watertight")}
        return Surface(result["vertices"], result["faces"], method, resolved, info)
    import time

    from recon.surfaces.isolation import watertight

    start = time.perf_counter()
    vertices, faces = spec.run(cloud, **resolved)
    elapsed = time.perf_counter() - start
    vertices, faces = check_surface(vertices, faces, cloud.points, method=method)
    return Surface(vertices, faces, method, resolved,
                   {"wall_time_s": elapsed, "watertight": watertight(faces)})
