"""Truth-free judgement: pass-blocked hold-out, the chi-square against the recorded noise and the
free-space evidence of the beams."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from recon.surfaces import judge

NOISE = 0.1   # the 1-sigma range noise of TRACK_SPHERE (0.3 m 3-sigma)


def _through(points):
    """A surface through every one of ``points`` (on a sphere about the origin): their radial
    projections triangulated, each vertex at its noisy point."""
    hull = ConvexHull(points / np.linalg.norm(points, axis=1, keepdims=True))
    return points, hull.simplices.astype(np.int64)


def _judged(cloud, folds, mesh, f=0):
    """Fold ``f``'s tested strikes against ``mesh`` (held out), its training strikes (fitted),
    and the held-out chi-square with its block standard error."""
    strikes = judge.Strikes.of(cloud)
    caster = judge.Caster(*mesh)
    options = {"tau": judge.tau_of(cloud.points), "noise": NOISE}
    test = folds.test(f)
    held = judge.check(strikes.take(test), caster, **options)
    fit = judge.check(strikes.take(folds.train(f)), caster, fitted=True, **options)
    return judge.block_mean_se(held.cost, folds.block[test]), held, fit


def test_pass_folds_deal_every_block_to_one_fold(track_sphere):
    cloud, _ = track_sphere
    folds = judge.pass_folds(cloud, 4, seed=0)
    shot = cloud.attributes["shot"].astype(np.int64)
    # The track moves far less than the noise a shot; the margin covers two noise lengths.
    assert folds.step_m < NOISE / 10
    assert folds.margin == pytest.approx(2 * NOISE / folds.step_m, rel=0.35)
    assert folds.block_shots == 4 * folds.margin
    # Every strike in one fold, the folds a quarter each, every block in a single fold.
    assert np.bincount(folds.fold).tolist() == pytest.approx([len(shot) / 4] * 4, rel=0.05)
    for f in range(4):
        train, test = folds.train(f), folds.test(f)
        assert not set(train) & set(test) and len(np.unique(folds.fold[folds.block == 7])) == 1
        # No tested strike has a training strike within a margin of shots.
        gap = np.abs(shot[test][:, None] - shot[train][None, :]).min(axis=1)
        assert gap.min() > folds.margin
    # Every strike held out once; the interiors of the blocks are tested.
    assert sum(len(folds.test(f)) for f in range(4)) == folds.tested.sum()
    assert folds.tested.mean() == pytest.approx(0.5, abs=0.05)
    again = judge.pass_folds(cloud, 4, seed=0)
    np.testing.assert_array_equal(again.fold, folds.fold)


def test_a_surface_through_the_noise_scores_worse_than_the_truth(track_sphere):
    cloud, truth = track_sphere
    folds = judge.pass_folds(cloud, 4, seed=0)
    (truth_chi2, _), truth_held, truth_fit = _judged(cloud, folds, truth)
    (noisy_chi2, _), noisy_held, noisy_fit = _judged(cloud, folds, _through(
        cloud.points[folds.train(0)]))
    # At the truth the chi-square per strike is ~1; a surface through the training strikes'
    # noise adds its own error to the held-out strikes' and scores worse, by more than twice
    # the block-level standard error of the difference...
    assert 0.8 < truth_chi2 < 1.2
    block = folds.block[folds.test(0)]
    worse, se = judge.block_mean_se(noisy_held.cost - truth_held.cost, block)
    assert noisy_chi2 > 1.2 and worse > 2 * se
    # ... while on its own training strikes it reads far below the noise.
    assert 0.9 < truth_fit.chi() < 1.1
    assert noisy_fit.chi() < 0.1


def test_a_surface_cutting_the_beams_is_penalised(track_sphere):
    cloud, (vertices, faces) = track_sphere
    folds = judge.pass_folds(cloud, 4, seed=0)
    (truth_chi2, _), truth_held, _ = _judged(cloud, folds, (vertices, faces))
    (big_chi2, _), big, _ = _judged(cloud, folds, (1.05 * vertices, faces))
    (small_chi2, _), small, _ = _judged(cloud, folds, (0.95 * vertices, faces))
    # 0.5 m too large: it stands in the empty space every beam crossed.
    assert truth_held.violated.mean() < 0.01
    assert big.violated.mean() > 0.9
    # 0.5 m too small: no beam is cut, but the strikes are in the air above it (holes).
    assert small.violated.mean() < 0.01 and small.hole.mean() > 0.9
    assert big_chi2 > 5 * truth_chi2 and small_chi2 > 5 * truth_chi2


def test_check_measures_along_the_beam_and_flags_misses_and_cuts():
    # The plane z = 0 over [-1, 1]^2, beams straight down from 10 m.
    vertices = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], dtype=float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    points = np.array([[0.0, 0.0, 0.01], [0.5, 0.5, -0.5], [1.2, 0.0, 0.0], [0, 0.3, 0.05]])
    strikes = judge.Strikes(points, points + np.array([0.0, 0.0, 10.0]))
    result = judge.check(strikes, judge.Caster(vertices, faces), tau=0.1, noise=0.01)
    # Close; 0.5 behind the plane (the beam was cut before it); beyond the edge (missed);
    # close. Cost: (residual / sigma)^2, the cap (tau / sigma)^2 = 100 when cut or missed.
    assert result.violated.tolist() == [False, True, False, False]
    assert result.missed.tolist() == [False, False, True, False]
    assert result.hole.tolist() == [False, True, True, False]
    np.testing.assert_allclose(result.cost, [1.0, 100.0, 100.0, 25.0], rtol=1e-3)
    fitted = judge.check(strikes, judge.Caster(vertices, faces), tau=0.1, noise=0.01,
                         fitted=True)
    # Fitted: the closest-point distance (0.2 m to the edge, capped at tau), no miss charged.
    np.testing.assert_allclose(fitted.cost[[2, 3]], [100.0, 25.0], rtol=1e-3)


def test_block_mean_se_is_the_spread_of_the_block_means():
    values = np.array([1.0, 1.0, 3.0, 3.0, 2.0, 2.0])
    block = np.array([0, 0, 1, 1, 2, 2])
    mean, se = judge.block_mean_se(values, block)
    assert mean == pytest.approx(2.0)
    assert se == pytest.approx(np.std([1.0, 3.0, 2.0], ddof=1) / np.sqrt(3))
    assert judge.block_mean_se(values, np.zeros(6, dtype=int))[1] == 0.0
