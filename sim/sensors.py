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

Each pattern is one ``Pattern`` entry of ``PATTERNS``, added by ``register``: its beam builder,
its beam count and the ``[sensor]`` keys it reads. The scene schema (sim/defaults.py,
sim/schema.py), the cost estimate (sim/derive.py) and the simulator (sim/pipeline.py) read the
registry, so a new pattern touches only the module that registers it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from formats.strike_log import angles_to_directions


@dataclass(frozen=True)
class BeamPattern:
    """The beams a sensor fires at every shot.

    Attributes
    ----------
    pattern : str
        The scene's name of the pattern (a key of ``PATTERNS``).
    azimuth, elevation : (n_beams,) float64, radians
    field_of_view : (4,) float64, radians, ``[az_min, az_max, el_min, el_max]`` (zeros: single)
    reports_angles : bool
    recorded_as : str
        The pattern name the strike log records (formats/SPEC.md).
    """

    pattern: str
    azimuth: np.ndarray
    elevation: np.ndarray
    field_of_view: tuple[float, float, float, float]
    reports_angles: bool
    recorded_as: str

    @property
    def directions(self) -> np.ndarray:
        """(n_beams, 3) float64 unit vectors in S."""
        return angles_to_directions(self.azimuth, self.elevation)

    @property
    def n_beams(self) -> int:
        return len(self.azimuth)


FieldOfView = tuple[float, float, float, float]


@dataclass(frozen=True)
class Pattern:
    """One registered beam pattern: where its beams point and how many there are.

    Attributes
    ----------
    name : str
        The value of ``sensor.pattern`` that selects it.
    build : callable ``(sensor, fov) -> (azimuth, elevation)``
        ``sensor`` is the checked ``[sensor]`` section (dict), ``fov`` its field of view
        ``(az_min, az_max, el_min, el_max)`` [rad] (zeros when the pattern reads no
        ``field_of_view_deg``); returns ``(n_beams,) float64`` angles [rad] in S, in beam order.
    count : callable ``(sensor) -> int``
        The number of beams ``build`` returns, counted without building them (for the cost
        estimate of sim/derive.py).
    keys : tuple of str
        The ``[sensor]`` keys it reads besides ``pattern``; a scene giving one of the others'
        keys is refused (sim/schema.py).
    reports_angles : bool
        Each strike carries its measured angles (a scanning LIDAR), or only a range (a fixed LRF).
    recorded_as : str
        Its name in the strike log: one of formats/SPEC.md's patterns, ``custom`` for any other.
    """

    name: str
    build: Callable[[dict, FieldOfView], tuple[np.ndarray, np.ndarray]]
    count: Callable[[dict], int]
    keys: tuple[str, ...] = ()
    reports_angles: bool = False
    recorded_as: str = "custom"


# Every beam pattern by name. Adding one is one ``register`` call (here or in a module of its
# own that is imported before the scene is checked).
PATTERNS: dict[str, Pattern] = {}


def register(pattern: Pattern) -> Pattern:
    """Add ``pattern`` to ``PATTERNS`` under its name; return it."""
    PATTERNS[pattern.name] = pattern
    return pattern


def patterns_using(key: str) -> tuple[str, ...]:
    """Names of the registered patterns that read ``[sensor]`` key ``key``."""
    return tuple(name for name, p in PATTERNS.items() if key in p.keys)


def field_of_view(fov_deg) -> FieldOfView:
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


def _pattern(sensor: dict) -> Pattern:
    name = sensor["pattern"]
    if name not in PATTERNS:
        raise ValueError(f"unknown beam pattern {name!r}; patterns are {', '.join(PATTERNS)}")
    return PATTERNS[name]


def beam_pattern(sensor: dict) -> BeamPattern:
    """Build the beam pattern of a ``[sensor]`` section.

    Parameters
    ----------
    sensor : dict
        ``pattern`` (a key of ``PATTERNS``) and the keys that pattern reads:
        ``field_of_view_deg`` (2 or 4 floats, degrees: total extents ``[az, el]`` centred on the
        boresight, or ``[az_min, az_max, el_min, el_max]`` per side), ``beams`` (zigzag),
        ``resolution`` (grid: beams in azimuth and in elevation).

    Returns
    -------
    BeamPattern
    """
    pattern = _pattern(sensor)
    missing = [key for key in pattern.keys if sensor.get(key) is None]
    if missing:
        raise ValueError(f"a {pattern.name} pattern needs sensor.{missing[0]}")
    fov = (field_of_view(sensor["field_of_view_deg"]) if "field_of_view_deg" in pattern.keys
           else (0.0, 0.0, 0.0, 0.0))
    azimuth, elevation = pattern.build(sensor, fov)
    return BeamPattern(pattern.name, np.asarray(azimuth, dtype=np.float64),
                       np.asarray(elevation, dtype=np.float64), fov, pattern.reports_angles,
                       pattern.recorded_as)


def n_beams(sensor: dict) -> int:
    """Beams of a ``[sensor]`` section's pattern, counted without building it."""
    return int(_pattern(sensor).count(sensor))


def _single(sensor: dict, fov: FieldOfView) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros(1), np.zeros(1)


def _cross(sensor: dict, fov: FieldOfView) -> tuple[np.ndarray, np.ndarray]:
    az_min, az_max, el_min, el_max = fov
    return (np.array([0.0, az_max, az_min, 0.0, 0.0]),
            np.array([0.0, 0.0, 0.0, el_max, el_min]))


def _zigzag(sensor: dict, fov: FieldOfView) -> tuple[np.ndarray, np.ndarray]:
    az_min, az_max, el_min, el_max = fov
    beams = int(sensor["beams"])
    if beams < 2:
        raise ValueError(f"a zigzag needs at least 2 beams, got {beams}")
    return (np.linspace(az_min, az_max, beams),
            np.where(np.arange(beams) % 2 == 0, el_max, el_min))


def _grid(sensor: dict, fov: FieldOfView) -> tuple[np.ndarray, np.ndarray]:
    az_min, az_max, el_min, el_max = fov
    n_az, n_el = sensor["resolution"]
    el, az = np.meshgrid(_spaced(el_min, el_max, n_el), _spaced(az_min, az_max, n_az),
                         indexing="ij")
    return az.ravel(), el.ravel()


register(Pattern("single", _single, lambda sensor: 1, recorded_as="single"))
register(Pattern("cross", _cross, lambda sensor: 5, keys=("field_of_view_deg",),
                 recorded_as="cross"))
register(Pattern("zigzag", _zigzag, lambda sensor: int(sensor["beams"]),
                 keys=("field_of_view_deg", "beams"), recorded_as="zigzag"))
register(Pattern("grid", _grid, lambda sensor: int(np.prod(sensor["resolution"])),
                 keys=("field_of_view_deg", "resolution"), reports_angles=True,
                 recorded_as="grid"))


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
