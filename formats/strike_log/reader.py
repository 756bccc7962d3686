"""The strike-log reader: the format, version and schema checked on open, every block checked as
it is read, so a corrupt log raises ``InputError`` instead of numbers that look right."""

from __future__ import annotations

import time
from collections.abc import Generator, Iterator
from dataclasses import fields
from pathlib import Path

import h5py
import numpy as np

from formats.atomic import partial_pid, process_alive
from formats.errors import InputError
from formats.geometry import Mesh
from formats.hdf5_check import check_hdf5, check_whole, is_hdf5
from formats.paths import check_source
from formats.strike_log.schema import (
    _ANGLE_FIELDS,
    _ROOT_ATTRS,
    _SHOT_FIELDS,
    _STRIKE_FIELDS,
    _TRUTH_SHOT_FIELDS,
    _TRUTH_STRIKE_FIELDS,
    FORMAT_NAME,
    FORMAT_VERSION,
    LIVE_COMMITTED,
    POSE_ERROR_FIELDS,
    POSE_ERROR_VECTORS,
    READ_CHUNK_ROWS,
    SensorErrors,
    SensorInfo,
    Shots,
    StrikeChunk,
    TruthStrikes,
    _check_finite,
    _check_quaternions,
    _check_sensor,
    _check_shot_rows,
    _check_strike_rows,
    _hdf5_errors,
    angles_to_directions,
    check_time,
    directions_to_angles,
    mesh_checksum,
)


