"""``-m auto``'s band floor in metres (step 3 of ``recon.surfaces.auto``): on a log without
range noise a finer surface does not win by held-out differences far below tau."""

from __future__ import annotations

import numpy as np
import pytest

from recon.surfaces import auto
from recon.surfaces.auto import METRIC_FLOOR, choose, format_choice, metric_floor, select
from tests.recon.surfaces.test_auto import BLOCK, _candidate

# A 10 m sphere seen by the 5-beam cross LRF from 50 m over half a rotation: about 3,900
# strikes on sparse crossing tracks, no range noise (the noise length is the local-plane
# scatter, a few millimetres, against tau 0.27 m).
CLEAN_CROSS_SPHERE = ["target.semi_axes=[10,10,10]", "target.subdivisions=4",
                      "orbit.radius=50", "time.rotations=0.5"]


@pytest.fixture(scope="module")
def clean_cross_sphere(tmp_path_factory):
    """The ``CLEAN_CROSS_SPHERE`` log, ingested."""
    import sim
    from recon.registration.ingest import ingest

    path = tmp_path_factory.mktemp("logs") / "clean-cross-sphere.h5"
    sim.simulate(sim.load_scene("asteroid-cross", CLEAN_CROSS_SPHERE), path, seed=0,
                 progress=False)
    return ingest(path)


def test_on_a_clean_log_a_finer_poisson_does_not_win_by_a_metric_free_difference(
        clean_cross_sphere):
    # Poisson depth 9 follows the noise-free strikes closer than depth 6, by several paired
    # standard errors of the held-out chi-square (the noise length is the scatter's, the
    # errors are tiny), but by a few millimetres of residual against tau: the floor puts depth
    # 6 in the band, and the smaller model wins.
    cloud = clean_cross_sphere
    choice = choose(cloud.points, view_points=cloud.view_points, uncertainty=cloud.attributes,
                    candidates=[("poisson", {"depth": 6}), ("poisson", {"depth": 9})], seed=0,
                    n_workers=1)
    assert choice.noise_m < METRIC_FLOOR * choice.tau_m
    table = {c.label: c for c in choice.candidates}
    fine, coarse = table["poisson depth=9"], table["poisson depth=6"]
    gap, se = auto.judge.block_mean_se(coarse.cost - fine.cost, choice.folds.block[
        np.concatenate([choice.folds.test(f) for f in range(choice.folds.k)])])
    assert fine.chi2 < coarse.chi2 and gap > auto.BAND_SES * se   # out of the bare band
    assert choice.label == "poisson depth=6", format_choice(choice)
    assert coarse.eligible and fine.eligible
    assert "on a log without range noise" in choice.reason


def test_the_floor_acts_only_where_three_noise_lengths_are_below_it():
    assert metric_floor(1.0, 0.0) == pytest.approx(METRIC_FLOOR**2)
    assert metric_floor(1.0, 0.999 * METRIC_FLOOR / 3) == pytest.approx(METRIC_FLOOR**2)
    assert metric_floor(1.0, METRIC_FLOOR / 3) == 0.0
    assert metric_floor(0.2, 0.1) == 0.0   # a noisy satellite's figures
    assert metric_floor(6.53, 0.745) == 0.0   # a noisy asteroid under the LIDAR: 0.11 tau


def test_the_floor_admits_a_metric_free_gap_and_nothing_beyond_it():
    # 32 strikes of sigma 1 mm, tau 0.1 m: the floor is (1.5 cm)^2. "coarse" is 0.2 chi-square
    # above "fine", 14 paired standard errors but (0.45 mm)^2 of squared residual: in the band
    # with the floor, out without it; "tiny", (2.0 cm)^2 above, is out either way.
    scale = np.full(len(BLOCK), 0.001**2)
    floor = metric_floor(0.1, 0.001)
    candidates = [_candidate("fine", 1.0, 100_000), _candidate("coarse", 1.2, 5_000),
                  _candidate("tiny", 400.0, 9)]
    selection = select(candidates, BLOCK, 20_000, scale=scale, floor=floor)
    assert set(selection.eligible) == {0, 1} and selection.floored == (1,)
    assert candidates[selection.chosen].label == "coarse"
    assert candidates[select(candidates, BLOCK, 20_000).chosen].label == "fine"
    # 5 mm of noise, a third of the floor: no floor
    assert candidates[select(candidates, BLOCK, 20_000, scale=scale,
                             floor=metric_floor(0.1, 0.005)).chosen].label == "fine"


