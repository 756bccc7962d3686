"""``benchmarks/judge_rules.py --held-out``: the suite's held-out clouds are read only on
request (once their evaluation is done), and a natural held-out body is told so."""

from __future__ import annotations

from types import SimpleNamespace

from benchmarks import judge_rules
from benchmarks import suite as suite_clouds


def _suite(tmp_path, clouds):
    for cloud in clouds:
        (tmp_path / cloud).mkdir(parents=True)
        (tmp_path / cloud / "results.jsonl").write_text("")
    return tmp_path


def test_held_out_clouds_are_read_only_with_the_option(tmp_path):
    tuning, held = suite_clouds.TUNING[0], suite_clouds.HELD_OUT[0]
    suite = _suite(tmp_path, [tuning, held])
    assert judge_rules.clouds_of(suite, None) == [tuning]
    assert judge_rules.clouds_of(suite, [held]) == []
    assert judge_rules.clouds_of(suite, [held], held_out=True) == [held]
    assert judge_rules.clouds_of(suite, None, held_out=True) == [tuning, held]


def test_collected_reads_the_option(tmp_path):
    held = suite_clouds.HELD_OUT[0]
    suite = _suite(tmp_path / "suite", [held])
    work = tmp_path / "work"
    (work / "folds").mkdir(parents=True)
    (work / "folds" / f"{held}.json").write_text("{}")
    args = SimpleNamespace(suite=suite, work=work, clouds=None)
    assert judge_rules.collected(args) == []
    args.held_out = True
    assert judge_rules.collected(args) == [held]


def test_a_natural_held_out_body_is_told_natural():
    natural = [c for c in suite_clouds.HELD_OUT
               if suite_clouds.CLOUDS[c].target_kind == "natural"]
    assert natural
    assert all(judge_rules.target_of(c) == "natural" for c in natural)
    assert all(judge_rules.target_of(c, prior=False) == "unknown" for c in natural)


def test_the_command_line_takes_the_option(monkeypatch):
    parsed = []
    monkeypatch.setattr(judge_rules, "rules", parsed.append)
    judge_rules.main(["rules", "--suite", "s", "--work", "w", "--held-out"])
    judge_rules.main(["rules", "--suite", "s", "--work", "w"])
    assert [a.held_out for a in parsed] == [True, False]
