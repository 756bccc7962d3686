"""``-m auto``'s race: a run far worse than the best on the first folds is not fitted on the
others and leaves the choice; a close one, a closed one near the best closed, a model of a few
numbers and a failed one stay; the choice is the full ladder's."""

from __future__ import annotations

import numpy as np
import pytest
from sphere_clouds import small_sphere

from recon.surfaces import auto
from recon.surfaces.auto import choose, format_choice, outpaced


def costs(mean: float, n_blocks: int = 40, per_block: int = 10, seed: int = 0) -> np.ndarray:
    """Costs of ``n_blocks`` blocks of strikes around ``mean`` with a shared block effect."""
    rng = np.random.default_rng(seed)
    shared = np.repeat(np.random.default_rng(99).normal(0.0, 0.5, n_blocks), per_block)
    return mean + shared + rng.normal(0.0, 0.3, n_blocks * per_block)


def test_outpaced_drops_a_run_far_worse_and_keeps_a_close_one():
    block = np.repeat(np.arange(40), 10)
    best, close, far = costs(1.0), costs(1.03, seed=1), costs(3.0, seed=2)
    leaves = outpaced([best, close, far, None], block, [True] * 4, [False] * 4)
    assert leaves[0] is None and leaves[1] is None and leaves[3] is None
    gap, se = leaves[2]
    assert gap == pytest.approx(2.0, abs=0.1) and gap > auto.RACE_STAGES[-1][1] * se
    # a run of a level that is not raced stays however far it is
    assert outpaced([best, far], block, [True, False], [False, False]) == [None, None]


def test_outpaced_keeps_the_best_closed_run():
    """A closed run far worse than the best stays when it is the best closed one (it measures
    the coverage), and leaves when another closed run is far better."""
    block = np.repeat(np.arange(40), 10)
    best, far, farther = costs(1.0), costs(3.0, seed=2), costs(6.0, seed=3)
    leaves = outpaced([best, far, farther], block, [True] * 3, [False, True, True])
    assert leaves[1] is None and leaves[2] is not None


@pytest.mark.parametrize("stages, folds", [
    (None, 1),                                           # auto's stages: gone after one fold
    (((1, float("inf")), (2, 2.0 * auto.BAND_SES)), 2),  # kept by the first, out at the second
])
def test_racing_leaves_the_far_run_after_its_stage_and_chooses_as_the_full_ladder(
        monkeypatch, fitted_labels, stages, folds):
    """On a noisy sphere the ellipsoid is exact and a polyhedron of planes far worse: raced at
    level 1, the planes leave at the first stage that can tell (one fit, or two when the first
    stage keeps every run; not four) and a coarser ellipsoid mesh, close to the best, stays;
    the choice and every remaining candidate's figures are those of the ladder without the
    race."""
    cloud, view = small_sphere()
    monkeypatch.setattr(auto, "LADDER", ((("ellipsoid", {}),),
                                         (("planes", {}), ("ellipsoid", {"subdivisions": 3}))))
    monkeypatch.setattr(auto, "ALWAYS_LEVELS", 2)
    if stages is not None:
        monkeypatch.setattr(auto, "RACE_STAGES", stages)
    options = {"view_points": view, "uncertainty": cloud.attributes, "seed": 0}
    fits = fitted_labels
    raced = choose(cloud.points, **options)
    # each run fitted once a fold: the planes on the folds of the stage they left at
    assert sorted(fits) == sorted(["ellipsoid"] * 4 + ["ellipsoid subdivisions=3"] * 4
                                  + ["planes"] * folds)
    monkeypatch.setattr(auto, "RACE_STAGES", ())
    full = choose(cloud.points, **options)
    table = {c.label: c for c in raced.candidates}
    whole = {c.label: c for c in full.candidates}
    assert table["planes"].status == "outpaced", format_choice(raced)
    assert not table["planes"].scored and table["planes"].folds == folds
    assert f"first {folds} fold(s)" in table["planes"].reason
    assert whole["planes"].scored and whole["planes"].chi2 > 5 * whole["ellipsoid"].chi2
    assert table["ellipsoid subdivisions=3"].scored
    assert raced.label == full.label == "ellipsoid"
    for label, c in table.items():
        if c.scored:
            assert (c.chi2, c.chi2_se, c.holes, c.n_faces) == \
                (whole[label].chi2, whole[label].chi2_se, whole[label].holes,
                 whole[label].n_faces)
    assert f"left after {folds} fold(s)" in format_choice(raced)
    assert "1 of them fitted on the first fold(s) only, far worse than the best there " \
        f"(planes on {folds} fold{'s' if folds > 1 else ''})" in raced.reason


def test_closed_means_no_edge_borders_a_single_face():
    """A tetrahedron is closed; without one face it is not; two tetrahedra sharing an edge
    (a non-manifold edge, four faces on it) are closed; no face is not closed."""
    import numpy as np

    from recon.surfaces.auto import closed

    tetra = np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]])
    assert closed(tetra) and not closed(tetra[1:])
    other = np.array([[0, 1, 4], [0, 5, 1], [1, 5, 4], [4, 5, 0]])   # shares edge (0, 1)
    assert closed(np.vstack([tetra, other]))
    assert not closed(np.zeros((0, 3), dtype=np.int64))
