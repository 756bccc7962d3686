"""Whole files written by a callback (summaries, charts) keep the writers' guarantees."""

from __future__ import annotations

import os

import pytest

from formats import interrupt
from formats.atomic import write_atomically, write_text_atomically
from formats.errors import ReconError


class _Refused(ReconError):
    pass


def _partials(directory):
    return [p.name for p in directory.iterdir() if ".partial" in p.name]


def test_writes_the_file_with_the_users_umask(tmp_path):
    old = os.umask(0o027)
    try:
        path = write_text_atomically(tmp_path / "summary.json", "{}\n")
    finally:
        os.umask(old)
    assert path.read_text() == "{}\n"
    assert path.stat().st_mode & 0o777 == 0o640
    assert _partials(tmp_path) == []


def test_the_temporary_keeps_the_suffix(tmp_path):
    seen = []
    write_atomically(tmp_path / "chart.png", lambda tmp: (seen.append(tmp), tmp.write_bytes(b"x")))
    assert seen[0].suffix == ".png" and seen[0].parent == tmp_path


def test_a_failing_write_leaves_the_old_file_and_no_partial(tmp_path):
    path = tmp_path / "summary.json"
    path.write_text("old")

    def fail(tmp):
        tmp.write_text("half")
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError):
        write_atomically(path, fail)
    assert path.read_text() == "old" and _partials(tmp_path) == []


def test_a_signal_before_the_rename_keeps_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "summary.json"
    path.write_text("old")
    monkeypatch.setattr(interrupt, "_received", [2])   # a SIGINT whose exception was swallowed
    with pytest.raises(interrupt.Interrupted):
        write_text_atomically(path, "new")
    assert path.read_text() == "old" and _partials(tmp_path) == []


def test_a_directory_is_refused_with_the_given_error(tmp_path):
    (tmp_path / "out.json").mkdir()
    with pytest.raises(_Refused, match=r"out\.json: is a directory"):
        write_text_atomically(tmp_path / "out.json", "x", error=_Refused)
    with pytest.raises(_Refused, match="does not exist"):
        write_text_atomically(tmp_path / "missing" / "out.json", "x", error=_Refused)
