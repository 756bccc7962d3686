"""`recon score` end to end: logs, clouds from other tools, meshes, and every bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

import sim
from cli.main import main
from formats.cloud_io import write_cloud
from formats.geometry import Cloud
from formats.mesh_io import write_mesh

KEYS = ("n_points", "tau_m", "accuracy_mean_m", "completeness_mean_m", "chamfer_m",
        "hausdorff_m", "precision", "recall", "fscore", "coverage", "edge_score")


@pytest.fixture(scope="module")
def rso_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("score") / "rso.h5"
    sim.simulate(sim.load_scene("rso-a-lrf", ["time.rotations=2"]), path, seed=1)
    return path


def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_log_scores_against_its_own_truth(rso_log, capsys):
    result = _json(capsys, ["score", str(rso_log), "--json"])
    assert all(k in result for k in KEYS)
    assert result["accuracy_mean_m"] < 1e-6  # noise-free strikes lie on the truth
    assert 0 < result["coverage"] < 1 and 0 <= result["edge_score"] <= 1


def test_open3d_cloud_against_a_truth_mesh_file(rso_log, tmp_path, capsys):
    import open3d as o3d

    assert main(["truth", str(rso_log), "-o", str(tmp_path / "truth.ply")]) == 0
    assert main(["ingest", str(rso_log), "-o", str(tmp_path / "cloud.ply")]) == 0
    pcd = o3d.io.read_point_cloud(str(tmp_path / "cloud.ply"))
    o3d.io.write_point_cloud(str(tmp_path / "o3d.ply"), pcd)
    capsys.readouterr()
    a = _json(capsys, ["score", str(tmp_path / "o3d.ply"), "--truth",
                       str(tmp_path / "truth.ply"), "--json", "--no-edges"])
    b = _json(capsys, ["score", str(rso_log), "--json", "--no-edges"])
    assert a["n_points"] == b["n_points"]
    assert a["chamfer_m"] == pytest.approx(b["chamfer_m"], rel=1e-6)
    assert a["edge_score"] is None


def test_mesh_scores_and_table_output(rso_log, tmp_path, capsys):
    assert main(["truth", str(rso_log), "-o", str(tmp_path / "truth.ply")]) == 0
    capsys.readouterr()
    assert main(["score", str(tmp_path / "truth.ply"), "--truth", str(rso_log), "--tau",
                 "0.1", "--no-edges"]) == 0
    out = capsys.readouterr().out
    assert "(mesh)" in out and "F-score at tau" in out
    assert "tau                                0.1 m" in out


def _error(capsys, argv):
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0, err
    return err


def test_log_without_truth_and_no_truth_argument(tmp_path, capsys):
    from tests.conftest import write_sphere_log

    path = tmp_path / "bare.h5"
    write_sphere_log(path, with_truth=False)
    assert _error(capsys, ["score", str(path)]) == (
        f"recon score: error: --truth: {path} is a strike log without a truth mesh; give a "
        "mesh file as the truth")


def test_cloud_without_truth_argument(tmp_path, capsys):
    write_cloud(tmp_path / "c.ply", Cloud(np.ones((5, 3))))
    assert _error(capsys, ["score", str(tmp_path / "c.ply")]) == (
        f"recon score: error: --truth must be given: {tmp_path / 'c.ply'} is not a strike log "
        "with truth")


def test_truth_that_is_not_a_mesh(rso_log, tmp_path, capsys):
    write_cloud(tmp_path / "c.ply", Cloud(np.ones((5, 3))))
    assert "has no triangles" in _error(
        capsys, ["score", str(rso_log), "--truth", str(tmp_path / "c.ply")])
    write_cloud(tmp_path / "c.las", Cloud(np.ones((5, 3))))
    assert "is not a mesh" in _error(
        capsys, ["score", str(rso_log), "--truth", str(tmp_path / "c.las")])


def test_empty_cloud(rso_log, tmp_path, capsys):
    write_cloud(tmp_path / "empty.ply", Cloud(np.zeros((0, 3))))
    assert "empty" in _error(capsys, ["score", str(tmp_path / "empty.ply"), "--truth",
                                      str(rso_log)])


def test_nan_coordinates(rso_log, tmp_path, capsys):
    points = np.ones((10, 3))
    points[3, 1] = np.nan
    write_cloud(tmp_path / "nan.ply", Cloud(points))
    assert "NaN or Inf" in _error(capsys, ["score", str(tmp_path / "nan.ply"), "--truth",
                                           str(rso_log)])


def test_km_against_m_warns(rso_log, tmp_path, capsys):
    from sim.targets import rso_a

    vertices, faces = rso_a()
    write_mesh(tmp_path / "km.ply", vertices / 1000.0, faces)
    assert main(["score", str(rso_log), "--truth", str(tmp_path / "km.ply"), "--no-edges"]) == 0
    err = capsys.readouterr().err
    assert "recon score: warning:" in err and "probably km against m" in err


def test_edge_variant_option(rso_log, capsys):
    from recon import api

    for variant in ("weighted", "feature"):
        result = _json(capsys, ["score", str(rso_log), "--json", "--edge-variant", variant])
        expected = api.score(rso_log, truth=rso_log, edge_options={"variant": variant})
        assert result["edge"]["variant"] == variant
        assert result["edge_score"] == expected.edge_score
    with pytest.raises(SystemExit) as exit_:
        main(["score", str(rso_log), "--edge-variant", "sharp"])
    assert exit_.value.code == 1
    assert "invalid choice: 'sharp'" in capsys.readouterr().err


def test_precision_option_states_what_it_asked(rso_log, capsys):
    coarse = _json(capsys, ["score", str(rso_log), "--json", "--no-edges", "--precision", "0.2"])
    default = _json(capsys, ["score", str(rso_log), "--json", "--no-edges"])
    assert coarse["target_precision"] == 0.2 and default["target_precision"] == 0.02
    assert default["chamfer_se_m"] <= 1.05 * 0.02 * default["chamfer_m"]
    assert default["fscore_se"] <= 1.05 * 0.005
    assert main(["score", str(rso_log), "--precision", "-1"]) == 1
    assert "precision must be a number in (0, 0.5]" in capsys.readouterr().err


def test_a_precision_whose_lattice_would_not_fit_is_one_line_before_any_work(
        tmp_path, capsys, monkeypatch):
    import importlib

    from tests.conftest import icosphere

    def never(*args):
        raise AssertionError("the coverage lattice was built")

    monkeypatch.setattr(importlib.import_module("metrics.score"), "coverage_lattice", never)
    vertices, faces = icosphere(10.0, 3)
    write_cloud(tmp_path / "c.ply", Cloud(vertices))
    write_mesh(tmp_path / "t.ply", vertices, faces)
    assert _error(capsys, ["score", str(tmp_path / "c.ply"), "--truth", str(tmp_path / "t.ply"),
                           "--precision", "1e-9", "--no-edges"]) == (
        "recon score: error: --precision 1e-09 asks a coverage lattice of 335,544,320 points on "
        "the truth's 1,280 faces, about 80.5 GB of memory, more than the 4.3 GB allowed; give "
        "at least 0.00048")
