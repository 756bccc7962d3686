"""``-m auto``: the simplest model whose held-out beam error is within the noise of the best."""

from __future__ import annotations

import numpy as np
import pytest

from recon.surfaces.auto import AutoError, choose, format_choice, select
from recon.surfaces.methods import MethodFailed
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
    table = {c["label"]: c for c in choice.candidates}
    assert table["planes"]["n_faces"] < 50 and table["planes"]["n_params"] <= 3 * 12
    assert table["planes"]["chosen"] and table["planes"]["eligible"]


def test_auto_explains_an_ellipsoid_by_nine_numbers():
    points, view, _ = ellipsoid_points(5000, noise=0.005, seed=3)
    choice = choose(points, view_points=view, candidates=CANDIDATES, seed=0)
    assert choice.method == "ellipsoid", format_choice(choice)
    assert "9 parameters" in choice.reason
    planes = next(c for c in choice.candidates if c["method"] == "planes")
    chosen = next(c for c in choice.candidates if c["chosen"])
    assert planes["heldout_mean_m"] > 2 * chosen["heldout_mean_m"]


def test_a_mesh_with_holes_pays_for_the_beams_it_misses():
    # Half a sphere seen from all around: ball pivoting's open cap misses the beams of the
    # held-out strikes on the far side, which cost a full tolerance each.
    points, view, _ = ellipsoid_points(4000, noise=0.002, seed=5)
    choice = choose(points, view_points=view, candidates=[("ellipsoid", {}),
                                                          ("ball-pivoting", {"radii": (1.0,)})],
                    seed=0)
    table = {c["method"]: c for c in choice.candidates}
    assert table["ellipsoid"]["beam_hits"] == pytest.approx(1.0)
    assert table["ball-pivoting"]["beam_hits"] < table["ellipsoid"]["beam_hits"]
    assert choice.method == "ellipsoid"


def test_the_ladder_runs_coarse_to_fine_and_stops():
    from recon.surfaces.auto import LADDER, MAX_FITS

    points, view, _ = ellipsoid_points(3000, noise=0.005, seed=4)
    choice = choose(points, view_points=view,
                    methods=["ellipsoid", "poisson", "plane", "ball-pivoting"], seed=0)
    levels = [c["level"] for c in choice.candidates]
    assert levels == sorted(levels)
    fitted = [c for c in choice.candidates if c["status"] != "skipped"]
    skipped = [c for c in choice.candidates if c["status"] == "skipped"]
    # The ellipsoid is exact: the defaults (level 2) are not measurably better than it, so the
    # finest level (ball pivoting) is never fitted.
    assert choice.method == "ellipsoid", format_choice(choice)
    assert [c["method"] for c in skipped] == ["ball-pivoting"]
    assert "the ladder stopped" in choice.reason
    assert len(fitted) < MAX_FITS <= 12 and len(LADDER) >= 3


def _candidate(label, distances, params, *, closed=True):
    return {"label": label, "distances": None if distances is None else np.asarray(distances),
            "n_params": params, "n_faces": params, "closed": closed,
            "reason": "" if distances is not None else "crashed"}


def test_select_takes_the_smallest_model_within_one_standard_error():
    rng = np.random.default_rng(0)
    base = rng.exponential(0.01, 10_000)  # held-out residuals of the best fit
    se = base.std(ddof=1) / np.sqrt(base.size)
    candidates = [
        _candidate("fine", base, 100_000),
        _candidate("coarse", base + 0.5 * se, 5_000),    # inside the band: smaller wins
        _candidate("tiny", base + 3 * se, 9),           # outside the band
        _candidate("crashed", None, 0),
    ]
    chosen, threshold, reason = select(candidates)
    assert candidates[chosen]["label"] == "coarse"
    assert threshold == pytest.approx(base.mean() + se)
    assert "within one standard error" in reason and "fine" in reason


def test_select_puts_closed_models_first_when_coverage_is_incomplete():
    rng = np.random.default_rng(1)
    base = rng.exponential(0.01, 10_000)
    candidates = [_candidate("closed", base, 50_000),
                  _candidate("open", base, 5_000, closed=False)]
    assert candidates[select(candidates, coverage=0.95)[0]]["label"] == "open"
    chosen, _, reason = select(candidates, coverage=0.6)
    assert candidates[chosen]["label"] == "closed"
    assert "cover 60%" in reason and "closed candidates came first" in reason


