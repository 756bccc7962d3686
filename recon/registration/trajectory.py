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

The same poses go to SPICE as kernels (``.bsp``, ``.bc``; conventions in formats/spice.py): an
SPK of the sensor relative to the target in J2000 (the log's I), or a CK of the sensor and
target attitudes, each with the frames kernel (``.tf``) it needs written beside it, and for a CK
the clock kernel (``.tsc``): ``traj.bsp`` comes with ``traj.tf``, ``att.bc`` with ``att.tf``
and ``att.tsc``. A shot at time ``t`` is at ``ET = epoch + t``: the log's ``epoch_et`` when
its scene was SPICE-driven, otherwise the epoch given (0, the J2000 epoch, by default).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from formats import StrikeLog
from formats.atomic import AtomicWriter
from formats.errors import ParameterError
from formats.geometry import FRAMES, file_metadata
from formats.strike_log import READ_CHUNK_ROWS

COLUMNS = ("time", "x", "y", "z", "roll", "pitch", "yaw", "qx", "qy", "qz", "qw")
UNITS = ("s", "m", "m", "m", "rad", "rad", "rad", "1", "1", "1", "1")
SUFFIXES = (".txt", ".csv")
KERNEL_SUFFIXES = (".bsp", ".bc")


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
    missing_dir_error = ParameterError

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
        raise ParameterError(f"{output}: a trajectory is written as .txt or .csv (text), "
                              ".bsp (SPK) or .bc (CK)")
    if frame not in FRAMES:
        raise ParameterError(f"frame must be one of {', '.join(FRAMES)}, got {frame!r}")
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


def log_epoch(log: StrikeLog, epoch_et: float | None) -> float:
    """ET [s] of the log's time 0: ``epoch_et`` when given, else the log's, else 0 (J2000)."""
    if epoch_et is not None:
        if not np.isfinite(epoch_et):
            raise ParameterError(f"epoch must be a finite ET, got {epoch_et!r}")
        return float(epoch_et)
    return 0.0 if log.epoch_et is None else log.epoch_et


def kernel_files(output) -> list[Path]:
    """Every file ``export_kernel`` writes for ``output``: the kernel, its frames kernel
    (``.tf``) and, for a CK, its clock kernel (``.tsc``)."""
    output = Path(output)
    clock = [output.with_suffix(".tsc")] if output.suffix.lower() == ".bc" else []
    return [output, output.with_suffix(".tf"), *clock]


def export_kernel(log, output, *, epoch_et: float | None = None) -> dict:
    """Write the recorded poses of a strike log as a SPICE kernel (see the module docstring).

    Parameters
    ----------
    log : str or Path
        Strike log.
    output : str or Path
        ``.bsp``: SPK of ``RECON_SENSOR`` relative to ``RECON_TARGET`` in J2000 (with ``.tf``
        beside it); ``.bc``: CK of ``RECON_SENSOR_FRAME`` and ``RECON_TARGET_FIXED`` relative
        to J2000 (with ``.tf`` and ``.tsc`` beside it). Every file is written atomically.
    epoch_et : float, optional
        ET [s, TDB past J2000] of the log's time 0 (default: the log's ``epoch_et``, else 0).

    Returns
    -------
    dict
        ``n_shots``, ``epoch_et``, ``output`` and ``written`` (every file written).
    """
    from formats import spice
    from formats.atomic import write_atomically, write_text_atomically

    output = Path(output)
    suffix = output.suffix.lower()
    if suffix not in KERNEL_SUFFIXES:
        raise ParameterError(f"{output}: a kernel is written as {' or '.join(KERNEL_SUFFIXES)}")
    with StrikeLog(log) as strike_log:
        if strike_log.n_shots == 0:
            raise ParameterError(f"{log}: no shots to write")
        shots = strike_log.shots()
        epoch = log_epoch(strike_log, epoch_et)
    et = epoch + shots.time
    if not np.all(np.diff(et) > 0):
        raise ParameterError(f"{log}: shot times do not stay strictly increasing at ET "
                              f"{epoch:.17g} + t (float64 resolution); give an earlier epoch")
    comment = (f"recon {Path(log).name}: {len(et)} recorded shots, ET = {epoch!r} + time")
    _, frames, *clock = kernel_files(output)
    write_text_atomically(frames, spice.frames_kernel(), error=ParameterError)
    written = [frames]

    def kernel(write):
        def into(temporary):
            Path(temporary).unlink(missing_ok=True)   # the toolkit creates the file itself
            write(temporary)
        write_atomically(output, into, error=ParameterError)

    if suffix == ".bsp":
        kernel(lambda tmp: spice.write_spk(tmp, et, shots.sensor_position, comment=comment))
    else:
        write_text_atomically(clock[0], spice.clock_kernel(epoch), error=ParameterError)
        written.append(clock[0])
        with spice.loaded(clock, "SCLK"):
            kernel(lambda tmp: spice.write_ck(
                tmp, et, {spice.SENSOR_CK_ID: shots.sensor_attitude,
                          spice.TARGET_CK_ID: shots.target_attitude}, comment=comment))
    return {"n_shots": len(et), "epoch_et": epoch, "output": str(output),
            "written": [str(output), *map(str, written)]}
