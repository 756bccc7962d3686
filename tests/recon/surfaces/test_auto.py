"""``-m auto``: the simplest model whose held-out chi-square is within a block standard error of
the best, and a reason that says truthfully what was chosen."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from formats.errors import MethodFailed, ParameterError
from recon.surfaces.auto import Candidate, choose, format_choice, select
from tests.recon.conftest import box_points, ellipsoid_points

# Candidates of the tests: one of each kind, two resolutions of Poisson (a full default run of
# every method and grid takes minutes; the rule does not depend on how many there are).
CANDIDATES = [("planes", {}), ("convex-hull", {}), ("poisson", {"depth": 6}),
              ("poisson", {}), ("plane", {}), ("ball-pivoting", {}), ("ellipsoid", {})]


def test_auto_picks_planes_for_a_box():
    points, view, _ = box_points(5000, noise=0.004, seed=2)
    choice = choose(points, view_points=view, candidates=CANDIDATES, seed=0)
    assert choice.method == "planes", format_choice(choice)
    assert "chose planes" in choice.reason
    table = {c.label: c for c in choice.candidates}
    assert table["planes"].n_faces < 50 and table["planes"].n_params <= 3 * 12
    assert table["planes"].chosen and table["planes"].eligible
    assert "a closed surface" in choice.reason


def test_auto_explains_an_ellipsoid_by_nine_numbers():
    points, view, _ = ellipsoid_points(5000, noise=0.005, seed=3)
    choice = choose(points, view_points=view, candidates=CANDIDATES, seed=0)
    assert choice.method == "ellipsoid", format_choice(choice)
    assert "9 parameters" in choice.reason
    planes = next(c for c in choice.candidates if c.run.method == "planes")
    assert planes.chi2 > 2 * choice.chosen.chi2


def test_a_mesh_with_holes_pays_for_the_beams_it_misses():
    # Half a sphere seen from all around: ball pivoting's open cap misses the beams of the
    # held-out strikes on the far side, which cost a full tolerance each.
    points, view, _ = ellipsoid_points(4000, noise=0.002, seed=5)
    choice = choose(points, view_points=view, candidates=[("ellipsoid", {}),
                                                          ("ball-pivoting", {"radii": (1.0,)})],
                    seed=0)
    table = {c.run.method: c for c in choice.candidates}
    assert table["ellipsoid"].beam_misses == pytest.approx(0.0)
    assert table["ball-pivoting"].beam_misses > table["ellipsoid"].beam_misses
    assert choice.method == "ellipsoid"


def test_the_ladder_runs_coarse_to_fine_and_stops():
    from recon.surfaces.auto import LADDER, MAX_FITS

    points, view, _ = ellipsoid_points(3000, noise=0.005, seed=4)
    choice = choose(points, view_points=view,
                    methods=["ellipsoid", "poisson", "plane", "ball-pivoting"], seed=0)
    levels = [c.level for c in choice.candidates]
    assert levels == sorted(levels)
    fitted = [c for c in choice.candidates if c.status != "skipped"]
    skipped = [c for c in choice.candidates if c.status == "skipped"]
    # The ellipsoid is exact: the defaults (level 2) are not measurably better than it, so the
    # finest level (the fine local-plane grid, and ball pivoting: a named method off the
    # ladder joins its last level) is never fitted.
    assert choice.method == "ellipsoid", format_choice(choice)
    assert [c.label for c in skipped] == ["plane cell=0.5", "ball-pivoting"]
    assert "the ladder stopped" in choice.reason
    assert len(fitted) < MAX_FITS <= 12 and len(LADDER) >= 3


def test_the_ladder_holds_the_convex_hull_and_names_visibility_only_when_registered():
    from recon.surfaces import methods
    from recon.surfaces.auto import ladder

    names = [run.method for level in ladder() for run in level]
    assert "convex-hull" in names and "planes" in names
    assert {"cell": 0.5} in [{k: run.params[k] for k in ("cell",)} for level in ladder()
                             for run in level if run.method == "plane"]
    assert ("visibility" in names) == ("visibility" in methods.available())


def test_auto_on_a_noisy_track_log_chooses_the_sphere(track_sphere):
    # Single-beam tracks whose strikes are 5 mm apart under 0.1 m noise: the pass-blocked
    # hold-out sees the noise-following surfaces for what they are.
    cloud, _ = track_sphere
    choice = choose(cloud.points, view_points=cloud.view_points, uncertainty=cloud.attributes,
                    candidates=[("ellipsoid", {}), ("poisson", {"depth": 9}),
                                ("ball-pivoting", {})], seed=0)
    assert choice.method == "ellipsoid", format_choice(choice)
    assert 0.8 < choice.chosen.chi2 < 1.2
    assert choice.folds.margin > 10 and choice.noise_m == pytest.approx(0.1)
    others = [c for c in choice.candidates if c.scored and not c.chosen]
    assert all(c.chi2 > choice.chosen.chi2 + c.chi2_se for c in others)
    record = choice.to_dict()
    assert record["folds"]["margin_shots"] == choice.folds.margin
    assert record["folds"]["k"] == 4
    assert record["n_checked"] == len(cloud.points)
    assert {"chi2", "chi2_se", "chi_fit", "violated", "holes"} <= set(record["candidates"][0])


# The tested strikes of the selection tests: 8 blocks of 4. Candidate j's cost per strike is
# its chi-square plus se sqrt(7) times column j + 1 of a Hadamard matrix (+-1 a block,
# orthogonal to every other candidate's): its block standard error is se, and the paired
# standard error of two candidates sqrt(se_1^2 + se_2^2).
BLOCK = np.repeat(np.arange(8), 4)
COLUMNS = itertools.cycle(range(1, 8))


def _candidate(label, chi2, params, *, se=0.01, closed=True):
    from scipy.linalg import hadamard

    from recon.surfaces.methods import bind

    run = bind("ellipsoid")
    run = type(run)(run.method, run.params, run.module, run.kind, label)
    if chi2 is None:
        return Candidate(run, 0, status="failed", reason="crashed")
    cost = chi2 + se * np.sqrt(7) * hadamard(8)[:, next(COLUMNS)][BLOCK]
    return Candidate(run, 0, status="ok", n_params=params, n_faces=params, closed=closed,
                     chi2=chi2, chi2_se=se, chi_heldout=chi2**0.5, chi_fit=chi2**0.5,
                     violated=0.0, holes=0.0, cost=cost)


def test_select_takes_the_smallest_model_within_two_paired_standard_errors():
    candidates = [_candidate("fine", 1.00, 100_000, se=0.05),
                  _candidate("coarse", 1.04, 5_000),      # 0.04 above, paired se 0.051: in
                  _candidate("tiny", 1.20, 9),            # 0.20 above: out
                  _candidate("crashed", None, 0)]
    selection = select(candidates, BLOCK, 20_000)
    assert candidates[selection.chosen].label == "coarse"
    assert selection.threshold == pytest.approx(1.04)
    assert set(selection.eligible) == {0, 1}


def test_the_reason_says_an_open_choice_is_open():
    from recon.surfaces.auto import explain

    candidates = [_candidate("closed big", 1.3, 50_000),
                  _candidate("open", 1.0, 5_000, closed=False)]
    selection = select(candidates, BLOCK, 20_000)
    assert candidates[selection.chosen].label == "open"
    reason = explain(candidates, selection, 0.6)
    assert "chose open, an open surface" in reason
    assert "preferred" not in reason and "closed candidates" not in reason
    assert "the lowest held-out statistic" in reason and "cover 60%" in reason


def test_open_and_closed_compete_alike_and_the_reason_names_the_paired_gap():
    from recon.surfaces.auto import explain

    # The closed model is 0.02 above the best, within 2 paired standard errors (0.051), but
    # larger: the smaller open model wins whatever the coverage.
    candidates = [_candidate("closed", 1.02, 50_000),
                  _candidate("open", 1.0, 5_000, se=0.05, closed=False)]
    assert candidates[select(candidates, BLOCK, 20_000).chosen].label == "open"
    candidates = [_candidate("closed small", 1.02, 500),
                  _candidate("open", 1.0, 5_000, se=0.05, closed=False)]
    selection = select(candidates, BLOCK, 20_000)
    assert candidates[selection.chosen].label == "closed small"
    reason = explain(candidates, selection, 0.3)
    assert "chose closed small, a closed surface" in reason
    assert "0.02 +- 0.051 above the best, open (1, 5,000 parameters)" in reason
    assert "within 2 paired standard error(s) of the best" in reason
    assert "the smallest model" in reason and "preferred" not in reason


def test_a_band_member_leaving_strikes_in_holes_beyond_the_noise_drops_out():
    from recon.surfaces.auto import HOLE_RATE, explain, hole_limit

    # Three candidates the held-out passes cannot tell apart. The smallest leaves 1.5 % of
    # 16,000 strikes with no surface within tolerance, where Gaussian noise leaves 0.27 % beyond
    # 3 sigma: it misses surface the strikes show, and the smaller of the two others wins.
    candidates = [_candidate("holed", 1.00, 20_000, se=0.05, closed=False),
                  _candidate("whole", 1.02, 30_000),
                  _candidate("big", 1.01, 50_000)]
    for c, holes in zip(candidates, (0.015, 0.0016, 0.0019), strict=True):
        c.holes = holes
    selection = select(candidates, BLOCK, 16_000)
    assert set(selection.eligible) == {0, 1, 2}
    assert selection.holed == (0,)
    assert candidates[selection.chosen].label == "whole"
    assert selection.hole_limit == pytest.approx(
        HOLE_RATE + 3 * np.sqrt(HOLE_RATE * (1 - HOLE_RATE) / 16_000))
    assert hole_limit([0.0016, 0.0019], 16_000) == selection.hole_limit
    reason = explain(candidates, selection, 0.9)
    assert "chose whole" in reason and "that hold the strikes it is the smallest model" in reason
    assert "left out of the band for the strikes they leave in holes" in reason
    assert "holed (1.50%)" in reason
    # The same figures over 100 strikes are within what chance gives: nothing drops out.
    assert candidates[select(candidates, BLOCK, 100).chosen].label == "holed"


def test_holes_within_the_noise_of_the_band_s_fewest_do_not_decide():
    # 0.29 % against 0.39 % of 7,000 strikes (one standard error apart), and a band whose
    # fewest holes (2 %) are above the noise's rate: measured from those, not from the rate.
    candidates = [_candidate("small", 1.00, 20_000, se=0.05), _candidate("large", 1.01, 50_000)]
    candidates[0].holes, candidates[1].holes = 0.0039, 0.0029
    assert candidates[select(candidates, BLOCK, 7_000).chosen].label == "small"


def test_holes_against_the_band_s_fewest_count_the_error_of_both_fractions():
    from recon.surfaces.auto import HOLE_RATE, HOLE_SES, hole_limit

    # A satellite's figures: the smaller model leaves 1.00 % of 4,184 strikes in holes, the
    # larger 0.55 %, both above the noise's rate. The fewest is a count as uncertain as the
    # other: the difference, 0.45 %, is 2.8 standard errors of a difference of two counts,
    # within the band's chance, so the smaller model stays (one count's error: 3.9, out).
    candidates = [_candidate("small", 1.00, 8_000, se=0.05, closed=False),
                  _candidate("large", 0.98, 32_000, closed=False)]
    candidates[0].holes, candidates[1].holes = 0.0100, 0.0055
    selection = select(candidates, BLOCK, 4_184)
    assert set(selection.eligible) == {0, 1} and selection.holed == ()
    assert candidates[selection.chosen].label == "small"
    assert selection.hole_limit == pytest.approx(
        0.0055 + HOLE_SES * np.sqrt(2 * 0.0055 * (1 - 0.0055) / 4_184))
    assert hole_limit([0.0100, 0.0055], 4_184) == pytest.approx(0.01035, abs=1e-5)
    # twice the holes is beyond it
    candidates[0].holes = 0.0110
    assert select(candidates, BLOCK, 4_184).holed == (0,)
    # no jump where the band's fewest crosses the noise's rate: the larger of the two limits
    assert hole_limit([0.999 * HOLE_RATE], 4_184) == pytest.approx(
        hole_limit([1.001 * HOLE_RATE], 4_184), rel=0.01)
    candidates[0].holes, candidates[1].holes = 0.022, 0.020
    selection = select(candidates, BLOCK, 7_000)
    assert candidates[selection.chosen].label == "small" and not selection.holed
    candidates[0].holes = 0.03
    assert select(candidates, BLOCK, 7_000).holed == (0,)


def test_an_uncarved_surface_the_missed_beams_refute_leaves_for_its_carved_twin():
    from recon.surfaces.auto import MISS_REFUTES, explain

    # A membrane 30 standard errors better on the held-out strikes than its carved twin: the
    # held-out strikes lie where both are right. Cutting more than MISS_REFUTES of the missed
    # beams, it leaves the choice and the twin takes its place; cutting fewer, or without a
    # scored twin to stand in, it stays.
    whole = _candidate("membrane", 1.00, 8_000)
    twin = _candidate("membrane", 1.30, 8_000)
    twin.carved, twin.misses_cut = True, 0.0
    whole.misses_cut = MISS_REFUTES + 0.01
    selection = select([whole, twin], BLOCK, 20_000)
    assert selection.refuted == (0,) and selection.chosen == 1 == selection.best
    reason = explain([whole, twin], selection, 0.5)
    assert f"cuts {MISS_REFUTES + 0.01:.1%} of the missed beams" in reason
    assert f"more than {MISS_REFUTES:.0%}: the beams refute it" in reason
    whole.misses_cut = MISS_REFUTES - 0.01
    selection = select([whole, twin], BLOCK, 20_000)
    assert selection.refuted == () and selection.chosen == 0
    whole.misses_cut, twin.chi2 = 0.5, None
    assert select([whole, twin], BLOCK, 20_000).chosen == 0


def test_select_fails_when_every_candidate_failed():
    with pytest.raises(MethodFailed, match="auto: every candidate failed: x: crashed"):
        select([_candidate("x", None, 0)], BLOCK, 20_000)


@pytest.mark.parametrize("kwargs, match", [
    ({"holdout": 0.0}, r"holdout must be in \(0, 0.5\]"),
    ({"holdout": 0.9}, r"holdout must be in \(0, 0.5\]"),
    ({"holdout": 0.01}, "auto needs at least 30 held-out points"),
])
def test_bad_options_are_named(kwargs, match):
    points, view, _ = box_points(500)
    with pytest.raises(ParameterError, match=match):
        choose(points, view_points=view, candidates=CANDIDATES, **kwargs)


def test_closed_allows_non_manifold_edges_but_no_border():
    from recon.surfaces.auto import closed
    from tests.recon.conftest import box_mesh

    _, faces = box_mesh()
    assert closed(faces)
    assert not closed(faces[1:])
    assert closed(np.concatenate([faces, faces + 8]))       # two boxes: still no border
