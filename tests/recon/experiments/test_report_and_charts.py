"""The report says its title once and rounds table numbers; every log axis of the charts has
readable tick labels; a chart of runs that all failed is drawn without a warning."""

from __future__ import annotations

import json
import re

import pytest
from matplotlib.colors import LogNorm

from recon.experiments import charts
from recon.experiments.report import render


def _study_dir(path):
    path.mkdir()
    (path / "summary.json").write_text(json.dumps({
        "study": "errors", "title": "Error sources: Table 1", "size": "quick", "claims": [],
        "files": ["table.csv"], "n_cases": 1, "n_failed": 0}))
    (path / "table.csv").write_text("case,chamfer_m,n_points,label\n"
                                    "a,4.613966767999955,15480,x\nb,1e-07,3,2.5e3\n")
    return path


def test_report_title_once_and_numbers_rounded(tmp_path):
    page = render(_study_dir(tmp_path / "errors"))
    headings = re.findall(r"<h\d[^>]*>([^<]*)</h\d>", page)
    assert headings.count("Error sources: Table 1") == 1
    assert "<td class=num>4.614</td>" in page and "4.61396" not in page
    assert "<td class=num>15480</td>" in page  # integers as they are
    assert "<td class=num>1e-07</td>" in page and "<td class=num>2500</td>" in page


def test_compare_report_title_once(tmp_path):
    (tmp_path / "results.json").write_text(json.dumps({"runs": [], "pareto_chamfer": [],
                                                       "pareto_fscore": []}))
    (tmp_path / "results.csv").write_text("label,status,wall_time_s\npoisson,ok,4.613966767\n")
    page = render(tmp_path)
    title = f"Method comparison: {tmp_path.name}"
    assert re.findall(r"<h\d[^>]*>([^<]*)</h\d>", page).count(title) == 1
    assert "<td class=num>4.614</td>" in page


@pytest.mark.parametrize(("lo", "hi"), [(36.1, 36.9), (1.2, 1.5), (0.05, 0.3), (3.0, 20.0),
                                        (0.01, 500.0)])
def test_log_axes_have_readable_ticks(lo, hi):
    plt = charts._pyplot()
    fig, ax = plt.subplots()
    ax.plot([lo, hi], [lo, hi])
    ax.set_yscale("log")
    charts._plain_log_ticks(ax.yaxis)
    image = ax.imshow([[lo, hi]], norm=LogNorm(lo, hi), extent=(lo, hi, lo, hi))
    bar = fig.colorbar(image, ax=ax)
    charts._plain_log_ticks(bar.ax.yaxis)
    fig.canvas.draw()
    for axis in (ax.yaxis, bar.ax.yaxis):
        low, high = sorted(axis.get_view_interval())
        labels = [t.get_text() for t in axis.get_ticklabels()
                  if low <= t.get_position()[1] <= high and t.get_text()]
        assert len(labels) >= 2, (lo, hi, labels)
        assert all("10^" not in s and "times" not in s and "$" not in s for s in labels)
        assert all(float(s) > 0 for s in labels)
    plt.close(fig)


def test_speed_accuracy_of_failed_runs_draws_without_warning(tmp_path):
    records = [{"method": m, "label": m, "status": "failed", "failure": "crash",
                "wall_time_s": 1.0} for m in ("poisson", "alpha-shape")]
    path = charts.speed_accuracy(records, tmp_path / "sa.png")  # filterwarnings=error
    assert path.stat().st_size > 0
