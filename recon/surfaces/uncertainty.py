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
    normals are estimated, so the factor ``tan theta`` is applied in ``normal_sigma``.

``normal_sigma`` projects these onto each point's surface normal: with ``c = |n . b|`` the
cosine between the normal and the beam,

    sigma_n^2 = (sigma_along^2 + (d_along t)^2) c^2 + (sigma_across^2 + (d_across t)^2) (1 - c^2)

with ``t = tan(theta) = sqrt(1 - c^2) / c`` (``c`` floored at ``MIN_COS``). A grazing strike of
a LIDAR with 0.2 deg angle error at 750 m is uncertain by ~0.9 m along the surface normal, a
head-on one by its 0.33 m range error: weights ``1 / sigma_n^2`` trust the head-on strike ~7x
more. The errors here are the log's own model, never the truth.
"""

from __future__ import annotations

import numpy as np

from formats.strike_log import SensorErrors, sigma_from_sigma3

# Per-point columns ingest writes (float32 is ample for a 1-sigma value).
COLUMNS = ("sigma_along", "sigma_across", "dilation_along", "dilation_across")
# Smallest |cos(incidence)| used for tan(incidence): 84 deg, beyond which a strike's dilation
# error is capped (the paper's Eq. (1) diverges at grazing incidence).
MIN_COS = 0.1


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


def normal_sigma(normals: np.ndarray, view_points: np.ndarray, points: np.ndarray,
                 columns: dict[str, np.ndarray]) -> np.ndarray | None:
    """1-sigma uncertainty of each point along its surface normal.

    Parameters
    ----------
    normals : (n, 3) float64, unit
    view_points, points : (n, 3) float64, metres, body frame
        Sensor positions and strikes (their difference is the beam).
    columns : dict of str to (n,) arrays
        ``COLUMNS`` (``strike_columns``).

    Returns
    -------
    (n,) float64, metres, or None when the recorded model is error-free (every column zero):
    then no point is more trustworthy than another.
    """
    if not any(np.asarray(columns[k]).any() for k in COLUMNS):
        return None
    beam = points - view_points
    beam /= np.maximum(np.linalg.norm(beam, axis=1, keepdims=True), 1e-300)
    sigma = sigma_at_incidence(columns, np.abs(np.einsum("ij,ij->i", normals, beam)))
    return np.maximum(sigma, 1e-3 * sigma.max())


def sigma_at_incidence(columns: dict[str, np.ndarray], cos_incidence: np.ndarray) -> np.ndarray:
    """1-sigma uncertainty along the surface normal of strikes meeting a surface at incidence
    angles of cosine ``cos_incidence`` (n,): the formula of the module docstring."""
    along, across, d_along, d_across = (np.asarray(columns[k], dtype=np.float64)
                                        for k in COLUMNS)
    c = np.clip(np.abs(cos_incidence), MIN_COS, 1.0)
    tan = np.sqrt(1.0 - c * c) / c
    return np.sqrt((along**2 + (d_along * tan) ** 2) * c * c
                   + (across**2 + (d_across * tan) ** 2) * (1.0 - c * c))


def weights(sigma: np.ndarray | None, n: int) -> np.ndarray:
    """``1 / sigma^2`` normalised to mean 1, or ones when ``sigma`` is None."""
    if sigma is None:
        return np.ones(n)
    w = 1.0 / np.asarray(sigma, dtype=np.float64) ** 2
    return w / w.mean()
