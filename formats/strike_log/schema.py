"""Strike-log format v1 (formats/SPEC.md): names, layout, the records a log holds, and the
checks the reader and writer share."""

from __future__ import annotations

import contextlib
from dataclasses import asdict, dataclass, field

import numpy as np

from formats.errors import InputError

FORMAT_NAME = "recon-strike-log"
FORMAT_VERSION = 1
# Suffixes a strike log is written under: it is an HDF5 file.
LOG_SUFFIXES = (".h5", ".hdf5")

# Largest chunk rows: 65,536 strike rows of float64 are 512 KiB, inside HDF5's default 1 MiB chunk
# cache. A writer told the expected row counts uses chunks no longer than those (SPEC.md, Storage),
# so a small log is not padded to these sizes.
STRIKE_CHUNK_ROWS = 65_536
SHOT_CHUNK_ROWS = 16_384
# Live logs (SPEC.md, Live logs): while an SWMR writer is open, this dataset holds the shot and
# strike rows complete and flushed, and 1 once the writer is closing.
LIVE_COMMITTED = "live_committed"
# How far from 1 a stored quaternion's norm may be (SPEC.md, Conventions).
QUATERNION_NORM_TOLERANCE = 1e-6
# Rows handed out per chunk by StrikeLog.iter_chunks: 2**20 strikes is ~100 MB of derived arrays.
READ_CHUNK_ROWS = 1 << 20
# Storage filters (SPEC.md, Storage; docs/decisions.md): deflate (gzip) + shuffle by default,
# the filters every HDF5 build has, so that h5dump, HDFView, MATLAB and IDL read every dataset;
# lzf (h5py's own filter) on request; Fletcher-32 checksums always. The level is the fastest that
# kept simulate time within 1.3x of lzf on the demo and asteroid-lidar logs (docs/decisions.md).
COMPRESSIONS = ("none", "lzf", "gzip")
GZIP_LEVEL = 1
DEFAULT_COMPRESSION = f"gzip:{GZIP_LEVEL}"


def compression_filters(spec: str, where: str | None = None) -> dict:
    """The h5py filter keywords of a compression named ``none``, ``lzf``, ``gzip`` or
    ``gzip:LEVEL`` (LEVEL 0-9; plain ``gzip`` is level ``GZIP_LEVEL``), shuffle included.

    Raises
    ------
    InputError
        Any other name; the message names ``where`` (the log, when given) and the allowed
        forms.
    """
    name, colon, level = str(spec).partition(":")
    if name == "none" and not colon:
        return {}
    if name == "lzf" and not colon:
        return {"compression": "lzf", "shuffle": True}
    if name == "gzip" and (not colon or (level.isdigit() and 0 <= int(level) <= 9)):
        return {"compression": "gzip", "compression_opts": int(level or GZIP_LEVEL),
                "shuffle": True}
    prefix = f"{where}: " if where else ""
    raise InputError(f"{prefix}compression must be one of none, lzf, gzip or gzip:LEVEL "
                         f"(LEVEL 0-9), got {spec!r}")


# Columns stored with Fletcher-32 only, under any compression (docs/decisions.md):
# - the per-strike float64 measurements, noise down to their last bits: lzf keeps 80-85 % of
#   their bytes at 10x the CPU of storing them (44-48 ns a value against 4-5, measured on an
#   asteroid-lidar log), which made it 4/5 of the simulator's time; deflate costs more still;
#   the angle offsets too when an angle error or pulse dilation fills them (without one they
#   are zeros, which either filter stores in 1 % of the bytes, cheaply);
# - the truth's facet ids: deflate level 1 with shuffle kept 17 % of their bytes at a quarter of
#   the writer's time (15 of 64 ns a ray on an asteroid-lidar log; 8 % more bytes without it).
UNFILTERED_COLUMNS = frozenset({"strikes/range", "truth/point", "truth/range", "truth/facet"})
NOISY_ANGLE_COLUMNS = frozenset({"strikes/azimuth_offset", "strikes/elevation_offset"})

