"""Command-line habits: one list syntax (commas; spaces and repeats accepted) that never swallows
the positional argument, required options shown as required, and ``python -m recon``."""

from __future__ import annotations

import subprocess
import sys

import pytest

from cli.main import build_parser, main


@pytest.fixture
def captured(monkeypatch):
    """Replace api.compare and api.stability by recorders of the arguments they get."""
    import cli.main
    from recon import api

    calls = {}

    def record(name):
        def fake(*args, **kwargs):
            calls[name] = (args, kwargs)
            raise KeyboardInterrupt  # stop the command here; main() returns 130

        return fake

    # main() ends the process at once after an interrupt when children are alive (warm
    # workers that earlier tests in this process left): here it must only return the status.
    monkeypatch.setattr(cli.main, "_leave_now", lambda status, at_once=False: status)
    monkeypatch.setattr(api, "compare", record("compare"))
    monkeypatch.setattr(api, "stability", record("stability"))
    return calls


@pytest.mark.parametrize("methods", [
    ["--methods", "convex-hull", "poisson"],           # spaces, positional after the list
    ["--methods", "convex-hull,poisson"],               # the documented syntax
    ["--methods=convex-hull,poisson"],
    ["--methods", "convex-hull", "--methods", "poisson"],
])
def test_method_lists_do_not_swallow_the_input(tmp_path, captured, methods):
    argv = ["compare", *methods, "cloud.ply", "--truth", "t.ply", "-o", str(tmp_path)]
    assert main(argv) == 130
    args, kwargs = captured["compare"]
    assert args[0] == "cloud.ply"
    assert kwargs["methods"] == ["convex-hull", "poisson"]


def test_input_before_the_list_and_missing_input(tmp_path, captured, capsys):
    assert main(["compare", "cloud.ply", "--methods", "poisson", "--truth", "t.ply",
                 "-o", str(tmp_path)]) == 130
    assert captured["compare"][0][0] == "cloud.ply"
    assert main(["compare", "--methods", "poisson", "--truth", "t.ply", "-o", str(tmp_path)]) == 1
    assert "compare needs INPUT" in capsys.readouterr().err


def test_level_lists_take_the_same_syntax(tmp_path, captured):
    for noise in (["--noise", "0,0.5"], ["--noise", "0", "0.5"], ["--noise=0,0.5"]):
        assert main(["stability", *noise, "--methods", "poisson", "scene.toml",
                     "-o", str(tmp_path)]) == 130
        args, kwargs = captured["stability"]
        assert args[0] == "scene.toml"
        assert kwargs["noise"] == (0, 0.5) and kwargs["density"] == (1, 0.3, 0.1)


@pytest.mark.parametrize(("command", "required"), [
    ("simulate", ["-o LOG.h5", "SCENE"]),
    ("reconstruct", ["-o MESH.ply", "INPUT"]),
    ("study", ["-o DIR", "NAME"]),
    ("compare", ["--truth TRUTH", "-o OUTPUT", "INPUT"]),
    ("stability", ["-o", "SOURCE"]),
])
def test_required_arguments_show_as_required(command, required):
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices[command]
    usage = " ".join(sub.format_usage().split())
    for text in required:
        assert text in usage and f"[{text}" not in usage, usage


def test_list_syntax_reads_as_one_item_in_usage():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices["compare"]
    usage = " ".join(sub.format_usage().split())
    assert "[--methods METHOD[,...]]" in usage


@pytest.mark.parametrize(("command", "says"), [
    ("compare", ["runs at once on this machine, each in its own worker process",
                 "not used with --scheduler ADDRESS"]),
    ("stability", ["runs at once on this machine, each in its own worker process",
                   "with --scheduler ADDRESS the cluster's workers run them: give its size, "
                   "which the grid's time estimate divides by"]),
    ("study", ["the worker processes of the local Dask cluster, or threads with --scheduler "
               "threads", "not used with --scheduler ADDRESS"]),
])
def test_workers_help_says_what_n_sets_under_each_scheduler(command, says):
    """--workers is a local count: of the runs at once (compare, stability: threads each
    waiting on a worker process) or of a local cluster's processes (study); a cluster given by
    address runs the work on its own workers, and 'serial' one case at a time."""
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices[command]
    text = " ".join(next(a for a in sub._actions if a.dest == "workers").help.split())
    for words in [*says, "default: one per core", "'serial' runs one at a time"]:
        assert words in text, text


@pytest.mark.parametrize("package", ["recon", "cli"])
def test_python_dash_m_runs_recon(package):
    result = subprocess.run([sys.executable, "-m", package, "--version"], capture_output=True,
                            text=True, timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("recon ")


def test_the_package_lists_its_verbs():
    import recon
    from recon import api

    listed = set(dir(recon))
    assert {"simulate", "ingest", "reconstruct", "score", "compare", "edges"} <= listed
    assert recon.score is api.score


def test_a_reader_that_goes_away_ends_recon_quietly():
    """``recon ... | head``: the pipe closes before recon writes; recon stops with SIGPIPE's
    status and no traceback (it printed one from the listing's print)."""
    proc = subprocess.Popen([sys.executable, "-m", "cli", "reconstruct", "--list-methods"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()   # long before the interpreter has started
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 141, err.decode()
    assert err == b""
