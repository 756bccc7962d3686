"""The bennu-ola preset's log written as OLA Level-2 and Hayabusa2 LIDAR Level-2 products, read
back by ``recon ingest`` and accepted by ``recon score`` against the log's truth."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from cli.main import main
from formats import StrikeLog
from formats.altimetry import read_label
from formats.cloud_io import read_cloud
from formats.errors import InputError
from recon import api
from recon.registration.altimetry import export_altimetry
from sim.scene import MESH_PATH_VARIABLE
from tests.conftest import SHARED_MESHES

BENNU = "bennu_radar_2.7k.obj"


def _mesh_dirs() -> list[str]:
    """Where the shared Bennu model is: RECON_MESH_PATH, else the shared folder beside the
    checkout."""
    dirs = [d for d in os.environ.get(MESH_PATH_VARIABLE, "").split(os.pathsep) if d]
    return [d for d in [*dirs, str(SHARED_MESHES)] if os.path.isfile(os.path.join(d, BENNU))]


pytestmark = pytest.mark.skipif(not _mesh_dirs(), reason="the shared Bennu model is not present")


@pytest.fixture(scope="module")
def bennu_log(tmp_path_factory):
    """A quarter rotation of the preset (64 shots x 400 beams)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(MESH_PATH_VARIABLE, _mesh_dirs()[0])
        path = tmp_path_factory.mktemp("bennu") / "bennu.h5"
        return api.simulate("bennu-ola", path, seed=4, overrides=["time.rotations=0.25"]).path


def test_preset_is_bennu_sized_in_metres(bennu_log):
    with StrikeLog(bennu_log) as log:
        vertices = log.truth_mesh().vertices
        assert log.sensor.pattern == "grid" and log.sensor.n_beams == 400
        assert log.sensor.errors.range_sigma3 == pytest.approx(0.06)
    extent = np.ptp(vertices, axis=0)
    assert extent == pytest.approx([566.5, 535.9, 508.8], rel=1e-3)   # the km model x 1000


def test_preset_names_its_mesh_path_when_it_is_not_found(monkeypatch, tmp_path):
    monkeypatch.setenv(MESH_PATH_VARIABLE, str(tmp_path))
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "bennu-ola", "-o", str(tmp_path / "x.h5")]) == 1


@pytest.mark.parametrize(("name", "product"), [("ola.xml", "ola-l2"),
                                               ("lidar.csv", "hayabusa2-lidar-l2")])
def test_products_read_back_and_score_against_the_truth(bennu_log, tmp_path, capsys, name,
                                                        product):
    summary = export_altimetry(bennu_log, tmp_path / name, epoch_et=6.03e8)
    with StrikeLog(bennu_log) as log:
        misses = log.n_shots * log.sensor.n_beams - log.n_strikes
    if product == "ola-l2":
        assert summary["n_no_return"] == misses > 0
        assert read_label(tmp_path / name).record_length == 186
    cloud_path = tmp_path / "cloud.ply"
    assert main(["ingest", str(tmp_path / name), "-o", str(cloud_path)]) == 0
    out = capsys.readouterr().out
    assert f"{product}" in out
    assert (f"dropped {misses} no return" if product == "ola-l2" else "dropped none") in out
    ingested = api.ingest(bennu_log)
    cloud = read_cloud(cloud_path)
    # the products hold the log's registered strikes: metres (OLA: binary doubles; CSV: 1 um)
    np.testing.assert_allclose(cloud.points, ingested.points, atol=1e-6)
    np.testing.assert_allclose(cloud.view_points, ingested.view_points, atol=1e-6)
    np.testing.assert_allclose(cloud.attributes["et"], 6.03e8 + ingested.attributes["time"],
                               atol=1e-6)
    assert main(["score", str(cloud_path), "--truth", str(bennu_log), "--no-edges",
                 "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["n_test_points"] == len(ingested.points) >= report["n_points"]
    # centimetre ranges: every return within a few cm of the truth surface
    assert report["accuracy_p95_m"] < 0.1 and report["precision"] == 1.0


def test_export_refuses_a_suffix_it_cannot_write(bennu_log, tmp_path, capsys):
    with pytest.raises(InputError, match=r"written as its \.xml label"):
        export_altimetry(bennu_log, tmp_path / "x.dat")
    assert main(["ingest", str(tmp_path / "none.xml"), "-o", str(tmp_path / "c.ply")]) == 1
    assert "none.xml" in capsys.readouterr().err
    assert main(["ingest", str(tmp_path / "none.csv"), "-o", str(tmp_path / "c.ply"),
                 "--refine"]) == 1
    assert "--refine apply to strike logs" in capsys.readouterr().err


def test_a_truncated_table_is_one_line_from_the_command(bennu_log, tmp_path):
    """Through a real process: exit status 1, one line naming the table, no traceback."""
    import subprocess
    import sys
    from pathlib import Path

    export_altimetry(bennu_log, tmp_path / "ola.xml")
    data = tmp_path / "ola.dat"
    data.write_bytes(data.read_bytes()[:-100])
    repo = Path(__file__).resolve().parents[3]
    done = subprocess.run([sys.executable, "-m", "cli", "ingest", str(tmp_path / "ola.xml"),
                           "-o", str(tmp_path / "c.ply")], capture_output=True, text=True,
                          cwd=tmp_path, env=os.environ | {"PYTHONPATH": str(repo)},
                          timeout=120)
    assert done.returncode == 1
    assert done.stderr.count("\n") == 1 and "ola.dat" in done.stderr
    assert "declares" in done.stderr and "Traceback" not in done.stderr
    assert not (tmp_path / "c.ply").exists()
