"""An error about one argument names it as its reader passed it: ``recon.api`` raises a
``ReconError`` subclass naming the Python parameter (``resume``, ``overrides``,
``memory_limit``), and ``recon`` prints the same line with the option instead (``--resume``,
``--set``, ``--memory-limit``), on one line with exit status 1."""

from __future__ import annotations

import pickle
import re
import subprocess
import sys

import pytest

from cli.main import main
from cli.options import flag, message
from formats.cloud_io import write_cloud
from formats.errors import ParameterError, ReconError, ResourceError, SceneError
from formats.geometry import Cloud, Mesh
from formats.mesh_io import write_mesh
from recon import api
from tests.conftest import icosphere


@pytest.fixture
def files(tmp_path):
    """A small sphere cloud and its truth mesh, and a plain file where a directory belongs."""
    vertices, faces = icosphere(10.0, 3)
    write_cloud(tmp_path / "c.ply", Cloud(vertices))
    write_mesh(tmp_path / "t.ply", Mesh(vertices, faces))
    (tmp_path / "file").write_text("x")
    return tmp_path


def _damaged_sweep(tmp_path):
    """An output directory whose sweep record is damaged: resuming it is refused."""
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "sweep.json").write_text("[1, 2]")
    return tmp_path / "out"


def _compare(tmp_path, **options):
    return api.compare(tmp_path / "c.ply", truth=tmp_path / "t.ply", methods=["convex-hull"],
                       **{"output": tmp_path / "out", "scheduler": "serial", **options})


def _compare_argv(tmp_path, *options):
    return ["compare", str(tmp_path / "c.ply"), "--truth", str(tmp_path / "t.ply"), "--methods",
            "convex-hull", "--scheduler", "serial", *options]


# (argument, flag, error class, API call, the API's message (regex, from its start),
#  command-line arguments, the CLI's message (regex, after "recon COMMAND: error: "))
CASES = [
    ("resume", "--resume", ParameterError,
     lambda d: _compare(d, output=_damaged_sweep(d), resume=True),
     r"resume: .*sweep\.json is damaged \(not a JSON object\); use a new output directory, "
     r"or run again without resuming$",
     lambda d: _compare_argv(d, "-o", str(_damaged_sweep(d)), "--resume"),
     r"--resume: .*sweep\.json is damaged"),
    ("samples", "--samples", ParameterError,
     lambda d: _compare(d, samples=99),
     r"samples must be at least 100, got 99$",
     lambda d: _compare_argv(d, "-o", str(d / "out"), "--samples", "99"),
     r"--samples must be at least 100, got 99$"),
    ("output", "-o", ParameterError,
     lambda d: _compare(d, output=d / "file"),
     r"output .*file: is a file, not a directory$",
     lambda d: _compare_argv(d, "-o", str(d / "file")),
     r"-o .*file: is a file, not a directory$"),
    ("timeout", "--timeout", ParameterError,
     lambda d: api.reconstruct(d / "c.ply", timeout=0),
     r"timeout must be positive, got 0$",
     lambda d: ["reconstruct", str(d / "c.ply"), "-o", str(d / "m.ply"), "--timeout", "0"],
     r"--timeout must be positive, got 0$"),
    ("memory_limit", "--memory-limit", ParameterError,
     lambda d: api.reconstruct(d / "c.ply", memory_limit=10**20),
     r"memory_limit must be from 0 to 8796093022207 MB, got 100000000000000000000$",
     lambda d: ["reconstruct", str(d / "c.ply"), "-o", str(d / "m.ply"), "--memory-limit", "-1"],
     r"--memory-limit must be from 0 to 8796093022207 MB, got -1$"),
    ("voxel", "--voxel", ParameterError,
     lambda d: api.reconstruct(d / "c.ply", voxel=-1.0),
     r"voxel must be a positive size in metres, got -1$",
     lambda d: ["reconstruct", str(d / "c.ply"), "-o", str(d / "m.ply"), "--voxel", "-1"],
     r"--voxel must be a positive size in metres, got -1$"),
    ("normals_k", "--normals-k", ParameterError,
     lambda d: api.reconstruct(d / "c.ply", normals_k=0),
     r"normals_k must be >= 1, got 0$",
     lambda d: ["reconstruct", str(d / "c.ply"), "-o", str(d / "m.ply"), "--normals-k", "0"],
     r"--normals-k must be >= 1, got 0$"),
    ("params", "--param", ParameterError,
     lambda d: api.reconstruct(d / "c.ply", params=["depth"]),
     r"params must be key=value, got 'depth'$",
     lambda d: ["reconstruct", str(d / "c.ply"), "-o", str(d / "m.ply"), "--param", "depth"],
     r"--param must be key=value, got 'depth'$"),
    ("holdout", "--holdout", ParameterError,
     lambda d: api.reconstruct(d / "c.ply", method="auto", holdout=0.9),
     r"holdout must be in \(0, 0\.5\], got 0\.9$",
     lambda d: ["reconstruct", str(d / "c.ply"), "-o", str(d / "m.ply"), "-m", "auto",
                "--holdout", "0.9"],
     r"--holdout must be in \(0, 0\.5\], got 0\.9$"),
    ("overrides", "--set", SceneError,
     lambda d: api.simulate("asteroid-lrf", d / "x.h5", overrides=["orbit.radius"]),
     r"overrides 'orbit\.radius': expected section\.key=value, e\.g\. time\.duration=3600$",
     lambda d: ["simulate", "asteroid-lrf", "-o", str(d / "x.h5"), "--set", "orbit.radius"],
     r"--set 'orbit\.radius': expected section\.key=value"),
    ("overrides", "--set", SceneError,
     lambda d: api.simulate("asteroid-lrf", d / "x.h5", overrides=["time.durration=60"]),
     r"overrides: unknown scene key time\.durration \(did you mean time\.duration\?\)$",
     lambda d: ["simulate", "asteroid-lrf", "-o", str(d / "x.h5"), "--set",
                "time.durration=60"],
     r"--set: unknown scene key time\.durration \(did you mean time\.duration\?\)$"),
    ("truth", "--truth", ParameterError,
     lambda d: api.default_truth(d / "c.ply"),
     r"truth must be given: .*c\.ply is not a strike log with truth$",
     lambda d: ["score", str(d / "c.ply")],
     r"--truth must be given: .*c\.ply is not a strike log with truth$"),
    ("n_workers", "--workers", ParameterError,
     lambda d: api.study("duration", d / "out", size="tiny", n_workers=0),
     r"n_workers must be >= 1, got 0$",
     lambda d: ["study", "duration", "-o", str(d / "out"), "--workers", "0"],
     r"--workers must be >= 1, got 0$"),
]
IDS = [f"{case[0]}-{i}" for i, case in enumerate(CASES)]


