"""Error models, applied to what a sensor records and never to the truth.

All configured as 3-sigma values (as the paper states them); each costs nothing when zero, and
each draws from its own random stream, so switching one model on or off leaves the draws of the
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
- **pose knowledge** (Gaussian per axis, per shot): added to the recorded sensor position.

Where several apply they add, as in the paper ("summed directly to account for the worst case").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from formats.strike_log import SensorErrors

# Random streams, one per error model.
STREAM_POSITION, STREAM_POINTING, STREAM_ANGLES, STREAM_RANGE, STREAM_DILATION = range(5)
# cos(theta) floor for pulse dilation, so a sub-ray exactly along a facet gives a large finite
# tan(theta) (1e9) rather than an infinite error.
MIN_COS_INCIDENCE = 1e-9


def stream(seed: int, model: int, chunk: int) -> np.random.Generator:
    """The random generator of one error model for one chunk of shots."""
    return np.random.default_rng((seed, model, chunk))


@dataclass(frozen=True)
class ErrorModel:
    """Error-model parameters in SI units, as 1-sigma values.

    Attributes
    ----------
    range_sigma : float, metres
    azimuth_sigma, elevation_sigma : float, radians
    position_sigma : float, metres per axis
    dilation_alpha : float, dimensionless (0: off)
    dilation_half_angle : float, radians
    dilation_subrays : int
    """

    range_sigma: float = 0.0
    azimuth_sigma: float = 0.0
    elevation_sigma: float = 0.0
    position_sigma: float = 0.0
    dilation_alpha: float = 0.0
    dilation_half_angle: float = 0.0
    dilation_subrays: int = 30

    @classmethod
    def from_scene(cls, errors: dict) -> ErrorModel:
        """From a scene's ``[errors]`` section (3-sigma values, degrees, milliradians)."""
        return cls(range_sigma=errors["range_sigma3"] / 3.0,
                   azimuth_sigma=math.radians(errors["azimuth_sigma3_deg"]) / 3.0,
                   elevation_sigma=math.radians(errors["elevation_sigma3_deg"]) / 3.0,
                   position_sigma=errors["position_sigma3"] / 3.0,
                   dilation_alpha=errors["dilation_alpha"],
                   dilation_half_angle=errors["dilation_half_angle_mrad"] * 1e-3,
                   dilation_subrays=errors["dilation_subrays"])

    @property
    def angles(self) -> bool:
        return self.azimuth_sigma > 0 or self.elevation_sigma > 0

    @property
    def dilation(self) -> bool:
        return self.dilation_alpha > 0

    def record(self) -> SensorErrors:
        """The 3-sigma values for the log's ``/sensor/errors`` (zero when a model is off)."""
        on = self.dilation
        return SensorErrors(range_sigma3=3 * self.range_sigma,
                            azimuth_sigma3=3 * self.azimuth_sigma,
                            elevation_sigma3=3 * self.elevation_sigma,
                            position_sigma3=3 * self.position_sigma,
                            pulse_dilation_alpha=self.dilation_alpha,
                            pulse_dilation_half_angle=self.dilation_half_angle if on else 0.0,
                            pulse_dilation_subrays=float(self.dilation_subrays) if on else 0.0)

    def angle_errors(self, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Azimuth and elevation errors (n,) [rad]."""
        return (rng.normal(0.0, self.azimuth_sigma, n), rng.normal(0.0, self.elevation_sigma, n))


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
    return alpha * true_range * mean_tan / 3.0