_PATTERNS = ("single", "cross", "zigzag", "grid", "custom")
_ROOT_ATTRS = ("format", "format_version", "producer", "producer_version", "created_utc", "scene",
               "seed", "target")
_SHOT_FIELDS = {"time": (), "sensor_position": (3,), "sensor_attitude": (4,),
                "target_attitude": (4,)}
_STRIKE_FIELDS = {"shot": ((), np.uint32), "beam": ((), np.uint32), "range": ((), np.float64)}
_ANGLE_FIELDS = ("azimuth_offset", "elevation_offset")
_TRUTH_SHOT_FIELDS = {"sensor_position": (3,), "sensor_attitude": (4,), "target_attitude": (4,)}
_TRUTH_STRIKE_FIELDS = {"point": ((3,), np.float64), "facet": ((), np.uint32),
                        "range": ((), np.float64)}
# The ``units`` and ``frame`` attributes of every dataset (SPEC.md): units "1" for indices and
# other dimensionless values; frame a frame of SPEC.md, "A->B" for a rotation, "none" for values
# that are in no frame.
DATASET_UNITS = {
    "sensor/beam_directions": ("1", "S"),
    "shots/time": ("s", "none"),
    "shots/sensor_position": ("m", "I"),
    "shots/sensor_attitude": ("1", "S->I"),
    "shots/target_attitude": ("1", "B->I"),
    "strikes/shot": ("1", "none"),
    "strikes/beam": ("1", "none"),
    "strikes/range": ("m", "none"),
    "strikes/azimuth_offset": ("rad", "S"),
    "strikes/elevation_offset": ("rad", "S"),
    "truth/sensor_position": ("m", "I"),
    "truth/sensor_attitude": ("1", "S->I"),
    "truth/target_attitude": ("1", "B->I"),
    "truth/point": ("m", "B"),
    "truth/facet": ("1", "none"),
    "truth/range": ("m", "none"),
    "truth/mesh/vertices": ("m", "B"),
    "truth/mesh/faces": ("1", "none"),
}


# --------------------------------------------------------------------------- records

# Pose-knowledge error models of /sensor/errors (SPEC.md): optional attributes, zero when absent
# (logs written before they existed), the vectors of them 3 floats.
POSE_ERROR_FIELDS = ("boresight_misalignment", "attitude_bias", "attitude_walk",
                     "position_bias", "position_bias_inertial", "position_drift",
                     "position_drift_time",
                     "spin_axis_error", "spin_period_error", "time_tag_offset")
POSE_ERROR_VECTORS = ("boresight_misalignment", "attitude_bias", "position_bias",
                      "position_bias_inertial")


# The paper states every error as a 3-sigma bound and the log records those (SPEC.md,
# /sensor/errors); a Gaussian error model draws with the 1-sigma value, a third of it.
SIGMA3_PER_SIGMA = 3.0


def sigma_from_sigma3(sigma3):
    """The 1-sigma value of a Gaussian error stated as its 3-sigma bound.

    Parameters
    ----------
    sigma3 : float or ndarray, any unit

    Returns
    -------
    float or ndarray, same unit and shape: ``sigma3 / 3``.
    """
    return sigma3 / SIGMA3_PER_SIGMA


