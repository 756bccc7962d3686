"""Reader and writer of strike logs, format v1 (formats/SPEC.md).

The writer streams shots and strikes in chunks into a temporary file that is renamed into place
only on a clean close; the reader checks the schema on open, and validates every chunk it hands
out, so a corrupt log raises ``StrikeLogError`` instead of yielding numbers that look right.
"""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field, fields
from datetime import UTC, datetime
from pathlib import Path

import h5py
import numpy as np

from formats.atomic import AtomicWriter
from formats.errors import StrikeLogError
from formats.geometry import Mesh
from formats.version import __version__

FORMAT_NAME = "recon-strike-log"
FORMAT_VERSION = 1

# Chunk rows: 65,536 strike rows of float64 are 512 KiB, inside HDF5's default 1 MiB chunk cache.
STRIKE_CHUNK_ROWS = 65_536
SHOT_CHUNK_ROWS = 16_384
# How far from 1 a stored quaternion's norm may be (SPEC.md, Conventions).
QUATERNION_NORM_TOLERANCE = 1e-6
# Rows handed out per chunk by StrikeLog.iter_chunks: 2**20 strikes is ~100 MB of derived arrays.
READ_CHUNK_ROWS = 1 << 20
# Storage filters (SPEC.md, Storage; measured in benchmarks/bench_log_compression.py): no
# compression by default, Fletcher-32 checksums always.
COMPRESSIONS = {"none": {}, "lzf": {"compression": "lzf", "shuffle": True},
                "gzip": {"compression": "gzip", "compression_opts": 4, "shuffle": True}}

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


