"""Prepare a point cloud for a surface method: clean it, thin it, estimate what methods need.

Two steps, each optional, then one required:

1. remove statistical outliers (``remove_statistical_outliers``);
2. downsample on a voxel grid (``voxel_downsample``; view points are averaged with their
   points, so normals can still be oriented by them);
3. ``prepare``: PCA normals oriented toward each point's view point (``recon.surfaces.normals``),
   the median spacing and the noise scale, as the ``MethodInput`` every method receives.

``Preparation`` holds the options of all three; ``load_prepared`` applies them to a file.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from formats.errors import InputError, ParameterError
from formats.geometry import Cloud
from recon.registration.uncertainty import COLUMNS as SIGMA_COLUMNS
from recon.surfaces.methods import MethodInput
from recon.surfaces.normals import DEFAULT_K, Fallback, local_planes, orient
from recon.surfaces.uncertainty import normal_sigma

# Statistical outlier removal (Rusu et al. 2008, PCL's StatisticalOutlierRemoval): a point is an
# outlier when its mean distance to its OUTLIER_K neighbours exceeds the cloud's mean of that
# distance by OUTLIER_STD standard deviations. 20 and 2.0 are PCL's and Open3D's tutorial values.
OUTLIER_K = 20
OUTLIER_STD = 2.0
# Fewest points any method is given.
MIN_POINTS = 16
# Most voxels along a cloud's extent in voxel downsampling: voxel indices are int64, and a
# billion voxels across is already finer than float64 coordinates of a 100 km target resolve.
MAX_VOXELS_ACROSS = 1e9
# Attributes that say when and by which beam a strike was taken (ingest writes them).
ORDER_COLUMNS = ("time", "shot", "beam")


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
    from scipy.spatial import cKDTree  # imported when used: ``recon.surfaces.normals``

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
    if not (voxel > 0 and np.isfinite(voxel)):
        raise InputError(f"voxel must be a positive size in metres, got {voxel}")
    extent = float(np.ptp(points, axis=0).max()) if len(points) else 0.0
    if extent / voxel > MAX_VOXELS_ACROSS:
        raise InputError(f"voxel {voxel:g} m is too small for the cloud: {extent:g} m across "
                         f"would be more than {MAX_VOXELS_ACROSS:g} voxels")
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
        Points and (when the input had them) view points and, without downsampling, the
        uncertainty columns (``recon.surfaces.uncertainty``; a voxel mean has no recorded
        error) and ``ORDER_COLUMNS`` (when and by which beam each strike was taken: the
        held-out passes of ``recon.surfaces.auto``); other attributes are dropped.
    """
    points = cloud.points
    view = cloud.view_points
    sigmas = {k: cloud.attributes[k] for k in (*SIGMA_COLUMNS, *ORDER_COLUMNS)
              if k in cloud.attributes}
    if remove_outliers:
        keep = remove_statistical_outliers(points, k=outlier_k, std_ratio=outlier_std)
        points = points[keep]
        view = None if view is None else view[keep]
        sigmas = {k: v[keep] for k, v in sigmas.items()}
    if voxel is not None:
        points, view = voxel_downsample(points, voxel, view_points=view)
        sigmas = {}
    attributes = {} if view is None else {"view_x": view[:, 0], "view_y": view[:, 1],
                                          "view_z": view[:, 2]}
    return Cloud(points, attributes | sigmas, frame=cloud.frame)


def prepare(points: np.ndarray, *, view_points: np.ndarray | None = None,
            normals: np.ndarray | None = None, k: int = DEFAULT_K,
            fallback: Fallback = "centroid", seed: int = 0,
            uncertainty: dict[str, np.ndarray] | None = None, misses=None) -> MethodInput:
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
    uncertainty : dict of str to (n,) arrays, optional
        The strikes' recorded uncertainty columns (``recon.registration.uncertainty.COLUMNS``, as
        ingest writes them); with ``view_points`` they give ``MethodInput.sigma``.
    misses : recon.registration.misses.MissedBeams, optional
        The strike log's missed beams near the points (``recon.surfaces.auto.misses_near``),
        passed on as ``MethodInput.misses``.

    Returns
    -------
    MethodInput
        Its ``noise`` is the recorded noise length when ``uncertainty`` records one (the median
        1-sigma error along the beam: range and pose knowledge), else the median local-plane
        scatter. The recorded value is the better one: on a single-beam track the local plane
        contains the beam and reads a scatter far below the range noise.
        With ``view_points`` when given (they travel with the cloud into isolated runs).
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(f"points must be (n, 3), got {points.shape}")
    if len(points) < MIN_POINTS:
        raise InputError(f"need at least {MIN_POINTS} points to reconstruct, got {len(points)}")
    if not np.all(np.isfinite(points)):
        raise InputError("points contain NaN or Inf")
    if view_points is not None:
        view_points = np.asarray(view_points, dtype=np.float64)
        if view_points.shape != points.shape:
            raise InputError(f"view_points must match points {points.shape}, got "
                             f"{view_points.shape}")
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
    sigma = None
    noise = float(np.median(planes.noise))
    if uncertainty is not None and all(key in uncertainty for key in SIGMA_COLUMNS):
        if view_points is not None:
            sigma = normal_sigma(normals, view_points, points, uncertainty)
        along = np.asarray(uncertainty["sigma_along"], dtype=np.float64)
        if along.any():
            noise = float(np.median(along))
    return MethodInput(points=points, normals=normals, spacing=spacing, noise=noise,
                       seed=int(seed), neighbours=planes.neighbours, sigma=sigma,
                       view_points=view_points, misses=misses)