@dataclass(frozen=True)
class SensorErrors:
    """Error models a producer applied to the recorded values (SPEC.md, /sensor/errors).

    The one definition of the error-model parameters. Fields are what the log records: 3-sigma
    values in SI units (metres, radians), zero when a model is off. Properties give the 1-sigma
    values a Gaussian model draws with.

    Attributes
    ----------
    range_sigma3 : float, metres, along the beam
    azimuth_sigma3, elevation_sigma3 : float, radians
    position_sigma3 : float, metres per axis of the recorded sensor position, frame I
    pulse_dilation_alpha : float, dimensionless, paper Eq. (1) (0: off)
    pulse_dilation_half_angle : float, radians, half-angle of the beam-spread cone
    pulse_dilation_subrays : float, a whole number, sub-rays in the cone
    boresight_misalignment : 3 floats, radians, rotation vector in S
        Constant rotation ``E`` of the sensor frame: the recorded attitude is the true one times
        ``E`` (``R_SI_recorded = R_SI_true E``).
    attitude_bias : 3 floats, radians, rotation vector in S
        Constant attitude-knowledge bias, composed after the misalignment.
    attitude_walk : float, radians per sqrt(second)
        Attitude-knowledge random walk: per axis, the error's 1-sigma growth is
        ``attitude_walk * sqrt(t)``.
    position_bias : 3 floats, metres, (radial, along-track, cross-track)
        Constant error of the recorded sensor position in the local orbital frame.
    position_bias_inertial : 3 floats, metres, I
        Constant error of the recorded sensor position in the inertial frame (a target
        ephemeris error when the chaser's own orbit is known inertially).
    position_drift : float, metres
        1-sigma per axis of a slowly varying (first-order Gauss-Markov) position error, same
        frame.
    position_drift_time : float, seconds
        Correlation time of the position drift.
    spin_axis_error : float, radians
        Tilt of the spin axis the target attitude was recorded with from the true one.
    spin_period_error : float, seconds
        Recorded spin period minus the true one.
    time_tag_offset : float, seconds
        The recorded poses are the true poses at ``time + time_tag_offset``.
    """

    range_sigma3: float = 0.0
    azimuth_sigma3: float = 0.0
    elevation_sigma3: float = 0.0
    position_sigma3: float = 0.0
    pulse_dilation_alpha: float = 0.0
    pulse_dilation_half_angle: float = 0.0
    pulse_dilation_subrays: float = 0.0
    boresight_misalignment: tuple[float, float, float] = (0.0, 0.0, 0.0)
    attitude_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    attitude_walk: float = 0.0
    position_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    position_bias_inertial: tuple[float, float, float] = (0.0, 0.0, 0.0)
    position_drift: float = 0.0
    position_drift_time: float = 0.0
    spin_axis_error: float = 0.0
    spin_period_error: float = 0.0
    time_tag_offset: float = 0.0

    @property
    def range_sigma(self) -> float:
        """1-sigma range error [m]."""
        return sigma_from_sigma3(self.range_sigma3)

    @property
    def azimuth_sigma(self) -> float:
        """1-sigma azimuth error [rad]."""
        return sigma_from_sigma3(self.azimuth_sigma3)

    @property
    def elevation_sigma(self) -> float:
        """1-sigma elevation error [rad]."""
        return sigma_from_sigma3(self.elevation_sigma3)

    @property
    def position_sigma(self) -> float:
        """1-sigma per-axis error of the recorded sensor position [m]."""
        return sigma_from_sigma3(self.position_sigma3)

    @property
    def angles(self) -> bool:
        """True when an azimuth or elevation error is on."""
        return self.azimuth_sigma3 > 0 or self.elevation_sigma3 > 0

    @property
    def dilation(self) -> bool:
        """True when pulse dilation is on."""
        return self.pulse_dilation_alpha > 0

    @property
    def pose(self) -> bool:
        """True when a pose-knowledge error model other than ``position_sigma3`` is on."""
        return any(np.any(np.asarray(getattr(self, name)) != 0) for name in POSE_ERROR_FIELDS)


