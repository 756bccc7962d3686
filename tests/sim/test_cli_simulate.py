"""`recon simulate`, in-process through cli.main.main and once as a real subprocess."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

import cli.main
import sim
from formats.strike_log import StrikeLog

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def recon(monkeypatch, capsys):
    """Run ``recon ARGS`` in-process with only the simulate subcommand; (status, out, err)."""
    monkeypatch.setattr(cli.main, "COMMAND_MODULES", ("cli.simulate",))

    def run(*argv):
        try:
            status = cli.main.main(list(argv))
        except SystemExit as exc:   # argparse usage errors exit directly, with status 1
            status = exc.code
        out, err = capsys.readouterr()
        return status, out, err
    return run


def test_list_prints_one_line_per_preset(recon):
    status, out, _ = recon("simulate", "--list")
    lines = out.splitlines()
    assert status == 0 and len(lines) == len(sim.list_presets())
    assert [line.split()[0] for line in lines] == [n for n, _ in sim.list_presets()]
    status, out, _ = recon("simulate", "--list", "--json")
    assert {p["name"] for p in json.loads(out)} >= {"asteroid-lrf", "rso-a-cross"}


def test_simulate_a_preset_with_overrides(recon, tmp_path):
    log = tmp_path / "run.h5"
    status, out, err = recon("simulate", "asteroid-lrf", "-o", str(log), "--seed", "3",
                             "--set", "time.duration=600", "--set", "slew.amplitude_deg=2")
    assert status == 0 and err == ""
    assert out.startswith(f"wrote {log}: 60 shots, 60 strikes")
    with StrikeLog(log) as f:
        assert f.n_shots == 60 and f.attrs["seed"] == 3
        assert "amplitude_deg = 2.0" in f.attrs["scene"]
        assert "# Overrides: time.duration=600 slew.amplitude_deg=2" in f.attrs["scene"]
    status, out, _ = recon("simulate", "rso-a-cross", "-o", str(log), "--json",
                           "--set", "time.rotations=0.1")
    summary = json.loads(out)
    assert status == 0 and summary["beams"] == 5 and summary["shots"] == 154


def test_user_errors_are_one_line_without_traceback(recon, tmp_path):
    status, out, err = recon("simulate", "asteroid-lrf", "-o", str(tmp_path / "x.h5"),
                             "--set", "orbit.radius=100")
    assert status == 1 and out == ""
    assert err.strip().splitlines() == [
        "recon simulate: error: orbit.radius = 100 m puts the orbit inside the target (its "
        "farthest point is 287.5 m from the centre)"]
    assert not (tmp_path / "x.h5").exists()
    status, _, err = recon("simulate", "asteroid-lrf")
    assert status == 1 and "SCENE and -o LOG.h5 are required" in err
    status, _, err = recon("simulate", "asteroid-lrf", "-o", "x.h5", "--seed", "-4")
    assert status == 1 and "--seed must be an integer from 0 to" in err
    status, _, err = recon("simulate", "nope", "-o", str(tmp_path / "x.h5"))
    assert status == 1 and "scene 'nope' is neither a preset nor a .toml file" in err


@pytest.mark.skipif(not all(importlib.util.find_spec(m) for m in cli.main.COMMAND_MODULES),
                    reason="not every recon subcommand module exists yet")
def test_recon_simulate_subprocess(tmp_path):
    log = tmp_path / "sub.h5"
    done = subprocess.run([sys.executable, "-m", "cli.main", "simulate", "asteroid-cross", "-o",
                           str(log), "--set", "time.duration=300"], cwd=ROOT,
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    assert "30 shots, 150 strikes of 150 pulses" in done.stdout and log.exists()


def test_keys_lists_every_scene_key_with_its_default(recon):
    from sim.defaults import SCHEMA

    status, out, _ = recon("simulate", "--keys")
    assert status == 0
    for section, keys in SCHEMA.items():
        assert f"[{section}]" in out
        for name in keys:
            assert f"  {name} = " in out
    assert "  inclination_deg = 85.0 " in out and "  mu = (none) " in out
