"""What a reader meets in ``recon report``: the summary's data as tables of rounded numbers (no
raw JSON), readable column headers, verdicts by the page's own rule, charts whose alt text is
their title, a stability directory, and no tracker numbers in any user-facing text."""

from __future__ import annotations

import json
import re
from pathlib import Path

from recon.experiments import charts
from recon.experiments.report import header, render
from recon.experiments.stability import finish

ROOT = Path(__file__).resolve().parents[3]


def _chart(path, title):
    plt = charts._pyplot()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    fig.suptitle(title)
    return charts._save(fig, path)


def _study(path, size):
    path.mkdir()
    _chart(path / "score_vs_time.png", "Score against time on the asteroid (τ = 1 %)")
    claim = {"id": "c", "figure": "Fig. 9", "claim": "coverage reaches 95 %", "paper": "-",
             "ours": "0.857 at 12 h", "verdict": "not reproduced", "rule": "95 % reached"}
    (path / "summary.json").write_text(json.dumps({
        "study": "closed-loop", "title": "Closed loop", "size": size, "claims": [claim],
        "files": ["results.csv", "score_vs_time.png"], "n_cases": 1, "n_failed": 0,
        "wall_time_s": 12.0, "case_wall_time_s": 30.123456789,
        "score_options": [{"n_truth_samples": 20000}],
        "table": [{"case": "rso-a gaps", "coverage_12h": 0.857012345678, "hours_to_95%": None}],
        "rule": {"fscore_fraction": 0.95}, "rotations": 4.0000001}))
    (path / "results.csv").write_text("case,wall_time_s,chamfer_m\na,1.23456789,0.5\n")
    return path


def _cells(page):
    return re.sub(r"<[^>]+>", " ", page)


def test_summary_data_is_a_table_of_rounded_numbers(tmp_path):
    page = render(_study(tmp_path / "quick", "quick"))
    assert "<pre" not in page and "&quot;coverage_12h&quot;" not in page
    assert "<td class=num>0.857</td>" in page and "0.857012" not in page
    assert "<td class=num>4</td>" in page               # 4.0000001 to 4 significant digits
    assert ">coverage 12h</th>" in page and ">F-score fraction: 0.95<" not in page
    assert "fscore fraction: 0.95" in page
    # Human headers, the key kept as the header's tooltip.
    assert '<th title="wall_time_s">wall time [s]</th>' in page
    assert '<th title="chamfer_m">Chamfer distance [m]</th>' in page
    assert "<td class=num>1.235</td>" in page


def test_verdicts_follow_the_pages_rule(tmp_path):
    quick = render(_study(tmp_path / "quick", "quick"))
    assert "a claim it does not reproduce, or cannot test, reads 'not tested'" in quick
    assert "<b>not tested</b>" in quick and "<b>not reproduced</b>" not in quick
    assert "reduced run: not reproduced at this size" in quick
    full = render(_study(tmp_path / "full", "full"))
    assert "<b>not reproduced</b>" in full and "<b>not tested</b>" not in full


def test_alt_text_is_the_charts_title_not_its_file_name(tmp_path):
    page = render(_study(tmp_path / "quick", "quick"))
    alts = re.findall(r'<img alt="([^"]*)"', page)
    assert alts == ["Score against time on the asteroid (τ = 1 %)"]


def test_alt_text_without_a_title_names_the_study(tmp_path):
    study = _study(tmp_path / "quick", "quick")
    plt = charts._pyplot()
    fig, _ = plt.subplots()
    fig.savefig(study / "score_vs_time.png")   # a PNG without a title
    plt.close(fig)
    alts = re.findall(r'<img alt="([^"]*)"', render(study))
    assert alts == ["chart of Closed loop: score vs time"]


def test_report_of_a_stability_directory(tmp_path):
    records = []
    for noise in (0.0, 0.3):
        for method, chamfer in (("convex-hull", 0.5), ("plane", None)):
            records.append({"label": method, "method": method, "noise_sigma3_m": noise,
                            "density": 1.0, "outliers": 0.0,
                            "status": "ok" if chamfer else "failed",
                            "failure": None if chamfer else "crash",
                            "reason": None if chamfer else "crashed", "wall_time_s": 0.25,
                            "chamfer_m": chamfer, "fscore": 0.9 if chamfer else None})
    finish(records, tmp_path, noise=(0.0, 0.3), density=(1.0,), outliers=(0.0,))
    page = render(tmp_path)
    assert f"<h1>Stability: {tmp_path.name}</h1>" in page
    assert "<td>plane</td><td>100%</td>" in page and "<td>convex-hull</td><td>0%</td>" in page
    alts = re.findall(r'<img alt="([^"]*)"', page)
    assert len(alts) == 4 and all(a.startswith(("convex-hull:", "plane:")) for a in alts)
    assert '<th title="noise_sigma3_m">range noise, 3 sigma [m]</th>' in page


def test_headers_read_as_words_with_units():
    assert header("wall_time_s") == "wall time [s]"
    assert header("peak_memory_mb") == "peak memory [MB]"
    assert header("requirement_deg") == "requirement [deg]"
    assert header("n_truth_samples") == "number of truth samples"
    assert header("coverage") == "coverage"


def test_no_tracker_numbers_in_user_facing_text():
    pattern = re.compile(r"\b(issue|ticket)s?\s*#?\d+|\bfiled as #\d+", re.IGNORECASE)
    found = []
    for package in ("recon", "cli", "sim", "metrics", "formats"):
        for path in sorted((ROOT / package).rglob("*.py")):
            for number, line in enumerate(path.read_text().splitlines(), 1):
                if pattern.search(line):
                    found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    for path in (ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))):
        if path.name == "decisions.md":   # how it came to be: the tracker belongs there
            continue
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if pattern.search(line):
                found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not found, "\n".join(found)


def test_deeply_nested_summary_data_is_one_line_not_a_traceback(tmp_path):
    study = _study(tmp_path / "quick", "quick")
    summary = json.loads((study / "summary.json").read_text())
    deep = 0.123456
    for _ in range(470):   # 940 levels: Python's parser reads it, a recursive walk may not
        deep = {"a": [deep]}
    summary["nested"] = {"x": {"y": {"z": {"w": {"v": 1.23456}}}}}
    summary["deep"] = deep
    (study / "summary.json").write_text(json.dumps(summary))
    page = render(study)
    assert "(nested too deeply to show; see the file)" in page
    assert "{&quot;v&quot;: 1.235}" in page   # tables three levels down, then compact JSON