@dataclass(frozen=True)
class SensorInfo:
    """What fired: the beam pattern, its field of view and range limits.

    Attributes
    ----------
    pattern : str
        ``single``, ``cross``, ``zigzag``, ``grid`` or ``custom``.
    beam_directions : (n_beams, 3) float64, unit vectors, sensor frame S (+z boresight)
    field_of_view : (4,) float64, radians
        ``[az_min, az_max, el_min, el_max]`` on each side of the boresight.
    range_min, range_max : float, metres
    reports_angles : bool
        True when strikes carry measured azimuth and elevation offsets.
    errors : SensorErrors
    """

    pattern: str
    beam_directions: np.ndarray
    range_min: float
    range_max: float
    field_of_view: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    reports_angles: bool = False
    errors: SensorErrors = field(default_factory=SensorErrors)

    @property
    def n_beams(self) -> int:
        return len(self.beam_directions)

    def to_dict(self) -> dict:
        """A JSON-ready description (directions as lists, angles in radians)."""
        out = asdict(self)
        out["beam_directions"] = np.asarray(self.beam_directions).tolist()
        out["field_of_view"] = [float(a) for a in self.field_of_view]
        out["n_beams"] = self.n_beams
        return out


@dataclass(frozen=True)
class Shots:
    """Rows of ``/shots`` (or their true values from ``/truth``).

    Attributes
    ----------
    time : (n,) float64, seconds
    sensor_position : (n, 3) float64, metres, inertial frame I
    sensor_attitude : (n, 4) float64, quaternion (x, y, z, w), sends S vectors to I
    target_attitude : (n, 4) float64, quaternion (x, y, z, w), sends B vectors to I
    """

    time: np.ndarray
    sensor_position: np.ndarray
    sensor_attitude: np.ndarray
    target_attitude: np.ndarray

    def __len__(self) -> int:
        return len(self.time)


@dataclass(frozen=True)
class TruthStrikes:
    """Rows of the per-strike truth: hit points in B, facet ids and true ranges."""

    point: np.ndarray
    facet: np.ndarray
    range: np.ndarray


@dataclass(frozen=True)
class StrikeChunk:
    """A contiguous block of strikes with the shot rows they refer to.

    Attributes
    ----------
    start : int
        Index of the first strike of the block in the whole log.
    shot, beam : (n,) uint32
        Global shot and beam indices.
    range : (n,) float64, metres
    direction : (n, 3) float64, unit vectors, sensor frame S
        Measured beam direction of each strike (nominal direction plus reported angle offsets).
    shots : Shots
        Rows ``shot_offset .. shot_offset + len(shots)`` of ``/shots``; strike ``i`` was taken at
        ``shots[shot[i] - shot_offset]``.
    shot_offset : int
    """

    start: int
    shot: np.ndarray
    beam: np.ndarray
    range: np.ndarray
    direction: np.ndarray
    shots: Shots
    shot_offset: int

    def __len__(self) -> int:
        return len(self.shot)


# --------------------------------------------------------------------------- shared helpers


def angles_to_directions(azimuth: np.ndarray, elevation: np.ndarray) -> np.ndarray:
    """Unit directions in the sensor frame from azimuth and elevation.

    Parameters
    ----------
    azimuth, elevation : (n,) float64, radians, zero on the boresight (+z)

    Returns
    -------
    (n, 3) float64 unit vectors, ``(cos el sin az, sin el, cos el cos az)``.
    """
    cos_el = np.cos(elevation)
    return np.stack([cos_el * np.sin(azimuth), np.sin(elevation), cos_el * np.cos(azimuth)],
                    axis=-1)


