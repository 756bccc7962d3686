"""Register strikes into the target body frame using only the recorded poses and measurements.

For strike ``k`` of shot ``i`` with measured range ``rho`` along the measured unit direction
``d_S`` (sensor frame), the recorded sensor position ``r_I``, sensor attitude ``R_SI`` (sends S
to I) and target attitude ``R_BI`` (sends B to I):

    p_I = r_I + R_SI (rho d_S)
    p_B = R_BI^T p_I

The sensor position in the same frame is kept as the view point of each point (``view_x/y/z``),
which orients normals later. The log's ``/truth`` group is never read here.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from formats import StrikeChunk, StrikeLog
from formats.atomic import check_space
from formats.cloud_io import open_cloud_writer
from formats.errors import InputError
from formats.geometry import Cloud
from formats.memory import check_memory
from formats.strike_log import follow
from formats.strike_log.schema import directions_to_angles
from recon.registration.uncertainty import COLUMNS as SIGMA_COLUMNS
from recon.registration.uncertainty import strike_columns

Frame = Literal["body", "inertial"]
# Strikes per block when a log is scored as it is read (``iter_points``): the reader's and the
# registration's temporaries, ~250 bytes a strike, stay near 65 MB, and the scoring of a block
# (metrics.defaults.STREAM_BLOCK points) adds its own.
SCORE_CHUNK_ROWS = 1 << 18
FRAMES = ("body", "inertial")
# Per-point attributes written by ingest, with their dtypes (formats/cloud_io.py names them).
ATTRIBUTE_DTYPES = {"time": np.float64, "shot": np.uint32, "beam": np.uint32,
                    "range": np.float64, "azimuth": np.float64, "elevation": np.float64,
                    "view_x": np.float64, "view_y": np.float64,
                    "view_z": np.float64} | dict.fromkeys(SIGMA_COLUMNS, np.float32)
# Bytes of a registered strike: its point (x, y, z float64) and its attributes.
STRIKE_BYTES = 24 + sum(np.dtype(d).itemsize for d in ATTRIBUTE_DTYPES.values())


def register_chunk(chunk: StrikeChunk, *, frame: Frame = "body", correction=None
                   ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Place one block of strikes in space.

    Parameters
    ----------
    chunk : StrikeChunk
        Strikes with their recorded shots (``StrikeLog.iter_chunks``).
    frame : {"body", "inertial"}
        Target body frame B (default) or the target-centred inertial frame I (for debugging).
    correction : recon.registration.refine.PoseCorrection, optional
        Corrections of the recorded poses estimated from the strikes (``refine``).

    Returns
    -------
    points : (n, 3) float64, metres, in ``frame``
    attributes : dict of (n,) arrays
        ``time`` [s], ``shot``, ``beam``, ``range`` [m], the measured beam direction's
        ``azimuth`` and ``elevation`` [rad] in the sensor frame S, and the sensor position
        ``view_x/y/z`` [m] in ``frame``.
    """
    if correction is not None:
        chunk = correction.correct_chunk(chunk)
    row = chunk.shot - chunk.shot_offset
    position = chunk.shots.sensor_position[row]
    points = position + Rotation.from_quat(chunk.shots.sensor_attitude[row]).apply(
        chunk.range[:, None] * chunk.direction)
    if frame == "body":
        to_body = Rotation.from_quat(chunk.shots.target_attitude[row]).inv()
        points = to_body.apply(points)
        position = to_body.apply(position)
    azimuth, elevation = directions_to_angles(chunk.direction)
    attributes = {"time": chunk.shots.time[row], "shot": chunk.shot.astype(np.uint32),
                  "beam": chunk.beam.astype(np.uint32), "range": chunk.range,
                  "azimuth": azimuth, "elevation": elevation,
                  "view_x": position[:, 0], "view_y": position[:, 1], "view_z": position[:, 2]}
    return points, attributes


