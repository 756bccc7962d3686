"""The strike-log writer: shots and strikes streamed in chunks into a temporary file that is
renamed into place only on a clean close (formats/SPEC.md)."""

from __future__ import annotations

import shutil
from dataclasses import fields
from datetime import UTC, datetime
from pathlib import Path

import h5py
import numpy as np

from formats.atomic import LIVE_SUFFIX, AtomicWriter
from formats.errors import InputError
from formats.hdf5_check import trust
from formats.strike_log.schema import (
    _ANGLE_FIELDS,
    _SHOT_FIELDS,
    _STRIKE_FIELDS,
    _TRUTH_SHOT_FIELDS,
    _TRUTH_STRIKE_FIELDS,
    DATASET_UNITS,
    DEFAULT_COMPRESSION,
    FORMAT_NAME,
    FORMAT_VERSION,
    LIVE_COMMITTED,
    NOISY_ANGLE_COLUMNS,
    SHOT_CHUNK_ROWS,
    STRIKE_CHUNK_ROWS,
    UNFILTERED_COLUMNS,
    SensorErrors,
    SensorInfo,
    Shots,
    TruthStrikes,
    _as_array,
    _check_finite,
    _check_sensor,
    _check_shot_rows,
    _check_strike_rows,
    compression_filters,
    mesh_checksum,
)
from formats.version import __version__