def directions_to_angles(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth and elevation [rad] of unit directions in the sensor frame (inverse of above)."""
    d = np.asarray(directions, dtype=np.float64)
    return np.arctan2(d[..., 0], d[..., 2]), np.arcsin(np.clip(d[..., 1], -1.0, 1.0))


def _check_finite(name: str, values: np.ndarray, where: str) -> None:
    if not np.all(np.isfinite(values)):
        bad = int(np.flatnonzero(~np.isfinite(values).reshape(len(values), -1).all(axis=1))[0])
        raise InputError(f"{where}: {name} has NaN or Inf (first at row {bad})")


def _check_quaternions(name: str, q: np.ndarray, where: str, row0: int = 0) -> None:
    _check_finite(name, q, where)
    err = np.abs(np.linalg.norm(q, axis=1) - 1.0)
    if np.any(err > QUATERNION_NORM_TOLERANCE):
        bad = int(np.argmax(err > QUATERNION_NORM_TOLERANCE))
        raise InputError(
            f"{where}: {name} row {row0 + bad} is not a unit quaternion "
            f"(norm {np.linalg.norm(q[bad]):.9g})")


def _check_shot_rows(shots: Shots, where: str, row0: int, previous_time: float | None) -> None:
    """Finite values, unit quaternions and strictly increasing time (SPEC.md, /shots)."""
    _check_finite("time", shots.time, where)
    _check_finite("sensor_position", shots.sensor_position, where)
    _check_quaternions("sensor_attitude", shots.sensor_attitude, where, row0)
    _check_quaternions("target_attitude", shots.target_attitude, where, row0)
    check_time(shots.time, where, row0, previous_time)


def check_time(time: np.ndarray, where: str, row0: int, previous_time: float | None) -> None:
    """Shot times ``time`` (n,) [s] of shots ``row0..`` are finite and strictly increase,
    also from ``previous_time`` (the shot before ``row0``)."""
    _check_finite("time", time, where)
    t = time if previous_time is None else np.concatenate([[previous_time], time])
    steps = np.diff(t)
    if np.any(steps <= 0):
        bad = int(np.argmax(steps <= 0)) + row0 + (0 if previous_time is None else -1) + 1
        raise InputError(f"{where}: time does not increase at shot {bad}")


def _check_strike_rows(shot: np.ndarray, beam: np.ndarray, rng: np.ndarray, *, n_shots: int,
                       n_beams: int, where: str, row0: int, previous_shot: int | None,
                       range_min: float = 0.0, range_max: float = np.inf) -> None:
    """Index ranges, ordering and positive finite ranges from ``range_min`` to ``range_max``
    (SPEC.md, /strikes)."""
    if len(shot) and int(shot.max()) >= n_shots:
        bad = int(np.argmax(shot >= n_shots))
        raise InputError(f"{where}: strike {row0 + bad} has shot index {int(shot[bad])} out "
                             f"of range (n_shots = {n_shots})")
    if len(beam) and int(beam.max()) >= n_beams:
        bad = int(np.argmax(beam >= n_beams))
        raise InputError(f"{where}: strike {row0 + bad} has beam index {int(beam[bad])} out "
                             f"of range (n_beams = {n_beams})")
    if len(shot) and ((previous_shot is not None and int(shot[0]) < previous_shot)
                      or np.any(shot[1:] < shot[:-1])):
        s = shot.astype(np.int64)
        if previous_shot is not None:
            s = np.concatenate([[previous_shot], s])
        bad = int(np.argmax(np.diff(s) < 0)) + row0 + (0 if previous_shot is None else -1) + 1
        raise InputError(f"{where}: strikes are not ordered by shot at strike {bad}")
    if not len(rng):
        return
    lo, hi = rng.min(), rng.max()   # NaN if any range is: two passes decide the valid case
    if 0 < lo and range_min <= lo and hi <= range_max and hi < np.inf:
        return
    if not np.all(np.isfinite(rng) & (rng > 0)):
        bad = int(np.argmax(~(np.isfinite(rng) & (rng > 0))))
        raise InputError(f"{where}: strike {row0 + bad} has range {float(rng[bad])!r}, "
                             "expected a finite positive number of metres")
    if lo < range_min:
        bad = int(np.argmax(rng < range_min))
        raise InputError(f"{where}: strike {row0 + bad} has range {float(rng[bad])!r} m, "
                             f"below the sensor's range_min of {range_min!r} m")
    if hi > range_max:
        bad = int(np.argmax(rng > range_max))
        raise InputError(f"{where}: strike {row0 + bad} has range {float(rng[bad])!r} m, "
                             f"beyond the sensor's range_max of {range_max:g} m")


def estimate_log_bytes(n_shots: int, n_strikes: int, *, reports_angles: bool, truth: bool,
                       n_vertices: int = 0, n_faces: int = 0) -> int:
    """Bytes of a log as ``StrikeLogWriter`` stores it: every chunked dataset takes whole
    chunks (SHOT_CHUNK_ROWS, STRIKE_CHUNK_ROWS rows), the truth mesh is contiguous.

    Parameters
    ----------
    n_shots, n_strikes : int
    reports_angles : bool
        Strikes carry the two angle offsets.
    truth : bool
        The log has a ``/truth`` group (true poses and hits, the mesh).
    n_vertices, n_faces : int
        Size of the truth mesh.
    """
    def chunked(rows: int, chunk: int, row_bytes: int) -> int:
        return -(-rows // chunk) * chunk * row_bytes

    shot_row = 8 * (1 + 3 + 4 + 4) + (8 * (3 + 4 + 4) if truth else 0)
    strike_row = 4 + 4 + 8 + (16 if reports_angles else 0) + (8 * 3 + 4 + 8 if truth else 0)
    mesh = 24 * n_vertices + 12 * n_faces if truth else 0
    return chunked(n_shots, SHOT_CHUNK_ROWS, shot_row) + chunked(
        n_strikes, STRIKE_CHUNK_ROWS, strike_row) + mesh


def mesh_checksum(vertices: np.ndarray, faces: np.ndarray) -> str:
    """SHA-256 (hex) of a truth mesh as stored: vertices as little-endian float64, then faces
    as little-endian uint32, row-major (SPEC.md, /truth/mesh attribute ``sha256``)."""
    import hashlib

    digest = hashlib.sha256(np.ascontiguousarray(vertices, dtype="<f8").tobytes())
    digest.update(np.ascontiguousarray(faces, dtype="<u4").tobytes())
    return digest.hexdigest()


def _as_array(name: str, values, shape_tail: tuple, dtype, where: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{where}: {name} cannot be read as {np.dtype(dtype)}: "
                             f"{exc}") from None
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        want = "(n" + "".join(f", {k}" for k in shape_tail) + ")"
        raise InputError(f"{where}: {name} must have shape {want}, got {arr.shape}")
    return arr


def _check_sensor(sensor: SensorInfo, where: str) -> None:
    if sensor.pattern not in _PATTERNS:
        raise InputError(f"{where}: sensor pattern {sensor.pattern!r} is not one of "
                             f"{', '.join(_PATTERNS)}")
    d = _as_array("sensor beam_directions", sensor.beam_directions, (3,), np.float64, where)
    if len(d) == 0:
        raise InputError(f"{where}: sensor has no beams")
    _check_finite("sensor beam_directions", d, where)
    if np.any(np.abs(np.linalg.norm(d, axis=1) - 1.0) > 1e-9):
        raise InputError(f"{where}: sensor beam_directions must be unit vectors")
    if not (np.isfinite(sensor.range_min) and np.isfinite(sensor.range_max)
            and 0 <= sensor.range_min < sensor.range_max):
        raise InputError(f"{where}: sensor range limits must satisfy 0 <= range_min < "
                             f"range_max, got {sensor.range_min}, {sensor.range_max}")
    fov = np.asarray(sensor.field_of_view, dtype=np.float64)
    if fov.shape != (4,) or not np.all(np.isfinite(fov)):
        raise InputError(f"{where}: sensor field_of_view must be 4 finite angles [rad]")


@contextlib.contextmanager
def _hdf5_errors(where: str):
    """Turn what h5py raises on damaged files into one-line StrikeLogErrors."""
    try:
        yield
    except InputError:
        raise
    except (OSError, KeyError, ValueError, TypeError, RuntimeError, IndexError) as exc:
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f"{where}: damaged or unreadable HDF5 ({message})") from None
