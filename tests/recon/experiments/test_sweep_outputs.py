"""A sweep's outputs: a damaged ``results.jsonl`` or ``sweep.json`` on ``--resume``, an output
that is a directory, a read-only parent, a full disk while a chart is written: each is one line,
before the work where it can be, and never a half-written file over the previous one."""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from formats.errors import ParameterError, ResourceError
from recon.experiments import charts
from recon.experiments.sweep import read_results, run_sweep
from tests.recon.experiments.test_sweep import _cases, _ran, square

REPO = Path(__file__).resolve().parents[3]


def _first_run(tmp_path):
    calls = str(tmp_path / "calls")
    run_sweep(square, _cases(3), tmp_path / "out", shared={"calls": calls}, scheduler="serial")
    return calls


def test_resume_of_a_results_file_that_is_not_utf8_is_one_line(tmp_path):
    calls = _first_run(tmp_path)
    results = tmp_path / "out" / "results.jsonl"
    results.write_bytes(b"\xff\xfe garbage\n" + results.read_bytes())
    with pytest.raises(ParameterError, match=r"^resume: .*results.jsonl: line 1 is not UTF-8"):
        run_sweep(square, _cases(3), tmp_path / "out", shared={"calls": calls},
                  scheduler="serial", resume=True)


def test_a_torn_last_line_inside_a_character_is_dropped(tmp_path):
    _first_run(tmp_path)
    results = tmp_path / "out" / "results.jsonl"
    results.write_bytes(results.read_bytes() + b'{"key": "\xc3')
    assert sorted(read_results(results)) == ["x=0", "x=1", "x=2"]


@pytest.mark.parametrize("damage", [b"\xff\xfe", b"[1, 2]", b"{not json"])
def test_resume_of_a_damaged_fingerprint_is_one_line(tmp_path, damage):
    calls = _first_run(tmp_path)
    (tmp_path / "out" / "sweep.json").write_bytes(damage)
    with pytest.raises(ParameterError, match=r"^resume: .*sweep.json is damaged"):
        run_sweep(square, _cases(3), tmp_path / "out", shared={"calls": calls},
                  scheduler="serial", resume=True)


@pytest.mark.parametrize("name", ["results.jsonl", "sweep.json", "results.csv"])
def test_an_output_that_is_a_directory_is_refused_before_any_work(tmp_path, name):
    calls = str(tmp_path / "calls")
    (tmp_path / "out" / name).mkdir(parents=True)
    with pytest.raises(ParameterError, match=rf"{name}: is a directory"):
        run_sweep(square, _cases(2), tmp_path / "out", shared={"calls": calls},
                  scheduler="serial", outputs=("results.csv",))
    assert _ran(calls) == []


def test_a_full_disk_while_a_chart_is_written_keeps_the_old_chart(tmp_path, monkeypatch):
    chart = tmp_path / "speed_accuracy.png"
    records = [{"method": "poisson", "label": "poisson", "status": "ok", "wall_time_s": 1.0,
                "chamfer_m": 0.1, "fscore": 0.9}]
    charts.speed_accuracy(records, chart)
    before = chart.read_bytes()

    def half_then_full(self, path, **options):
        Path(path).write_bytes(before[: len(before) // 2])
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr("matplotlib.figure.Figure.savefig", half_then_full)
    with pytest.raises(ResourceError, match=r"speed_accuracy\.png: no space left"):
        charts.speed_accuracy(records, chart)
    assert chart.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["speed_accuracy.png"]


@pytest.mark.skipif(shutil.which("setpriv") is None or os.geteuid() != 0,
                    reason="needs root and setpriv to run recon as an unprivileged user")
def test_compare_into_a_read_only_parent_is_one_line():
    """Run as ``nobody`` (root writes anywhere): the parent of ``-o`` is not writable."""
    with tempfile.TemporaryDirectory(prefix="recon-test-ro-") as tmp:
        parent = Path(tmp) / "ro"
        parent.mkdir()
        os.chmod(tmp, 0o755)
        os.chmod(parent, 0o555)
        done = subprocess.run(["setpriv", "--reuid=nobody", "--regid=nogroup", "--clear-groups",
                               sys.executable, "-m", "cli", "compare", "in.ply", "--truth",
                               "t.ply", "-o", str(parent / "out")], cwd=tmp,
                              capture_output=True, text=True, timeout=300,
                              env=dict(os.environ, PYTHONPATH=str(REPO), HOME=tmp))
    assert done.returncode == 1, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "cannot create the directory (Permission denied)" in lines[0]