def test_the_race_keeps_a_run_within_the_floor():
    # The same figures on the first folds: "coarse" is far beyond three band widths of
    # standard errors, but within the floor of squared residual, so it is fitted on every
    # fold; "tiny" is beyond the floor by far more than six standard errors of that excess.
    from recon.surfaces.auto import outpaced

    scale = np.full(len(BLOCK), 0.001**2)
    candidates = [_candidate("fine", 1.0, 100_000), _candidate("coarse", 1.2, 5_000),
                  _candidate("tiny", 400.0, 9)]
    args = ([c.cost for c in candidates], BLOCK, [True] * 3, [True] * 3)
    assert [gap is not None for gap in outpaced(*args, ses=6.0)] == [False, True, True]
    kept = outpaced(*args, ses=6.0, scale=scale, floor=metric_floor(0.1, 0.001))
    assert [gap is not None for gap in kept] == [False, False, True]


def test_a_candidate_the_floor_lets_in_is_no_reference_of_the_hole_test():
    # rso-a-cross-clean's figures: the best leaves 0.47 % of 15,000 strikes in holes, a larger
    # local-plane grid the floor lets in 0.02 %. Measured from the grid, the best would drop out
    # for its holes and the grid be chosen; the grid is not within the held-out strikes' band,
    # so the best's holes are measured from the band's own fewest and the best stays.
    scale = np.full(len(BLOCK), 0.001**2)
    candidates = [_candidate("best", 1.0, 11_000), _candidate("grid", 1.2, 37_000)]
    candidates[0].holes, candidates[1].holes = 0.0047, 0.0002
    selection = select(candidates, BLOCK, 15_000, scale=scale, floor=metric_floor(0.1, 0.001))
    assert selection.floored == (1,) and selection.holed == ()
    assert candidates[selection.chosen].label == "best"
    candidates[1].holes = 0.02   # beyond the band's fewest: the grid drops out
    assert select(candidates, BLOCK, 15_000, scale=scale,
                  floor=metric_floor(0.1, 0.001)).holed == (1,)


def _of_method(method, candidate):
    """``candidate`` as a run of ``method`` (its figures unchanged)."""
    run = candidate.run
    candidate.run = type(run)(method, run.params, run.module, run.kind, run.label)
    return candidate


def test_the_floor_admits_only_the_bests_method():
    # spot under the LIDAR without noise: a coarse local-plane grid 22 paired standard errors
    # above the visibility cut, within the floor's squared residual, won as the smaller model
    # (Chamfer 2.46 times the best). Of another method it stays out; a coarser setting of the
    # best's method is let in as before.
    scale = np.full(len(BLOCK), 0.001**2)
    floor = metric_floor(0.1, 0.001)
    candidates = [_of_method("visibility", _candidate("cut", 1.0, 50_000)),
                  _of_method("plane", _candidate("grid", 1.2, 30_000))]
    selection = select(candidates, BLOCK, 20_000, scale=scale, floor=floor)
    assert selection.floored == () and candidates[selection.chosen].label == "cut"
    _of_method("visibility", candidates[1])
    selection = select(candidates, BLOCK, 20_000, scale=scale, floor=floor)
    assert selection.floored == (1,) and candidates[selection.chosen].label == "grid"


def test_the_race_keeps_within_the_floor_only_the_bests_method():
    from recon.surfaces.auto import outpaced

    scale = np.full(len(BLOCK), 0.001**2)
    candidates = [_candidate("fine", 1.0, 100_000), _candidate("coarse", 1.2, 5_000),
                  _candidate("other", 1.2, 5_000)]
    args = ([c.cost for c in candidates], BLOCK, [True] * 3, [True] * 3)
    kept = outpaced(*args, ses=6.0, scale=scale, floor=metric_floor(0.1, 0.001),
                    methods=["poisson", "poisson", "plane"])
    assert [gap is not None for gap in kept] == [False, False, True]