def iter_registered(log: StrikeLog, *, frame: Frame = "body", chunk_rows: int | None = None,
                    progress=None, correction=None
                    ) -> Iterator[tuple[np.ndarray, dict[str, np.ndarray]]]:
    """Yield registered blocks ``(points, attributes)`` of a log, in bounded memory.

    Parameters
    ----------
    log : StrikeLog
    frame : {"body", "inertial"}
    chunk_rows : int, optional
        Strikes per block (default: the reader's block size).
    progress : callable, optional
        Called as ``progress(strikes_in_block, total_strikes)`` after each block.
    correction : recon.registration.refine.PoseCorrection, optional
        Corrections of the recorded poses (``refine``).

    Each block's attributes are ``register_chunk``'s plus the strikes' 1-sigma uncertainty
    columns from the log's recorded error model (``recon.registration.uncertainty``).
    """
    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")
    chunks = log.iter_chunks() if chunk_rows is None else log.iter_chunks(chunk_rows)
    for chunk in chunks:
        yield _registered_block(log, chunk, frame=frame, correction=correction)
        if progress:
            progress(len(chunk), log.n_strikes)


def _registered_block(log: StrikeLog, chunk: StrikeChunk, *, frame: Frame, correction=None
                      ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """``register_chunk``'s points and attributes plus the strikes' 1-sigma uncertainty columns
    from the log's recorded error model: one block as every writer of ingest writes it."""
    points, attributes = register_chunk(chunk, frame=frame, correction=correction)
    sigmas = strike_columns(log.sensor.errors, chunk.range,
                            reports_angles=log.sensor.reports_angles)
    return points, attributes | {k: v.astype(np.float32) for k, v in sigmas.items()}


def _register_and_write(log_path, output, *, frame: Frame, chunk_rows: int | None, progress,
                        keep: bool, correction=None) -> tuple[int, list]:
    """One pass over a log: register every block, write it to ``output`` (if given) and keep it
    (if ``keep``). Returns the strike count and the kept blocks."""
    kept = []
    with StrikeLog(log_path) as log:
        if keep:   # the kept blocks, then the cloud they are joined into
            _check_memory(log, 2 * STRIKE_BYTES)
        if output is not None:
            check_space(output, log.n_strikes * STRIKE_BYTES)
        writer = (open_cloud_writer(output, log.n_strikes, ATTRIBUTE_DTYPES, frame=frame,
                                    source=Path(log_path).name)
                  if output is not None else contextlib.nullcontext())
        with writer:
            for block in iter_registered(log, frame=frame, chunk_rows=chunk_rows,
                                         progress=progress, correction=correction):
                if output is not None:
                    writer.write(*block)
                if keep:
                    kept.append(block)
        return log.n_strikes, kept


def _check_memory(log: StrikeLog, bytes_per_strike: int) -> None:
    """Refuse, before any strike is read, to register ``log`` in memory at
    ``bytes_per_strike`` [bytes] when that is more than is available (a compressed log of a few
    MB can hold 1e8 strikes)."""
    check_memory(f"{log.path}: registering its {log.n_strikes:,} strikes in memory",
                 log.n_strikes * bytes_per_strike, InputError,
                 advice="register it to a cloud file instead (recon ingest), which streams")


def ingest_to_file(log_path, out_path, *, frame: Frame = "body", chunk_rows: int | None = None,
                   progress=None, correction=None) -> dict:
    """Register every strike of a log and stream the cloud to ``out_path`` (.ply, .las, .laz, .h5),
    in bounded memory.

    The output appears only when every block was read, checked and written.

    Returns
    -------
    dict
        ``n_points``, ``frame``, ``output``.
    """
    n_points, _ = _register_and_write(log_path, out_path, frame=frame, chunk_rows=chunk_rows,
                                      progress=progress, keep=False, correction=correction)
    return {"n_points": n_points, "frame": frame, "output": str(Path(out_path))}


def iter_points(log_path, *, frame: Frame = "body", chunk_rows: int | None = None
                ) -> Iterator[np.ndarray]:
    """The registered points of a log, block by block: (b, 3) float64 metres in ``frame``.

    Opens the log on the first block and closes it after the last, so each iteration is a
    fresh pass (``metrics.score.score_stream`` makes one or two). ``chunk_rows``: strikes per
    block (default ``SCORE_CHUNK_ROWS``).
    """
    with StrikeLog(log_path) as log:
        for chunk in log.iter_chunks(chunk_rows or SCORE_CHUNK_ROWS):
            yield register_chunk(chunk, frame=frame)[0]


def ingest_points(log_path, *, frame: Frame = "body", chunk_rows: int | None = None
                  ) -> np.ndarray:
    """The registered points of a log alone, (n, 3) float64 metres in ``frame``.

    For scoring: one preallocated array of 24 bytes a strike, filled block by block, instead of
    the 80 bytes a strike of ``ingest``'s cloud with its attributes and the blocks it joins.
    """
    with StrikeLog(log_path) as log:
        _check_memory(log, 24)
        points = np.empty((log.n_strikes, 3))
        for chunk in (log.iter_chunks() if chunk_rows is None else
                      log.iter_chunks(chunk_rows)):
            points[chunk.start:chunk.start + len(chunk)] = register_chunk(chunk, frame=frame)[0]
    return points


def ingest_following(log_path, out_path, *, frame: Frame = "body", progress=None,
                     poll_s: float = 0.5, timeout_s: float = 60.0) -> dict:
    """Register the strikes of a log while a live writer writes it, then write the cloud.

    Blocks are registered as they arrive (``formats.strike_log.follow``), so the work is done
    when the writer closes; the registered cloud is held in memory until then and written to
    ``out_path`` (.ply, .las, .laz, .h5) only once the log is complete.

    Parameters
    ----------
    log_path : str or Path
        The log's final path (``recon simulate --live -o LOG``).
    out_path : str or Path
    frame : {"body", "inertial"}
    progress : callable, optional
        Called as ``progress(strikes_in_block, strikes_committed_so_far)`` after each block.
    poll_s, timeout_s : float, seconds
        How often to look for new strikes; how long to wait for the writer before giving up.

    Returns
    -------
    dict
        ``n_points``, ``frame``, ``output``.
    """
    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")
    blocks = []
    for chunk, log in follow(log_path, poll_s=poll_s, timeout_s=timeout_s):
        blocks.append(_registered_block(log, chunk, frame=frame))
        if progress:
            progress(len(chunk), log.n_strikes)
    n_points = sum(len(points) for points, _ in blocks)
    with open_cloud_writer(out_path, n_points, ATTRIBUTE_DTYPES, frame=frame,
                           source=Path(log_path).name) as writer:
        for block in blocks:
            writer.write(*block)
    return {"n_points": n_points, "frame": frame, "output": str(Path(out_path))}


def ingest(log_path, *, frame: Frame = "body", output=None, chunk_rows: int | None = None,
           progress=None, correction=None) -> Cloud:
    """Register a whole log in memory and return it as a point cloud with its attributes.

    Parameters
    ----------
    log_path : str or os.PathLike
    frame : {"body", "inertial"}
    output : str or Path, optional
        Also stream the cloud to this file (.ply, .las, .laz, .h5) from the same pass; it
        appears only when every block was written.
    chunk_rows : int, optional
        Strikes per block (default: the reader's block size).
    progress : callable, optional
        Called as ``progress(strikes_in_block, total_strikes)`` after each block.
    correction : recon.registration.refine.PoseCorrection, optional
        Corrections of the recorded poses estimated from the strikes
        (``recon.registration.refine.refine(log).correction``).

    Returns
    -------
    Cloud
        (n, 3) float64 metres in ``frame``; attributes ``time``, ``shot``, ``beam``, ``range``,
        ``azimuth``, ``elevation``, ``view_x/y/z`` and the uncertainty columns
        (``recon.registration.uncertainty.COLUMNS``).
    """
    _, blocks = _register_and_write(log_path, output, frame=frame, chunk_rows=chunk_rows,
                                    progress=progress, keep=True, correction=correction)
    if not blocks:
        return Cloud(np.zeros((0, 3)), {k: np.zeros(0, dtype=v)
                                        for k, v in ATTRIBUTE_DTYPES.items()}, frame=frame)
    points = np.concatenate([b[0] for b in blocks])
    attributes = {k: np.concatenate([b[1][k] for b in blocks]) for k in ATTRIBUTE_DTYPES}
    return Cloud(points, attributes, frame=frame)
