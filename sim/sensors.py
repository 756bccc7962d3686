"""Beam patterns of the simulated sensors, in the sensor frame S (formats/SPEC.md).

Angles are azimuth ``az`` (towards +x) and elevation ``el`` (towards +y), zero on the boresight
(+z); a direction is ``(cos el sin az, sin el, cos el cos az)``. The field of view is
``[az_min, az_max, el_min, el_max]`` on each side of the boresight (paper, Figure 2), so a grid
can be skewed (Figure 3).

==========  ======================================================================  ===========
pattern     beams, in order                                                         reports
                                                                                    angles
==========  ======================================================================  ===========
single      the boresight                                                           no
cross       boresight, (az_max, 0), (az_min, 0), (0, el_max), (0, el_min)           no
zigzag      N beams equally spaced in azimuth from az_min to az_max, alternately    no
            at el_max and el_min: two rows offset by one beam spacing (Figure 5)
grid        n_az x n_el beams, evenly spaced over the field of view (Figure 3);     yes
            beam ``i_el * n_az + i_az``; a single row or column sits mid-field
==========  ======================================================================  ===========

The scanning LIDAR (grid) reports each strike's measured angles; the fixed multi-beam LRFs report
only a range per beam.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from formats.strike_log import angles_to_directions


@dataclass(frozen=True)
class BeamPattern:
    """The beams a sensor fires at every shot.

    Attributes
    ----------
    pattern : str
        ``single``, ``cross``, ``zigzag`` or ``grid``.
    azimuth, elevation : (n_beams,) float64, radians
    field_of_view : (4,) float64, radians, ``[az_min, az_max, el_min, el_max]`` (zeros: single)
    reports_angles : bool
    """

    pattern: str
    azimuth: np.ndarray
    elevation: np.ndarray
    field_of_view: tuple[float, float, float, float]
    reports_angles: bool

    @property
    def directions(self) -> np.ndarray:
        """(n_beams, 3) float64 unit vectors in S."""
        return angles_to_directions(self.azimuth, self.elevation)

    @property
    def n_beams(self) -> int:
        return len(self.azimuth)


def field_of_view(fov_deg) -> tuple[float, float, float, float]:
    """``[az, el]`` total extents (centred) or ``[az_min, az_max, el_min, el_max]`` [deg] to
    ``(az_min, az_max, el_min, el_max)`` [rad]."""
    fov = [math.radians(a) for a in fov_deg]
    if len(fov) == 2:
        return (-fov[0] / 2, fov[0] / 2, -fov[1] / 2, fov[1] / 2)
    if len(fov) == 4:
        return tuple(fov)
    raise ValueError(f"field of view must have 2 or 4 angles, got {fov_deg!r}")


def _spaced(lo: float, hi: float, n: int) -> np.ndarray:
    return np.array([(lo + hi) / 2.0]) if n == 1 else np.linspace(lo, hi, n)


def beam_pattern(pattern: str, *, fov_deg=None, beams: int | None = None,
                 resolution=None) -> BeamPattern:
    """Build a beam pattern.

    Parameters
    ----------
    pattern : {"single", "cross", "zigzag", "grid"}
    fov_deg : 2 or 4 floats, degrees
        Total extents ``[az, el]`` centred on the boresight, or ``[az_min, az_max, el_min,
        el_max]`` per side. Needed by every pattern but ``single``.
    beams : int
        Zigzag: number of beams (>= 2).
    resolution : 2 ints
        Grid: beams in azimuth and in elevation.

    Returns
    -------
    BeamPattern
    """
    if pattern == "single":
        return BeamPattern("single", np.zeros(1), np.zeros(1), (0.0, 0.0, 0.0, 0.0), False)
    if pattern not in ("cross", "zigzag", "grid"):
        raise ValueError(f"unknown beam pattern {pattern!r}")
    if fov_deg is None:
        raise ValueError(f"a {pattern} pattern needs fov_deg")
    az_min, az_max, el_min, el_max = fov = field_of_view(fov_deg)
    if pattern == "cross":
        az = np.array([0.0, az_max, az_min, 0.0, 0.0])
        el = np.array([0.0, 0.0, 0.0, el_max, el_min])
        return BeamPattern("cross", az, el, fov, False)
    if pattern == "zigzag":
        if beams is None or beams < 2:
            raise ValueError(f"a zigzag needs at least 2 beams, got {beams}")
        az = np.linspace(az_min, az_max, beams)
        el = np.where(np.arange(beams) % 2 == 0, el_max, el_min)
        return BeamPattern("zigzag", az, el, fov, False)
    if resolution is None:
        raise ValueError("a grid needs resolution = (n_az, n_el)")
    n_az, n_el = resolution
    el, az = np.meshgrid(_spaced(el_min, el_max, n_el), _spaced(az_min, az_max, n_az),
                         indexing="ij")
    return BeamPattern("grid", az.ravel(), el.ravel(), fov, True)


def cone_pattern(m: int, half_angle: float) -> tuple[np.ndarray, np.ndarray]:
    """Sub-ray offsets filling a cone evenly (a sunflower spiral), for pulse dilation.

    Parameters
    ----------
    m : int
        Number of sub-rays (paper: 30).
    half_angle : float, radians
        Cone half-angle (paper: 0.6 mrad).

    Returns
    -------
    polar : (m,) float64, radians from the beam axis, in (0, half_angle]
    azimuth : (m,) float64, radians about the beam axis
    """
    k = np.arange(m, dtype=np.float64)
    polar = half_angle * np.sqrt((k + 0.5) / m)   # equal areas of the spot per sub-ray
    azimuth = k * math.pi * (3.0 - math.sqrt(5.0))  # the golden angle
    return polar, azimuth
