"""A held-out beam that slips through a crack of a surface (an opening narrower than the
strikes resolve) costs its strike's closest-point distance; one through a hole costs the cap."""

from __future__ import annotations

import numpy as np
import pytest
from cracked_plates import CRACKED, HOLED, JUNCTION

from recon.surfaces import auto, judge

WIDTH = 0.3   # the widest crack [m] (auto.miss_reach in auto)


def _check(surface, **options):
    """A beam straight down through the plate's centre, its strike 0.02 m below the plane."""
    strikes = judge.Strikes(np.array([[0.0, 0.0, -0.02]]), np.array([[0.0, 0.0, 10.0]]))
    return judge.check(strikes, judge.Caster(*surface), tau=0.1, noise=0.01, **options)


@pytest.mark.parametrize("surface, closest", [(CRACKED, np.hypot(0.05, 0.02)),
                                              (JUNCTION, np.hypot(np.hypot(0.05, 0.05), 0.02))])
def test_a_beam_through_a_crack_costs_its_closest_point_distance(surface, closest):
    result = _check(surface, crack=WIDTH)
    assert result.missed.all() and result.crack.all()
    assert result.cost[0] == pytest.approx((closest / result.sigma[0]) ** 2, rel=1e-4)
    # Without a crack width every missed beam costs the cap, as before.
    plain = _check(surface)
    assert not plain.crack.any()
    assert plain.cost[0] == (plain.tolerance[0] / plain.sigma[0]) ** 2 > result.cost[0]


def test_a_beam_through_a_hole_costs_the_cap():
    result = _check(HOLED, crack=WIDTH)
    assert result.missed.all() and not result.crack.any()
    assert result.cost[0] == (result.tolerance[0] / result.sigma[0]) ** 2
    # A hole narrower than the width is a crack: the width decides, not the shape.
    assert _check(HOLED, crack=8 * WIDTH).crack.all()


def test_strikes_a_surface_was_fitted_on_are_not_tested_for_cracks():
    result = _check(CRACKED, crack=WIDTH, fitted=True)
    assert not result.crack.any()
    assert result.cost[0] == pytest.approx((np.hypot(0.05, 0.02) / result.sigma[0]) ** 2,
                                           rel=1e-4)


def test_any_missed_beam_cut_makes_a_carved_twin():
    def candidate(misses_cut, carved=False):
        return auto.Candidate(None, 0, status="ok", misses_cut=misses_cut, carved=carved)

    assert auto.fills_free_space(candidate(1 / 20_000))
    assert not auto.fills_free_space(candidate(0.0))
    assert not auto.fills_free_space(candidate(None))      # no missed beams: a cloud file
    assert not auto.fills_free_space(candidate(0.5, carved=True))