class StrikeLog:
    """Read a strike log, checking the format, the version and the schema on open.

    Data are read on demand: ``shots(start, stop)``, ``strikes(start, stop)`` and
    ``iter_chunks()``; nothing holds the whole log in memory. Every block read is checked
    (finite values, unit quaternions, increasing time, indices in range) and a violation raises
    ``InputError``. ``validate()`` streams through everything once.

    Parameters
    ----------
    path : str or Path
    """

    def __init__(self, path):
        self.path = check_source(path, InputError)
        where = self._where = str(self.path)
        if not is_hdf5(self.path, InputError):
            raise InputError(f"{where}: not an HDF5 file")
        check_hdf5(self.path, InputError)   # no other files, no loops: formats/hdf5_check.py
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
            raise InputError(f"{where}: missing {place} attribute '{name}'")
        value = obj.attrs[name]
        if kind is str:
            if isinstance(value, bytes):
                value = value.decode("utf-8")
            if not isinstance(value, str):
                raise InputError(f"{where}: attribute '{name}' must be a string")
            return value
        arr = np.asarray(value)
        if kind is int and (arr.shape != () or arr.dtype.kind not in "iu"):
            raise InputError(f"{where}: attribute '{name}' must be an integer")
        if kind is float and (arr.shape != () or arr.dtype.kind not in "iuf"):
            raise InputError(f"{where}: attribute '{name}' must be a number")
        if kind is bool and (arr.shape != () or arr.dtype.kind not in "biu"):
            raise InputError(f"{where}: attribute '{name}' must be a boolean")
        return kind(arr)

    def _error_attr(self, errors, name: str):
        """One attribute of /sensor/errors: a number, or 3 finite numbers for a pose vector."""
        if name not in POSE_ERROR_VECTORS:
            return self._attr(errors, name, float)
        arr = np.asarray(errors.attrs[name])
        if arr.shape != (3,) or arr.dtype.kind not in "iuf" or not np.all(np.isfinite(arr)):
            raise InputError(f"{self._where}: /sensor/errors attribute '{name}' must be 3 "
                                 "finite numbers")
        return tuple(float(v) for v in arr)

    def _counts(self) -> tuple[int, int]:
        """Shot and strike rows of a complete log (written last, on a clean close)."""
        for name in ("n_shots", "n_strikes"):
            if name not in self._file.attrs:
                raise InputError(f"{self._where}: incomplete log (no '{name}' attribute: "
                                     "the writer did not close cleanly)")
        return self._attr(self._file, "n_shots", int), self._attr(self._file, "n_strikes", int)

    # A log being written has datasets longer than its committed rows (LiveStrikeLog).
    _growing = False

    def _dataset(self, path: str, n: int | None, tail: tuple, dtype) -> h5py.Dataset:
        """Open dataset ``/path``, refusing one missing or of another shape than ``(n, *tail)``
        (``n`` None: any length); a dtype other than ``dtype`` (either byte order) is noted in
        ``self._wrong_dtypes``, for ``_check_schema`` to report every one at once."""
        where = self._where
        if path not in self._file:
            raise InputError(f"{where}: missing dataset /{path}")
        ds = self._file[path]
        if not isinstance(ds, h5py.Dataset):
            raise InputError(f"{where}: /{path} is not a dataset")
        short = n is not None and (ds.shape[0] < n if self._growing else ds.shape[0] != n)
        if ds.ndim != 1 + len(tail) or ds.shape[1:] != tail or short:
            want = ("n" if n is None else str(n)) + "".join(f", {k}" for k in tail)
            raise InputError(f"{where}: /{path} has shape {ds.shape}, expected ({want})")
        want = np.dtype(dtype)
        if (ds.dtype.kind, ds.dtype.itemsize) != (want.kind, want.itemsize):
            self._wrong_dtypes.append(f"/{path} has dtype {ds.dtype}, expected {want}")
        return ds

    def _check_schema(self) -> None:
        """Check the whole layout of SPEC.md (attributes, sensor, every dataset's shape and
        dtype) and open the datasets, without reading their rows.

        A dataset of another dtype than SPEC.md's is refused, by the reader as by
        ``validate``, and every such dataset is named at once: converting a float32 column
        would hide that its producer rounded the values (docs/decisions.md, Strike-log
        dtypes)."""
        self._check_root()
        self._wrong_dtypes = []
        self.sensor = self._read_sensor()
        self._open_datasets()
        if self._wrong_dtypes:
            raise InputError(f"{self._where}: " + "; ".join(self._wrong_dtypes))
        _check_sensor(self.sensor, self._where)

    def _check_root(self) -> None:
        """The root attributes: format and version, the others of SPEC.md, the row counts."""
        f, where = self._file, self._where
        fmt = f.attrs.get("format")
        if isinstance(fmt, bytes):
            fmt = fmt.decode("utf-8", "replace")
        if fmt != FORMAT_NAME:
            raise InputError(f"{where}: not a strike log (root attribute 'format' is "
                                 f"{fmt!r}, expected {FORMAT_NAME!r})")
        version = self._attr(f, "format_version", int)
        if version != FORMAT_VERSION:
            raise InputError(f"{where}: format version {version} is not supported (this "
                                 f"recon reads version {FORMAT_VERSION})")
        self.attrs = {name: self._attr(f, name, str) for name in _ROOT_ATTRS
                      if name not in ("format_version", "seed")}
        self.attrs["format_version"] = version
        self.attrs["seed"] = self._attr(f, "seed", int)
        # Optional (SPEC.md): ET of time 0 when the scene was SPICE-driven.
        self.epoch_et = self._attr(f, "epoch_et", float) if "epoch_et" in f.attrs else None
        if self.epoch_et is not None and not np.isfinite(self.epoch_et):
            raise InputError(f"{where}: root attribute 'epoch_et' must be finite")
        self.n_shots, self.n_strikes = self._counts()
        if self.n_shots < 0 or self.n_strikes < 0:
            raise InputError(f"{where}: negative row counts")

    def _read_sensor(self) -> SensorInfo:
        """The /sensor group and its /sensor/errors."""
        f, where = self._file, self._where
        if "sensor" not in f:
            raise InputError(f"{where}: missing group /sensor")
        g = f["sensor"]
        beams = self._dataset("sensor/beam_directions", None, (3,), np.float64)
        check_whole(where, [beams], InputError)
        directions = beams[()]
        if "sensor/errors" not in f:
            raise InputError(f"{where}: missing group /sensor/errors")
        errors = f["sensor/errors"]
        fov = np.asarray(g.attrs.get("field_of_view", np.zeros(0)))
        if fov.shape != (4,) or fov.dtype.kind != "f":
            raise InputError(f"{where}: /sensor attribute 'field_of_view' must be 4 floats")
        return SensorInfo(
            pattern=self._attr(g, "pattern", str), beam_directions=directions,
            range_min=self._attr(g, "range_min", float),
            range_max=self._attr(g, "range_max", float),
            field_of_view=tuple(float(a) for a in fov),
            reports_angles=self._attr(g, "reports_angles", bool),
            errors=SensorErrors(**{k.name: self._error_attr(errors, k.name)
                                   for k in fields(SensorErrors)
                                   if k.name in errors.attrs or k.name not in POSE_ERROR_FIELDS}))

    def _open_datasets(self) -> None:
        """The shot, strike and (when present) truth datasets, each of its declared shape."""
        self._shots = {k: self._dataset(f"shots/{k}", self.n_shots, tail, np.float64)
                       for k, tail in _SHOT_FIELDS.items()}
        spec = dict(_STRIKE_FIELDS)
        if self.sensor.reports_angles:
            spec |= {k: ((), np.float64) for k in _ANGLE_FIELDS}
        self._strikes = {k: self._dataset(f"strikes/{k}", self.n_strikes, tail, dtype)
                         for k, (tail, dtype) in spec.items()}
        self.has_truth = "truth" in self._file
        if self.has_truth:
            self._truth_shots = {k: self._dataset(f"truth/{k}", self.n_shots, tail,
                                                  np.float64)
                                 for k, tail in _TRUTH_SHOT_FIELDS.items()}
            self._truth_strikes = {k: self._dataset(f"truth/{k}", self.n_strikes, tail, dtype)
                                   for k, (tail, dtype) in _TRUTH_STRIKE_FIELDS.items()}
            self._dataset("truth/mesh/vertices", None, (3,), np.float64)
            self._dataset("truth/mesh/faces", None, (3,), np.uint32)

    # ------------------------------------------------------------------ reading

    def _slice(self, start: int, stop: int | None, n: int) -> tuple[int, int]:
        stop = n if stop is None else stop
        if not (0 <= start <= stop <= n):
            raise InputError(f"{self._where}: rows {start}:{stop} out of range (0:{n})")
        return start, stop

    def _blocks(self, n: int, chunk_rows: int, first: int = 0) -> Iterator[tuple[int, int]]:
        """``(start, stop)`` of consecutive blocks of at most ``chunk_rows`` of rows
        ``first .. n - 1``."""
        if chunk_rows < 1:
            raise InputError(f"{self._where}: chunk_rows must be positive")
        for start in range(first, n, chunk_rows):
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
        _check_strike_rows(shot, beam, rng, n_shots=self.n_shots, n_beams=self.sensor.n_beams,
                           where=self._where, row0=start, previous_shot=previous_shot,
                           range_min=self.sensor.range_min,
                           range_max=self.sensor.range_max)
        return shot.astype(np.int64), beam.astype(np.int64), rng

    def _check_unique_pairs(self, shot: np.ndarray, beam: np.ndarray, carried: np.ndarray,
                            start: int) -> np.ndarray:
        """Refuse a (shot, beam) pair seen twice in this block or in ``carried`` (the pairs of
        the previous block's last shot); return the pairs to carry into the next block."""
        n_beams = self.sensor.n_beams
        pairs = np.concatenate([carried, shot * n_beams + beam])
        ordered = np.sort(pairs)   # np.unique is ~200x slower than a sort (1e6 rows)
        if np.any(ordered[1:] == ordered[:-1]):
            raise InputError(f"{self._where}: a (shot, beam) pair appears twice near "
                                 f"strike {start}")
        return pairs[pairs // n_beams == shot[-1]] if len(shot) else carried

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

    def check_time(self, chunk_rows: int = READ_CHUNK_ROWS) -> None:
        """Check that the time of every shot is finite and strictly increases, reading the
        time column alone block by block (shots that no strike uses included: a log whose
        time does not increase is refused even when it holds no strikes)."""
        previous_time = None
        for start, stop in self._blocks(self.n_shots, chunk_rows):
            with _hdf5_errors(self._where):
                time = np.asarray(self._shots["time"][start:stop], dtype=np.float64)
            check_time(time, self._where, start, previous_time)
            previous_time = float(time[-1])

    def iter_chunks(self, chunk_rows: int = READ_CHUNK_ROWS, *, first: int = 0,
                    previous_shot: int | None = None) -> Iterator[StrikeChunk]:
        """Yield consecutive blocks of at most ``chunk_rows`` strikes with their shots.

        Ordering and duplicate (shot, beam) pairs across block boundaries are checked too, and
        the shots against the shots of the block before, so a full pass makes every check of
        ``validate`` on the strikes and the shots they use. ``first`` is the first strike read;
        ``previous_shot`` the shot of the strike before it. A pass from the first strike
        checks the time of every shot first (``check_time``).
        """
        if first == 0:
            self.check_time(chunk_rows)
        previous_time = None
        carried = np.zeros(0, dtype=np.int64)
        for start, stop in self._blocks(self.n_strikes, chunk_rows, first):
            shot, beam, rng = self._checked_strikes(start, stop, previous_shot)
            carried = self._check_unique_pairs(shot, beam, carried, start)
            lo, hi = int(shot[0]), int(shot[-1]) + 1
            if previous_shot == lo:   # the shot shared with the block before: checked there
                shots = self.shots(lo, hi)
            else:
                shots = self._checked_shots(lo, hi, previous_time)
            previous_shot, previous_time = int(shot[-1]), float(shots.time[-1])
            yield StrikeChunk(start=start, shot=shot, beam=beam, range=rng,
                              direction=self.directions(beam, start, stop),
                              shots=shots, shot_offset=lo)

    # ------------------------------------------------------------------ truth

    def _require_truth(self) -> None:
        if not self.has_truth:
            raise InputError(f"{self._where}: log has no /truth group")

    def truth_mesh(self) -> Mesh:
        """The truth mesh: vertices (n, 3) float64 [m, body frame] and faces (m, 3) int64."""
        self._require_truth()
        with _hdf5_errors(self._where):
            stored = self._file["truth/mesh/vertices"], self._file["truth/mesh/faces"]
            check_whole(self._where, stored, InputError)
            vertices = np.asarray(stored[0][()], dtype=np.float64)
            faces = np.asarray(stored[1][()]).astype(np.int64)
        _check_finite("truth mesh vertices", vertices, self._where)
        if len(faces) == 0:
            raise InputError(f"{self._where}: truth mesh has no faces")
        if faces.min() < 0 or faces.max() >= len(vertices):
            raise InputError(f"{self._where}: truth mesh faces index missing vertices")
        with _hdf5_errors(self._where):
            stored = self._file["truth/mesh"].attrs.get("sha256")
        if stored is not None:
            stored = stored.decode("ascii", "replace") if isinstance(stored, bytes) else stored
            if stored != mesh_checksum(vertices, faces):
                raise InputError(f"{self._where}: truth mesh does not match its sha256 "
                                     "checksum (the file is damaged)")
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
        """Check every row of the log (streaming); raise InputError at the first problem.

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
        for start, stop in self._blocks(self.n_strikes, chunk_rows):
            shot, beam, _ = self._checked_strikes(start, stop, previous_shot)
            if self.sensor.reports_angles:
                self._angle_offsets(start, stop)
            previous_shot = int(shot[-1])
            carried = self._check_unique_pairs(shot, beam, carried, start)
            if progress:
                progress(stop - start)
        if self.has_truth:
            self._validate_truth(chunk_rows, progress)

    def _validate_truth(self, chunk_rows: int, progress) -> None:
        """Read and check every row of ``/truth``: the mesh (with its checksum), the true poses
        and the true hits (finite, unit quaternions, facets of the mesh, positive ranges)."""
        where = self._where
        n_faces = len(self.truth_mesh().faces)
        for start, stop in self._blocks(self.n_shots, chunk_rows):
            rows = self.truth_shots(start, stop)
            _check_finite("truth sensor_position", rows.sensor_position, where)
            _check_quaternions("truth sensor_attitude", rows.sensor_attitude, where, start)
            _check_quaternions("truth target_attitude", rows.target_attitude, where, start)
        for start, stop in self._blocks(self.n_strikes, chunk_rows):
            hits = self.truth_strikes(start, stop)
            _check_finite("truth point", hits.point, where)
            if len(hits.facet) and (hits.facet.min() < 0 or hits.facet.max() >= n_faces):
                raise InputError(f"{where}: truth facet out of range (the mesh has "
                                     f"{n_faces} faces) near strike {start}")
            if not np.all(np.isfinite(hits.range) & (hits.range > 0)):
                raise InputError(f"{where}: truth range is not a finite positive number "
                                     f"near strike {start}")

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
            "epoch_et": self.epoch_et,
        }

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> StrikeLog:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class LiveStrikeLog(StrikeLog):
    """A log still being written by a live (SWMR) writer, opened at its temporary path.

    ``n_shots`` and ``n_strikes`` are the rows the writer has committed (flushed and published,
    SPEC.md, Live logs); :meth:`refresh` moves them on. Every read of :class:`StrikeLog` works on
    the committed rows, so a reader never sees a half-written block.
    """

    _growing = True

    def __init__(self, path):
        self.path = Path(path)
        self._where = str(self.path)
        with _hdf5_errors(self._where):
            # No file lock: the writer reopens the file to finish it while readers hold it.
            self._file = h5py.File(self.path, "r", libver="latest", swmr=True, locking=False)
        try:
            if LIVE_COMMITTED not in self._file:
                raise InputError(f"{self._where}: not a live log (no /{LIVE_COMMITTED})")
            live = self._file[LIVE_COMMITTED]
            if not (isinstance(live, h5py.Dataset) and live.shape == (3,)
                    and (live.dtype.kind, live.dtype.itemsize) == ("i", 8)):
                raise InputError(f"{self._where}: /{LIVE_COMMITTED} must be a dataset of 3 "
                                 "int64 values")
            self.closing = False
            with _hdf5_errors(self._where):
                self._check_schema()
        except BaseException:
            self._file.close()
            raise

    def _counts(self) -> tuple[int, int]:
        committed = self._file[LIVE_COMMITTED]
        committed.refresh()
        n_shots, n_strikes, closing = (int(v) for v in committed[()])
        self.closing = closing == 1
        return n_shots, n_strikes

    def refresh(self) -> None:
        """Read the committed counts again and make the rows up to them readable."""
        with _hdf5_errors(self._where):
            n_shots, n_strikes = self._counts()
            for datasets, n in ((self._shots, n_shots), (self._strikes, n_strikes)):
                for ds in datasets.values():
                    ds.refresh()
                    if ds.shape[0] < n:
                        raise InputError(f"{self._where}: committed rows beyond {ds.name}")
        if n_shots < self.n_shots or n_strikes < self.n_strikes:
            raise InputError(f"{self._where}: committed counts went backwards")
        self.n_shots, self.n_strikes = n_shots, n_strikes


def _open_live(path: Path, deadline: float, poll_s: float) -> LiveStrikeLog:
    """Open a writer's temporary file, waiting until the writer has made it readable."""
    while True:
        try:
            return LiveStrikeLog(path)
        except InputError:
            if time.monotonic() > deadline:
                raise
        time.sleep(poll_s)


def _is_file(path: Path, inode: int) -> bool:
    """Whether ``path`` is the file with inode number ``inode`` (a renamed temporary file)."""
    try:
        return path.stat().st_ino == inode
    except FileNotFoundError:
        return False


def _partial_logs(path: Path) -> list[Path]:
    """Temporary files of writers of ``path`` (formats/atomic.py), newest first."""
    found = []
    for p in path.parent.glob(f".{path.name}.partial-*"):
        try:
            found.append((p.stat().st_mtime, p))
        except FileNotFoundError:   # a writer finished or gave up meanwhile
            continue
    return [p for _, p in sorted(found, reverse=True)]


def follow(path, *, chunk_rows: int = READ_CHUNK_ROWS, poll_s: float = 0.5,
           timeout_s: float = 60.0) -> Iterator[tuple[StrikeChunk, StrikeLog]]:
    """Read the strikes of a log while a live writer (``StrikeLogWriter(live=True)``) writes it.

    Waits for the writer's temporary file beside ``path``, yields every block of committed
    strikes as it arrives, and ends once the writer has closed and renamed the log into place,
    with the last blocks read from the complete log. A complete ``path`` with no writer at work is
    read whole.

    Parameters
    ----------
    path : str or Path
        The log's final path.
    chunk_rows : int
        Most strikes per block.
    poll_s : float, seconds
        How often to look for new strikes.
    timeout_s : float, seconds
        How long to wait for a writer to start, and for new strikes or the close.

    Yields
    ------
    (StrikeChunk, StrikeLog)
        A block of strikes, and the log it was read from (its ``sensor``, ``n_strikes``).

    Raises
    ------
    InputError
        No writer appeared, the writer stopped (its temporary file vanished without the log
        appearing, or nothing arrived for ``timeout_s``), or a block fails its checks.
    """
    path = Path(path)
    deadline = time.monotonic() + timeout_s
    temporary = _await_writer(path, deadline, poll_s, timeout_s)
    if temporary is None:
        with StrikeLog(path) as log:
            for chunk in log.iter_chunks(chunk_rows):
                yield chunk, log
        return
    inode = temporary.stat().st_ino
    done, previous_shot = yield from _follow_live(path, temporary, deadline, chunk_rows, poll_s,
                                                  timeout_s)
    _await_rename(path, temporary, inode, poll_s, timeout_s)
    with StrikeLog(path) as final:
        for chunk in final.iter_chunks(chunk_rows, first=done, previous_shot=previous_shot):
            yield chunk, final


def _await_writer(path: Path, deadline: float, poll_s: float, timeout_s: float
                  ) -> Path | None:
    """The live writer's temporary file beside ``path``, or None when the complete log is there
    and no writer is at work (waiting until ``deadline``, a ``time.monotonic()``)."""
    while True:
        partial = _partial_logs(path)
        if partial:
            return partial[0]
        if path.exists():
            return None
        if time.monotonic() > deadline:
            raise InputError(f"{path}: no log and no writer at work after {timeout_s:g} s")
        time.sleep(poll_s)


def _follow_live(path: Path, temporary: Path, deadline: float, chunk_rows: int, poll_s: float,
                 timeout_s: float
                 ) -> Generator[tuple[StrikeChunk, StrikeLog], None, tuple[int, int | None]]:
    """Yield the committed strikes of the writer's temporary file until it closes (waiting for
    it to become readable until ``deadline``); return the strikes read and the last shot."""
    done, previous_shot = 0, None
    with _open_live(temporary, deadline, poll_s) as log:
        deadline = time.monotonic() + timeout_s
        while True:
            log.refresh()
            if log.n_strikes > done:
                for chunk in log.iter_chunks(chunk_rows, first=done, previous_shot=previous_shot):
                    yield chunk, log
                    done, previous_shot = chunk.start + len(chunk), int(chunk.shot[-1])
                deadline = time.monotonic() + timeout_s
            if log.closing or not temporary.exists():
                return done, previous_shot
            if _writer_died(path, temporary, log, done):
                continue
            if time.monotonic() > deadline:
                raise InputError(f"{path}: nothing new for {timeout_s:g} s (is the writer "
                                     "still running?)")
            time.sleep(poll_s)


def _writer_died(path: Path, temporary: Path, log: StrikeLog, done: int) -> bool:
    """Whether the writer's process is gone; raise if it left strikes unfinished (nothing
    closing, nothing new since ``done``)."""
    pid = partial_pid(temporary)
    if pid is None or process_alive(pid):
        return False
    log.refresh()
    if not log.closing and temporary.exists() and log.n_strikes == done:
        raise InputError(
            f"{path}: the writer (process {pid}) died after {log.n_shots} shots and "
            f"{done} strikes; `recon recover {path} -o LOG.h5` makes a log of them")
    return True


def _await_rename(path: Path, temporary: Path, inode: int, poll_s: float, timeout_s: float
                  ) -> None:
    """Wait for the finishing writer to rename its temporary file (``inode``) to ``path``."""
    deadline = time.monotonic() + timeout_s
    while not _is_file(path, inode):
        gone = not temporary.exists()
        if (gone and not _is_file(path, inode)) or time.monotonic() > deadline:
            raise InputError(f"{path}: the writer stopped before completing the log")
        time.sleep(poll_s)
