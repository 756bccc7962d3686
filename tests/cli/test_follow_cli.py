"""``recon ingest LOG --follow`` against ``recon simulate --live`` running in another process."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from cli.main import main
from formats.cloud_io import read_cloud

# A closed-loop run: planned interval by interval, so it is written over a few seconds.
SCENE = ["asteroid-lrf", "--set", "target.subdivisions=3", "--set", "time.duration=7200",
         "--set", "attitude.mode=gaps", "--set", "orbit.inclination_deg=60"]


def test_follow_registers_a_live_simulation_as_a_plain_ingest_of_the_finished_log(tmp_path):
    log = tmp_path / "live.h5"
    writer = subprocess.Popen([sys.executable, "-m", "cli.main", "simulate", *SCENE, "-o",
                               str(log), "--live", "--no-progress"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert main(["ingest", str(log), "--follow", "--timeout", "120", "-o",
                     str(tmp_path / "followed.ply")]) == 0
    finally:
        _, err = writer.communicate(timeout=300)
    assert writer.returncode == 0, err
    assert main(["ingest", str(log), "-o", str(tmp_path / "plain.ply")]) == 0
    followed, plain = read_cloud(tmp_path / "followed.ply"), read_cloud(tmp_path / "plain.ply")
    assert len(plain.points) > 500
    np.testing.assert_array_equal(followed.points, plain.points)
    np.testing.assert_array_equal(followed.attributes["shot"], plain.attributes["shot"])


def test_follow_gives_up_on_a_log_nobody_writes(tmp_path, capsys):
    assert main(["ingest", str(tmp_path / "none.h5"), "--follow", "--timeout", "0.2", "-o",
                 str(tmp_path / "c.ply")]) == 1
    assert "no log and no writer at work after 0.2 s" in capsys.readouterr().err
    assert main(["ingest", str(tmp_path / "none.h5"), "--follow", "--timeout", "0", "-o",
                 str(tmp_path / "c.ply")]) == 1
    assert "--timeout must be a positive number of seconds, got 0" in capsys.readouterr().err
    assert not (tmp_path / "c.ply").exists()
