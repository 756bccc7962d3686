"""Error models, applied to what a sensor records and never to the truth.

All configured as 3-sigma values (as the paper states them) and held, in SI units, in one
``formats.SensorErrors`` built once at scene load (``Scene.errors``, sim/derive.py); its
properties give the 1-sigma values drawn with. Each model costs nothing when zero, and each
draws from its own random stream, so switching one model on or off leaves the draws of the
others unchanged. A stream is ``np.random.default_rng((seed, stream, chunk))``: the same seed
gives the same values whatever else is configured.

How each error reaches the log (formats/SPEC.md places a strike at ``r_I + R_SI (rho d_S)``,
with ``d_S`` the beam's nominal direction plus any reported angle offsets):

- **range** (Gaussian, along the beam): added to the recorded ``range``.
- **azimuth and elevation** (Gaussian): the recorded direction minus the true firing direction.
  A scanning LIDAR (``reports_angles``) fires along its nominal directions and reports angles
  with this error, recorded as ``azimuth_offset`` and ``elevation_offset``. A fixed LRF reports
  no angles (the log says it fired along its nominal direction), so the error is a pointing
  error: the true beam fires ``error`` away from nominal, is cast that way, and the recorded
  range is measured along it.
- **pulse dilation** (paper, Eq. (1)): the strike moves by a 3D Gaussian error with, per axis,
  ``sigma = alpha * rho * mean(tan theta_i) / 3``; ``theta_i`` is the angle between sub-ray ``i``
  of a cone of ``m`` sub-rays about the true beam and the normal of the facet it hits (sub-rays
  that miss are left out of the mean), ``rho`` the true range. Eq. (1) as printed has no
  ``rho``, which would make ``alpha = 0.0002`` a length of 0.2 mm; the paper chose alpha "so
  that the 3-sigma error added to each x, y and z component is less than 1 m", which the range
  scaling gives (0.15 m x tan theta at 750 m), and SPEC.md records alpha as dimensionless. Only
  strikes whose main beam hits get it. A LIDAR records the moved point exactly (its range and
  reported angles are those of the moved point); a fixed LRF can only record a range, so it
  records the along-beam component (distributed like any one axis of the error) and the lateral
  components, which a single range cannot carry, are dropped.
- **pose knowledge** (Gaussian per axis, per shot): added to the recorded sensor position. The
  correlated pose-knowledge errors (misalignment, attitude bias and walk, position bias and
  drift, spin knowledge, time tags) are in sim/pose_errors.py.

Where several apply they add, as in the paper ("summed directly to account for the worst case").
"""

from __future__ import annotations

import numpy as np

from formats.strike_log import SensorErrors, sigma_from_sigma3

# Random streams, one per error model (the pose-knowledge ones: sim/pose_errors.py).
(STREAM_POSITION, STREAM_POINTING, STREAM_ANGLES, STREAM_RANGE, STREAM_DILATION,
 STREAM_ATTITUDE_WALK, STREAM_POSITION_DRIFT, STREAM_SPIN_AXIS) = range(8)
# cos(theta) floor for pulse dilation, so a sub-ray exactly along a facet gives a large finite
# tan(theta) (1e9) rather than an infinite error.
MIN_COS_INCIDENCE = 1e-9


def stream(seed: int, model: int, chunk: int) -> np.random.Generator:
    """The random generator of one error model for one chunk of shots."""
    return np.random.default_rng((seed, model, chunk))


def angle_errors(errors: SensorErrors, rng: np.random.Generator, n: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian azimuth and elevation errors.

    Parameters
    ----------
    errors : SensorErrors
        The scene's error models (1-sigma values from its properties).
    rng : numpy.random.Generator
    n : int

    Returns
    -------
    (n,) float64 and (n,) float64, radians: azimuth and elevation errors.
    """
    return (rng.normal(0.0, errors.azimuth_sigma, n), rng.normal(0.0, errors.elevation_sigma, n))


def dilation_sigma(alpha: float, true_range: np.ndarray, cos_incidence: np.ndarray,
                   hit: np.ndarray) -> np.ndarray:
    """Per-axis 1-sigma pulse-dilation error of each strike, paper Eq. (1) scaled by range.

    Parameters
    ----------
    alpha : float
    true_range : (h,) float64, metres
    cos_incidence : (h, m) float64, |cos| of the angle between sub-ray and facet normal
    hit : (h, m) bool, which sub-rays hit

    Returns
    -------
    (h,) float64, metres: ``alpha * rho * mean(tan theta over hitting sub-rays) / 3``; zero for
    a strike none of whose sub-rays hit.
    """
    c = np.maximum(cos_incidence, MIN_COS_INCIDENCE)
    tan = np.where(hit, np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c, 0.0)
    count = hit.sum(axis=1)
    mean_tan = np.divide(tan.sum(axis=1), count, out=np.zeros(len(count)), where=count > 0)
    return sigma_from_sigma3(alpha * true_range * mean_tan)
