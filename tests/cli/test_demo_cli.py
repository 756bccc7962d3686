"""``recon demo`` is ``recon.api.demo``: the whole pipeline, every file in one directory."""

from __future__ import annotations

import json

from cli.main import main


def test_cli_help_defaults_match_the_library():
    from cli import demo as cli_demo
    from recon import api

    assert (cli_demo.DEMO_SCENE, cli_demo.DEMO_METHOD) == (api.DEMO_SCENE, api.DEMO_METHOD)


def test_demo_writes_every_file_and_scores_both(tmp_path, capsys):
    out = tmp_path / "demo"
    code = main(["demo", "-o", str(out), "--scene", "asteroid-cross", "--method", "poisson",
                 "--set", "time.rotations=0.5"])
    printed = capsys.readouterr().out
    assert code == 0
    for name in ("strikes.h5", "cloud.ply", "truth.ply", "surface.ply", "scores.json"):
        assert (out / name).is_file(), name
    scores = json.loads((out / "scores.json").read_text())["scores"]
    assert set(scores) == {"cloud", "surface"}
    assert scores["surface"]["n_points"] > 0 and 0 < scores["cloud"]["fscore"] <= 1
    assert "- ingest: register strikes into the target body frame" in printed
    assert "Chamfer [m]" in printed and "wrote " in printed
