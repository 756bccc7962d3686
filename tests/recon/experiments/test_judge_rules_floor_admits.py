"""``benchmarks/judge_rules.py rules --floor-admits``: which candidates step 3's floor lets into
the band stay there (any: auto's; method: those of the best's method; race: none), and the
race's share of it (``method_kept``)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks import judge_rules
from recon.surfaces import auto


def _candidates(*methods):
    return [SimpleNamespace(run=SimpleNamespace(method=m)) for m in methods]


@pytest.fixture
def fixed_band(monkeypatch):
    """auto.band stubbed: 0 the best, 1 in the bare band, 2 and 3 let in by the floor."""
    monkeypatch.setattr(auto, "band", lambda *args: ((0, 1, 2, 3), (2, 3)))


def test_any_is_autos_band(fixed_band):
    band = judge_rules.floor_admitting("any")
    assert band(_candidates("poisson", "visibility", "poisson", "plane"), [0, 1, 2, 3], 0,
                {}, None, 1.0) == ((0, 1, 2, 3), (2, 3))


def test_method_keeps_only_the_floors_candidates_of_the_best_method(fixed_band):
    band = judge_rules.floor_admitting("method")
    # the best (0) is Poisson: the floor's Poisson (2) stays, its plane (3) leaves; the bare
    # band's visibility (1) stays whatever its method
    assert band(_candidates("poisson", "visibility", "poisson", "plane"), [0, 1, 2, 3], 0,
                {}, None, 1.0) == ((0, 1, 2), (2,))


def test_race_keeps_none_of_the_floors_candidates(fixed_band):
    band = judge_rules.floor_admitting("race")
    assert band(_candidates("poisson", "visibility", "poisson", "plane"), [0, 1, 2, 3], 0,
                {}, None, 1.0) == ((0, 1), ())


def test_an_unknown_choice_is_refused():
    with pytest.raises(ValueError, match="admits"):
        judge_rules.floor_admitting("all")


def test_method_on_autos_select(monkeypatch):
    """Through ``auto.select``: a finer Poisson is the best, a coarser Poisson and a smaller
    plane surface are both beyond the bare band and within the floor; auto chooses the plane
    surface (the smallest model), ``method`` the coarser Poisson."""
    rng = np.random.default_rng(0)
    block = np.arange(400)
    base = 1.0 + rng.random(400)
    costs = {"fine": base, "coarse": base + 0.5 + 0.01 * rng.random(400),
             "plane": base + 0.6 + 0.01 * rng.random(400)}
    runs = [("fine", "poisson", 1000), ("coarse", "poisson", 500), ("plane", "plane", 400)]
    candidates = []
    for name, method, params in runs:
        c = auto.Candidate(SimpleNamespace(method=method, key=name, label=name), 1,
                           status="ok", n_params=params, holes=0.0, closed=False)
        c.cost = costs[name]
        c.chi2 = float(np.mean(c.cost))
        candidates.append(c)
    monkeypatch.setattr(auto.Candidate, "scored", property(lambda c: c.cost is not None))
    monkeypatch.setattr(auto.Candidate, "carved", property(lambda c: False))
    scale, floor = np.ones(400), 1.0
    assert auto.select(candidates, block, 400, scale=scale, floor=floor).chosen == 2
    monkeypatch.setattr(auto, "band", judge_rules.floor_admitting("method"))
    assert auto.select(candidates, block, 400, scale=scale, floor=floor).chosen == 1


def test_method_kept_lets_the_race_drop_the_floors_runs_of_other_methods():
    pool = _candidates("poisson", "poisson", "plane", "visibility")
    partial = [np.array([1.0]), np.array([2.0]), np.array([3.0]), np.array([9.0])]
    with_floor = [None, None, None, (8.0, 1.0)]     # the floor kept 1 and 2
    bare = [None, (1.0, 0.1), (2.0, 0.1), (8.0, 1.0)]
    assert judge_rules.method_kept(pool, partial, with_floor, bare) == [
        None, None, (2.0, 0.1), (8.0, 1.0)]


def test_the_command_line_takes_the_option(monkeypatch):
    parsed = []
    monkeypatch.setattr(judge_rules, "rules", parsed.append)
    judge_rules.main(["rules", "--suite", "s", "--work", "w", "--floor-admits", "method"])
    judge_rules.main(["rules", "--suite", "s", "--work", "w"])
    assert [a.floor_admits for a in parsed] == ["method", "any"]
