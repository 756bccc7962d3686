"""``benchmarks/judge_rules.py rules --floor-admits``: which candidates step 3's floor lets into
the band stay there (method: those of the best's method, auto's; race: none)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from benchmarks import judge_rules
from recon.surfaces import auto


def _candidates(*methods):
    return [SimpleNamespace(run=SimpleNamespace(method=m)) for m in methods]


@pytest.fixture
def fixed_band(monkeypatch):
    """auto.band stubbed: 0 the best, 1 in the bare band, 2 let in by the floor."""
    monkeypatch.setattr(auto, "band", lambda *args: ((0, 1, 2), (2,)))


def test_method_is_autos_band(fixed_band):
    band = judge_rules.floor_admitting("method")
    assert band(_candidates("poisson", "visibility", "poisson"), [0, 1, 2], 0,
                {}, None, 1.0) == ((0, 1, 2), (2,))


def test_race_keeps_none_of_the_floors_candidates(fixed_band):
    band = judge_rules.floor_admitting("race")
    assert band(_candidates("poisson", "visibility", "poisson"), [0, 1, 2], 0,
                {}, None, 1.0) == ((0, 1), ())


def test_an_unknown_choice_is_refused():
    with pytest.raises(ValueError, match="admits"):
        judge_rules.floor_admitting("any")


def test_the_command_line_takes_the_option(monkeypatch):
    parsed = []
    monkeypatch.setattr(judge_rules, "rules", parsed.append)
    judge_rules.main(["rules", "--suite", "s", "--work", "w", "--floor-admits", "race"])
    judge_rules.main(["rules", "--suite", "s", "--work", "w"])
    assert [a.floor_admits for a in parsed] == ["race", "method"]