# --------------------------------------------------------------------------- records


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
    """

    range_sigma3: float = 0.0
    azimuth_sigma3: float = 0.0
    elevation_sigma3: float = 0.0
    position_sigma3: float = 0.0
    pulse_dilation_alpha: float = 0.0
    pulse_dilation_half_angle: float = 0.0
    pulse_dilation_subrays: float = 0.0

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
        raise StrikeLogError(f"{where}: {name} has NaN or Inf (first at row {bad})")


def _check_quaternions(name: str, q: np.ndarray, where: str, row0: int = 0) -> None:
    _check_finite(name, q, where)
    err = np.abs(np.linalg.norm(q, axis=1) - 1.0)
    if np.any(err > QUATERNION_NORM_TOLERANCE):
        bad = int(np.argmax(err > QUATERNION_NORM_TOLERANCE))
        raise StrikeLogError(
            f"{where}: {name} row {row0 + bad} is not a unit quaternion "
            f"(norm {np.linalg.norm(q[bad]):.9g})")


def _check_shot_rows(shots: Shots, where: str, row0: int, previous_time: float | None) -> None:
    """Finite values, unit quaternions and strictly increasing time (SPEC.md, /shots)."""
    _check_finite("time", shots.time, where)
    _check_finite("sensor_position", shots.sensor_position, where)
    _check_quaternions("sensor_attitude", shots.sensor_attitude, where, row0)
    _check_quaternions("target_attitude", shots.target_attitude, where, row0)
    t = shots.time if previous_time is None else np.concatenate([[previous_time], shots.time])
    steps = np.diff(t)
    if np.any(steps <= 0):
        bad = int(np.argmax(steps <= 0)) + row0 + (0 if previous_time is None else -1) + 1
        raise StrikeLogError(f"{where}: time does not increase at shot {bad}")


def _check_strike_rows(shot: np.ndarray, beam: np.ndarray, rng: np.ndarray, *, n_shots: int,
                       n_beams: int, where: str, row0: int, previous_shot: int | None) -> None:
    """Index ranges, ordering and positive finite ranges (SPEC.md, /strikes)."""
    if len(shot) and int(shot.max()) >= n_shots:
        bad = int(np.argmax(shot >= n_shots))
        raise StrikeLogError(f"{where}: strike {row0 + bad} has shot index {int(shot[bad])} out "
                             f"of range (n_shots = {n_shots})")
    if len(beam) and int(beam.max()) >= n_beams:
        bad = int(np.argmax(beam >= n_beams))
        raise StrikeLogError(f"{where}: strike {row0 + bad} has beam index {int(beam[bad])} out "
                             f"of range (n_beams = {n_beams})")
    s = shot.astype(np.int64)
    if previous_shot is not None:
        s = np.concatenate([[previous_shot], s])
    if np.any(np.diff(s) < 0):
        bad = int(np.argmax(np.diff(s) < 0)) + row0 + (0 if previous_shot is None else -1) + 1
        raise StrikeLogError(f"{where}: strikes are not ordered by shot at strike {bad}")
    if not np.all(np.isfinite(rng) & (rng > 0)):
        bad = int(np.argmax(~(np.isfinite(rng) & (rng > 0))))
        raise StrikeLogError(f"{where}: strike {row0 + bad} has range {float(rng[bad])!r}, "
                             "expected a finite positive number of metres")


def _as_array(name: str, values, shape_tail: tuple, dtype, where: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise StrikeLogError(f"{where}: {name} cannot be read as {np.dtype(dtype)}: "
                             f"{exc}") from None
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        want = "(n" + "".join(f", {k}" for k in shape_tail) + ")"
        raise StrikeLogError(f"{where}: {name} must have shape {want}, got {arr.shape}")
    return arr


def _check_sensor(sensor: SensorInfo, where: str) -> None:
    if sensor.pattern not in _PATTERNS:
        raise StrikeLogError(f"{where}: sensor pattern {sensor.pattern!r} is not one of "
                             f"{', '.join(_PATTERNS)}")
    d = _as_array("sensor beam_directions", sensor.beam_directions, (3,), np.float64, where)
    if len(d) == 0:
        raise StrikeLogError(f"{where}: sensor has no beams")
    _check_finite("sensor beam_directions", d, where)
    if np.any(np.abs(np.linalg.norm(d, axis=1) - 1.0) > 1e-9):
        raise StrikeLogError(f"{where}: sensor beam_directions must be unit vectors")
    if not (np.isfinite(sensor.range_min) and np.isfinite(sensor.range_max)
            and 0 <= sensor.range_min < sensor.range_max):
        raise StrikeLogError(f"{where}: sensor range limits must satisfy 0 <= range_min < "
                             f"range_max, got {sensor.range_min}, {sensor.range_max}")
    fov = np.asarray(sensor.field_of_view, dtype=np.float64)
    if fov.shape != (4,) or not np.all(np.isfinite(fov)):
        raise StrikeLogError(f"{where}: sensor field_of_view must be 4 finite angles [rad]")


@contextlib.contextmanager
def _hdf5_errors(where: str):
    """Turn what h5py raises on damaged files into one-line StrikeLogErrors."""
    try:
        yield
    except StrikeLogError:
        raise
    except (OSError, KeyError, ValueError, TypeError, RuntimeError, IndexError) as exc:
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise StrikeLogError(f"{where}: damaged or unreadable HDF5 ({message})") from None


# --------------------------------------------------------------------------- writer


class StrikeLogWriter(AtomicWriter):
    """Write a strike log, streaming shots and strikes in chunks.

    The file is written under a temporary name beside ``path`` and renamed into place only when
    the writer closes without an exception, after the row counts are written. An interrupted run
    leaves no file that looks complete and never replaces an existing ``path``.

    Parameters
    ----------
    path : str or Path
        Destination, usually ``*.h5``.
    sensor : SensorInfo
    target : str
        Short target name, e.g. ``asteroid``.
    scene : str, optional
        Full text of the scene description.
    seed : int, optional
        Random seed used; -1 when none.
    truth_mesh : tuple of (n_vertices, 3) float64 and (n_faces, 3) int, optional
        Truth mesh in metres, body frame. When given, the log has a ``/truth`` group and every
        ``write_shots`` and ``write_strikes`` call must carry the truth arrays too.
    producer, producer_version : str, optional
    compression : {"none", "lzf", "gzip"}, optional
        Filter for the chunked datasets (default none; see SPEC.md, Storage, for the trade-off).

    Examples
    --------
    >>> with StrikeLogWriter("run.h5", sensor=sensor, target="asteroid") as log:  # doctest: +SKIP
    ...     log.write_shots(time, position, sensor_q, target_q)
    ...     log.write_strikes(shot, beam, rng)
    """

    missing_dir_error = StrikeLogError

    def __init__(self, path, *, sensor: SensorInfo, target: str, scene: str = "", seed: int = -1,
                 truth_mesh: tuple[np.ndarray, np.ndarray] | None = None,
                 producer: str = "recon", producer_version: str = __version__,
                 compression: str = "none"):
        where = str(path)
        _check_sensor(sensor, where)
        if compression not in COMPRESSIONS:
            raise StrikeLogError(f"{where}: compression must be one of "
                                 f"{', '.join(COMPRESSIONS)}, got {compression!r}")
        super().__init__(path)
        self.sensor = sensor
        self.has_truth = truth_mesh is not None
        self._n_shots = self._n_strikes = 0
        self._last_time: float | None = None
        self._last_shot: int | None = None
        try:
            self._file = h5py.File(self.temporary, "w")
            self._create_layout(sensor, target=target, scene=scene, seed=seed,
                                truth_mesh=truth_mesh, producer=producer,
                                producer_version=producer_version,
                                filters={"fletcher32": True} | COMPRESSIONS[compression])
        except BaseException:
            self.abort()
            raise

    @classmethod
    def append(cls, path) -> StrikeLogWriter:
        """Open an existing complete log to add shots and strikes to its end.

        The log is copied to a temporary file; the original is replaced only on a clean close.
        """
        path = Path(path)
        with StrikeLog(path) as log:
            last_time = float(log.shots(log.n_shots - 1).time[-1]) if log.n_shots else None
            last_shot = int(log.strikes(log.n_strikes - 1)[0][-1]) if log.n_strikes else None
            sensor, has_truth = log.sensor, log.has_truth
            n_shots, n_strikes = log.n_shots, log.n_strikes
        self = cls.__new__(cls)
        AtomicWriter.__init__(self, path)
        self.sensor, self.has_truth = sensor, has_truth
        shutil.copyfile(path, self.temporary)
        self._file = h5py.File(self.temporary, "r+")
        for name in ("n_shots", "n_strikes"):  # the file is incomplete until close
            del self._file.attrs[name]
        self._n_shots, self._n_strikes = n_shots, n_strikes
        self._last_time, self._last_shot = last_time, last_shot
        return self

    def _create_layout(self, sensor, *, target, scene, seed, truth_mesh, producer,
                       producer_version, filters):
        f = self._file
        f.attrs.update({
            "format": FORMAT_NAME, "format_version": np.int64(FORMAT_VERSION),
            "producer": producer, "producer_version": producer_version,
            "created_utc": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            "scene": scene, "seed": np.int64(seed), "target": target,
        })
        g = f.create_group("sensor")
        g.attrs.update({
            "pattern": sensor.pattern,
            "field_of_view": np.asarray(sensor.field_of_view, dtype=np.float64),
            "range_min": float(sensor.range_min), "range_max": float(sensor.range_max),
            "reports_angles": bool(sensor.reports_angles),
        })
        g.create_dataset("beam_directions",
                         data=np.asarray(sensor.beam_directions, dtype=np.float64))
        g.create_group("errors").attrs.update(
            {k.name: float(getattr(sensor.errors, k.name)) for k in fields(SensorErrors)})

        def columns(group, spec, rows):
            for name, (tail, dtype) in spec.items():
                group.create_dataset(name, shape=(0, *tail), maxshape=(None, *tail), dtype=dtype,
                                     chunks=(rows, *tail), **filters)

        shots = {k: (tail, np.float64) for k, tail in _SHOT_FIELDS.items()}
        columns(f.create_group("shots"), shots, SHOT_CHUNK_ROWS)
        strikes = dict(_STRIKE_FIELDS)
        if sensor.reports_angles:
            strikes.update({k: ((), np.float64) for k in _ANGLE_FIELDS})
        columns(f.create_group("strikes"), strikes, STRIKE_CHUNK_ROWS)
        if truth_mesh is not None:
            t = f.create_group("truth")
            columns(t, {k: (tail, np.float64) for k, tail in _TRUTH_SHOT_FIELDS.items()},
                    SHOT_CHUNK_ROWS)
            columns(t, _TRUTH_STRIKE_FIELDS, STRIKE_CHUNK_ROWS)
            vertices, faces = truth_mesh
            m = t.create_group("mesh")
            m.create_dataset("vertices", data=np.asarray(vertices, dtype=np.float64))
            m.create_dataset("faces", data=np.asarray(faces, dtype=np.uint32))

    # ------------------------------------------------------------------ appending rows

    def _require_open(self) -> None:
        if self.closed:
            raise StrikeLogError(f"{self.path}: the writer is closed")

    @staticmethod
    def _extend(group, values: dict) -> None:
        for name, arr in values.items():
            ds = group[name]
            n = ds.shape[0]
            ds.resize(n + len(arr), axis=0)
            ds[n:] = arr

    def write_shots(self, time, sensor_position, sensor_attitude, target_attitude, *,
                    truth: Shots | None = None) -> None:
        """Append shots.

        Parameters
        ----------
        time : (n,) float64, seconds, strictly increasing (also across calls)
        sensor_position : (n, 3) float64, metres, inertial frame I, as recorded
        sensor_attitude : (n, 4) float64, quaternion (x, y, z, w), S->I, as recorded
        target_attitude : (n, 4) float64, quaternion (x, y, z, w), B->I, as known
        truth : Shots, optional
            True poses of the same shots; required when the log has a truth mesh.
        """
        self._require_open()
        where = str(self.path)
        rows = Shots(*(_as_array(k, v, tail, np.float64, where) for (k, tail), v in zip(
            _SHOT_FIELDS.items(), (time, sensor_position, sensor_attitude, target_attitude),
            strict=True)))
        n = len(rows)
        if any(len(getattr(rows, k)) != n for k in _SHOT_FIELDS):
            raise StrikeLogError(f"{where}: write_shots arrays differ in length")
        _check_shot_rows(rows, where, self._n_shots, self._last_time)
        if self.has_truth != (truth is not None):
            raise StrikeLogError(f"{where}: write_shots needs truth= exactly when the log has a "
                                 "truth mesh")
        if truth is not None:
            t = {k: _as_array(f"truth {k}", getattr(truth, k), tail, np.float64, where)
                 for k, tail in _TRUTH_SHOT_FIELDS.items()}
            if any(len(v) != n for v in t.values()):
                raise StrikeLogError(f"{where}: truth shots differ in length from the shots")
            self._extend(self._file["truth"], t)
        self._extend(self._file["shots"], {k: getattr(rows, k) for k in _SHOT_FIELDS})
        self._n_shots += n
        if n:
            self._last_time = float(rows.time[-1])

    def write_strikes(self, shot, beam, range, *, azimuth_offset=None, elevation_offset=None,
                      truth: TruthStrikes | None = None) -> None:
        """Append strikes (beam returns); misses are not written.

        Parameters
        ----------
        shot : (n,) int, index into the shots written so far, non-decreasing (also across calls)
        beam : (n,) int, index into ``sensor.beam_directions``
        range : (n,) float64, metres, measured
        azimuth_offset, elevation_offset : (n,) float64, radians, optional
            Measured angle offsets from the beam's nominal direction; required exactly when
            ``sensor.reports_angles``.
        truth : TruthStrikes, optional
            True hit points (metres, body frame), facet ids and ranges; required when the log
            has a truth mesh.
        """
        self._require_open()
        where = str(self.path)
        shot = _as_array("shot", shot, (), np.int64, where)
        beam = _as_array("beam", beam, (), np.int64, where)
        rng = _as_array("range", range, (), np.float64, where)
        n = len(shot)
        if len(beam) != n or len(rng) != n:
            raise StrikeLogError(f"{where}: write_strikes arrays differ in length")
        if n and (shot.min() < 0 or beam.min() < 0):
            raise StrikeLogError(f"{where}: shot and beam indices must be non-negative")
        _check_strike_rows(shot, beam, rng, n_shots=self._n_shots, n_beams=self.sensor.n_beams,
                           where=where, row0=self._n_strikes, previous_shot=self._last_shot)
        values = {"shot": shot.astype(np.uint32), "beam": beam.astype(np.uint32), "range": rng}
        if self.sensor.reports_angles != (azimuth_offset is not None
                                          and elevation_offset is not None):
            raise StrikeLogError(f"{where}: write_strikes needs azimuth_offset and "
                                 "elevation_offset exactly when the sensor reports angles")
        if self.sensor.reports_angles:
            for k, v in zip(_ANGLE_FIELDS, (azimuth_offset, elevation_offset), strict=True):
                values[k] = _as_array(k, v, (), np.float64, where)
                if len(values[k]) != n:
                    raise StrikeLogError(f"{where}: {k} differs in length from the strikes")
                _check_finite(k, values[k], where)
        if self.has_truth != (truth is not None):
            raise StrikeLogError(f"{where}: write_strikes needs truth= exactly when the log "
                                 "has a truth mesh")
        if truth is not None:
            t = {k: _as_array(f"truth {k}", getattr(truth, k), tail, dtype, where)
                 for k, (tail, dtype) in _TRUTH_STRIKE_FIELDS.items()}
            if any(len(v) != n for v in t.values()):
                raise StrikeLogError(f"{where}: truth strikes differ in length from the strikes")
            self._extend(self._file["truth"], t)
        self._extend(self._file["strikes"], values)
        self._n_strikes += n
        if n:
            self._last_shot = int(shot[-1])

    # ------------------------------------------------------------------ closing

    def _finish(self) -> None:
        """Write the row counts that mark the log complete (SPEC.md, root attributes)."""
        self._file.attrs["n_shots"] = np.int64(self._n_shots)
        self._file.attrs["n_strikes"] = np.int64(self._n_strikes)
        self._file.close()

    def _release(self) -> None:
        self._file.close()


# --------------------------------------------------------------------------- reader


class StrikeLog:
    """Read a strike log, checking the format, the version and the schema on open.

    Data are read on demand: ``shots(start, stop)``, ``strikes(start, stop)`` and
    ``iter_chunks()``; nothing holds the whole log in memory. Every block read is checked
    (finite values, unit quaternions, increasing time, indices in range) and a violation raises
    ``StrikeLogError``. ``validate()`` streams through everything once.

    Parameters
    ----------
    path : str or Path
    """

    def __init__(self, path):
        self.path = Path(path)
        where = self._where = str(self.path)
        if not self.path.exists():
            raise StrikeLogError(f"{where}: no such file")
        if self.path.is_dir():
            raise StrikeLogError(f"{where}: is a directory, not a strike log")
        if not h5py.is_hdf5(self.path):
            raise StrikeLogError(f"{where}: not an HDF5 file")
        with _hdf5_errors(where):
            self._file = h5py.File(self.path, "r")
        try:
            with _hdf5_errors(where):
                self._check_schema()
        except BaseException:
            self._file.close()
            raise

    # ------------------------------------------------------------------ schema

    def _attr(self, obj, name: str, kind: type):
        where = self._where
        if name not in obj.attrs:
            place = "root" if obj.name == "/" else obj.name
            raise StrikeLogError(f"{where}: missing {place} attribute '{name}'")
        value = obj.attrs[name]
        if kind is str:
            if isinstance(value, bytes):
                value = value.decode("utf-8")
            if not isinstance(value, str):
                raise StrikeLogError(f"{where}: attribute '{name}' must be a string")
            return value
        arr = np.asarray(value)
        if kind is int and (arr.shape != () or arr.dtype.kind not in "iu"):
            raise StrikeLogError(f"{where}: attribute '{name}' must be an integer")
        if kind is float and (arr.shape != () or arr.dtype.kind not in "iuf"):
            raise StrikeLogError(f"{where}: attribute '{name}' must be a number")
        if kind is bool and (arr.shape != () or arr.dtype.kind not in "biu"):
            raise StrikeLogError(f"{where}: attribute '{name}' must be a boolean")
        return kind(arr)

    def _dataset(self, path: str, n: int | None, tail: tuple, kinds: str) -> h5py.Dataset:
        where = self._where
        if path not in self._file:
            raise StrikeLogError(f"{where}: missing dataset /{path}")
        ds = self._file[path]
        if not isinstance(ds, h5py.Dataset):
            raise StrikeLogError(f"{where}: /{path} is not a dataset")
        if ds.ndim != 1 + len(tail) or ds.shape[1:] != tail or (n is not None and
                                                                ds.shape[0] != n):
            want = ("n" if n is None else str(n)) + "".join(f", {k}" for k in tail)
            raise StrikeLogError(f"{where}: /{path} has shape {ds.shape}, expected ({want})")
        if ds.dtype.kind not in kinds:
            raise StrikeLogError(f"{where}: /{path} has dtype {ds.dtype}, expected "
                                 + {"f": "float", "iu": "integer"}.get(kinds, kinds))
        return ds

    def _check_schema(self) -> None:
        f, where = self._file, self._where
        fmt = f.attrs.get("format")
        if isinstance(fmt, bytes):
            fmt = fmt.decode("utf-8", "replace")
        if fmt != FORMAT_NAME:
            raise StrikeLogError(f"{where}: not a strike log (root attribute 'format' is "
                                 f"{fmt!r}, expected {FORMAT_NAME!r})")
        version = self._attr(f, "format_version", int)
        if version != FORMAT_VERSION:
            raise StrikeLogError(f"{where}: format version {version} is not supported (this "
                                 f"recon reads version {FORMAT_VERSION})")
        self.attrs = {name: self._attr(f, name, str) for name in _ROOT_ATTRS
                      if name not in ("format_version", "seed")}
        self.attrs["format_version"] = version
        self.attrs["seed"] = self._attr(f, "seed", int)
        for name in ("n_shots", "n_strikes"):
            if name not in f.attrs:
                raise StrikeLogError(f"{where}: incomplete log (no '{name}' attribute: the "
                                     "writer did not close cleanly)")
        self.n_shots = self._attr(f, "n_shots", int)
        self.n_strikes = self._attr(f, "n_strikes", int)
        if self.n_shots < 0 or self.n_strikes < 0:
            raise StrikeLogError(f"{where}: negative row counts")

        g = f["sensor"] if "sensor" in f else None
        if g is None:
            raise StrikeLogError(f"{where}: missing group /sensor")
        directions = self._dataset("sensor/beam_directions", None, (3,), "f")[()]
        errors = f["sensor/errors"] if "sensor/errors" in f else None
        if errors is None:
            raise StrikeLogError(f"{where}: missing group /sensor/errors")
        fov = np.asarray(g.attrs.get("field_of_view", np.zeros(0)))
        if fov.shape != (4,) or fov.dtype.kind != "f":
            raise StrikeLogError(f"{where}: /sensor attribute 'field_of_view' must be 4 floats")
        self.sensor = SensorInfo(
            pattern=self._attr(g, "pattern", str), beam_directions=directions,
            range_min=self._attr(g, "range_min", float),
            range_max=self._attr(g, "range_max", float),
            field_of_view=tuple(float(a) for a in fov),
            reports_angles=self._attr(g, "reports_angles", bool),
            errors=SensorErrors(**{k.name: self._attr(errors, k.name, float)
                                   for k in fields(SensorErrors)}))
        _check_sensor(self.sensor, where)

        self._shots = {k: self._dataset(f"shots/{k}", self.n_shots, tail, "f")
                       for k, tail in _SHOT_FIELDS.items()}
        spec = {k: ((), "iu") for k in ("shot", "beam")} | {"range": ((), "f")}
        if self.sensor.reports_angles:
            spec |= {k: ((), "f") for k in _ANGLE_FIELDS}
        self._strikes = {k: self._dataset(f"strikes/{k}", self.n_strikes, tail, kinds)
                         for k, (tail, kinds) in spec.items()}
        self.has_truth = "truth" in f
        if self.has_truth:
            self._truth_shots = {k: self._dataset(f"truth/{k}", self.n_shots, tail, "f")
                                 for k, tail in _TRUTH_SHOT_FIELDS.items()}
            self._truth_strikes = {
                k: self._dataset(f"truth/{k}", self.n_strikes, tail,
                                 "f" if dtype == np.float64 else "iu")
                for k, (tail, dtype) in _TRUTH_STRIKE_FIELDS.items()}
            self._dataset("truth/mesh/vertices", None, (3,), "f")
            self._dataset("truth/mesh/faces", None, (3,), "iu")

    # ------------------------------------------------------------------ reading

    def _slice(self, start: int, stop: int | None, n: int) -> tuple[int, int]:
        stop = n if stop is None else stop
        if not (0 <= start <= stop <= n):
            raise StrikeLogError(f"{self._where}: rows {start}:{stop} out of range (0:{n})")
        return start, stop

    def _blocks(self, n: int, chunk_rows: int) -> Iterator[tuple[int, int]]:
        """``(start, stop)`` of consecutive blocks of at most ``chunk_rows`` of ``n`` rows."""
        if chunk_rows < 1:
            raise StrikeLogError(f"{self._where}: chunk_rows must be positive")
        for start in range(0, n, chunk_rows):
            yield start, min(start + chunk_rows, n)

    def shots(self, start: int = 0, stop: int | None = None) -> Shots:
        """Recorded shots ``start:stop``, checked."""
        start, stop = self._slice(start, stop, self.n_shots)
        return self._checked_shots(start, stop, previous_time=None)

    def _checked_shots(self, start: int, stop: int, previous_time: float | None) -> Shots:
        """Read shots ``start:stop`` and check them once, time also against ``previous_time``."""
        with _hdf5_errors(self._where):
            rows = Shots(*(np.asarray(self._shots[k][start:stop], dtype=np.float64)
                           for k in _SHOT_FIELDS))
        _check_shot_rows(rows, self._where, start, previous_time)
        return rows

    def strikes(self, start: int = 0, stop: int | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Shot index, beam index and measured range of strikes ``start:stop``, checked."""
        start, stop = self._slice(start, stop, self.n_strikes)
        return self._checked_strikes(start, stop, previous_shot=None)

    def _checked_strikes(self, start: int, stop: int, previous_shot: int | None
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Read strikes ``start:stop`` and check them once, ordering also against the shot
        index ``previous_shot`` of the strike before ``start``."""
        with _hdf5_errors(self._where):
            shot = np.asarray(self._strikes["shot"][start:stop])
            beam = np.asarray(self._strikes["beam"][start:stop])
            rng = np.asarray(self._strikes["range"][start:stop], dtype=np.float64)
        if shot.dtype.kind == "i" and len(shot) and shot.min() < 0:
            raise StrikeLogError(f"{self._where}: negative shot index")
        if beam.dtype.kind == "i" and len(beam) and beam.min() < 0:
            raise StrikeLogError(f"{self._where}: negative beam index")
        _check_strike_rows(shot, beam, rng, n_shots=self.n_shots, n_beams=self.sensor.n_beams,
                           where=self._where, row0=start, previous_shot=previous_shot)
        return shot.astype(np.int64), beam.astype(np.int64), rng

    def _angle_offsets(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """Reported azimuth and elevation offsets (n,) [rad] of strikes ``start:stop``, checked."""
        with _hdf5_errors(self._where):
            d_az = np.asarray(self._strikes["azimuth_offset"][start:stop], dtype=np.float64)
            d_el = np.asarray(self._strikes["elevation_offset"][start:stop], dtype=np.float64)
        _check_finite("azimuth_offset", d_az, self._where)
        _check_finite("elevation_offset", d_el, self._where)
        return d_az, d_el

    def directions(self, beam: np.ndarray, start: int, stop: int) -> np.ndarray:
        """Measured directions (n, 3) in S of strikes ``start:stop`` with beams ``beam``."""
        nominal = np.asarray(self.sensor.beam_directions)[beam]
        if not self.sensor.reports_angles:
            return nominal
        d_az, d_el = self._angle_offsets(start, stop)
        az, el = directions_to_angles(nominal)
        return angles_to_directions(az + d_az, el + d_el)

    def iter_chunks(self, chunk_rows: int = READ_CHUNK_ROWS) -> Iterator[StrikeChunk]:
        """Yield consecutive blocks of at most ``chunk_rows`` strikes with their shots.

        Ordering across block boundaries is checked too, so a full pass validates the strikes.
        """
        previous_shot = None
        for start, stop in self._blocks(self.n_strikes, chunk_rows):
            shot, beam, rng = self._checked_strikes(start, stop, previous_shot)
            previous_shot = int(shot[-1])
            lo, hi = int(shot[0]), int(shot[-1]) + 1
            yield StrikeChunk(start=start, shot=shot, beam=beam, range=rng,
                              direction=self.directions(beam, start, stop),
                              shots=self.shots(lo, hi), shot_offset=lo)

    # ------------------------------------------------------------------ truth

    def _require_truth(self) -> None:
        if not self.has_truth:
            raise StrikeLogError(f"{self._where}: log has no /truth group")

    def truth_mesh(self) -> Mesh:
        """The truth mesh: vertices (n, 3) float64 [m, body frame] and faces (m, 3) int64."""
        self._require_truth()
        with _hdf5_errors(self._where):
            vertices = np.asarray(self._file["truth/mesh/vertices"][()], dtype=np.float64)
            faces = np.asarray(self._file["truth/mesh/faces"][()]).astype(np.int64)
        _check_finite("truth mesh vertices", vertices, self._where)
        if len(faces) == 0:
            raise StrikeLogError(f"{self._where}: truth mesh has no faces")
        if faces.min() < 0 or faces.max() >= len(vertices):
            raise StrikeLogError(f"{self._where}: truth mesh faces index missing vertices")
        return Mesh(vertices, faces)

    def truth_shots(self, start: int = 0, stop: int | None = None) -> Shots:
        """True poses of shots ``start:stop`` (time is the recorded time)."""
        self._require_truth()
        start, stop = self._slice(start, stop, self.n_shots)
        with _hdf5_errors(self._where):
            time = np.asarray(self._shots["time"][start:stop], dtype=np.float64)
            rest = (np.asarray(self._truth_shots[k][start:stop], dtype=np.float64)
                    for k in _TRUTH_SHOT_FIELDS)
            return Shots(time, *rest)

    def truth_strikes(self, start: int = 0, stop: int | None = None) -> TruthStrikes:
        """True hit points [m, body frame], facet ids and ranges of strikes ``start:stop``."""
        self._require_truth()
        start, stop = self._slice(start, stop, self.n_strikes)
        with _hdf5_errors(self._where):
            return TruthStrikes(*(np.asarray(self._truth_strikes[k][start:stop])
                                  for k in _TRUTH_STRIKE_FIELDS))

    # ------------------------------------------------------------------ whole-log checks

    def validate(self, chunk_rows: int = READ_CHUNK_ROWS, progress=None) -> None:
        """Check every row of the log (streaming); raise StrikeLogError at the first problem.

        Parameters
        ----------
        chunk_rows : int
        progress : callable, optional
            Called with the number of rows checked after each block.
        """
        # Each block is read and checked once: shots, then strikes (with their angle offsets),
        # each against the last row of the block before it.
        previous_time = None
        for start, stop in self._blocks(self.n_shots, chunk_rows):
            rows = self._checked_shots(start, stop, previous_time)
            previous_time = float(rows.time[-1])
            if progress:
                progress(stop - start)
        previous_shot = None
        carried = np.zeros(0, dtype=np.int64)  # pairs of the shot that may continue
        n_beams = self.sensor.n_beams
        for start, stop in self._blocks(self.n_strikes, chunk_rows):
            shot, beam, _ = self._checked_strikes(start, stop, previous_shot)
            if self.sensor.reports_angles:
                self._angle_offsets(start, stop)
            previous_shot = int(shot[-1])
            pairs = np.concatenate([carried, shot * n_beams + beam])
            if len(np.unique(pairs)) != len(pairs):
                raise StrikeLogError(f"{self._where}: a (shot, beam) pair appears twice near "
                                     f"strike {start}")
            carried = pairs[pairs // n_beams == previous_shot]
            if progress:
                progress(stop - start)
        if self.has_truth:
            self.truth_mesh()

    def summary(self) -> dict:
        """Counts, time span, sensor and target, as a JSON-ready dict."""
        with _hdf5_errors(self._where):
            t0 = float(self._shots["time"][0]) if self.n_shots else None
            t1 = float(self._shots["time"][self.n_shots - 1]) if self.n_shots else None
        return {
            "path": str(self.path),
            "format": FORMAT_NAME,
            "format_version": self.attrs["format_version"],
            "producer": f"{self.attrs['producer']} {self.attrs['producer_version']}",
            "created_utc": self.attrs["created_utc"],
            "seed": self.attrs["seed"],
            "target": self.attrs["target"],
            "n_shots": self.n_shots,
            "n_strikes": self.n_strikes,
            "n_pulses": self.n_shots * self.sensor.n_beams,
            "time_start_s": t0,
            "time_end_s": t1,
            "duration_s": None if t0 is None else t1 - t0,
            "sensor": self.sensor.to_dict(),
            "has_truth": self.has_truth,
        }

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> StrikeLog:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
