"""A live log whose writer died, turned into a complete log of the rows it had committed.

A live writer (``StrikeLogWriter(live=True)``, SPEC.md, Live logs) flushes every block and then
publishes the committed row counts in ``/live_committed``. When the writer is killed (SIGKILL,
a crash, a power loss) its hidden temporary file ``.LOG.partial-PID-*.live`` stays behind with every
committed row intact; the rows it had not committed, and whatever it had not yet written, are
lost. ``recover`` copies the committed rows into a new, complete log (checked row by row as
every read is) and says what was lost.
"""

from __future__ import annotations

import glob
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import h5py

from formats.atomic import LIVE_SUFFIX, partial_pid, process_alive
from formats.errors import InputError
from formats.hdf5_check import check_hdf5, is_hdf5
from formats.paths import check_destination, check_source
from formats.strike_log.reader import LiveStrikeLog
from formats.strike_log.schema import _SHOT_FIELDS, READ_CHUNK_ROWS
from formats.strike_log.writer import StrikeLogWriter


@dataclass(frozen=True)
class Recovery:
    """What a recovered log holds and what the dead writer lost.

    Attributes
    ----------
    output : Path
        The complete log written.
    n_shots, n_strikes : int
        Committed rows copied into it.
    uncommitted_shots, uncommitted_strikes : int
        Rows in the partial file beyond the committed counts (written but never published:
        possibly half-written, dropped).
    closing : bool
        Whether the writer had begun to close (every row was committed).
    time_end_s : float or None
        Time of the last recovered shot [s]; shots after it were not in the file.
    """

    output: Path
    n_shots: int
    n_strikes: int
    uncommitted_shots: int
    uncommitted_strikes: int
    closing: bool
    time_end_s: float | None

    def describe(self) -> str:
        """One paragraph for a person: what was kept and what was lost."""
        end = "" if self.time_end_s is None else f", up to t = {self.time_end_s:g} s"
        lost = ("nothing was lost: the writer had committed every row and was closing"
                if self.closing else
                "lost: every shot after the last commit (the writer's later work was never "
                "written)")
        if self.uncommitted_shots or self.uncommitted_strikes:
            lost += (f"; {self.uncommitted_shots} shot and {self.uncommitted_strikes} strike "
                     "rows written but not committed were dropped")
        return (f"{self.output}: recovered {self.n_shots} shots and {self.n_strikes} strikes"
                f"{end}; {lost}")


_PARTIAL = re.compile(r"^\..+\.partial-\d+-.*" + re.escape(LIVE_SUFFIX) + "$")


def find_partial(path) -> Path:
    """The temporary file of a dead live writer: ``path`` itself, or the newest one beside it
    when ``path`` names the log the writer was writing.

    Raises
    ------
    InputError
        No such file, or its writer is still running.
    """
    path = Path(path)
    if _PARTIAL.match(path.name):
        found = [path]
    else:
        prefix = f".{path.name}.partial-"
        found = sorted((p for p in path.parent.glob(f"{glob.escape(prefix)}*{LIVE_SUFFIX}")
                        if _PARTIAL.match(p.name)), key=lambda p: p.stat().st_mtime, reverse=True)
        if not found:
            raise InputError(f"{path}: no live writer's file beside it to recover "
                                 f"({prefix}*{LIVE_SUFFIX}; only logs written with --live can "
                                 "be recovered)")
    pid = partial_pid(found[0])
    if pid != os.getpid() and process_alive(pid):
        raise InputError(f"{found[0]}: its writer (process {pid}) is still running; "
                             "follow it with `recon ingest --follow` or wait for it to end")
    return found[0]


def _dataset_rows(file: h5py.File, group: str) -> int:
    """Longest first dimension among the datasets of ``group`` (rows present in the file)."""
    return max((ds.shape[0] for ds in file[group].values() if isinstance(ds, h5py.Dataset)),
               default=0)


def recover(partial, output, *, chunk_rows: int = READ_CHUNK_ROWS,
            progress: Callable[[int], object] | None = None) -> Recovery:
    """Write the committed rows of a dead live writer's temporary file as a complete log.

    Parameters
    ----------
    partial : str or Path
        The writer's temporary file (``.LOG.h5.partial-PID-*.live`` beside the log it was writing),
        or the log's own path to recover the newest such file beside it (``find_partial``).
    output : str or Path
        The complete log to write (atomically; never the partial file itself).
    chunk_rows : int
        Rows copied per block.
    progress : callable, optional
        Called with the number of rows copied after each block.

    Returns
    -------
    Recovery

    Raises
    ------
    InputError
        ``partial`` is not a live log, is damaged, or ``output`` is ``partial`` itself.
    """
    partial = check_source(find_partial(partial), InputError)
    output = check_destination(output, InputError)
    if output.exists() and output.samefile(partial):
        raise InputError(f"{output}: is the partial log itself; name another output")
    if not is_hdf5(partial, InputError):
        raise InputError(f"{partial}: not an HDF5 file")
    check_hdf5(partial, InputError, live=True)
    with LiveStrikeLog(partial) as log:
        log.refresh()
        present = (_dataset_rows(log._file, "shots"), _dataset_rows(log._file, "strikes"))
        mesh = log.truth_mesh() if log.has_truth else None
        writer = StrikeLogWriter(
            output, sensor=log.sensor, target=log.attrs["target"], scene=log.attrs["scene"],
            seed=log.attrs["seed"], producer=log.attrs["producer"],
            producer_version=log.attrs["producer_version"],
            truth_mesh=None if mesh is None else (mesh.vertices, mesh.faces),
            expected_shots=log.n_shots, expected_strikes=log.n_strikes)
        with writer:
            time_end = None
            for start in range(0, log.n_shots, chunk_rows):
                stop = min(start + chunk_rows, log.n_shots)
                shots = log.shots(start, stop)
                truth = log.truth_shots(start, stop) if log.has_truth else None
                writer.write_shots(*(getattr(shots, k) for k in _SHOT_FIELDS), truth=truth)
                time_end = float(shots.time[-1])
                if progress is not None:
                    progress(stop - start)
            for start in range(0, log.n_strikes, chunk_rows):
                stop = min(start + chunk_rows, log.n_strikes)
                shot, beam, rng = log.strikes(start, stop)
                angles = (log._angle_offsets(start, stop) if log.sensor.reports_angles
                          else (None, None))
                truth = log.truth_strikes(start, stop) if log.has_truth else None
                writer.write_strikes(shot, beam, rng, azimuth_offset=angles[0],
                                     elevation_offset=angles[1], truth=truth)
                if progress is not None:
                    progress(stop - start)
        return Recovery(output=Path(output), n_shots=log.n_shots, n_strikes=log.n_strikes,
                        uncommitted_shots=present[0] - log.n_shots,
                        uncommitted_strikes=present[1] - log.n_strikes,
                        closing=log.closing, time_end_s=time_end)