def test_select_keeps_the_best_when_nothing_simpler_is_close():
    candidates = [_candidate("a", [0.1, 0.2, 0.3], 10), _candidate("b", [1.0, 1.1, 1.2], 5)]
    chosen, _, reason = select(candidates)
    assert chosen == 0 and "the lowest held-out error" in reason


def test_select_fails_when_every_candidate_failed():
    with pytest.raises(MethodFailed, match="auto: every candidate failed: x: crashed"):
        select([_candidate("x", None, 0)])


@pytest.mark.parametrize("kwargs, match", [
    ({"holdout": 0.0}, r"holdout must be in \(0, 0.5\]"),
    ({"holdout": 0.9}, r"holdout must be in \(0, 0.5\]"),
    ({"holdout": 0.01}, "auto needs at least 30 held-out points"),
])
def test_bad_options_are_named(kwargs, match):
    points, view, _ = box_points(500)
    with pytest.raises(AutoError, match=match):
        choose(points, view_points=view, candidates=CANDIDATES, **kwargs)


def test_heldout_geometry_measures_distances_and_which_beams_hit():
    from recon.surfaces.auto import heldout_geometry

    # The plane z = 0 over [-1, 1]^2; beams come in at 45 degrees from above.
    vertices = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    points = np.array([[0.0, 0.0, 0.1], [0.2, 0.3, -0.05], [5.0, 0.0, 0.2]])
    view = points + np.array([-10.0, 0.0, 10.0])
    distance, hit, cos = heldout_geometry(points, view, vertices, faces)
    assert hit.tolist() == [True, True, False]
    np.testing.assert_allclose(cos[:2], np.sqrt(0.5), rtol=1e-6)
    # Closest-point distances, the third to the edge x = 1 at (1, 0, 0).
    np.testing.assert_allclose(distance, [0.1, 0.05, np.hypot(4.0, 0.2)], rtol=1e-5)
    again, none, _ = heldout_geometry(points, None, vertices, faces)
    np.testing.assert_allclose(again, distance)
    assert not none.any()


def test_heldout_errors_cost_a_full_cap_where_the_beam_misses():
    from recon.surfaces.auto import heldout_errors

    vertices = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    points = np.array([[0.0, 0.0, 0.01], [0.5, 0.5, 0.5], [1.2, 0.0, 0.0]])
    view = points + np.array([0.0, 0.0, 10.0])
    context = {"points": points, "view": view, "columns": None, "noise": 0.01, "tau": 0.1}
    error, hits = heldout_errors(context, vertices, faces)
    # Hit and close; hit but 0.5 off (capped at tau); missed although only 0.2 from the edge.
    np.testing.assert_allclose(error, [0.01, 0.1, 0.1], rtol=1e-5)
    assert hits.tolist() == [True, True, False]


def test_strike_sigma_grows_with_incidence_as_the_error_model_says():
    from recon.surfaces.auto import strike_sigma

    columns = {"sigma_along": np.array([0.1, 0.1]), "sigma_across": np.array([0.2, 0.2]),
               "dilation_along": np.zeros(2), "dilation_across": np.zeros(2)}
    sigma = strike_sigma(columns, np.array([1.0, np.sqrt(0.5)]), noise=0.05)
    # Head-on: the range error; at 45 deg half of each variance along the normal.
    np.testing.assert_allclose(sigma, [0.1, np.sqrt(0.5 * 0.1**2 + 0.5 * 0.2**2)])
    np.testing.assert_allclose(strike_sigma(None, np.ones(3), noise=0.05), 0.05)
    zero = dict.fromkeys(columns, np.zeros(2))
    np.testing.assert_allclose(strike_sigma(zero, np.ones(2), noise=0.05), 0.05)


def test_closed_allows_non_manifold_edges_but_no_border():
    from recon.surfaces.auto import closed
    from tests.recon.conftest import box_mesh

    _, faces = box_mesh()
    assert closed(faces)
    assert not closed(faces[1:])
    assert closed(np.concatenate([faces, faces + 8]))       # two boxes: still no border


def test_select_band_is_at_least_the_slack():
    rng = np.random.default_rng(2)
    base = rng.exponential(0.01, 10_000)
    se = base.std(ddof=1) / np.sqrt(base.size)
    candidates = [_candidate("interpolating", base, 17_000),
                  _candidate("ellipsoid", base + 5 * se, 9)]
    assert candidates[select(candidates)[0]]["label"] == "interpolating"
    chosen, threshold, reason = select(candidates, slack=10 * se)
    assert candidates[chosen]["label"] == "ellipsoid"
    assert threshold == pytest.approx(base.mean() + 10 * se)
    assert "1% of the score threshold tau" in reason