def _check_voxel(voxel: float | None, name: str) -> None:
    if voxel is not None and not (voxel > 0 and np.isfinite(voxel)):
        raise ParameterError(f"{name} must be a positive size in metres, got {voxel:g}",
                             argument=name)


@dataclass(frozen=True)
class Preparation:
    """Options of the preparation: cleaning, thinning and normals.

    Attributes
    ----------
    remove_outliers : bool
        Statistical outlier removal (``OUTLIER_K`` neighbours, ``OUTLIER_STD`` deviations).
    voxel : float, metres, optional
        Edge of the voxels of the downsampling (None: no downsampling).
    k : int
        Neighbours of the PCA normals (``prepare``).
    fallback : {"centroid", "propagate"}
        Normal orientation without view points.
    seed : int
    """

    remove_outliers: bool = False
    voxel: float | None = None
    k: int = DEFAULT_K
    fallback: Fallback = "centroid"
    seed: int = 0

    def __post_init__(self):
        _check_voxel(self.voxel, "voxel")
        if self.k < 1:
            raise ParameterError(f"k must be >= 1, got {self.k}")

    @classmethod
    def from_options(cls, *, remove_outliers: bool = False, voxel: float | None = None,
                     normals_k: int = DEFAULT_K, orient: Fallback = "centroid", seed: int = 0
                     ) -> Preparation:
        """The preparation of the API's ``remove_outliers``, ``voxel``, ``normals_k``,
        ``orient`` and ``seed`` arguments; errors name these arguments."""
        _check_voxel(voxel, "voxel")
        if normals_k < 1:
            raise ParameterError(f"normals_k must be >= 1, got {normals_k}", argument="normals_k")
        return cls(remove_outliers=remove_outliers, voxel=voxel, k=normals_k, fallback=orient,
                   seed=seed)

    def apply(self, cloud: Cloud) -> tuple[Cloud, MethodInput]:
        """Clean, thin and prepare ``cloud``.

        Returns
        -------
        cloud : Cloud
            The cleaned and thinned points, with their view points when ``cloud`` had them.
        prepared : MethodInput
        """
        cloud = self.clean(cloud)
        return cloud, self.prepare(cloud)

    def clean(self, cloud: Cloud) -> Cloud:
        """``cloud`` cleaned and thinned (``preprocess``)."""
        return preprocess(cloud, remove_outliers=self.remove_outliers, voxel=self.voxel)

    def prepare(self, cloud: Cloud) -> MethodInput:
        """A cleaned ``cloud`` prepared (``prepare``: normals, spacing, noise)."""
        return prepare(cloud.points, view_points=cloud.view_points, k=self.k,
                       fallback=self.fallback, seed=self.seed, uncertainty=cloud.attributes)


def load_prepared(source, preparation: Preparation | None = None
                  ) -> tuple[Cloud, MethodInput]:
    """Read (or take) a cloud and prepare it.

    Parameters
    ----------
    source : str or Path, Cloud, or (n, 3) array
        A point cloud file (.ply, .las, .laz, .h5) or strike log (registered on the fly,
        ``recon.inputs.load_cloud``), or the cloud itself.
    preparation : Preparation, optional
        Default: ``Preparation()``.

    Returns
    -------
    cloud : Cloud
        The cleaned and thinned points, metres, body frame (view points kept).
    prepared : MethodInput
    """
    preparation = preparation or Preparation()
    cloud = load_cleaned(source, preparation)
    return cloud, preparation.prepare(cloud)


def load_cleaned(source, preparation: Preparation | None = None) -> Cloud:
    """Read (or take) a cloud, cleaned and thinned (``load_prepared`` without the
    preparation: ``Preparation.prepare`` then makes it)."""
    import os

    if not isinstance(source, str | os.PathLike):
        return (preparation or Preparation()).clean(Cloud.of(source, "cloud"))
    from recon.inputs import load_cloud

    read = load_cloud(source)
    cloud = (preparation or Preparation()).clean(read)
    if len(cloud) < MIN_POINTS:   # said here, where the file is known
        kept = "" if len(cloud) == len(read) else f" ({len(read)} before cleaning)"
        raise InputError(f"{source}: {len(cloud)} points{kept}; need at least {MIN_POINTS} to "
                         "reconstruct")
    return cloud