@pytest.mark.parametrize("argument, option, error, call, api_text, argv, cli_text", CASES,
                         ids=IDS)
def test_the_api_names_its_parameter(files, argument, option, error, call, api_text, argv,
                                     cli_text):
    with pytest.raises(error, match="^" + api_text) as info:
        call(files)
    assert info.value.argument == argument
    assert "--" not in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize("argument, option, error, call, api_text, argv, cli_text", CASES,
                         ids=IDS)
def test_the_command_line_names_its_option(files, capsys, argument, option, error, call,
                                           api_text, argv, cli_text):
    args = argv(files)
    assert main(args) == 1
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"recon {args[0]}: error: {option}")
    assert re.search(cli_text, lines[0]), lines[0]


def test_argparse_types_and_usage_checks_name_the_option_once(files, capsys):
    """``--scheduler`` is checked while the arguments are parsed, ``--seed`` before the
    simulation: both go through argparse's usage error (exit 1)."""
    with pytest.raises(ParameterError, match=r"^scheduler must be a Dask scheduler address"):
        api.check_scheduler("my cluster")
    with pytest.raises(SystemExit) as done:
        main(_compare_argv(files, "-o", str(files / "out"), "--scheduler", "my cluster"))
    assert done.value.code == 1
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        "recon compare: error: argument --scheduler: must be a Dask scheduler address "
        "(tcp://host:port), 'threads' or 'serial', got 'my cluster'")
    with pytest.raises(ParameterError, match=r"^seed must be an integer from 0 to") as info:
        api.check_seed(-4)
    assert info.value.argument == "seed"
    with pytest.raises(SystemExit) as done:
        main(["simulate", "asteroid-lrf", "-o", str(files / "x.h5"), "--seed", "-4"])
    assert done.value.code == 1
    assert capsys.readouterr().err.strip().splitlines()[-1].startswith(
        "recon simulate: error: --seed must be an integer from 0 to")


# Every command with --seed, run as it would work but for the seed (the one it is given).
SEEDED = {
    "simulate": lambda d: ["simulate", "asteroid-lrf", "-o", str(d / "x.h5")],
    "score": lambda d: ["score", str(d / "c.ply"), "--truth", str(d / "t.ply")],
    "edges": lambda d: ["edges", str(d / "c.ply"), "--truth", str(d / "t.ply"), "-o",
                        str(d / "edges")],
    "reconstruct": lambda d: ["reconstruct", str(d / "c.ply"), "-o", str(d / "m.ply")],
    "compare": lambda d: _compare_argv(d, "-o", str(d / "out")),
    "stability": lambda d: ["stability", str(d / "c.ply"), "--truth", str(d / "t.ply"),
                            "--methods", "convex-hull", "--scheduler", "serial", "-o",
                            str(d / "out")],
}
# The same verbs through the API, and refine (``recon ingest --refine`` passes no seed).
SEEDED_API = {
    "simulate": lambda d, seed: api.simulate("asteroid-lrf", d / "x.h5", seed=seed),
    "refine": lambda d, seed: api.refine(d / "none.h5", seed=seed),
    "score": lambda d, seed: api.score(d / "c.ply", truth=d / "t.ply", seed=seed),
    "edges": lambda d, seed: api.edges(d / "c.ply", truth=d / "t.ply", output=d / "edges",
                                       seed=seed),
    "reconstruct": lambda d, seed: api.reconstruct(d / "c.ply", seed=seed),
    "compare": lambda d, seed: _compare(d, seed=seed),
    "stability": lambda d, seed: api.stability(d / "c.ply", truth=d / "t.ply",
                                               methods=["convex-hull"], scheduler="serial",
                                               output=d / "out", seed=seed),
}


