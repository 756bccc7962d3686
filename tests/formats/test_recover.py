"""``recon recover``: a live writer killed with SIGKILL leaves a file whose committed rows become a
complete, valid log; nothing else is kept and nothing is invented."""

from __future__ import annotations

import hashlib
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from formats import StrikeLog, StrikeLogWriter
from formats.atomic import LIVE_SUFFIX
from formats.errors import InputError
from formats.strike_log import SensorInfo, TruthStrikes, angles_to_directions, follow
from formats.strike_log.recover import find_partial, recover
from tests.conftest import icosphere

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="SWMR needs POSIX semantics")

BLOCKS, SHOTS, BEAMS = 6, 40, 3


def _sensor() -> SensorInfo:
    beams = angles_to_directions(np.array([0.0, 0.1, -0.1]), np.zeros(3))
    return SensorInfo("zigzag", beams, range_min=1.0, range_max=5000.0,
                      field_of_view=(-.1, .1, 0.0, 0.0))


def _block(k: int, truth: bool):
    """Shots and strikes of block ``k``, every value a function of its row."""
    shot = np.arange(k * SHOTS, (k + 1) * SHOTS)
    t = 10.0 * (shot + 1)
    position = np.stack([t, -t, t + 1], axis=1)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (SHOTS, 1))
    strike_shot = np.repeat(shot, BEAMS)
    beam = np.tile(np.arange(BEAMS), SHOTS)
    rng = 100.0 + strike_shot + beam / 10.0
    shots_truth = strikes_truth = None
    if truth:
        from formats import Shots
        shots_truth = Shots(t, position, q, q)
        strikes_truth = TruthStrikes(point=np.stack([rng, rng, rng], 1),
                                     facet=np.zeros(len(rng), dtype=np.int64), range=rng)
    return (t, position, q, q), shots_truth, (strike_shot, beam, rng), strikes_truth


def _write_and_die(path: str, blocks: int, truth: bool, hang: bool) -> None:
    """A live writer that commits ``blocks`` blocks, then dies by SIGKILL (or, ``hang``, waits
    to be killed) without closing."""
    mesh = icosphere(10.0, 1) if truth else None
    writer = StrikeLogWriter(path, sensor=_sensor(), target="test", live=True, truth_mesh=mesh)
    for k in range(blocks):
        shots, shots_truth, strikes, strikes_truth = _block(k, truth)
        writer.write_shots(*shots, truth=shots_truth)
        writer.write_strikes(*strikes, truth=strikes_truth)
    if hang:
        print("committed", flush=True)
        signal.pause()
    os.kill(os.getpid(), signal.SIGKILL)


def _crash(path: Path, blocks: int = BLOCKS - 2, truth: bool = False) -> Path:
    """Run a writer of ``path`` in a fresh interpreter until SIGKILL; its temporary file."""
    process = multiprocessing.get_context("spawn").Process(
        target=_write_and_die, args=(str(path), blocks, truth, False))
    process.start()
    process.join(120)
    assert process.exitcode == -signal.SIGKILL
    partial = list(path.parent.glob(f".{path.name}.partial-*{LIVE_SUFFIX}"))
    assert len(partial) == 1 and not path.exists()
    return partial[0]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.parametrize("truth", [False, True])
