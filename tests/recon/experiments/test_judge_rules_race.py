"""``benchmarks/judge_rules.py rules --race``: the folds recovered from a collection's blocks are
``judge.pass_folds``'s, and the replayed race takes out the run ``auto.outpaced`` takes out."""

from __future__ import annotations

import numpy as np

from benchmarks import judge_rules
from formats.geometry import Cloud
from recon.surfaces import auto, judge
from recon.surfaces.methods import bind


def collected_blocks(seed: int, folds_out: list | None = None):
    """The tested strikes' blocks of a 2000-shot log as ``collect`` keeps them (fold by fold)
    and its ``folds`` record."""
    points = np.random.default_rng(0).normal(size=(2000, 3))
    cloud = Cloud(points, {"shot": np.arange(2000), "beam": np.zeros(2000)})
    folds = judge.pass_folds(cloud, 4, seed=seed)
    if folds_out is not None:
        folds_out.append(folds)
    block = np.concatenate([folds.block[folds.test(f)] for f in range(folds.k)])
    return block, {"k": folds.k, "n_blocks": folds.n_blocks}


def test_fold_of_recovers_the_folds_of_the_collected_strikes():
    for seed in (0, 3):
        out = []
        block, record = collected_blocks(seed, out)
        folds = out[0]
        assert np.array_equal(judge_rules.fold_of(block, record, seed), np.concatenate(
            [folds.fold[folds.test(f)] for f in range(folds.k)]))


def test_the_replayed_race_takes_out_the_far_run_with_its_carved_twin():
    block, record = collected_blocks(0)
    rng = np.random.default_rng(1)

    def candidate(method, params, level, mean, carved=False):
        c = auto.Candidate(bind(method, params), level, "ok", closed=False, carved=carved)
        c.cost = mean + rng.normal(0.0, 0.3, len(block))
        c.chi2, c.chi2_se = judge.block_mean_se(c.cost, block)
        return c

    table = [candidate("ellipsoid", {}, 0, 1.0), candidate("planes", {}, 0, 9.0),
             candidate("poisson", {"depth": 6}, 1, 1.02),
             candidate("poisson", {"depth": 9}, 2, 4.0),
             candidate("poisson", {"depth": 9}, 2, 3.9, carved=True)]
    kept, gone = judge_rules.race(table, block, record, 0)
    assert [c.label for c in gone] == ["poisson depth=9"]
    status = {c.label: c.status for c in kept}
    assert status == {"ellipsoid": "ok", "planes": "ok", "poisson depth=6": "ok",
                      "poisson depth=9": "outpaced"}   # level 0 is not raced; no twin left
    assert not next(c for c in kept if c.status == "outpaced").scored


def test_the_replay_fits_the_completion_of_a_natural_body_after_the_ladder_as_auto_does():
    # A natural body seen over a fifth of it: the ellipsoid lies far from the held-out strikes
    # (the prior does not act), Poisson depth 6 is the ladder's choice, and the completion,
    # collected after the ladder, fits the held-out strikes as well while the ellipsoid reaches
    # only 1.1 times the strikes' extent: auto takes it (``auto.completed``), and so does the
    # replay. Told nothing of the target, neither fits it. It does not race.
    block, record = collected_blocks(0)
    rng = np.random.default_rng(2)

    def candidate(method, params, level, mean, n_params, **kwargs):
        c = auto.Candidate(bind(method, params), level, "ok", n_params=n_params, holes=0.0,
                           **kwargs)
        c.cost = mean + rng.normal(0.0, 0.3, len(block))
        c.chi2, c.chi2_se = judge.block_mean_se(c.cost, block)
        return c

    table = [candidate("ellipsoid", {}, 0, 9.0, 9, closed=True, heldout_mean_m=5.0, span=1.1),
             candidate("poisson", {"depth": 6}, 1, 1.0, 10_000, closed=False),
             candidate("poisson", {"depth": 9}, 2, 1.1, 20_000, closed=False),
             candidate(auto.NATURAL_COMPLETION, {}, len(auto.LADDER), 1.01, 12_000,
                       closed=True)]
    chosen, fitted = judge_rules.replay(table, block, 0.2, 1.0, 2000, "natural")
    assert chosen.run.method == auto.NATURAL_COMPLETION
    chosen, fitted = judge_rules.replay(table, block, 0.2, 1.0, 2000, "unknown")
    assert chosen.label == "poisson depth=6"
    assert auto.NATURAL_COMPLETION not in [c.run.method for c in fitted]
    kept, gone = judge_rules.race(table, block, record, 0)
    assert kept[-1] is table[-1] and table[-1] not in gone