def _chunk_rows(expected: int | None, largest: int) -> int:
    """Rows per chunk: ``largest`` when nothing is expected, else the fewest chunks of at most
    ``largest`` rows that hold ``expected`` rows, split evenly (the last chunk is not padded)."""
    if expected is None:
        return largest
    expected = max(1, int(expected))
    return -(-expected // -(-expected // largest))


def _filters(compression: str, name: str, noisy_angles: bool) -> dict:
    """h5py filter keywords of dataset ``name`` (e.g. ``strikes/range``): Fletcher-32 always,
    ``compression`` (schema.compression_filters) except on the noisy float64 strike columns
    (schema.UNFILTERED_COLUMNS, and the angle offsets when ``noisy_angles``)."""
    skip = name in UNFILTERED_COLUMNS or (noisy_angles and name in NOISY_ANGLE_COLUMNS)
    return {"fletcher32": True} | ({} if skip else compression_filters(compression))


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
    compression : str, optional
        Filter for the chunked datasets: ``"gzip"`` or ``"gzip:LEVEL"`` (deflate, LEVEL 0-9,
        with shuffle; readable by every HDF5 tool), ``"lzf"`` (with shuffle; h5py only) or
        ``"none"``. Default ``DEFAULT_COMPRESSION`` (SPEC.md, Storage, says why).
    expected_shots, expected_strikes : int, optional
        How many rows the log will hold (at most); chunks are no longer than that, so a small log
        is not padded to the default chunk sizes. Appending beyond it stays possible.
    live : bool, optional
        Write in HDF5 single-writer/multiple-reader mode, so that ``follow`` (reader.py) reads
        the strikes while they are written (SPEC.md, Live logs).

    Examples
    --------
    >>> with StrikeLogWriter("run.h5", sensor=sensor, target="asteroid") as log:  # doctest: +SKIP
    ...     log.write_shots(time, position, sensor_q, target_q)
    ...     log.write_strikes(shot, beam, rng)
    """

    missing_dir_error = InputError

    def __init__(self, path, *, sensor: SensorInfo, target: str, scene: str = "", seed: int = -1,
                 truth_mesh: tuple[np.ndarray, np.ndarray] | None = None,
                 producer: str = "recon", producer_version: str = __version__,
                 compression: str = DEFAULT_COMPRESSION, expected_shots: int | None = None,
                 expected_strikes: int | None = None, live: bool = False):
        where = str(path)
        _check_sensor(sensor, where)
        compression_filters(compression, where)   # refuse a bad name before making a file
        super().__init__(path, suffix=LIVE_SUFFIX if live else "")
        self.sensor = sensor
        self.has_truth = truth_mesh is not None
        self._n_shots = self._n_strikes = 0
        self._datasets: dict = {}   # "group/name" -> h5py.Dataset, opened once
        self._held: dict = {}       # "group/name" -> rows not yet written (_extend)
        self._last_time: float | None = None
        self._last_shot: int | None = None
        self.live = live
        try:
            self._file = h5py.File(self.temporary, "w", **({"libver": "latest"} if live else {}))
            self._create_layout(sensor, target=target, scene=scene, seed=seed,
                                truth_mesh=truth_mesh, producer=producer,
                                producer_version=producer_version,
                                compression=compression,
                                rows=(_chunk_rows(expected_shots, SHOT_CHUNK_ROWS),
                                      _chunk_rows(expected_strikes, STRIKE_CHUNK_ROWS)))
            if live:
                self._file.create_dataset(LIVE_COMMITTED, data=np.zeros(3, dtype=np.int64))
                self._file.swmr_mode = True
        except BaseException:
            self.abort()
            raise

    @classmethod
    def append(cls, path) -> StrikeLogWriter:
        """Open an existing complete log to add shots and strikes to its end.

        The log is copied to a temporary file; the original is replaced only on a clean close.
        """
        from formats.strike_log.reader import StrikeLog

        path = Path(path)
        with StrikeLog(path) as log:
            last_time = float(log.shots(log.n_shots - 1).time[-1]) if log.n_shots else None
            last_shot = int(log.strikes(log.n_strikes - 1)[0][-1]) if log.n_strikes else None
            sensor, has_truth = log.sensor, log.has_truth
            n_shots, n_strikes = log.n_shots, log.n_strikes
        self = cls.__new__(cls)
        AtomicWriter.__init__(self, path)
        self.sensor, self.has_truth, self.live = sensor, has_truth, False
        shutil.copyfile(path, self.temporary)
        self._file = h5py.File(self.temporary, "r+")
        for name in ("n_shots", "n_strikes"):  # the file is incomplete until close
            del self._file.attrs[name]
        self._n_shots, self._n_strikes = n_shots, n_strikes
        self._datasets, self._held = {}, {}
        self._last_time, self._last_shot = last_time, last_shot
        return self

    def _create_layout(self, sensor, *, target, scene, seed, truth_mesh, producer,
                       producer_version, compression, rows):
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
            {k.name: np.asarray(getattr(sensor.errors, k.name), dtype=np.float64)
             for k in fields(SensorErrors)})

        noisy_angles = sensor.errors.angles or sensor.errors.dilation

        def columns(group, spec, rows):
            for name, (tail, dtype) in spec.items():
                group.create_dataset(name, shape=(0, *tail), maxshape=(None, *tail), dtype=dtype,
                                     chunks=(rows, *tail), fillvalue=0,
                                     **_filters(compression, f"{group.name[1:]}/{name}",
                                                noisy_angles))

        shot_rows, strike_rows = rows
        shots = {k: (tail, np.float64) for k, tail in _SHOT_FIELDS.items()}
        columns(f.create_group("shots"), shots, shot_rows)
        strikes = dict(_STRIKE_FIELDS)
        if sensor.reports_angles:
            strikes.update({k: ((), np.float64) for k in _ANGLE_FIELDS})
        columns(f.create_group("strikes"), strikes, strike_rows)
        if truth_mesh is not None:
            t = f.create_group("truth")
            columns(t, {k: (tail, np.float64) for k, tail in _TRUTH_SHOT_FIELDS.items()},
                    shot_rows)
            columns(t, _TRUTH_STRIKE_FIELDS, strike_rows)
            vertices, faces = truth_mesh
            m = t.create_group("mesh")
            m.create_dataset("vertices", data=np.asarray(vertices, dtype=np.float64))
            m.create_dataset("faces", data=np.asarray(faces, dtype=np.uint32))
            m.attrs["sha256"] = mesh_checksum(vertices, faces)
        for name, (units, frame) in DATASET_UNITS.items():
            if name in f:
                f[name].attrs.update({"units": units, "frame": frame})

    # ------------------------------------------------------------------ appending rows

    def _require_open(self) -> None:
        self._check()

    def _flush(self) -> None:
        self._file.flush()

    def _published(self) -> None:
        trust(self.path)   # our own file: readers need not walk it (formats/hdf5_check.py)

    def _extend(self, group: str, values: dict) -> None:
        """Append rows to the datasets ``group/name``.

        Outside live mode, rows are held until they complete a chunk, and only whole chunks
        are written: each chunk then passes through the filters once, where a chunk written in
        parts is filtered at every flush and read back to be completed. At most one chunk of
        each dataset is held, and written on close.
        """
        for name, arr in values.items():
            key = f"{group}/{name}"
            ds = self._datasets.get(key)
            if ds is None:   # held open: closing a dataset flushes its chunk cache
                ds = self._datasets[key] = self._file[key]
            if self.live:
                self._write(ds, arr)
                continue
            held = self._held.pop(key, arr[:0])
            start = ds.shape[0] + len(held)
            rows = ds.chunks[0]
            whole = (start + len(arr)) // rows * rows - start   # rows of arr up to a boundary
            if whole <= 0:
                self._held[key] = np.concatenate([held, arr])
                continue
            if len(held):
                room = -start % rows    # rows of arr that complete the held chunk
                self._write(ds, np.concatenate([held, arr[:room]]))
                arr, whole = arr[room:], whole - room
            if whole:
                self._write(ds, arr[:whole])
            if whole < len(arr):
                self._held[key] = arr[whole:].copy()

    def _write_held(self) -> None:
        """Write the rows held back by :meth:`_extend`."""
        for key, arr in self._held.items():
            self._write(self._datasets[key], arr)
        self._held = {}

    @staticmethod
    def _write(ds, arr: np.ndarray) -> None:
        n = ds.shape[0]
        ds.resize(n + len(arr), axis=0)
        if arr.any():   # rows never written read as the fill value, 0 (SPEC.md, Storage)
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
            raise InputError(f"{where}: write_shots arrays differ in length")
        _check_shot_rows(rows, where, self._n_shots, self._last_time)
        if self.has_truth != (truth is not None):
            raise InputError(f"{where}: write_shots needs truth= exactly when the log has a "
                                 "truth mesh")
        if truth is not None:
            t = {k: _as_array(f"truth {k}", getattr(truth, k), tail, np.float64, where)
                 for k, tail in _TRUTH_SHOT_FIELDS.items()}
            if any(len(v) != n for v in t.values()):
                raise InputError(f"{where}: truth shots differ in length from the shots")
            self._extend("truth", t)
        self._extend("shots", {k: getattr(rows, k) for k in _SHOT_FIELDS})
        self._wrote(n * (96 if truth is None else 184))   # bytes per row: SPEC.md, /shots
        self._n_shots += n
        if n:
            self._last_time = float(rows.time[-1])
        self._commit()

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
            raise InputError(f"{where}: write_strikes arrays differ in length")
        if n and (shot.min() < 0 or beam.min() < 0):
            raise InputError(f"{where}: shot and beam indices must be non-negative")
        _check_strike_rows(shot, beam, rng, n_shots=self._n_shots, n_beams=self.sensor.n_beams,
                           where=where, row0=self._n_strikes, previous_shot=self._last_shot,
                           range_min=self.sensor.range_min,
                           range_max=self.sensor.range_max)
        values = {"shot": shot.astype(np.uint32), "beam": beam.astype(np.uint32), "range": rng}
        if self.sensor.reports_angles != (azimuth_offset is not None
                                          and elevation_offset is not None):
            raise InputError(f"{where}: write_strikes needs azimuth_offset and "
                                 "elevation_offset exactly when the sensor reports angles")
        if self.sensor.reports_angles:
            for k, v in zip(_ANGLE_FIELDS, (azimuth_offset, elevation_offset), strict=True):
                values[k] = _as_array(k, v, (), np.float64, where)
                if len(values[k]) != n:
                    raise InputError(f"{where}: {k} differs in length from the strikes")
                _check_finite(k, values[k], where)
        if self.has_truth != (truth is not None):
            raise InputError(f"{where}: write_strikes needs truth= exactly when the log "
                                 "has a truth mesh")
        if truth is not None:
            t = {k: _as_array(f"truth {k}", getattr(truth, k), tail, dtype, where)
                 for k, (tail, dtype) in _TRUTH_STRIKE_FIELDS.items()}
            if any(len(v) != n for v in t.values()):
                raise InputError(f"{where}: truth strikes differ in length from the strikes")
            self._extend("truth", t)
        self._extend("strikes", values)
        self._wrote(n * (16 + 8 * len(values) + (44 if truth is not None else 0)))
        self._n_strikes += n
        if n:
            self._last_shot = int(shot[-1])
        self._commit()

    def _commit(self, closing: int = 0) -> None:
        """Live logs: flush every row, then publish the counts (SPEC.md, Live logs)."""
        if self.live:
            self._file.flush()
            self._file[LIVE_COMMITTED][:] = [self._n_shots, self._n_strikes, closing]
            self._file[LIVE_COMMITTED].flush()

    def write_epoch(self, epoch_et: float) -> None:
        """Record the ET of time 0 (root attribute ``epoch_et``, SPEC.md): the log's times are
        then ``ET = epoch_et + time``, TDB seconds past J2000 (a SPICE-driven scene)."""
        self._check()
        if not np.isfinite(epoch_et):
            raise InputError(f"{self.path}: epoch_et must be finite, got {epoch_et!r}")
        if self.live:   # attributes cannot be added in SWMR mode: written on close
            self._epoch_et = float(epoch_et)
        else:
            self._file.attrs["epoch_et"] = np.float64(epoch_et)

    # ------------------------------------------------------------------ closing

    def _finish(self) -> None:
        """Write the row counts that mark the log complete (SPEC.md, root attributes)."""
        self._write_held()
        if self.live:   # attributes cannot be added in SWMR mode: reopen once readers are told
            self._commit(closing=1)
            self._file.close()
            self._file = h5py.File(self.temporary, "r+")
        if getattr(self, "_epoch_et", None) is not None:   # held back by SWMR mode
            self._file.attrs["epoch_et"] = np.float64(self._epoch_et)
        self._file.attrs["n_shots"] = np.int64(self._n_shots)
        self._file.attrs["n_strikes"] = np.int64(self._n_strikes)
        self._file.close()

    def _release(self) -> None:
        self._file.close()