def test_every_seed_option_is_checked():
    """The commands with a --seed option (``recon --help``) are those checked below."""
    from cli.main import build_parser

    commands = next(a for a in build_parser()._actions if a.dest == "command").choices
    assert {name for name, parser in commands.items()
            if "--seed" in parser._option_string_actions} == set(SEEDED)


@pytest.mark.parametrize("seed", ["-1", str(2**63)])
@pytest.mark.parametrize("command", list(SEEDED))
def test_every_command_refuses_a_seed_out_of_range_before_any_work(files, capsys, command,
                                                                   seed):
    before = sorted(files.iterdir())
    try:
        status = main([*SEEDED[command](files), "--seed", seed])
    except SystemExit as done:   # simulate: a usage error, after its usage line
        status = done.code
    assert status == 1
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        f"recon {command}: error: --seed must be an integer from 0 to {2**63 - 1}, got {seed}")
    assert sorted(files.iterdir()) == before


@pytest.mark.parametrize("seed", [-1, 1.5, True])
@pytest.mark.parametrize("verb", list(SEEDED_API))
def test_every_verb_refuses_a_seed_that_is_not_a_count(files, verb, seed):
    before = sorted(files.iterdir())
    with pytest.raises(ParameterError, match=r"^seed must be an integer from 0 to "
                                             rf"{2**63 - 1}, got {seed!r}$") as info:
        SEEDED_API[verb](files, seed)
    assert info.value.argument == "seed"
    assert sorted(files.iterdir()) == before


def test_follow_names_timeout_s_and_the_command_line_its_timeout(files):
    with pytest.raises(ParameterError, match=r"^timeout_s must be a positive number of "
                                             r"seconds, got 0$") as info:
        api.follow(files / "none.h5", files / "c2.ply", timeout_s=0)
    assert message(info.value) == "--timeout must be a positive number of seconds, got 0"


def test_worded_replaces_only_a_leading_argument():
    spell = {"memory_limit": "--memory-limit"}.__getitem__
    error = ParameterError("memory_limit must be >= 0, got -1", argument="memory_limit")
    assert error.worded(spell) == "--memory-limit must be >= 0, got -1"
    assert str(error) == "memory_limit must be >= 0, got -1"
    # no argument, or a message that does not start with it: unchanged
    assert ParameterError("x.ply: no points").worded(spell) == "x.ply: no points"
    assert ParameterError("the memory_limit is odd",
                          argument="memory_limit").worded(spell) == "the memory_limit is odd"
    assert ParameterError("memory_limits are odd",
                          argument="memory_limit").worded(spell) == "memory_limits are odd"


@pytest.mark.parametrize("cls", [ParameterError, SceneError, ResourceError])
def test_the_argument_survives_a_process_boundary(cls):
    """Errors raised in a worker reach the parent pickled: the argument goes with them."""
    again = pickle.loads(pickle.dumps(cls("resume: damaged", argument="resume")))
    assert type(again) is cls and str(again) == "resume: damaged"
    assert again.argument == "resume" and isinstance(again, ReconError)


def test_options_are_the_parameters_in_kebab_case_unless_listed():
    assert [flag(a) for a in ("resume", "memory_limit", "normals_k", "target_kind")] == [
        "--resume", "--memory-limit", "--normals-k", "--target-kind"]
    assert [flag(a) for a in ("overrides", "params", "n_workers", "output", "timeout_s")] == [
        "--set", "--param", "--workers", "-o", "--timeout"]


def test_real_subprocess(files):
    """Once through a real process: the flag on stderr, one line, exit status 1."""
    done = subprocess.run([sys.executable, "-m", "cli.main", "reconstruct",
                           str(files / "c.ply"), "-o", str(files / "m.ply"), "--memory-limit",
                           "-1"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1 and done.stdout == ""
    assert done.stderr.strip().splitlines() == [
        "recon reconstruct: error: --memory-limit must be from 0 to 8796093022207 MB, got -1"]
    assert not (files / "m.ply").exists()


@pytest.mark.parametrize("command", ["compare", "stability"])
def test_sweeps_check_their_workers_and_scheduler_before_making_the_directory(files, capsys,
                                                                              command):
    assert main([*SEEDED[command](files), "--workers", "0"]) == 1
    assert capsys.readouterr().err.strip().splitlines() == [
        f"recon {command}: error: --workers must be >= 1, got 0"]
    verb = {"compare": _compare, "stability": lambda d, **options: api.stability(
        d / "c.ply", truth=d / "t.ply", output=d / "out", **options)}[command]
    with pytest.raises(ParameterError, match=r"^n_workers must be >= 1, got 0$"):
        verb(files, n_workers=0)
    with pytest.raises(ParameterError, match=r"^scheduler must be a Dask scheduler address"):
        verb(files, scheduler="my cluster")
    assert not (files / "out").exists()
