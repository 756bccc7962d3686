"""`recon reconstruct`, `compare` and `stability`: in-process, and once through a real process."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from cli.main import main
from formats.cloud_io import write_cloud
from formats.geometry import Cloud
from formats.mesh_io import read_mesh, write_mesh
from tests.recon.conftest import box_mesh, box_points


@pytest.fixture(scope="module")
def box_files(tmp_path_factory):
    """A noisy box cloud with view points (.ply) and its truth mesh (.ply)."""
    folder = tmp_path_factory.mktemp("box")
    points, view, _ = box_points(4000, noise=0.003, seed=5)
    cloud = folder / "box.ply"
    write_cloud(cloud, Cloud(points, {"view_x": view[:, 0], "view_y": view[:, 1],
                                           "view_z": view[:, 2]}))
    truth = folder / "truth.ply"
    write_mesh(truth, *box_mesh())
    return cloud, truth


def test_reconstruct_from_a_log(rso_log, tmp_path, capsys):
    out = tmp_path / "rso.ply"
    assert main(["reconstruct", str(rso_log), "-m", "plane", "--param", "cell=2",
                 "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"wrote {out}" in text and "predicted without the truth (in-sample" in text
    vertices, faces = read_mesh(out)
    assert len(faces) > 1000
    # RSO-A is 20 m wide across its 5 cm thin solar panels; plane keeps them (normals oriented
    # by view point keep the two faces of a panel apart), where Poisson loses them.
    assert np.ptp(vertices, axis=0).max() == pytest.approx(20.0, rel=0.05)


def test_the_written_surface_is_called_what_it_is():
    """A surface touching itself at an edge (as a minimum cut's may) is closed, not open."""
    from cli.reconstruct import CLOSURE
    from recon.surfaces.reconstruct import Surface

    vertices, faces = box_mesh()
    fin = np.array([[faces[0, 0], faces[0, 1], len(vertices)]])
    vertices = np.vstack([vertices, [[5.0, 5.0, 5.0]]])
    kinds = [Surface(vertices, f, "m", {}).closure
             for f in (faces, np.vstack([faces, fin, fin[:, ::-1]]), faces[1:])]
    assert kinds == ["watertight", "closed", "open"]
    assert set(CLOSURE) == set(kinds)


def test_a_cloud_file_with_too_few_points_is_named(tmp_path, capsys):
    path = tmp_path / "few.ply"
    write_cloud(path, Cloud(np.random.default_rng(0).random((5, 3))))
    assert main(["reconstruct", str(path), "-m", "convex-hull", "-o",
                 str(tmp_path / "o.ply")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.endswith(f"{path}: 5 points; need at least 16 to reconstruct"), err


@pytest.mark.parametrize("command", ["compare", "stability"])
def test_a_refused_input_leaves_no_new_output_directory(command, box_files, tmp_path, capsys):
    junk = tmp_path / "junk.ply"
    junk.write_bytes(b"ply\nformat nonsense\n")
    out = tmp_path / "new" / "out"
    assert main([command, str(junk), "--truth", str(box_files[1]), "-o", str(out),
                 "--methods", "convex-hull"]) == 1
    assert "junk.ply" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()


def test_reconstruct_json_and_preprocessing(box_files, tmp_path, capsys):
    out = tmp_path / "box.ply"
    assert main(["reconstruct", str(box_files[0]), "-m", "planes", "--remove-outliers",
                 "--voxel", "0.02", "-o", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["method"] == "planes" and summary["watertight"]
    assert summary["view_points"] and summary["n_points"] < 4000
    assert summary["peak_memory_mb"] > 0
    band = summary["estimate"]
    assert band["chamfer_low_m"] <= band["chamfer_m"] <= band["chamfer_high_m"]


def test_reconstruct_auto_says_what_it_chose_and_why(box_files, tmp_path, capsys):
    out = tmp_path / "auto.ply"
    assert main(["reconstruct", str(box_files[0]), "-m", "auto", "--auto-methods", "planes",
                 "convex-hull", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "chose planes, a closed surface" in text and "* planes" in text
    assert "predicted without the truth (held-out" in text
    assert len(read_mesh(out)[1]) < 50


def test_list_methods(capsys):
    assert main(["reconstruct", "--list-methods"]) == 0
    text = capsys.readouterr().out
    assert "poisson [smooth]" in text and "depth = 8" in text and "test-" not in text


@pytest.mark.parametrize("argv, message", [
    (["-m", "marching"], "unknown method 'marching'"),
    (["-m", "poisson", "--param", "depth=deep"], "parameter depth='deep' is not an integer"),
    (["-m", "poisson", "--param", "deep"], "--param must be key=value"),
    (["-m", "auto", "--param", "depth=6"], "--param cannot be combined with -m auto"),
    (["-m", "poisson", "--timeout", "0"], "--timeout must be positive"),
    (["-m", "poisson", "--voxel", "-1"], "--voxel must be a positive size"),
])
def test_bad_arguments_exit_1_with_one_line(box_files, tmp_path, capsys, argv, message):
    assert main(["reconstruct", str(box_files[0]), *argv, "-o", str(tmp_path / "x.ply")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err


def test_output_must_be_ply(box_files, tmp_path, capsys):
    assert main(["reconstruct", str(box_files[0]), "-o", str(tmp_path / "x.obj")]) == 1
    assert "-o must name a .ply file" in capsys.readouterr().err


def test_a_crash_is_an_error_not_a_traceback(box_files, tmp_path, capsys, monkeypatch):
    import recon_fake_methods  # noqa: F401  (registers test-abort in this process)

    assert main(["reconstruct", str(box_files[0]), "-m", "test-abort",
                 "-o", str(tmp_path / "x.ply")]) == 1
    assert "test-abort failed (crash): crashed with SIGABRT" in capsys.readouterr().err


def test_compare_through_a_real_process(box_files, tmp_path):
    out = tmp_path / "cmp"
    proc = subprocess.run(
        [sys.executable, "-m", "cli.main", "compare", str(box_files[0]), "--truth",
         str(box_files[1]), "-o", str(out), "--methods", "convex-hull", "planes",
         "--no-grid", "--scheduler", "threads", "--samples", "4000", "--auto",
         "--target-kind", "natural"],
        capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "Pareto front (time vs Chamfer)" in proc.stdout
    assert "auto vs truth: auto's choice ranks 1 of 2" in proc.stdout
    for name in ("results.csv", "results.json", "speed_accuracy.png", "auto.json",
                 "results.jsonl"):
        assert (out / name).is_file()
    assert json.loads((out / "auto.json").read_text())["choice"]["target_kind"] == "natural"
    saved = json.loads((out / "results.json").read_text())
    assert saved["runs"][0]["method"] == "planes"
    # --resume finds everything done and rewrites the same results.
    again = subprocess.run(
        [sys.executable, "-m", "cli.main", "compare", str(box_files[0]), "--truth",
         str(box_files[1]), "-o", str(out), "--methods", "convex-hull", "planes",
         "--no-grid", "--scheduler", "threads", "--samples", "4000", "--resume", "--json"],
        capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    rerun = json.loads(again.stdout)
    assert [r["wall_time_s"] for r in rerun["records"]] == \
        [r["wall_time_s"] for r in saved["runs"]]


def test_stability_on_a_cloud(box_files, tmp_path, capsys):
    out = tmp_path / "stab"
    assert main(["stability", str(box_files[0]), "--truth", str(box_files[1]), "-o", str(out),
                 "--methods", "convex-hull", "--noise", "0,0.03", "--density", "1",
                 "--outliers", "0", "--scheduler", "threads", "--samples", "2000"]) == 0
    assert "convex-hull" in capsys.readouterr().out
    assert (out / "convex-hull_failures.png").is_file()
    assert (out / "convex-hull_accuracy.png").is_file()


@pytest.mark.parametrize("argv, message", [
    (["--noise", "a,b"], "--noise must be comma-separated numbers"),
    (["--density", "2"], "density level 2 is out of range"),
    (["--set", "x=1"], "recon stability: error: --set: a cloud or a log ("),
])
def test_stability_bad_arguments(box_files, tmp_path, capsys, argv, message):
    assert main(["stability", str(box_files[0]), "--truth", str(box_files[1]),
                 "-o", str(tmp_path / "s"), "--methods", "convex-hull", *argv]) == 1
    assert message in capsys.readouterr().err


def test_compare_needs_a_truth_with_faces(box_files, tmp_path, capsys):
    assert main(["compare", str(box_files[0]), "--truth", str(box_files[0]),
                 "-o", str(tmp_path / "c")]) == 1
    assert "error" in capsys.readouterr().err


def test_compare_where_every_run_fails_exits_1_with_one_line(box_files, tmp_path, capsys):
    import recon_fake_methods  # noqa: F401  (registers test-refuse in this process)

    out = tmp_path / "cmp"
    assert main(["compare", str(box_files[0]), "--truth", str(box_files[1]), "-o", str(out),
                 "--methods", "test-refuse", "--scheduler", "serial", "--json"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "every run failed (1 runs: error)" in err
    assert (out / "results.csv").is_file() and (out / "speed_accuracy.png").is_file()
