"""Live logs: a writer in HDF5 SWMR mode and ``follow`` reading it from another process."""

from __future__ import annotations

import multiprocessing
import sys
import time

import h5py
import numpy as np
import pytest

from formats import StrikeLog, StrikeLogWriter
from formats.errors import InputError
from formats.strike_log import LIVE_COMMITTED, SensorInfo, angles_to_directions, follow

N_BLOCKS, SHOTS_PER_BLOCK, BEAMS = 40, 50, 3


def _sensor():
    beams = angles_to_directions(np.array([0.0, 0.1, -0.1]), np.zeros(3))
    return SensorInfo("zigzag", beams, range_min=1.0, range_max=5000.0,
                      field_of_view=(-.1, .1, 0.0, 0.0))


def _block(k: int):
    """Shots and strikes of block ``k``; every value is a function of its row, so a reader can
    tell a half-written row (HDF5 fills unwritten rows with zeros) from a written one."""
    shot = np.arange(k * SHOTS_PER_BLOCK, (k + 1) * SHOTS_PER_BLOCK)
    time_s = 10.0 * (shot + 1)
    position = np.stack([time_s, -time_s, time_s + 1], axis=1)
    quaternion = np.tile([0.0, 0.0, 0.0, 1.0], (len(shot), 1))
    strike_shot = np.repeat(shot, BEAMS)
    beam = np.tile(np.arange(BEAMS), len(shot))
    strike_range = 100.0 + strike_shot + beam / 10.0
    return (time_s, position, quaternion, quaternion), (strike_shot, beam, strike_range)


def _write(path, pause_s: float, abort: bool = False) -> None:
    """The writer process: N_BLOCKS blocks, ``pause_s`` apart; ``abort``: stop half-way."""
    writer = StrikeLogWriter(path, sensor=_sensor(), target="test", live=True)
    for k in range(N_BLOCKS):
        shots, strikes = _block(k)
        writer.write_shots(*shots)
        writer.write_strikes(*strikes)
        time.sleep(pause_s)
        if abort and k == N_BLOCKS // 2:
            writer.abort()
            return
    writer.close()


def _start(path, pause_s, abort=False):
    # spawn: a fresh interpreter, as a separate simulator would be (no inherited HDF5 state).
    context = multiprocessing.get_context("spawn")
    process = context.Process(target=_write, args=(path, pause_s, abort))
    process.start()
    return process


@pytest.mark.skipif(sys.platform == "win32", reason="SWMR needs POSIX file semantics")
def test_follow_reads_every_row_while_it_is_written_and_never_a_half_written_one(tmp_path):
    path = tmp_path / "live.h5"
    process = _start(path, pause_s=0.02)
    seen_live = 0        # blocks read before the log was complete
    strikes, shots_seen = [], set()
    try:
        for chunk, log in follow(path, chunk_rows=64, poll_s=0.002, timeout_s=60):
            if not path.exists():
                seen_live += 1
            # Every strike row and the shot row it refers to hold what the writer wrote.
            row = chunk.shot - chunk.shot_offset
            np.testing.assert_array_equal(chunk.range, 100.0 + chunk.shot + chunk.beam / 10.0)
            np.testing.assert_array_equal(chunk.shots.time[row], 10.0 * (chunk.shot + 1))
            np.testing.assert_array_equal(chunk.shots.sensor_position[row][:, 1],
                                          -10.0 * (chunk.shot + 1))
            assert chunk.start == len(strikes) and log.n_strikes >= chunk.start + len(chunk)
            strikes.extend(chunk.range)
            shots_seen.update(chunk.shot.tolist())
    finally:
        process.join(60)
    assert process.exitcode == 0
    assert len(strikes) == N_BLOCKS * SHOTS_PER_BLOCK * BEAMS
    assert shots_seen == set(range(N_BLOCKS * SHOTS_PER_BLOCK))
    assert seen_live >= 2, "the reader did not read while the writer was writing"
    with StrikeLog(path) as log:   # the finished log is complete and valid
        log.validate()
        assert log.n_strikes == len(strikes)
        np.testing.assert_array_equal(log.strikes()[2], strikes)


def test_follow_reports_a_writer_that_stops_before_completing(tmp_path):
    path = tmp_path / "aborted.h5"
    process = _start(path, pause_s=0.01, abort=True)
    try:
        with pytest.raises(InputError, match="stopped before completing"):
            for _ in follow(path, poll_s=0.002, timeout_s=60):
                pass
    finally:
        process.join(60)
    assert not path.exists()


def test_follow_reads_a_complete_log_whole_and_waits_only_so_long(tmp_path):
    path = tmp_path / "done.h5"
    _write(path, pause_s=0.0)
    with StrikeLog(path) as log:       # a live log, once closed, is an ordinary complete log
        assert log.n_shots == N_BLOCKS * SHOTS_PER_BLOCK
        log.validate()
    with h5py.File(path) as f:
        np.testing.assert_array_equal(f[LIVE_COMMITTED][()],
                                      [N_BLOCKS * SHOTS_PER_BLOCK,
                                       N_BLOCKS * SHOTS_PER_BLOCK * BEAMS, 1])
    total = sum(len(chunk) for chunk, _ in follow(path, timeout_s=5))
    assert total == N_BLOCKS * SHOTS_PER_BLOCK * BEAMS
    with pytest.raises(InputError, match=r"no log and no writer at work after 0\.05 s"):
        next(follow(tmp_path / "never.h5", poll_s=0.01, timeout_s=0.05))


@pytest.mark.parametrize("committed", [np.array([40, 80, 0], dtype=np.float64),
                                       np.array([40, 80], dtype=np.int64)])
def test_live_counts_of_another_dtype_or_shape_are_refused(tmp_path, committed):
    from formats.strike_log import LiveStrikeLog
    from tests.conftest import write_sphere_log

    path = tmp_path / "live.h5"
    write_sphere_log(path)
    with h5py.File(path, "r+", libver="latest") as f:
        f[LIVE_COMMITTED] = committed
    with pytest.raises(InputError, match=rf"^{path}: /{LIVE_COMMITTED} must be a dataset of 3 "
                                         r"int64 values$"):
        LiveStrikeLog(path)
