"""Each strike's uncertainty from the sensor error model its log records, anisotropic in the beam.

A strike log records the error models its producer applied (formats/SPEC.md, ``/sensor/errors``,
3-sigma values). Registration (``recon.registration.ingest``) turns them into per-point 1-sigma
columns, so they travel with the cloud through files:

``sigma_along`` [m]
    Along the beam: the range error and the pose-knowledge error (per axis, isotropic).
``sigma_across`` [m]
    Across the beam, per lateral axis: the angle error times the range (a LIDAR's reported
    angles and a fixed LRF's pointing error both displace the strike sideways by ``rho *
    error``) and the pose-knowledge error.
``dilation_along``, ``dilation_across`` [m per unit tan(incidence)]
    Pulse dilation, paper Eq. (1): per axis ``alpha * rho * mean(tan theta) / 3``. A LIDAR
    records the moved point (all three axes); a fixed LRF records only the along-beam part
    (sim/noise.py), so its ``dilation_across`` is zero. The incidence angle is unknown until
    normals are estimated, so the factor ``tan theta`` is applied by the surface methods
    (``recon.surfaces.uncertainty.normal_sigma``).

The errors here are the log's own model, never the truth.
"""

from __future__ import annotations

import numpy as np

from formats.strike_log import SensorErrors, sigma_from_sigma3

# Per-point columns ingest writes (float32 is ample for a 1-sigma value).
COLUMNS = ("sigma_along", "sigma_across", "dilation_along", "dilation_across")


def strike_columns(errors: SensorErrors, ranges: np.ndarray, *, reports_angles: bool
                   ) -> dict[str, np.ndarray]:
    """The per-strike uncertainty columns of the module docstring.

    Parameters
    ----------
    errors : SensorErrors
        The log's recorded error models (3-sigma, SI).
    ranges : (n,) float64, metres
        Recorded ranges.
    reports_angles : bool
        The sensor records the moved point in 3D (a scanning LIDAR), not only its range.

    Returns
    -------
    dict of str to (n,) float32
    """
    ranges = np.asarray(ranges, dtype=np.float64)
    pose = errors.position_sigma
    angle = max(errors.azimuth_sigma, errors.elevation_sigma)
    dilation = sigma_from_sigma3(errors.pulse_dilation_alpha) * ranges
    return {"sigma_along": np.hypot(errors.range_sigma, pose) * np.ones_like(ranges),
            "sigma_across": np.hypot(angle * ranges, pose),
            "dilation_along": dilation,
            "dilation_across": dilation if reports_angles else np.zeros_like(ranges)}
