"""``benchmarks/judge_rules.py collect`` on a natural body whose completion fails on every fold:
the ladder's collection is kept, without a completion (auto keeps such a completion as a failed
candidate; the harness's second ``choose`` on the completion alone raises)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks import judge_rules
from formats.errors import MethodFailed
from recon.surfaces import auto


def _choice():
    folds = SimpleNamespace(k=2, block=np.array([0, 1, 0, 1]),
                            test=lambda f: np.array([f, f + 2]))
    candidate = SimpleNamespace(key="plane {}", cost=None, to_dict=lambda: {"label": "plane"})
    return SimpleNamespace(candidates=[candidate], folds=folds,
                           to_dict=lambda: {"label": "plane", "folds": {"k": 2}})


def _args(tmp_path, cloud):
    (tmp_path / "suite" / cloud).mkdir(parents=True)
    (tmp_path / "suite" / cloud / "results.jsonl").write_text("")
    return SimpleNamespace(suite=tmp_path / "suite", work=tmp_path / "work", clouds=[cloud],
                           force=False, holdout=0.25, seed=0, workers=1)


@pytest.fixture
def natural_cloud(monkeypatch):
    cloud = judge_rules.NATURAL[0]
    cloud_points = SimpleNamespace(points=np.zeros((4, 3)), view_points=None, attributes={})
    monkeypatch.setattr(judge_rules, "load_cloud", lambda suite, name: cloud_points)
    monkeypatch.setattr(judge_rules, "candidate_runs", lambda rows: [])
    monkeypatch.setattr(auto, "misses_near", lambda *a, **k: None)
    return cloud


def test_a_completion_failing_everywhere_leaves_the_ladder_collected(tmp_path, monkeypatch,
                                                                     natural_cloud):
    calls = []

    def choose(*args, candidates, **kwargs):
        calls.append(candidates)
        if len(calls) == 2:
            raise MethodFailed("auto: every candidate failed: completed-poisson: degenerate")
        return _choice()

    monkeypatch.setattr(auto, "choose", choose)
    args = _args(tmp_path, natural_cloud)
    judge_rules.collect(args)
    assert len(calls) == 2      # the ladder, then the completion alone
    record = json.loads((args.work / "folds" / f"{natural_cloud}.json").read_text())
    assert [c["label"] for c in record["auto"]["candidates"]] == ["plane"]
    assert np.load(args.work / "folds" / f"{natural_cloud}.npz")["block"].tolist() == [0, 0, 1, 1]


def test_a_ladder_failing_everywhere_is_still_an_error(tmp_path, monkeypatch, natural_cloud):
    def choose(*args, **kwargs):
        raise MethodFailed("auto: every candidate failed")

    monkeypatch.setattr(auto, "choose", choose)
    args = _args(tmp_path, natural_cloud)
    with pytest.raises(MethodFailed):
        judge_rules.collect(args)
    assert not (args.work / "folds" / f"{natural_cloud}.json").exists()
