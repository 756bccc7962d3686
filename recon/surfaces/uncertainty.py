"""Each strike's uncertainty along its surface normal, from the per-strike columns of
registration (``recon.registration.uncertainty``), anisotropic in the beam:

``sigma_along``, ``sigma_across`` [m] and ``dilation_along``, ``dilation_across`` [m per unit
tan(incidence)], the columns ``COLUMNS`` that ingest writes from the log's recorded error model.

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

from recon.registration.uncertainty import COLUMNS

# Smallest |cos(incidence)| used for tan(incidence): 84 deg, beyond which a strike's dilation
# error is capped (the paper's Eq. (1) diverges at grazing incidence).
MIN_COS = 0.1


def normal_sigma(normals: np.ndarray, view_points: np.ndarray, points: np.ndarray,
                 columns: dict[str, np.ndarray]) -> np.ndarray | None:
    """1-sigma uncertainty of each point along its surface normal.

    Parameters
    ----------
    normals : (n, 3) float64, unit
    view_points, points : (n, 3) float64, metres, body frame
        Sensor positions and strikes (their difference is the beam).
    columns : dict of str to (n,) arrays
        ``COLUMNS`` (``recon.registration.uncertainty.strike_columns``).

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
