"""The auto suite's quick form on one tiny cloud: it runs, scores auto against the truth and
writes its table and chart (the full suite is ``python benchmarks/suite.py``)."""

from __future__ import annotations

import json

import pytest

from benchmarks import suite


def test_suite_defines_the_clouds_the_issue_asks_for():
    clouds = suite.CLOUDS.values()
    assert len(suite.CLOUDS) >= 12
    assert {"asteroid", "RSO-A", "RSO-B"} <= {c.target for c in clouds}
    assert {"LRF + 2 deg slew", "cross", "LIDAR"} <= {c.sensor for c in clouds}
    assert len({c.mesh for c in clouds if c.mesh}) >= 4
    assert {c.errors for c in clouds} == {"none", "paper"}
    assert {c.density for c in clouds} == {"dense", "sparse"}


def test_quick_suite_on_one_cloud(tmp_path):
    doc = tmp_path / "docs" / "auto-suite.md"
    doc.parent.mkdir()
    status = suite.main(["--quick", "--clouds", "asteroid-cross-noisy", "--methods",
                         "ellipsoid", "planes", "poisson", "--out", str(tmp_path / "out"),
                         "--doc", str(doc), "--workers", "2"])
    assert status == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    (cloud,) = summary["clouds"]
    labels = {r["label"] for r in cloud["ranking"]}
    # Every method at its defaults plus the ellipsoid's unweighted twin, all scored.
    assert labels == {"ellipsoid", "ellipsoid weighted=False", "planes", "poisson"}
    verdict = cloud["verdict"]
    # The paper's asteroid is an ellipsoid: 9 numbers are the truth's best model, and auto
    # must find them from ~800 noisy strikes.
    assert verdict["best_chamfer_label"].startswith("ellipsoid")
    assert verdict["within_f"] and verdict["within_chamfer"], cloud["auto"]["reason"]
    assert cloud["weighting"]["ellipsoid"]["chamfer_weighted"] > 0
    assert summary["totals"]["within_both"] == pytest.approx(1.0)
    text = doc.read_text()
    assert "asteroid-cross-noisy" in text and "| cloud | points | auto's choice" in text
    assert (doc.parent / "figures" / "auto-suite.png").stat().st_size > 10_000
