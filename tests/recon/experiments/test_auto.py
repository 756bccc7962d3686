"""``-m auto``: the simplest model whose held-out error is within the noise of the best."""

from __future__ import annotations

import numpy as np
import pytest

from recon.experiments.auto import AutoError, choose, format_choice, select
from recon.surfaces.methods import MethodFailed
from tests.recon.conftest import box_points, ellipsoid_points

# Candidates of the tests: one of each kind, two resolutions of Poisson (a full default run of
# every method and grid takes minutes; the rule does not depend on how many there are).
CANDIDATES = [("planes", {}), ("convex-hull", {}), ("poisson", {"depth": 6}),
              ("poisson", {}), ("plane", {}), ("ball-pivoting", {})]


def test_auto_picks_planes_for_a_box():
    points, view, _ = box_points(5000, noise=0.004, seed=2)
    choice = choose(points, view_points=view, candidates=CANDIDATES, seed=0)
    assert choice.method == "planes", format_choice(choice)
    assert "chose planes" in choice.reason
    table = {c["label"]: c for c in choice.candidates}
    assert table["planes"]["n_faces"] < 50
    assert table["planes"]["chosen"] and table["planes"]["eligible"]


def test_auto_picks_a_smooth_surface_for_an_ellipsoid():
    points, view, _ = ellipsoid_points(5000, noise=0.005, seed=3)
    choice = choose(points, view_points=view, candidates=CANDIDATES, seed=0)
    chosen = next(c for c in choice.candidates if c["chosen"])
    assert chosen["kind"] == "smooth", format_choice(choice)
    planes = next(c for c in choice.candidates if c["method"] == "planes")
    assert planes["heldout_mean_m"] > 2 * chosen["heldout_mean_m"]


def _candidate(label, distances, faces):
    return {"label": label, "distances": None if distances is None else np.asarray(distances),
            "n_faces": faces, "reason": "" if distances is not None else "crashed"}


def test_select_takes_fewest_faces_within_one_standard_error():
    rng = np.random.default_rng(0)
    base = rng.exponential(0.01, 10_000)  # held-out distances of the best fit
    se = base.std(ddof=1) / np.sqrt(base.size)
    candidates = [
        _candidate("fine", base, 100_000),
        _candidate("coarse", base + 0.5 * se, 5_000),    # inside the band: fewer faces wins
        _candidate("tiny", base + 3 * se, 12),          # outside the band
        _candidate("crashed", None, 0),
    ]
    chosen, threshold, reason = select(candidates)
    assert candidates[chosen]["label"] == "coarse"
    assert threshold == pytest.approx(base.mean() + se)
    assert "within one standard error" in reason and "fine" in reason


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


def test_heldout_residuals_are_range_errors_along_the_beam():
    from recon.experiments.auto import heldout_residuals

    # The plane z = 0 over [-1, 1]^2; beams come in at 45 degrees from above.
    vertices = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    points = np.array([[0.0, 0.0, 0.1], [0.2, 0.3, -0.05], [5.0, 0.0, 0.2]])
    view = points + np.array([-10.0, 0.0, 10.0])
    residual, hit = heldout_residuals(points, view, vertices, faces)
    assert hit.tolist() == [True, True, False]
    # Along a 45-degree beam the range error is the height times sqrt(2).
    np.testing.assert_allclose(residual[:2], [0.1 * np.sqrt(2), 0.05 * np.sqrt(2)], rtol=1e-9)
    # A beam that misses counts the closest-point distance: to the edge x = 1 at (1, 0, 0).
    assert residual[2] == pytest.approx(np.hypot(4.0, 0.2))
    closest, none = heldout_residuals(points, None, vertices, faces)
    np.testing.assert_allclose(closest[:2], [0.1, 0.05], rtol=1e-9)
    assert not none.any()
