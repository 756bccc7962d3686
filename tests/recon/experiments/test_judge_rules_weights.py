"""``benchmarks/judge_rules.py rules --weights area``: each held-out strike weighs by the area it
stands for (one over the strikes within the support reach), so a sparsely struck region counts
by its area, not by its strikes; on a uniformly struck surface the weights are all about 1 and
the choice is the strike-weighted one."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks import judge_rules
from recon.surfaces import auto, judge
from recon.surfaces.methods import bind


def half_dense_plate() -> tuple[np.ndarray, np.ndarray]:
    """A 2 m x 1 m plate struck every 2 cm on its left half and every 10 cm on its right half
    (2,500 and 100 strikes: 4 % of them on half the area); per strike, its block (ten strips
    across both halves)."""
    dense = np.stack(np.meshgrid(np.arange(50) * 0.02 + 0.01, np.arange(50) * 0.02 + 0.01),
                     -1).reshape(-1, 2)
    sparse = np.stack(np.meshgrid(np.arange(10) * 0.1 + 1.05, np.arange(10) * 0.1 + 0.05),
                      -1).reshape(-1, 2)
    xy = np.concatenate([dense, sparse])
    points = np.column_stack([xy, np.zeros(len(xy))])
    return points, np.minimum((xy[:, 1] * 10).astype(np.int64), 9)


def fibonacci_sphere(n: int) -> np.ndarray:
    """``n`` strikes spread evenly over the unit sphere (no edge: every strike has as many
    neighbours)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = np.pi * (1.0 + 5**0.5) * i
    r = np.sqrt(1.0 - z**2)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def candidates(block: np.ndarray, costs: dict[str, np.ndarray], weight=None) -> list:
    """Ladder candidates with held-out ``costs`` (``weighted`` by ``weight`` when given), as
    ``candidates_of`` makes them."""
    runs = {"ellipsoid": (bind("ellipsoid", {}), 0, 9), "poisson": (bind("poisson", {}), 1, 5000)}
    out = []
    for name, cost in costs.items():
        run, level, n_params = runs[name]
        c = auto.Candidate(run, level, "ok", n_params=n_params, holes=0.0, closed=True)
        c.cost = cost if weight is None else judge_rules.weighted(cost, weight)
        c.chi2, c.chi2_se = judge.block_mean_se(c.cost, block)
        out.append(c)
    return out


def test_area_weights_count_a_sparsely_struck_half_by_its_area_not_its_strikes():
    points, block = half_dense_plate()
    sparse = points[:, 0] > 1.0
    tested = np.arange(len(points))
    weight = judge_rules.strike_weights(points, tested, 0.15)
    assert weight.mean() == pytest.approx(1.0)
    assert sparse.mean() == pytest.approx(0.04, abs=0.002)   # strike-weighted share
    # area-weighted share: half the plate, less the sparse strikes that see dense ones at the
    # seam (their counts include them)
    assert 0.35 < np.mean(sparse * weight) < 0.55
    # a surface leaving the sparse half in holes (cost at the cap there) against one a little
    # worse than the noise everywhere: by strikes the holed one is best, by area the other
    rng = np.random.default_rng(0)
    costs = {"ellipsoid": np.where(sparse, 25.0, 0.5) + rng.normal(0, 0.05, len(points)),
             "poisson": 2.0 + rng.normal(0, 0.05, len(points))}
    by_strikes = candidates(block, costs)
    by_area = candidates(block, costs, weight)
    assert by_strikes[0].chi2 < by_strikes[1].chi2
    assert by_area[0].chi2 > 4 * by_area[1].chi2
    chosen = [judge_rules.replay(c, block, 1.0, 1.0, len(points))[0].run.method
              for c in (by_strikes, by_area)]
    assert chosen == ["ellipsoid", "poisson"]


def test_a_uniformly_struck_surface_weighs_every_strike_about_the_same_and_chooses_alike():
    points = fibonacci_sphere(4000)
    tested = np.arange(0, len(points), 2)
    block = (np.arctan2(points[tested, 1], points[tested, 0]) // (np.pi / 6)).astype(np.int64)
    weight = judge_rules.strike_weights(points, tested, 0.15)
    assert np.abs(weight - 1.0).max() < 0.1
    rng = np.random.default_rng(1)
    costs = {"ellipsoid": rng.gamma(2.0, 1.0, len(tested)),
             "poisson": rng.gamma(2.0, 0.8, len(tested))}
    by_strikes = candidates(block, costs)
    by_area = candidates(block, costs, weight)
    for a, b in zip(by_strikes, by_area, strict=True):
        assert b.chi2 == pytest.approx(a.chi2, rel=0.02)
        assert b.chi2_se == pytest.approx(a.chi2_se, rel=0.1)
    assert judge_rules.replay(by_strikes, block, 1.0, 1.0, len(tested))[0].run.method == \
        judge_rules.replay(by_area, block, 1.0, 1.0, len(tested))[0].run.method


def test_the_cap_bounds_a_lone_strike_s_weight_and_must_keep_the_median():
    weight = judge_rules.capped(np.array([1.0, 1.0, 1.0, 1.0, 50.0]), 4.0)
    assert weight.mean() == pytest.approx(1.0)
    assert weight[-1] / np.median(weight) == pytest.approx(4.0)
    assert np.array_equal(judge_rules.capped(np.ones(3), None), np.ones(3))
    with pytest.raises(ValueError, match="cap must be at least 1"):
        judge_rules.capped(np.ones(3), 0.5)
    with pytest.raises(ValueError, match="weight must match the costs"):
        judge_rules.weighted(np.ones(3), np.ones(4))


def test_collected_candidates_take_the_weights_into_their_chi_square(tmp_path):
    # a collection of two ladder runs (``collect``'s files): the weighted cost's block mean
    # and standard error are the candidates' chi-square, as the replay reads them
    points, block = half_dense_plate()
    sparse = points[:, 0] > 1.0
    cost = np.where(sparse, 25.0, 0.5)
    runs = [run for level in auto.ladder() for run in level][:2]
    rows = [{"method": r.method, "params": r.params, "key": r.key, "label": r.method,
             "status": "ok", "n_params": 9, "holes": 0.0, "closed": True, "chi2": 0.0}
            for r in runs]
    (tmp_path / "folds").mkdir()
    (tmp_path / "folds" / "plate.json").write_text(json.dumps({"auto": {
        "candidates": rows, "coverage": 1.0, "tau_m": 0.1, "n_checked": len(points)}}))
    np.savez(tmp_path / "folds" / "plate.npz", block=block,
             **{f"cost/{r.key}": cost for r in runs})
    weight = judge_rules.strike_weights(points, np.arange(len(points)), 0.15)
    plain = judge_rules.candidates_of(tmp_path, "plate", False)[0]
    area = judge_rules.candidates_of(tmp_path, "plate", False, weight=weight)[0]
    assert [c.chi2 for c in plain] == [0.0, 0.0]   # collected, as auto measured them
    for c in area:
        assert (c.chi2, c.chi2_se) == pytest.approx(judge.block_mean_se(cost * weight, block))
        assert c.chi2 == pytest.approx(np.sum(cost * weight) / np.sum(weight))
        assert c.chi2 > 10 * np.mean(cost) / 2


def test_a_weight_cap_without_area_weights_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        judge_rules.main(["rules", "--suite", str(tmp_path), "--work", str(tmp_path),
                          "--weight-cap", "4"])
    assert "--weight-cap needs --weights area" in capsys.readouterr().err
