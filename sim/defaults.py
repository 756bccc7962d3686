"""Every default of a simulated scene, in one place, with where each number comes from.

A scene file (TOML) states only what differs from this table. Units: lengths in metres, times in
seconds, masses in kilograms; **angles in degrees, and every angle key says so in its name**
(``inclination_deg``), except the pulse-dilation cone, which the paper gives in milliradians
(``dilation_half_angle_mrad``). The strike log itself is SI throughout (radians).

"Paper" is Nayak, Udrea, Marsella & Beck, *Application of a laser rangefinder for space object
imaging and shape reconstruction*.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass
from typing import Any

from sim.sensors import PATTERNS

# Newton's gravitational constant [m^3 kg^-1 s^-2], CODATA 2018.
GRAVITATIONAL_CONSTANT = 6.67430e-11


# "satellite", "polyhedron" and "cratered-asteroid" are generated from target.seed
# (sim/procedural.py).
TARGET_KINDS = ("ellipsoid", "rso-a", "rso-b", "mesh", "satellite", "polyhedron",
                "cratered-asteroid")
GENERATED_KINDS = ("satellite", "polyhedron", "cratered-asteroid")
SIZED_KINDS = ("polyhedron", "cratered-asteroid")
# "kepler": the circular orbit of [orbit] about the target and the uniform spin of [target];
# "spice": positions and attitudes read from SPICE kernels (sim/motion.py, SpiceGeometry).
ORBIT_KINDS = ("kepler", "spice")
# "fixed": nadir, or the sinusoidal slew of [slew]; "gaps": the closed-loop law of
# sim/gap_seeking.py, aiming the boresight at what the chaser has not yet struck.
ATTITUDE_MODES = ("fixed", "gaps")

# Limits on values (beyond sign checks) and why.
MAX_SUBDIVISIONS = 8          # 1.3 M faces; subdivision 9 would need ~1 GB of mesh
MAX_FIELD_OF_VIEW_DEG = 180.0  # a pattern spanning 180 deg or more is not a forward-looking sensor
# Pose-knowledge errors beyond these are failures, not calibration errors: a sensor 10 deg off its
# mounting, an attitude known to worse than a degree, a clock a minute off.
MAX_MISALIGNMENT_DEG = 10.0
MAX_ATTITUDE_ARCSEC = 3600.0
MAX_TIME_TAG_S = 60.0
# A beam-spread cone must open less than a right angle: 90 deg is 1000 * pi / 2 mrad.
MAX_HALF_ANGLE_MRAD = 1000.0 * math.pi / 2


@dataclass(frozen=True)
class Key:
    """One scene key: its default, kind, unit and meaning, and the values it accepts.

    Attributes
    ----------
    default : object or None
        ``None``: no default, the key is optional.
    kind : str
        ``number``, ``int``, ``str``, ``bool``, ``vec<N>`` (N numbers), ``ivec<N>`` (N
        integers), ``fov`` (2 or 4 numbers) or ``paths`` (an array of file names).
    unit : str
        Unit of the value as the scene gives it (``""``: none). Angles are in ``deg`` (or
        ``mrad``); sim/derive.py converts them to radians once, at load.
    help : str
        One line for ``recon simulate --keys``.
    minimum, maximum : float or None
        Bounds of the value (of each element, for arrays); ``None``: unbounded.
    exclusive_minimum, exclusive_maximum : bool
        The bound itself is refused (``minimum=0, exclusive_minimum=True``: positive).
    finite : bool
        Refuse infinities (NaN is always refused). ``False`` only where ``inf`` means something.
    choices : collection of str
        The allowed values of a ``str`` key (empty: any string); a live view for
        ``sensor.pattern``.
    nonzero : bool
        An array must not be all zeros (a direction or a quaternion).
    """

    default: Any
    kind: str
    unit: str
    help: str
    minimum: float | None = None
    maximum: float | None = None
    exclusive_minimum: bool = False
    exclusive_maximum: bool = False
    finite: bool = True
    choices: Collection[str] = ()
    nonzero: bool = False


# Shorthands for the bounds most keys declare.
POSITIVE = {"minimum": 0.0, "exclusive_minimum": True}
NON_NEGATIVE = {"minimum": 0.0}
DIRECTION = {"nonzero": True}


# fmt: off
SCHEMA: dict[str, dict[str, Key]] = {
    "target": {
        # "ellipsoid" (the paper's asteroid), "rso-a", "rso-b", "mesh" (a user file), or a
        # generated "satellite", "polyhedron" or "cratered-asteroid".
        "kind": Key("ellipsoid", "str", "", "ellipsoid, rso-a, rso-b, mesh, satellite, "
                    "polyhedron or cratered-asteroid", choices=TARGET_KINDS),
        # Paper, "Model: Tri-Axial Ellipsoid": 143.75, 86.25 and 287.50 m along x, y and z.
        "semi_axes": Key([143.75, 86.25, 287.5], "vec3", "m", "ellipsoid semi-axes along x, y, z",
                         **POSITIVE),
        # Icosphere subdivisions: 20 * 4**5 = 20,480 faces, the mesh size of the ray-casting
        # benchmark (benchmarks/bench_simulate.py); its facets are ~0.023 m off the exact
        # ellipsoid.
        "subdivisions": Key(5, "int", "", "ellipsoid resolution: 20 * 4**n faces",
                            minimum=0, maximum=MAX_SUBDIVISIONS),
        "path": Key(None, "str", "", "mesh file for kind = mesh: OBJ, PLY, STL, PDS table .tab, "
                                     "ICQ .icq or SPICE DSK .bds/.dsk"),
        # Units of the mesh file: PDS tables, ICQ and DSK are published in km (DSK always),
        # the 3D formats read as metres (formats/mesh_io.py, default_units).
        "units": Key(None, "str", "", "units of the mesh file (default: km for .tab, .icq, "
                                      ".bds, .dsk; m otherwise)", choices=("km", "m")),
        # An OBJ shape model in km (Gaskell's Itokawa and Eros, radar Bennu as OBJ) is read with
        # units = "km" or scale = 1000.
        "scale": Key(1.0, "number", "", "factor on the mesh coordinates after the unit "
                                        "conversion", **POSITIVE),
        "center": Key(False, "bool", "", "move the mesh's volume centroid to the origin"),
        # Generated targets: every dimension drawn from this seed (same seed, same mesh).
        "seed": Key(0, "int", "", "shape seed of a generated target", minimum=0),
        # Absent: 5.7 m for a polyhedron, 500 m for a cratered asteroid (sim/procedural.py).
        "size": Key(None, "number", "m", "longest extent of a generated polyhedron (none: "
                    "5.7) or cratered asteroid (none: 500)", **POSITIVE),
        # Paper: "a period of rotation of 15480 seconds, or 4.3 hours"; inf: not spinning.
        "spin_period": Key(15480.0, "number", "s", "spin period (inf: no spin)", **POSITIVE,
                           finite=False),
        # Paper: rotation "mainly about the z-axis"; body frame.
        "spin_axis": Key([0.0, 0.0, 1.0], "vec3", "", "spin axis in the body frame B", **DIRECTION),
        # Identity: B and I coincide at t = 0 (formats/SPEC.md, frame I).
        "attitude": Key([0.0, 0.0, 0.0, 1.0], "vec4", "", "B->I quaternion (x, y, z, w) at t = 0",
                        **DIRECTION),
    },
    "orbit": {
        "kind": Key("kepler", "str", "", "kepler (radius .. change_inclination_deg) or spice "
                    "(kernels .. start_et)",
                    choices=ORBIT_KINDS),
        # Paper: 750 m around the asteroid (the RSO presets set 250 m).
        "radius": Key(750.0, "number", "m", "circular orbit radius about the target centre",
                      **POSITIVE),
        # Paper: 85 deg to the target's equatorial plane is "near-optimal".
        "inclination_deg": Key(85.0, "number", "deg", "inclination to the equatorial plane",
                               minimum=0.0, maximum=180.0),
        "node_deg": Key(0.0, "number", "deg", "longitude of the ascending node"),
        "phase_deg": Key(0.0, "number", "deg", "argument of latitude at t = 0"),
        # The period comes from mu = G * density * volume unless mu or period is given. The paper
        # gives no mass; 2000 kg/m^3 is a rubble-pile asteroid's bulk density (Itokawa 1900,
        # Eros 2670). For the paper's ellipsoid: mu = 1.99 m^3/s^2, period 25.4 h at 750 m.
        "density": Key(2000.0, "number", "kg/m^3", "bulk density of the target", **POSITIVE),
        "mu": Key(None, "number", "m^3/s^2", "gravitational parameter (replaces density)",
                  **POSITIVE),
        "period": Key(None, "number", "s", "orbit period (replaces density and mu)", **POSITIVE),
        # Paper (RSO inclination test): 43 h at 85 deg, then 43 h at 76 to 94 deg.
        "change_time": Key(None, "number", "s", "time of the inclination change (at next node)",
                           **NON_NEGATIVE),
        "change_inclination_deg": Key(None, "number", "deg", "inclination after the change",
                                      minimum=0.0, maximum=180.0),
        # kind = "spice": where the chaser is and where everything points come from kernels;
        # shots at time t are at ET = start + t (TDB seconds past J2000).
        "kernels": Key(None, "paths", "", "spice: kernel files (SPK, CK, FK, SCLK, PCK, "
                       "meta-kernel), relative to the scene file"),
        "observer": Key(None, "str", "", "spice: NAIF name or ID of the sensor"),
        "target": Key(None, "str", "", "spice: NAIF name or ID of the target centre"),
        # The log's inertial frame I (formats/SPEC.md); J2000 as recon's own kernels write it.
        "inertial_frame": Key("J2000", "str", "", "spice: inertial frame of the log"),
        "target_frame": Key(None, "str", "", "spice: target body-fixed frame (B)"),
        "sensor_frame": Key(None, "str", "", "spice: sensor frame, +z the boresight (absent: "
                            "nadir pointing and the [slew] law)"),
        "start_utc": Key(None, "str", "", "spice: UTC of the first shot"),
        "start_et": Key(None, "number", "s", "spice: ET (TDB s past J2000) of the first shot"),
    },
    "time": {
        # Paper: "moved along the orbit path in time steps of 10 seconds".
        "step": Key(10.0, "number", "s", "time between shots", **POSITIVE),
        # Paper: "50 rotations are used in further trials that require a fixed time".
        "rotations": Key(50.0, "number", "target rotations", "duration in spin periods",
                         **POSITIVE),
        "duration": Key(None, "number", "s", "duration (replaces rotations)", **POSITIVE),
    },
    "slew": {
        # Paper: 2 deg at 85 deg inclination, 5 deg at 60 deg; 3 deg is "no better" than 2.
        "amplitude_deg": Key(0.0, "number", "deg", "sinusoidal slew amplitude (0: nadir)",
                             minimum=0.0, maximum=90.0, exclusive_maximum=True),
        # Not in the paper: 12.5 steps per cycle, so the 10 s step samples 25 distinct angles.
        "period": Key(125.0, "number", "s", "slew period", **POSITIVE),
        # Paper: slew "in a plane normal to the orbital plane", i.e. about the along-track axis,
        # which is +x of the nominal sensor frame (sim/motion.py).
        "axis": Key([1.0, 0.0, 0.0], "vec3", "", "slew axis in the nominal sensor frame",
                    **DIRECTION),
        "phase_deg": Key(0.0, "number", "deg", "slew phase at t = 0"),
    },
    "attitude": {
        "mode": Key("fixed", "str", "", "fixed (nadir or the [slew] law) or gaps (closed loop)",
                    choices=ATTITUDE_MODES),
        # A conservative rate for a reaction-wheel small satellite: 1 deg/s of a 100 kg chaser
        # (inertia ~10 kg m^2) stores 0.17 Nms, inside the 0.015-8 Nms of small-spacecraft wheels
        # (NASA Small Spacecraft Technology State of the Art, ch. 5 GNC, Table 5-1). At the
        # 10 s step it allows 10 deg between shots.
        "max_rate_deg_s": Key(1.0, "number", "deg/s", "gaps: slew-rate limit of the boresight",
                              **POSITIVE),
        # Off the nominal boresight (the target centre): the paper's asteroid spans 21 deg from
        # 750 m, so 30 deg reaches every limb with margin, while bounding how far off target a
        # body-mounted sensor (and the chaser's nadir-facing arrays and antenna) is turned.
        "max_offset_deg": Key(30.0, "number", "deg", "gaps: largest angle off the nominal "
                              "boresight", **POSITIVE, maximum=90.0, exclusive_maximum=True),
        # 30 shots of the paper's 10 s step: the target turns 7 deg per interval (4.3 h spin), so
        # what the plan predicts stays close to what is struck.
        "replan_s": Key(300.0, "number", "s", "gaps: replanning interval", **POSITIVE),
    },
    "sensor": {
        # The registered patterns (sim/sensors.py), read live: a pattern registered later counts.
        "pattern": Key("single", "str", "", "beam pattern: " + ", ".join(PATTERNS),
                       choices=PATTERNS.keys()),
        # Paper: "The cross configuration field of view is set to 10 x 10 deg" (asteroid); an
        # "A x B" field of view spans A in azimuth and B in elevation, centred on the boresight.
        # Four numbers give [az_min, az_max, el_min, el_max] per side (paper, Figures 2 and 3).
        "field_of_view_deg": Key([10.0, 10.0], "fov", "deg",
                                 "[az, el] extents or [az_min, az_max, el_min, el_max]"),
        # Paper, Figure 5(b): a zigzag of 5 beams.
        "beams": Key(5, "int", "", "zigzag: number of beams", minimum=2),
        # Paper, Figure 3: 5 x 5 grids.
        "resolution": Key([5, 5], "ivec2", "", "grid: beams in azimuth x elevation", minimum=1),
        # Jenoptik LIDAR (paper, Table 3): minimum operational range <= 1 m.
        "range_min": Key(1.0, "number", "m", "shortest range reported", **NON_NEGATIVE),
        # Paper: "5km for the scanning LIDAR and 3km for the LRF".
        "range_max": Key(3000.0, "number", "m", "longest range reported", **POSITIVE),
    },
    "errors": {
        # Off by default (the paper's error-free runs). Paper values: LIDAR 1 m range and 0.2 deg
        # angles; fixed LRFs 0.3 m range and no angle error; pose knowledge 2 m; pulse dilation
        # alpha 0.0002 with a 0.6 mrad cone of 30 sub-rays. All 3-sigma.
        "range_sigma3": Key(0.0, "number", "m", "3-sigma Gaussian range error", **NON_NEGATIVE),
        "azimuth_sigma3_deg": Key(0.0, "number", "deg", "3-sigma Gaussian azimuth error",
                                  **NON_NEGATIVE),
        "elevation_sigma3_deg": Key(0.0, "number", "deg", "3-sigma Gaussian elevation error",
                                    **NON_NEGATIVE),
        "position_sigma3": Key(0.0, "number", "m", "3-sigma per-axis error of recorded position",
                               **NON_NEGATIVE),
        "dilation_alpha": Key(0.0, "number", "1", "pulse dilation alpha, paper Eq. (1) (0: off)",
                              **NON_NEGATIVE),
        "dilation_half_angle_mrad": Key(0.6, "number", "mrad", "beam-spread cone half-angle",
                                        minimum=0.0, maximum=MAX_HALF_ANGLE_MRAD,
                                        exclusive_maximum=True),
        # At most 10,000 sub-rays (the paper uses 30): a shot casts 1 + m rays per beam.
        "dilation_subrays": Key(30, "int", "", "sub-rays m in the beam-spread cone", minimum=1,
                                maximum=10_000),
        # Pose knowledge (sim/pose_errors.py), off by default; the paper leaves it open. Scales
        # a mission engineer would quote: Hayabusa2's LIDAR misalignment gave 0.4 m of error at
        # 1 km (0.02 deg); star trackers know attitude to a few arcseconds; relative navigation
        # near a small body to metres (OSIRIS-REx, NEAR).
        "boresight_misalignment_deg": Key([0.0, 0.0, 0.0], "vec3", "deg",
                                          "constant sensor misalignment, rotation vector in S",
                                          minimum=-MAX_MISALIGNMENT_DEG,
                                          maximum=MAX_MISALIGNMENT_DEG),
        "attitude_bias_arcsec": Key([0.0, 0.0, 0.0], "vec3", "arcsec",
                                    "constant attitude-knowledge bias, rotation vector in S",
                                    minimum=-MAX_ATTITUDE_ARCSEC, maximum=MAX_ATTITUDE_ARCSEC),
        "attitude_walk_arcsec": Key(0.0, "number", "arcsec/sqrt(h)",
                                    "attitude random walk: 1-sigma per axis after one hour",
                                    minimum=0.0, maximum=MAX_ATTITUDE_ARCSEC),
        "position_bias": Key([0.0, 0.0, 0.0], "vec3", "m",
                             "constant position-knowledge bias: radial, along-track, cross-track"),
        "position_bias_inertial": Key([0.0, 0.0, 0.0], "vec3", "m",
                                      "constant position-knowledge bias in the inertial frame I"),
        "position_drift": Key(0.0, "number", "m",
                              "1-sigma per axis of a slowly varying (Gauss-Markov) position error",
                              **NON_NEGATIVE),
        # Relative navigation errors change over hours (an orbit here lasts 25 h).
        "position_drift_time": Key(3600.0, "number", "s", "correlation time of position_drift",
                                   **POSITIVE),
        "spin_axis_error_deg": Key(0.0, "number", "deg",
                                   "tilt of the known spin axis (direction from the seed)",
                                   minimum=0.0, maximum=MAX_MISALIGNMENT_DEG),
        "spin_period_error": Key(0.0, "number", "s", "known spin period minus the true one"),
        "time_tag_offset": Key(0.0, "number", "s",
                               "recorded poses are the true poses at time + offset",
                               minimum=-MAX_TIME_TAG_S, maximum=MAX_TIME_TAG_S),
    },
    # A run's cost is estimated before it starts (sim/derive.py, ``cost``) and refused above these;
    # raise them with --set limits.KEY=VALUE. The largest preset, asteroid-lidar-noise (15
    # rotations of a 32 x 32 grid), casts 2.4e7 rays, needs ~0.5 GB and writes up to ~1.8 GB.
    "limits": {
        # 1e10 rays: about 30 min at the 6.5 M rays/s benchmarks/bench_simulate.py measured
        # with embreex (docs/decisions.md, "Measurements behind the defaults").
        "rays": Key(1e10, "number", "rays", "most rays a run may cast", **POSITIVE),
        # 8 GiB: half of a 16 GiB workstation's memory (docs/decisions.md, "Measurements
        # behind the defaults").
        "memory_mb": Key(8192.0, "number", "MiB", "most memory a run may need", **POSITIVE),
        # 20 GB: ten times the largest preset's log.
        "disk_mb": Key(20000.0, "number", "MB", "largest log a run may write", **POSITIVE),
    },
}
# Longest string value of a scene (a mesh path): longer is a mistake or an attack, not a path.
MAX_STRING_CHARS = 4096
# Most files in an array of paths (orbit.kernels): a mission's meta-kernel lists a few hundred.
MAX_PATHS = 1000
# Magnitudes of the numbers of a scene, in each key's unit, beyond a key's own bounds: at most
# 1e15 (1e15 m is 6,700 au and 1e15 s 32 million years, beyond every scene recon simulates) and,
# unless zero, at least 1e-15 (a femtometre, a femtosecond). Cubes and inverse squares the
# derivations take (an orbit's period from radius**3 / mu, mu from the period) then stay far
# inside float64's range instead of overflowing.
MAX_MAGNITUDE = 1e15
MIN_MAGNITUDE = 1e-15
# Largest scene file read, bytes: a scene states a few dozen keys.
MAX_SCENE_BYTES = 1 << 20
# Largest seed: logs store it as a signed 64-bit integer.
MAX_SEED = 2**63 - 1
# Memory a run needs per ray in flight, bytes: RAYS_PER_CHUNK rays keep a chunk near 100 MB
# (below), ~190 bytes a ray; and per truth-mesh face, for the ray-casting structures (Embree's
# BVH and the float64 copies of sim/raycast.py).
BYTES_PER_RAY = 200
BYTES_PER_FACE = 300
# fmt: on

# Keys of which a layer (defaults, scene file, --set overrides) gives at most one; the last layer
# that gives one wins, so `--set time.duration=600` replaces the default `rotations`.
ALTERNATIVES: dict[str, tuple[str, ...]] = {
    "time": ("rotations", "duration"),
    "orbit": ("density", "mu", "period"),
}

# Keys that only mean something for some values of another key: (section, key) -> (section,
# key, allowed values). Giving one of these in a scene where it means nothing is an error. The
# [sensor] keys a beam pattern reads are declared by the pattern itself (sim/sensors.py,
# ``Pattern.keys``) and added to these by sim/schema.py.
ONLY_WITH: dict[tuple[str, str], tuple[str, str, tuple[str, ...]]] = {
    ("target", "semi_axes"): ("target", "kind", ("ellipsoid",)),
    ("target", "subdivisions"): ("target", "kind", ("ellipsoid",)),
    ("target", "path"): ("target", "kind", ("mesh",)),
    ("target", "scale"): ("target", "kind", ("mesh",)),
    ("target", "units"): ("target", "kind", ("mesh",)),
    ("target", "center"): ("target", "kind", ("mesh",)),
    ("target", "seed"): ("target", "kind", GENERATED_KINDS),
    ("target", "size"): ("target", "kind", SIZED_KINDS),
    ("attitude", "max_rate_deg_s"): ("attitude", "mode", ("gaps",)),
    ("attitude", "max_offset_deg"): ("attitude", "mode", ("gaps",)),
    ("attitude", "replan_s"): ("attitude", "mode", ("gaps",)),
    ("slew", "amplitude_deg"): ("attitude", "mode", ("fixed",)),
    ("slew", "period"): ("attitude", "mode", ("fixed",)),
    ("slew", "axis"): ("attitude", "mode", ("fixed",)),
    ("slew", "phase_deg"): ("attitude", "mode", ("fixed",)),
    **{("orbit", key): ("orbit", "kind", ("kepler",)) for key in (
        "radius", "inclination_deg", "node_deg", "phase_deg", "density", "mu", "period",
        "change_time", "change_inclination_deg")},
    **{("orbit", key): ("orbit", "kind", ("spice",)) for key in (
        "kernels", "observer", "target", "inertial_frame", "target_frame", "sensor_frame",
        "start_utc", "start_et")},
    # The target's attitude comes from its kernel frame in a SPICE-driven scene.
    **{("target", key): ("orbit", "kind", ("kepler",)) for key in (
        "spin_period", "spin_axis", "attitude")},
}

# Cross-key rules, each checked by sim/schema.py with a one-line message naming the key.
# A key with no default that a scene needs when another key has one of some values.
NEEDED_WHEN: dict[tuple[str, str], tuple[str, str, tuple[str, ...]]] = {
    ("target", "path"): ("target", "kind", ("mesh",)),
    **{("orbit", key): ("orbit", "kind", ("spice",)) for key in (
        "kernels", "observer", "target", "target_frame")},
}
# Keys given both or neither: the inclination change needs its time and its new inclination.
TOGETHER: tuple[tuple[tuple[str, str], tuple[str, str]], ...] = (
    (("orbit", "change_time"), ("orbit", "change_inclination_deg")),
)
# (lower, upper): upper must exceed lower.
ORDERED: tuple[tuple[tuple[str, str], tuple[str, str]], ...] = (
    (("sensor", "range_min"), ("sensor", "range_max")),
)

# Streaming: rays cast per chunk of shots. 2**19 rays keep a chunk's working set near 100 MB, so
# two chunks in flight and the writer's buffers stay far below the 2 GB budget of the issue, while
# per-chunk Python overhead stays below 1% of the casting time (benchmarks/bench_simulate.py).
RAYS_PER_CHUNK = 1 << 19
# The most shots in one chunk (single-beam runs): the 77,400-shot paper run is two chunks.
MAX_SHOTS_PER_CHUNK = 1 << 16
# Chunks computed ahead of the writer; each worker thread holds at most one.
CHUNKS_IN_FLIGHT = 3

# Progress bar: shown only on runs still going after this many seconds (issue: "a progress bar on
# runs longer than a couple of seconds").
PROGRESS_DELAY_S = 2.0

# Gap-seeking law (sim/gap_seeking.py) and its voxel map (sim/surface_map.py). Voxel edge: this
# fraction of the diagonal of the strikes' bounding box, just above the coverage metric's tau of
# 1 % of the truth's diagonal (metrics/defaults.py): one strike per voxel of surface then leaves
# almost no surface point farther than tau from a strike.
GAP_VOXEL_FRACTION = 0.013
# ... and at least the beam's angular step at the target's range: 0.05 deg is 0.22 m at 250 m,
# the tau of the paper's 20 m satellite, so the first few strikes (all within a metre of each
# other) do not make a map of millimetre voxels.
GAP_VOXEL_MIN_DEG = 0.05
# The map is rebuilt from every recorded beam when the voxel edge above drifts from the map's by
# more than this factor (the strikes' box grows as the target is seen).
GAP_VOXEL_REBUILD = 1.25
# Misses and beam paths are traversed within the occupied voxels' box grown by this fraction of
# its diagonal: space farther from the target holds nothing to plan for.
GAP_MARGIN_FRACTION = 0.25
# Frontier voxels the planner weighs per plan; beyond this it takes an even subset (every k-th
# key), bounding the planner's cost on large maps. A plan of GAP_PLAN_INTERVALS intervals of 30
# shots aims at most 120 of them.
GAP_MAX_CANDIDATES = 2048
# The law plans (the map takes the intervals observed since; the frontier and the candidates
# are chosen anew) at most this many replanning intervals apart (GAP_SETTLED_PLAN_INTERVALS late
# in the least-struck phase, below); while the frontier lasts, sooner when an interval could not
# aim every shot at a candidate (sim/gap_seeking.py). Planning everything every interval cost
# 70-85 % of a closed-loop run; in the least-struck phase, planning after every short interval
# too made 437 plans in RSO-A's 984 intervals of that phase instead of 246, for coverage within
# 0.0025 at every time the study reports (docs/decisions.md).
GAP_PLAN_INTERVALS = 4
# While the frontier holds more voxels than a plan weighs (GAP_MAX_CANDIDATES: a large body's
# unexplored boundary, its plans each weighing an even subset of it), a plan comes every
# GAP_LARGE_PLAN_INTERVALS intervals instead, sooner after a short interval as always. On the
# closed-loop study's asteroid that is from about 8 h until its shell is enclosed at 28.5 h
# (2,050-5,600 frontier voxels), 95 % coverage within an hour of a plan every 4; the spacecraft's
# frontiers never hold more than about 1,700 voxels (RSO-A), so their plans are as before.
GAP_LARGE_PLAN_INTERVALS = 8
# One candidate per cube of this many voxels on a side: a strike is expected to settle the
# frontier around its aim.
GAP_BLOCK_VOXELS = 2
# The frontier counts as exhausted after this many consecutive intervals with no frontier voxel
# predicted visible within the offset limit. From then on the law also aims at the least-struck
# surface voxels (strike count at most this quantile of the counts): a voxel 1.3 tau wide that
# holds one strike can hold surface farther than tau from it, and a voxel an oblique beam
# crossed beside a thin panel is marked free although part of the panel lies in it; neither is
# frontier, and a fixed slew keeps closing such holes by sweeping. (Halving the voxel edge
# instead was measured slower: docs/decisions.md.)
GAP_IDLE_INTERVALS = 2
GAP_RESIDUAL_QUANTILE = 0.25
# Once the least-struck phase has lasted this many intervals (12 h), the law plans only every
# GAP_SETTLED_PLAN_INTERVALS intervals (80 min): by then the coverage is within 0.002-0.05 of the
# target's ceiling on every target of the closed-loop study, what is left to strike is scattered
# and mostly hidden, and a plan every 16 intervals from then on took 0.02-0.03 off the planner's
# share of a 96 h run for coverage within 0.011 at every time the study reports (a plan every 8
# or 16 from the phase's start cost the seed-2 satellite 0.07-0.08 of coverage at 12 h:
# docs/decisions.md).
GAP_SETTLED_INTERVALS = 144
GAP_SETTLED_PLAN_INTERVALS = 16
# The settled phase begins with the least-struck phase, though, when the frontier ran out
# because the struck surface closed around it: at most GAP_CLOSED_FRONTIER_FRACTION frontier
# voxels per occupied voxel are left when the least-struck phase begins (a closed body's shell
# enclosed, what was left of its frontier struck: 0.012-0.026 on the study's asteroid at 30-32
# h, coverage 0.99 there), not because what is left is hidden from where the chaser has been
# (0.34-0.40 on the generated satellites, 0.69 on RSO-A and RSO-B at 6.2-14.3 h, coverage about
# 0.72-0.87: the least-struck phase's first 12 h are where they gain most). The asteroid's
# least-struck phase had cost about a fifth of its planner's time (docs/decisions.md).
GAP_CLOSED_FRONTIER_FRACTION = 0.1
# Such a closed map's settled phase plans every GAP_CLOSED_PLAN_INTERVALS intervals (160 min):
# what is left to strike on it is scattered over a surface seen all round. (A plan every 32 in
# every settled phase left RSO-B below the 2 deg slew at 96 h: docs/decisions.md.)
GAP_CLOSED_PLAN_INTERVALS = 32
# In that settled phase a plan weighs at most GAP_SETTLED_MAX_CANDIDATES candidates (an even
# subset, as above) and sets a candidate aside after GAP_SETTLED_ASIDE_WALKS walk that found it
# hidden: a sweep aims at every candidate of its plan and walks the open ones until its shots
# have aims, so most of a late interval's cost scaled with a pool of up to 2,048 mostly hidden
# voxels, for a plan's 16 intervals of 30 shots. With them most settled intervals have no
# candidate open and hold their shots without a sweep (sim/gap_seeking.py); together that took
# 0.01-0.03 off the planner's share of a 96 h run (planner / simulation), for coverage at most
# 0.008 lower at any time the study reports (0.006 at 96 h: docs/decisions.md).
GAP_SETTLED_MAX_CANDIDATES = 256
GAP_SETTLED_ASIDE_WALKS = 1
# Once the least-struck voxels are candidates, a candidate predicted hidden this many times (each
# time an interval's sweep reached it) is set aside: no longer walked or chosen (late in a run
# most candidates are hidden from any one place: a body's unknown interior behind its struck
# shell, least-struck voxels hard to see). A plan re-admits every set-aside candidate of its
# pool once this many intervals have passed since the last re-admission: the chaser's view of
# the target turns as it orbits and the target spins.
GAP_ASIDE_WALKS = 3
GAP_ASIDE_INTERVALS = 24
# The unknown voxels the struck ones enclose (a body's interior behind its struck shell) leave
# the frontier (sim/surface_map.py, SurfaceMap.enclose): a flood fill over the occupied voxels'
# box, run by a plan when GAP_ENCLOSE_INTERVALS intervals have passed since the last one; the
# wait doubles after a fill that enclosed nothing, up to GAP_ENCLOSE_MAX_INTERVALS, and is back
# to GAP_ENCLOSE_INTERVALS after one that enclosed some. A shell closes once, most of the way
# (with a fill every 24 intervals the 85 deg asteroid's interior, 33,000 voxels, was enclosed by
# one fill at about 23 h and 108 more voxels by the next 35 fills; RSO-A's inside, 6,000, by one
# fill, then none), and a fill costs about as much as two or three plans (docs/decisions.md).
# The longest wait, 32 h, lets a map whose shell is closed skip most fills for the rest of a run
# (with 8 h, 22 fills in the 85 deg asteroid's 96 h, most of them after its shell closed at 28 h,
# enclosing nothing: about a tenth of its planner's time).
GAP_ENCLOSE_INTERVALS = 24
GAP_ENCLOSE_MAX_INTERVALS = 384
# A fill counts as enclosing some only when it marks more than this fraction of the occupied
# voxels: after a shell closes, fills keep finding a few voxels each (1-3 on the 85 deg
# asteroid), which called the next fill 24 intervals later; counting those as nothing halved
# its fills in 96 h (18 -> 9), with RSO-A's decisions unchanged (docs/decisions.md).
GAP_ENCLOSE_MIN_FRACTION = 0.01
