"""``recon ingest --refine``: the estimated time said before a long refinement starts, one
estimated beyond the limit refused naming --refine-interval, and a bar that moves through both
stages of the fit."""

from __future__ import annotations

import re
import sys

import pytest

import sim
from cli.main import main
from recon.registration import refine as refine_module
from recon.registration.refine import refine
from tests.conftest import python_on_zero_size_pty

# Four of the paper's 15,480 s rotations of its asteroid under the single-beam LRF: 6,192
# strikes, refined in seconds (3,096 fitted); an interval of two rotations makes 3 knots.
SHORT = ["time.duration=61920", "target.subdivisions=4", "errors.range_sigma3=0.3"]
INTERVAL = "30960"


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    path = tmp_path_factory.mktemp("refine-cli") / "short.h5"
    sim.simulate(sim.load_scene("asteroid-lrf", SHORT), path, seed=0, progress=False)
    return path


def test_a_long_refinement_is_announced_before_it_starts(log, tmp_path, monkeypatch, capsys):
    out = tmp_path / "c.ply"
    args = ["ingest", str(log), "-o", str(out), "--refine", "--refine-interval", INTERVAL]
    assert main(args) == 0
    assert "refining" not in capsys.readouterr().out    # seconds: nothing said
    monkeypatch.setattr(refine_module, "ANNOUNCE_S", 0.0)
    assert main(args) == 0
    printed = capsys.readouterr().out.splitlines()
    assert re.fullmatch(r"refining 3 knots over 61,910 s: about \d+ s",
                        printed[0]), printed
    assert printed[1].startswith("pass agreement")


def test_a_refinement_beyond_the_limit_is_refused_naming_the_interval(log, tmp_path,
                                                                      monkeypatch, capsys):
    """With a limit between the estimates of 2 and 3 knots, the 3 knots asked for are refused
    in one line that names --refine-interval and the shortest interval of 2 knots; nothing is
    written."""
    n_fit = 3096
    monkeypatch.setattr(refine_module, "MAX_REFINE_S",
                        0.5 * (refine_module.refine_seconds(n_fit, 2)
                               + refine_module.refine_seconds(n_fit, 3)))
    out, estimates = tmp_path / "c.ply", tmp_path / "r.json"
    assert main(["ingest", str(log), "-o", str(out), "--refine", "--refine-interval", INTERVAL,
                 "--refine-json", str(estimates)]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert re.fullmatch(r"recon ingest: error: --refine-interval 30960 s makes 3 knots over "
                        r"the log's 61910 s; refining them with 3,096 sampled strikes would "
                        r"take about \d+ s, more than the \d+ s a refinement may take \(at most "
                        r"2 knots\); give at least 61910 s", err), err
    assert not out.exists() and not estimates.exists()
    assert main(["ingest", str(log), "-o", str(out), "--refine", "--refine-interval",
                 "61910"]) == 0


def test_progress_counts_both_stages_up_to_the_estimate(log):
    reports = []
    refine(log, interval=float(INTERVAL), progress=lambda done, total: reports.append(
        (done, total)))
    total = refine_module.refine_seconds(3096, 3)
    assert {t for _, t in reports} == {total}
    done = [d for d, _ in reports]
    assert done == sorted(done) and done[-1] == total
    # 25 coarse starts of up to 6 steps each, then up to 15 fine steps: every one reported.
    coarse = 25 * 6 * refine_module.step_seconds(310, 3)
    assert sum(d < coarse * (1 - 1e-9) for d in done) >= 25
    assert len(reports) > 25 + 1


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux pseudo-terminals")
def test_the_bar_moves_on_a_terminal(log, tmp_path):
    drawn = python_on_zero_size_pty(
        "import sys; from cli.main import main; sys.exit(main(sys.argv[1:]))",
        "ingest", str(log), "-o", str(tmp_path / "c.ply"), "--refine", "--refine-interval",
        INTERVAL)
    shown = set(re.findall(r"refine: +(\d+)%", drawn))
    assert len(shown) >= 3, drawn
