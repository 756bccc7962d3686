"""A sweep's bar moves while a case runs: the case's reported steps show as fractions of a case,
on a pseudo-terminal of 0 x 0 too (where tqdm alone draws nothing)."""

from __future__ import annotations

import itertools
import re
import sys
import time

import pytest

from recon.experiments import progress
from tests.conftest import python_on_zero_size_pty

# One case of five steps, each reported; the sweep's bar redraws every 0.2 s.
SWEEP = """
import sys, tempfile, time
import cli.main
cli.main.size_progress_bars()
from recon.experiments import progress
from recon.experiments.sweep import run_sweep

def case(n):
    for i in range(n):
        time.sleep(0.6)
        progress.step(i + 1, n)
    return {"status": "ok"}

progress.REFRESH_S = 0.2
run_sweep(case, {"a": {"n": 5}}, tempfile.mkdtemp(), scheduler=sys.argv[1], desc="cases")
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux pseudo-terminals")
@pytest.mark.parametrize("scheduler", ["serial", "threads"])
def test_the_bar_moves_within_a_case_on_a_zero_size_terminal(scheduler):
    drawn = python_on_zero_size_pty(SWEEP, scheduler)
    within = set(re.findall(r"cases: +\d+%\|[^|]*\| (0\.\d)/1 runs", drawn))
    assert len(within - {"0.0"}) >= 2, drawn   # at least two steps seen before the end


class _Bar:
    """What ``Watcher`` uses of a tqdm bar, recording what it showed."""

    disable = False
    total = 3

    def __init__(self):
        self.n, self.shown = 0, []

    def refresh(self):
        self.shown.append(self.n)


def test_watcher_counts_finished_cases_and_running_fractions(tmp_path, monkeypatch):
    monkeypatch.setattr(progress, "REFRESH_S", 0.05)
    bar = _Bar()
    with progress.Watcher(bar, tmp_path, finished=1) as watcher:
        with progress.reporting(tmp_path, "b"):
            progress.step(1, 4)
        with progress.reporting(tmp_path, "c"):
            progress.within(0.5, 1.0)(1, 2)     # half of the second half
        time.sleep(0.3)
        assert bar.n == pytest.approx(1 + 0.25 + 0.75)
        watcher.done("b")
        assert bar.n == pytest.approx(2 + 0.75)
    assert sorted(p.name for p in tmp_path.iterdir()) == [progress._file(tmp_path, "c").name]
    progress.step(1, 2)   # outside ``reporting``: goes nowhere, no error
    assert len(list(tmp_path.iterdir())) == 1


# ``study all`` over two (stand-in) studies: the overall bar counts them, naming the current one.
ALL = """
import sys, tempfile, time
import cli.main
cli.main.size_progress_bars()
from recon.experiments import studies

def fake(name, out_dir, **options):
    time.sleep(0.3)
    return {"title": name, "wall_time_s": 0.3, "n_cases": 1, "n_failed": 0, "claims": []}

studies.run = fake
studies.run_all(tempfile.mkdtemp(), size="tiny", scheduler="serial", only=["duration", "slew"])
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux pseudo-terminals")
def test_study_all_has_an_overall_bar():
    drawn = python_on_zero_size_pty(ALL)
    assert re.search(r"studies: +50%\|[^|]*\| 1/2 .*slew", drawn), drawn
    assert re.search(r"studies: +100%\|[^|]*\| 2/2", drawn), drawn


def test_simulate_reports_its_shot_blocks_to_a_callable(tmp_path):
    import sim

    scene = sim.load_scene("asteroid-lrf", ["time.duration=200", "target.subdivisions=2"])
    calls = []
    sim.simulate(scene, tmp_path / "run.h5", seed=0, progress=lambda done, total:
                 calls.append((done, total)))
    assert calls and calls[-1] == (scene.n_shots, scene.n_shots)
    assert all(b[0] > a[0] for a, b in itertools.pairwise(calls))
