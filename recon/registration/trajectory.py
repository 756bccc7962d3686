"""The sensor's recorded trajectory as text: one line per shot with time, position and attitude.

Like the trajectory file HELIOS++ writes beside its point clouds, so that a viewer can show where
each strike was taken from: space-separated columns after ``#`` header lines (``.txt``), or
comma-separated with one header row (``.csv``)::

    time x y z roll pitch yaw qx qy qz qw

``time`` [s] since the start of the campaign (the clouds' ``time`` and LAS ``gps_time``);
``x y z`` [m] the sensor position; ``qx qy qz qw`` the sensor attitude as a scalar-last quaternion
that sends sensor-frame (S) vectors to the output frame, and ``roll pitch yaw`` [rad] the same
rotation as intrinsic z-y'-x'' angles (yaw about z, then pitch about the new y, then roll about
the new x; scipy's ``as_euler("ZYX")`` reversed). In the body frame B (default) position and
attitude are relative to the target, like a body-frame cloud; in the inertial frame I they are
as recorded. Only the recorded poses are used, never the log's ``/truth``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from formats import StrikeLog
from formats.atomic import AtomicWriter
from formats.errors import ReconError
from formats.geometry import FRAMES, file_metadata
from formats.strike_log import READ_CHUNK_ROWS

COLUMNS = ("time", "x", "y", "z", "roll", "pitch", "yaw", "qx", "qy", "qz", "qw")
UNITS = ("s", "m", "m", "m", "rad", "rad", "rad", "1", "1", "1", "1")
SUFFIXES = (".txt", ".csv")


class TrajectoryError(ReconError, ValueError):
    """A trajectory cannot be written as asked (suffix, frame)."""


def trajectory_rows(shots, *, frame: str = "body") -> np.ndarray:
    """Rows of the trajectory file for a block of recorded shots.

    Parameters
    ----------
    shots : formats.Shots
    frame : {"body", "inertial"}

    Returns
    -------
    (n, 11) float64 in the order of ``COLUMNS``.
    """
    position = shots.sensor_position
    attitude = Rotation.from_quat(shots.sensor_attitude)  # S -> I
    if frame == "body":
        to_body = Rotation.from_quat(shots.target_attitude).inv()  # I -> B
        position = to_body.apply(position)
        attitude = to_body * attitude  # S -> B
    yaw_pitch_roll = attitude.as_euler("ZYX")
    return np.column_stack([shots.time, position, yaw_pitch_roll[:, ::-1], attitude.as_quat()])


class _TextWriter(AtomicWriter):
    missing_dir_error = TrajectoryError

    def __init__(self, path):
        super().__init__(path)
        self.fh = open(self.temporary, "w", encoding="utf-8")  # closed by _finish or _release

    def _finish(self) -> None:
        self.fh.close()

    def _release(self) -> None:
        self.fh.close()


def export_trajectory(log, output, *, frame: str = "body", chunk_rows: int = READ_CHUNK_ROWS
                      ) -> dict:
    """Write the recorded sensor trajectory of a strike log (see the module docstring).

    Parameters
    ----------
    log : str or Path
        Strike log.
    output : str or Path
        ``.txt`` (space-separated, ``#`` header) or ``.csv``; written atomically.
    frame : {"body", "inertial"}
    chunk_rows : int
        Shots read per block (bounded memory).

    Returns
    -------
    dict
        ``n_shots``, ``frame``, ``output``.
    """
    output = Path(output)
    if output.suffix.lower() not in SUFFIXES:
        raise TrajectoryError(f"{output}: a trajectory is written as {' or '.join(SUFFIXES)}")
    if frame not in FRAMES:
        raise TrajectoryError(f"frame must be one of {', '.join(FRAMES)}, got {frame!r}")
    csv = output.suffix.lower() == ".csv"
    with StrikeLog(log) as strike_log, _TextWriter(output) as writer:
        if csv:
            writer.fh.write(",".join(COLUMNS) + "\n")
        else:
            meta = file_metadata(frame, source=Path(log).name)
            writer.fh.write("".join(f"# {k}: {v}\n" for k, v in meta.items()))
            writer.fh.write("# column units: " + " ".join(UNITS) + "\n")
            writer.fh.write("# " + " ".join(COLUMNS) + "\n")
        for start in range(0, strike_log.n_shots, chunk_rows):
            stop = min(start + chunk_rows, strike_log.n_shots)
            rows = trajectory_rows(strike_log.shots(start, stop), frame=frame)
            np.savetxt(writer.fh, rows, fmt="%.17g", delimiter="," if csv else " ")
        n_shots = strike_log.n_shots
    return {"n_shots": n_shots, "frame": frame, "output": str(output)}
