"""The opening a missed held-out beam passed (``benchmarks/judge_rules.py``'s crack statistic):
a beam through a narrow crack of a surface is told from a beam through a wide hole."""

from __future__ import annotations

import numpy as np
from cracked_plates import CRACKED, HOLED

from benchmarks import judge_rules
from recon.surfaces import judge

RADIUS = 0.3   # the crack's limit [m] (auto.miss_reach in the harness)


def _missed_beam(surface, **options):
    """A beam straight down through the plate's centre, its strike 0.02 m below the plane."""
    strikes = judge.Strikes(np.array([[0.0, 0.0, -0.02]]), np.array([[0.0, 0.0, 10.0]]))
    caster = judge.Caster(*surface)
    return strikes, caster, judge.check(strikes, caster, tau=0.1, noise=0.01, **options)


def test_a_beam_through_a_crack_is_told_from_a_beam_through_a_hole():
    for surface, crack, opening in ((CRACKED, True, 0.25), (HOLED, False, 4.0)):
        strikes, caster, result = _missed_beam(surface)
        assert result.missed.all()
        size = judge_rules.opening_of(strikes, caster, result, RADIUS)
        # The smallest ring that meets the surface on at least half its rays: 0.075 m crosses
        # the crack's 0.05 m half-width; only 1.2 m reaches past the hole's 0.7 m.
        assert size.tolist() == [opening]
        # The product's crack test is the opening within the width.
        _, _, product = _missed_beam(surface, crack=RADIUS)
        assert product.crack.tolist() == [crack] == (size <= 1.0).tolist()


def test_the_replayed_crack_statistic_is_the_product_s_cost():
    costs = []
    for surface in (CRACKED, HOLED):
        strikes, caster, result = _missed_beam(surface)
        assert result.cost[0] == (result.tolerance[0] / result.sigma[0]) ** 2   # the cap
        per = {"distance": result.distance, "tolerance": result.tolerance,
               "sigma": result.sigma, "missed": result.missed, "cost": result.cost,
               "opening": judge_rules.opening_of(strikes, caster, result, RADIUS)}
        per["crack"] = per["missed"] & (per["opening"] <= 1.0)
        replayed = judge_rules.STATISTICS["closest-fold-cracks"](result.cost, per)[0]
        _, _, product = _missed_beam(surface, crack=RADIUS)
        assert replayed == product.cost[0]
        costs.append(replayed)
    crack_cost, hole_cost = costs
    # Through the crack: the strike's closest-point distance to the plate (0.05 m of the crack
    # and 0.02 m below it), in sigmas; through the hole: the cap.
    _, _, cracked = _missed_beam(CRACKED)
    assert np.isclose(crack_cost, (np.hypot(0.05, 0.02) / cracked.sigma[0]) ** 2, rtol=1e-4)
    assert crack_cost < hole_cost == (cracked.tolerance[0] / cracked.sigma[0]) ** 2


def test_beam_side_tells_a_surface_met_before_the_strike_from_one_beyond_it():
    plate = (np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]),
             np.array([[0, 1, 2], [0, 2, 3]]))
    tilted = np.array([-10 * np.sqrt(3), 0.0, 10.0])     # 60 degrees off the plate's normal
    view = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 10.0], tilted])
    # strikes below the plate, above it, and just below it along the tilted beam
    points = np.array([[0.0, 0.0, -0.02], [0.0, 0.0, 0.02], -0.001 * tilted])
    side = judge_rules.beam_side(judge.Strikes(points, view), judge.Caster(*plate))
    assert side["front"].tolist() == [True, False, True]
    np.testing.assert_allclose(side["cos"], [1.0, 1.0, 0.5], atol=1e-6)
    assert judge_rules.beam_side(judge.Strikes(points, None), judge.Caster(*plate)) == \
        {"front": None, "cos": None}


def test_the_recorded_checks_are_each_scored_candidate_s_own():
    # ``collect`` keeps a candidate's per-strike arrays only where its recorded held-out checks
    # add up to its cost: on a small box every scored candidate's must.
    from recon.surfaces.auto import choose
    from tests.recon.conftest import box_points

    points, view, _ = box_points(2000, noise=0.004, seed=2)
    with judge_rules.recording_checks():
        choice = choose(points, view_points=view, candidates=[("planes", {}),
                                                              ("convex-hull", {})], seed=0)
    scored = [c for c in choice.candidates if c.cost is not None]
    arrays = judge_rules.per_strike_arrays(scored)
    assert scored and {f"opening/{c.key}" for c in scored} <= set(arrays)
    for c in scored:
        assert len(c.held_checks) == choice.folds.k
        assert len(arrays[f"distance/{c.key}"]) == len(c.cost)
