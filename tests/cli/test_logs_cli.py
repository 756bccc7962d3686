"""`recon validate`, `info`, `ingest` and `truth`: in-process, and once through a real process."""

from __future__ import annotations

import json
import subprocess
import sys

import h5py
import numpy as np
import pytest

from cli.main import main
from formats.cloud_io import read_cloud
from formats.mesh_io import read_mesh


def test_help_lists_commands(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    for command in ("demo", "simulate", "validate", "info", "ingest", "truth", "score"):
        assert command in out


def test_validate_valid_log(sphere_log, capsys):
    assert main(["validate", str(sphere_log)]) == 0
    assert "valid strike log v1 (40 shots, 80 strikes)" in capsys.readouterr().out


def test_validate_damaged_log_exits_1_with_one_line(sphere_log, capsys):
    with h5py.File(sphere_log, "r+") as f:
        f["shots/time"][5] = 0.0
    assert main(["validate", str(sphere_log)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert err.startswith("recon validate: error:") and "time does not increase at shot 5" in err



def _float32_range(path):
    """Store ``/strikes/range`` of the log at ``path`` as float32 (the spec says float64)."""
    with h5py.File(path, "r+") as f:
        values, attrs = f["strikes/range"][()], dict(f["strikes/range"].attrs)
        del f["strikes/range"]
        f["strikes/range"] = values.astype(np.float32)
        f["strikes/range"].attrs.update(attrs)


@pytest.mark.parametrize("command", [["validate"], ["info"], ["ingest", "-o", "c.ply"]])
def test_float32_range_is_refused_by_every_reader(sphere_log, tmp_path, capsys, command):
    _float32_range(sphere_log)
    args = [command[0], str(sphere_log), *(str(tmp_path / a) if "." in a else a
                                           for a in command[1:])]
    assert main(args) == 1
    assert capsys.readouterr().err == (f"recon {command[0]}: error: {sphere_log}: "
                                       "/strikes/range has dtype float32, expected float64\n")
    assert not list(tmp_path.glob("c.*"))


def test_info_json(sphere_log, capsys):
    assert main(["info", str(sphere_log), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["n_shots"] == 40 and info["n_strikes"] == 80 and info["has_truth"]
    assert info["time_start_s"] == 0.0 and info["time_end_s"] == 390.0
    assert info["sensor"]["n_beams"] == 2 and info["target"] == "sphere"


def test_info_table(sphere_log, capsys):
    assert main(["info", str(sphere_log)]) == 0
    out = capsys.readouterr().out
    assert "80 of 80 pulses" in out and "truth    present" in out


@pytest.mark.parametrize("suffix", [".ply", ".las", ".h5"])
def test_ingest_places_strikes_on_the_sphere(sphere_log, tmp_path, suffix, capsys):
    out = tmp_path / f"cloud{suffix}"
    assert main(["ingest", str(sphere_log), "-o", str(out)]) == 0
    cloud = read_cloud(out)
    tol = 1e-4 if suffix == ".las" else 1e-9
    np.testing.assert_allclose(np.linalg.norm(cloud.points, axis=1), 50.0, atol=tol)
    np.testing.assert_allclose(np.linalg.norm(cloud.view_points, axis=1), 250.0, atol=tol)
    assert set(cloud.attributes) >= {"time", "shot", "beam", "range"}


def test_ingest_refuses_unknown_suffix_without_output(sphere_log, tmp_path, capsys):
    assert main(["ingest", str(sphere_log), "-o", str(tmp_path / "c.xyz")]) == 1
    assert "unknown point-cloud suffix '.xyz'" in capsys.readouterr().err
    assert not list(tmp_path.glob("c*"))


def test_truth_export(sphere_log, tmp_path):
    assert main(["truth", str(sphere_log), "-o", str(tmp_path / "t.ply")]) == 0
    vertices, _ = read_mesh(tmp_path / "t.ply")
    np.testing.assert_allclose(np.linalg.norm(vertices, axis=1), 50.0)


def test_missing_log_through_a_real_process(tmp_path):
    result = subprocess.run([sys.executable, "-m", "cli.main", "info", str(tmp_path / "x.h5")],
                            capture_output=True, text=True, check=False)
    assert result.returncode == 1
    assert result.stderr.strip() == f"recon info: error: {tmp_path / 'x.h5'}: no such file"


@pytest.mark.parametrize(("argv", "line"), [
    (["validate"], "recon validate: error: the following arguments are required: log"),
    (["reconstruct", "c.ply", "--seed", "abc"],
     "recon reconstruct: error: argument --seed: invalid int value: 'abc'"),
])
def test_usage_error_is_one_line_and_exits_1(capsys, argv, line):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 1
    assert capsys.readouterr().err == line + "\n"
