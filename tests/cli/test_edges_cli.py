"""`recon edges`: edge points of a cloud, a mesh or a log as a PLY, a picture and scores."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
import trimesh

import sim
from cli.main import main
from formats.cloud_io import write_cloud
from formats.geometry import Cloud, Mesh
from formats.mesh_io import write_mesh
from formats.ply import read_ply
from metrics import edge_score, sample_surface

BOX = trimesh.creation.box((4.0, 3.0, 2.0))
BOX_MESH = Mesh(np.asarray(BOX.vertices), np.asarray(BOX.faces))


@pytest.fixture(scope="module")
def box_files(tmp_path_factory):
    """A 20,000-point box cloud (noise 1 mm) and its truth mesh, as PLY files."""
    folder = tmp_path_factory.mktemp("edges")
    points, _ = sample_surface(BOX_MESH, 20_000, seed=3)
    points += np.random.default_rng(4).normal(scale=0.001, size=points.shape)
    write_cloud(folder / "box.ply", Cloud(points))
    write_mesh(folder / "truth.ply", BOX_MESH)
    return folder, points


def test_cloud_writes_labelled_points_picture_and_scores(box_files, tmp_path, capsys):
    folder, points = box_files
    out = tmp_path / "out"
    assert main(["edges", str(folder / "box.ply"), "--truth", str(folder / "truth.ply"),
                 "-o", str(out), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    expected = edge_score(points, BOX_MESH)
    assert result["edge"]["score"] == pytest.approx(expected.score, abs=1e-12)
    columns, faces, _ = read_ply(out / "edges.ply")
    assert faces is None
    assert np.allclose(np.column_stack([columns["x"], columns["y"], columns["z"]]), points)
    label = columns["label"]
    assert np.array_equal(label == 1, expected.is_edge & expected.near_edge)
    assert np.array_equal(label == 2, expected.is_edge & ~expected.near_edge)
    assert np.array_equal(columns["near_edge"] == 1, expected.near_edge)
    assert columns["drop"] == pytest.approx(expected.variation.drop)
    # Detected edge points lie on the box's edges: two coordinates at a face.
    on_faces = (np.abs(np.abs(points) - [2.0, 1.5, 1.0]) < 0.05).sum(axis=1)
    assert (on_faces[label == 1] >= 2).mean() > 0.95
    assert result["counts"]["true_edge_points"] == int((label == 1).sum()) > 100
    png = (out / "edges.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000
    saved = json.loads((out / "edges.json").read_text())
    assert saved["edge"] == result["edge"]
    assert not [p for p in out.iterdir() if ".partial" in p.name]


def test_log_against_its_own_truth_and_feature_variant(tmp_path, capsys):
    log = tmp_path / "rso.h5"
    sim.simulate(sim.load_scene("rso-a-lrf", ["time.rotations=2"]), log, seed=1)
    assert main(["edges", str(log), "-o", str(tmp_path / "w"), "--json"]) == 0
    weighted = json.loads(capsys.readouterr().out)["edge"]
    assert main(["edges", str(log), "-o", str(tmp_path / "f"), "--variant", "feature",
                 "--threshold", "0.001", "--title", "RSO-A"]) == 0
    out = capsys.readouterr().out
    assert "edge score" in out and "(feature)" in out and "wrote" in out
    feature = json.loads((tmp_path / "f" / "edges.json").read_text())["edge"]
    assert weighted["variant"] == "weighted" and feature["threshold"] == 0.001
    assert weighted["n_truth_edges"] > feature["n_truth_edges"] > 0


def test_mesh_is_sampled(box_files, tmp_path, capsys):
    folder, _ = box_files
    assert main(["edges", str(folder / "truth.ply"), "--truth", str(folder / "truth.ply"),
                 "-o", str(tmp_path / "m"), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["edge"]["n_points"] == 200_000


def _error(capsys, argv):
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0, err
    return err


def test_bad_inputs(box_files, tmp_path, capsys):
    folder, _ = box_files
    cloud, truth = str(folder / "box.ply"), str(folder / "truth.ply")
    assert (f"recon edges: error: --truth must be given: {cloud} is not a strike log with "
            "truth") in _error(capsys, ["edges", cloud, "-o", str(tmp_path / "a")])
    (tmp_path / "file").write_text("x")
    assert "is a file, not a directory" in _error(
        capsys, ["edges", cloud, "--truth", truth, "-o", str(tmp_path / "file")])
    assert "k must be an integer >= 4" in _error(
        capsys, ["edges", cloud, "--truth", truth, "-o", str(tmp_path / "b"), "--k", "2"])
    assert "--feature-angle must be in" in _error(
        capsys, ["edges", cloud, "--truth", truth, "-o", str(tmp_path / "b"),
                 "--feature-angle", "200"])
    assert "no such file" in _error(
        capsys, ["edges", str(tmp_path / "none.ply"), "--truth", truth, "-o",
                 str(tmp_path / "b")])


@pytest.mark.parametrize(("option", "value", "line"), [
    ("--k", "0", "--k must be an integer >= 4, got 0"),
    ("--threshold", "-1", "--threshold must be a finite number >= 0, got -1.0"),
    ("--feature-angle", "200", "--feature-angle must be in [0, 180), got 200.0"),
])
def test_edge_options_are_named_by_their_flag(box_files, tmp_path, capsys, option, value,
                                              line):
    folder, _ = box_files
    assert main(["edges", str(folder / "box.ply"), "--truth", str(folder / "truth.ply"),
                 "-o", str(tmp_path / "out"), option, value]) == 1
    assert capsys.readouterr().err == f"recon edges: error: {line}\n"
    assert not (tmp_path / "out").exists()


def test_failed_run_keeps_the_previous_outputs(box_files, tmp_path, capsys):
    folder, _ = box_files
    out = tmp_path / "keep"
    argv = ["edges", str(folder / "box.ply"), "--truth", str(folder / "truth.ply"), "-o",
            str(out)]
    assert main(argv) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert main([*argv, "--threshold", "-1"]) == 1
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_a_refused_run_leaves_the_previous_set_whole(box_files, tmp_path, capsys):
    """A bad seed, or an output that is a directory, is refused before any file is written:
    the earlier edges.ply, edges.png and edges.json stay as a set."""
    folder, _ = box_files
    out = tmp_path / "keep"
    argv = ["edges", str(folder / "box.ply"), "--truth", str(folder / "truth.ply"), "-o",
            str(out)]
    out.mkdir()
    for name in ("edges.ply", "edges.png", "edges.json"):   # an earlier run's, told apart
        (out / name).write_bytes(b"earlier " + name.encode())
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert _error(capsys, [*argv, "--seed", "-1"]) == (
        f"recon edges: error: --seed must be an integer from 0 to {2**63 - 1}, got -1")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    png = out / "edges.png"
    png.unlink()
    png.mkdir()
    assert _error(capsys, argv) == (
        f"recon edges: error: {png}: is a directory; give the name of a file to write")
    assert (out / "edges.ply").read_bytes() == before["edges.ply"]
    assert (out / "edges.json").read_bytes() == before["edges.json"]
    assert not [p for p in out.iterdir() if ".partial" in p.name]


def test_a_refused_run_leaves_no_new_directory(box_files, tmp_path, capsys):
    folder, _ = box_files
    empty = tmp_path / "empty.xyz"
    empty.write_text("")
    for test, options in ((folder / "box.ply", ["--k", "0"]), (empty, [])):
        assert "error" in _error(capsys, ["edges", str(test), "--truth",
                                          str(folder / "truth.ply"), "-o",
                                          str(tmp_path / "new" / "edges"), *options])
        assert not (tmp_path / "new").exists()


def test_through_a_real_subprocess(box_files, tmp_path):
    folder, _ = box_files
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    run = subprocess.run([sys.executable, "-c", "from cli.main import main; raise "
                          "SystemExit(main())", "edges", str(folder / "box.ply"), "--truth",
                          str(folder / "truth.ply"), "-o", str(tmp_path / "s")],
                         capture_output=True, text=True, env=env, timeout=240, check=False)
    assert run.returncode == 0, run.stderr
    assert (tmp_path / "s" / "edges.png").exists() and "wrote" in run.stdout
