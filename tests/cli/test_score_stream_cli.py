"""`recon score LOG` streams the log (metrics.score.score_stream): the same report as the whole
registered cloud scored at once, as `recon score` gave before it streamed."""

from __future__ import annotations

import json

import pytest

import sim
from cli.main import main
from formats.geometry import Cloud
from metrics import defaults, score
from recon.inputs import load_truth
from recon.registration import ingest

EXACT = ("accuracy_mean_m", "accuracy_rms_m", "chamfer_m")   # sums, grouped by block


def _assert_same_report(streamed: dict, whole: dict) -> None:
    """Every key equal, the block-grouped sums to 1e-9 relative."""
    assert streamed.keys() == whole.keys()
    for key, value in whole.items():
        if key in EXACT:
            assert streamed[key] == pytest.approx(value, rel=1e-9, abs=0), key
        else:
            assert streamed[key] == value, key


@pytest.fixture(scope="module")
def rso_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("stream") / "rso.h5"
    sim.simulate(sim.load_scene("rso-a-lrf", ["time.rotations=2"]), path, seed=1)
    return path


@pytest.mark.parametrize("log", ["rso_log", "sphere_log"])
@pytest.mark.parametrize("edges", [True, False])
def test_streamed_log_scores_as_the_whole_cloud(log, edges, request, monkeypatch, capsys):
    path = request.getfixturevalue(log)
    whole = score(Cloud(ingest.ingest_points(path)), load_truth(path), seed=0,
                  edges=edges and log == "rso_log").to_dict()
    # Many blocks, several nearest-distance groups, and radix passes for the median and p95.
    monkeypatch.setattr(ingest, "SCORE_CHUNK_ROWS", 37)
    monkeypatch.setattr(defaults, "STREAM_BLOCK", 500)
    monkeypatch.setattr(defaults, "QUANTILE_KEEP", 20)
    argv = ["score", str(path), "--json"] + ([] if edges and log == "rso_log" else ["--no-edges"])
    assert main(argv) == 0
    streamed = json.loads(capsys.readouterr().out)
    assert streamed.pop("test") == streamed.pop("truth") == str(path)
    _assert_same_report(streamed, whole)


@pytest.mark.parametrize("suffix", [".ply", ".h5", ".las"])
def test_streamed_cloud_file_scores_as_the_whole_cloud(suffix, rso_log, tmp_path, monkeypatch,
                                                       capsys):
    from formats import cloud_io

    path = cloud_io.write_cloud(tmp_path / f"cloud{suffix}",
                                Cloud(ingest.ingest_points(rso_log)))
    cloud = cloud_io.read_cloud(path)
    # A sample of the cloud smaller than the cloud (kept block by block), a small pilot.
    monkeypatch.setattr(defaults, "CLOUD_SAMPLES", 1000)
    monkeypatch.setattr(defaults, "PILOT_SAMPLES", 400)
    whole = score(cloud, load_truth(rso_log), seed=0).to_dict()
    assert 400 <= whole["n_points"] <= 1000 < len(cloud)
    monkeypatch.setattr(defaults, "STREAM_BLOCK", 500)   # the file read in many blocks
    monkeypatch.setattr(defaults, "QUANTILE_KEEP", 20)
    stream_cloud, blocks_read = cloud_io.stream_cloud, []

    def spy(file, rows):
        frame, blocks = stream_cloud(file, rows)
        return frame, lambda: (blocks_read.append(len(b[0])) or b for b in blocks())
    monkeypatch.setattr(cloud_io, "stream_cloud", spy)
    monkeypatch.setattr(cloud_io, "read_cloud", None)   # the file is never read whole
    assert main(["score", str(path), "--truth", str(rso_log), "--json"]) == 0
    assert max(blocks_read) == 500 and sum(blocks_read) >= len(cloud)   # blocks
    streamed = json.loads(capsys.readouterr().out)
    streamed.pop("test"), streamed.pop("truth")
    _assert_same_report(streamed, whole)


def test_a_sampled_cloud_says_so_in_the_readable_report(rso_log, tmp_path, monkeypatch, capsys):
    # Sampled to the precision, the report says how many of the cloud's points were scored and
    # that the median, 95th percentile and Hausdorff are the sample's; the JSON carries both.
    from formats import cloud_io

    path = cloud_io.write_cloud(tmp_path / "cloud.ply", Cloud(ingest.ingest_points(rso_log)))
    n = len(cloud_io.read_cloud(path))
    monkeypatch.setattr(defaults, "CLOUD_SAMPLES", 1000)
    monkeypatch.setattr(defaults, "PILOT_SAMPLES", 400)
    assert main(["score", str(path), "--truth", str(rso_log), "--no-edges"]) == 0
    text = capsys.readouterr().out
    assert f" of {n} (a seeded sample sized by the precision)" in text
    assert "Hausdorff are the sample's" in text
    assert main(["score", str(path), "--truth", str(rso_log), "--no-edges", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["n_test_points"] == n > report["n_points"]