def test_a_killed_writer_s_committed_rows_become_a_valid_log(tmp_path, truth):
    log_path = tmp_path / "run.h5"
    partial = _crash(log_path, truth=truth)
    before = _digest(partial)
    recovery = recover(partial, log_path)
    assert _digest(partial) == before            # the input is left as it was
    n = BLOCKS - 2
    assert (recovery.n_shots, recovery.n_strikes) == (n * SHOTS, n * SHOTS * BEAMS)
    assert not recovery.closing and recovery.time_end_s == 10.0 * n * SHOTS
    with StrikeLog(log_path) as log:
        log.validate()
        assert (log.n_shots, log.n_strikes, log.has_truth) == (n * SHOTS, n * SHOTS * BEAMS,
                                                                truth)
        blocks = [_block(k, truth) for k in range(n)]
        shots = log.shots()
        np.testing.assert_array_equal(shots.time, np.concatenate([b[0][0] for b in blocks]))
        np.testing.assert_array_equal(shots.sensor_position,
                                      np.concatenate([b[0][1] for b in blocks]))
        _, beam, rng = log.strikes()
        np.testing.assert_array_equal(rng, np.concatenate([b[2][2] for b in blocks]))
        np.testing.assert_array_equal(beam, np.concatenate([b[2][1] for b in blocks]))
        if truth:
            np.testing.assert_array_equal(log.truth_strikes().range, rng)
            assert len(log.truth_mesh().faces) == len(icosphere(10.0, 1)[1])


def test_recover_by_the_log_s_name_and_a_new_writer_keeps_the_file(tmp_path):
    log_path = tmp_path / "run.h5"
    partial = _crash(log_path)
    # A new writer of the same log removes dead writers' files, but not a live writer's.
    with StrikeLogWriter(tmp_path / "run.h5", sensor=_sensor(), target="again") as w:
        shots, _, strikes, _ = _block(0, False)
        w.write_shots(*shots)
        w.write_strikes(*strikes)
    assert partial.exists()
    assert find_partial(log_path) == partial
    out = tmp_path / "recovered.h5"
    done = subprocess.run([sys.executable, "-m", "cli", "recover", str(log_path), "-o", str(out)],
                          capture_output=True, text=True, cwd=Path(__file__).parents[2])
    assert done.returncode == 0, done.stderr
    assert "recovered 160 shots and 480 strikes" in done.stdout
    assert "lost: every shot after the last commit" in done.stdout
    with StrikeLog(out) as log:
        assert log.n_strikes == (BLOCKS - 2) * SHOTS * BEAMS


def test_a_running_writer_s_file_is_refused(tmp_path):
    log_path = tmp_path / "run.h5"
    process = multiprocessing.get_context("spawn").Process(
        target=_write_and_die, args=(str(log_path), 2, False, True))
    process.start()
    try:
        partial = None
        while partial is None and process.is_alive():
            found = list(tmp_path.glob(f".run.h5.partial-{process.pid}-*"))
            partial = found[0] if found else None
            time.sleep(0.05)
        with pytest.raises(InputError, match=rf"process {process.pid}\) is still running"):
            recover(partial, tmp_path / "out.h5")
    finally:
        process.kill()
        process.join()


@pytest.mark.parametrize("case", ["no file beside", "not live", "itself"])
def test_what_cannot_be_recovered_is_one_line(tmp_path, case):
    log_path = tmp_path / "run.h5"
    if case == "no file beside":
        args, match = (log_path, tmp_path / "out.h5"), "no live writer's file beside it"
    elif case == "not live":   # an ordinary complete log renamed to look like a live file
        fake = tmp_path / f".run.h5.partial-999999999-x{LIVE_SUFFIX}"
        with StrikeLogWriter(fake.with_name("done.h5"), sensor=_sensor(), target="t") as w:
            w.write_shots(*_block(0, False)[0])
        fake.with_name("done.h5").rename(fake)
        args, match = (fake, tmp_path / "out.h5"), "not a live log"
    else:
        partial = _crash(log_path, blocks=1)
        args, match = (partial, partial), "is the partial log itself"
    with pytest.raises(InputError, match=match):
        recover(*args)
    assert not (tmp_path / "out.h5").exists()


def test_follow_says_the_writer_died_and_how_to_recover(tmp_path):
    log_path = tmp_path / "run.h5"
    _crash(log_path)
    seen = 0
    with pytest.raises(InputError, match=r"died after 160 shots and 480 strikes; `recon "
                                             r"recover"):
        for chunk, _ in follow(log_path, poll_s=0.05, timeout_s=600):
            seen += len(chunk)
    assert seen == 480
