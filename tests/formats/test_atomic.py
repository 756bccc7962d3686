"""Whole files written by a callback (summaries, charts) keep the writers' guarantees."""

from __future__ import annotations

import os

import pytest

from formats import interrupt
from formats.atomic import write_atomically, write_text_atomically, written_together
from formats.errors import ReconError
from formats.paths import writing_into


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


def _old_set(directory):
    directory.mkdir(exist_ok=True)
    for name in ("a.ply", "b.png", "c.json"):
        (directory / name).write_text("old " + name)
    return [directory / name for name in ("a.ply", "b.png", "c.json")]


def test_a_set_is_published_together(tmp_path):
    paths = _old_set(tmp_path)
    with written_together(paths) as temporaries:
        assert [t.suffix for t in temporaries] == [".ply", ".png", ".json"]
        for temporary in temporaries:
            temporary.write_text("new")
        assert all(p.read_text().startswith("old") for p in paths)   # not before the end
    assert [p.read_text() for p in paths] == ["new"] * 3 and _partials(tmp_path) == []


def test_a_set_that_fails_part_way_keeps_the_whole_old_set(tmp_path, monkeypatch):
    paths = _old_set(tmp_path)
    with pytest.raises(RuntimeError), written_together(paths) as temporaries:
        temporaries[0].write_text("new")
        raise RuntimeError("the chart failed")
    monkeypatch.setattr(interrupt, "_received", [2])   # a SIGINT whose exception was swallowed
    with pytest.raises(interrupt.Interrupted), written_together(paths) as temporaries:
        for temporary in temporaries:
            temporary.write_text("new")
    assert [p.read_text() for p in paths] == [f"old {p.name}" for p in paths]
    assert _partials(tmp_path) == []


def test_every_destination_of_a_set_is_checked_before_the_work(tmp_path):
    paths = _old_set(tmp_path)
    paths[1].unlink()
    paths[1].mkdir()
    ran = []
    with pytest.raises(_Refused, match=r"b\.png: is a directory"), \
            written_together(paths, error=_Refused):
        ran.append(True)
    assert ran == [] and paths[0].read_text() == "old a.ply" and _partials(tmp_path) == []


def test_an_output_directory_made_for_a_failed_run_is_removed(tmp_path):
    with pytest.raises(_Refused), writing_into(tmp_path / "new" / "deep", _Refused):
        assert (tmp_path / "new" / "deep").is_dir()
        raise _Refused("k must be an integer >= 4, got 0")
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "kept").mkdir()   # a directory that was there stays, empty or not
    with pytest.raises(_Refused), writing_into(tmp_path / "kept" / "new", _Refused):
        raise _Refused("bad")
    assert list(tmp_path.iterdir()) == [tmp_path / "kept"] and not any(
        (tmp_path / "kept").iterdir())
    with writing_into(tmp_path / "kept" / "new", _Refused) as out:
        (out / "x.json").write_text("{}")
    assert (tmp_path / "kept" / "new" / "x.json").exists()
