"""``recon report DIR`` reads only inside DIR, and a damaged directory is one line naming the
file and what is wrong (exit 1), never a traceback or a page with another file in it."""

from __future__ import annotations

import json
import os

import pytest

from cli.main import main
from formats.errors import InputError
from recon.experiments.report import render

SECRET = "top-secret-line-outside-the-study"
PNG = b"\x89PNG\r\n\x1a\n" + bytes(32)


@pytest.fixture
def outside(tmp_path):
    """A CSV and a PNG beside the study directory, which the report must never read."""
    (tmp_path / "secret.csv").write_text(f"a,b\n{SECRET},1\n")
    (tmp_path / "secret.png").write_bytes(PNG)
    return tmp_path


def _study(directory, **summary):
    directory.mkdir(exist_ok=True)
    base = {"study": "errors", "title": "Errors", "size": "quick", "claims": [],
            "files": ["table.csv"], "n_cases": 1, "n_failed": 0}
    (directory / "summary.json").write_text(json.dumps(base | summary))
    (directory / "table.csv").write_text("case,value\na,1\n")
    return directory


def _report(directory, tmp_path, capsys) -> str:
    """Run ``recon report``; require exit 1, one error line, no page; return the line."""
    page = tmp_path / "page.html"
    assert main(["report", str(directory), "-o", str(page)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("recon report: error: "), err
    assert not page.exists()
    return err[0]


@pytest.mark.parametrize("listed", ["../secret.csv", "../secret.png", "sub/../../secret.csv",
                                    "ABSOLUTE.csv", "ABSOLUTE.png"])
def test_a_listed_file_outside_the_directory_is_refused(outside, tmp_path, capsys, listed):
    listed = listed.replace("ABSOLUTE", str(outside / "secret"))
    study = _study(tmp_path / "study", files=["table.csv", listed])
    line = _report(study, tmp_path, capsys)
    assert "summary.json" in line and "outside" in line and SECRET not in line


@pytest.mark.parametrize("name", ["linked.csv", "linked.png"])
def test_a_symbolic_link_leaving_the_directory_is_refused(outside, tmp_path, capsys, name):
    study = _study(tmp_path / "study", files=["table.csv", name])
    os.symlink(outside / f"secret{os.path.splitext(name)[1]}", study / name)
    line = _report(study, tmp_path, capsys)
    assert name in line and "outside" in line


def test_a_chart_linked_from_outside_is_refused_even_unlisted(outside, tmp_path, capsys):
    study = _study(tmp_path / "study")
    os.symlink(outside / "secret.png", study / "chart.png")
    assert "chart.png" in _report(study, tmp_path, capsys)


def test_a_study_directory_linked_from_outside_is_refused(tmp_path, capsys):
    elsewhere = _study(tmp_path / "elsewhere")
    top = tmp_path / "all"
    top.mkdir()
    _study(top / "errors")
    os.symlink(elsewhere, top / "slew")
    assert "slew" in _report(top, tmp_path, capsys)


def test_files_inside_the_directory_are_shown(tmp_path):
    study = _study(tmp_path / "study", files=["table.csv", "sub/chart.png"])
    (study / "sub").mkdir()
    (study / "sub" / "chart.png").write_bytes(PNG)
    os.symlink("table.csv", study / "same.csv")   # a link that stays inside is fine
    page = render(study)
    assert "<td>a</td>" in page and "data:image/png;base64," in page


DAMAGE = {
    "summary is a list": ("summary.json", b"[1, 2]", "holds a JSON list, not an object"),
    "summary not JSON": ("summary.json", b"{oops", "not valid JSON"),
    "summary not UTF-8": ("summary.json", b'{"title": "\xff\xfe"}', "not UTF-8"),
    "files a string": ("summary.json", json.dumps({"files": "table.csv"}).encode(),
                       "'files' must be a list"),
    "files of numbers": ("summary.json", json.dumps({"files": [1, 2]}).encode(),
                         "every item of 'files' must be a string"),
    "claims a dict": ("summary.json", json.dumps({"claims": {"a": 1}}).encode(),
                      "'claims' must be a list"),
    "claims of strings": ("summary.json", json.dumps({"claims": ["x"]}).encode(),
                          "every item of 'claims' must be an object"),
    "failures of numbers": ("summary.json", json.dumps({"failures": [3]}).encode(),
                            "every item of 'failures' must be an object"),
    "binary CSV": ("table.csv", b"a,b\n\x00\x01\x02,\x00\n", "not a readable CSV table"),
    "huge CSV field": ("table.csv", b"a,b\n" + b'"' + b"x" * 200_000 + b'",1\n',
                       "not a readable CSV table"),
    "CSV not UTF-8": ("table.csv", b"a,b\n\xff,1\n", "not UTF-8"),
    "chart not a PNG": ("chart.png", b"GIF89a" + bytes(20), "not a PNG"),
}


@pytest.mark.parametrize("damage", sorted(DAMAGE))
def test_a_damaged_study_directory_is_one_line(tmp_path, capsys, damage):
    name, data, message = DAMAGE[damage]
    study = _study(tmp_path / "study")
    (study / name).write_bytes(data)
    line = _report(study, tmp_path, capsys)
    assert name in line and message in line


@pytest.mark.parametrize("results, message", [
    (b"[]", "holds a JSON list"),
    (json.dumps({"pareto_chamfer": "x"}).encode(), "'pareto_chamfer' must be a list"),
    (json.dumps({"pareto_fscore": [1]}).encode(), "every item of 'pareto_fscore'"),
])
def test_a_damaged_comparison_directory_is_one_line(tmp_path, capsys, results, message):
    directory = tmp_path / "cmp"
    directory.mkdir()
    (directory / "results.json").write_bytes(results)
    line = _report(directory, tmp_path, capsys)
    assert "results.json" in line and message in line


def test_odd_values_in_a_comparison_are_shown_not_crashed_on(tmp_path):
    directory = tmp_path / "cmp"
    directory.mkdir()
    (directory / "results.json").write_text(json.dumps(
        {"pareto_chamfer": [{"label": "a", "wall_time_s": "soon"}]}))
    assert "a ( s)" in render(directory)


@pytest.mark.parametrize("index, message", [
    (json.dumps({"studies": [1]}).encode(), "'studies' must be an object"),
    (b"\x89\x00binary", "not UTF-8"),
])
def test_a_damaged_index_is_one_line(tmp_path, capsys, index, message):
    top = tmp_path / "all"
    top.mkdir()
    _study(top / "errors")
    (top / "index.json").write_bytes(index)
    line = _report(top, tmp_path, capsys)
    assert "index.json" in line and message in line


def test_the_report_never_replaces_a_file_it_reads(tmp_path):
    study = _study(tmp_path / "study")
    before = (study / "summary.json").read_bytes()
    with pytest.raises(InputError, match=r"one of the files of .* the report reads"):
        from recon.experiments.report import write_report

        write_report(study, study / "summary.json")
    assert (study / "summary.json").read_bytes() == before


def test_an_output_name_too_long_is_one_line(tmp_path, capsys):
    study = _study(tmp_path / "study")
    long = tmp_path / ("a" * 5000 + ".html")
    assert main(["report", str(study), "-o", str(long)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot be written (File name too long)" in err[0]
