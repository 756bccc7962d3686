"""Scratch directories go with their block, with an interrupted command line (its own and its
killed children's), and, after a crash, with the next run of the same kind."""

from __future__ import annotations

import subprocess
import sys

from formats import scratch


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def test_a_block_removes_its_directory(tmp_path, monkeypatch):
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr("tempfile.tempdir", None)
    with scratch.directory("recon-test-") as path:
        (path / "log.h5").write_bytes(b"x")
        assert path.parent == tmp_path
    assert list(tmp_path.iterdir()) == []


def test_stale_directories_of_dead_processes_go_live_ones_stay(tmp_path, monkeypatch):
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr("tempfile.tempdir", None)
    dead = tmp_path / f"recon-test-{_dead_pid()}-abc_1"
    live = tmp_path / "recon-test-1-abc"   # init never dies
    other = tmp_path / f"recon-other-{_dead_pid()}-abc"   # another kind: not this prefix's
    for path in (dead, live, other):
        path.mkdir()
        (path / "partial.h5").write_bytes(b"x" * 100)
    made = scratch.make("recon-test-")
    assert not dead.exists() and live.exists() and other.exists()
    scratch.remove(made)


def test_an_interrupted_run_removes_its_own_and_its_childrens(tmp_path, monkeypatch):
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr("tempfile.tempdir", None)
    mine = scratch.make("recon-test-")
    child = tmp_path / "recon-study-4242-xyz"
    stranger = tmp_path / "recon-study-4343-xyz"
    child.mkdir()
    stranger.mkdir()
    scratch.remove_owned([4242])
    assert not mine.exists() and not child.exists() and stranger.exists()
