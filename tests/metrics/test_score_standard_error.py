"""The score's stated sampling precision: standard errors of the two means and the Chamfer."""

from __future__ import annotations

import numpy as np
import trimesh
from metrics_reference import as_mesh

from metrics import score

SMALL = {"n_truth_samples": 4_000, "n_test_samples": 4_000, "coverage_points": 4_000,
         "edges": False}


def test_standard_errors_follow_their_definition():
    truth = as_mesh(trimesh.creation.icosphere(3, radius=10.0))
    bumpy = trimesh.creation.icosphere(2, radius=10.0)
    bumpy.vertices *= 1 + 0.02 * np.sin(5 * bumpy.vertices[:, :1])
    report = score((bumpy.vertices, bumpy.faces), truth, **SMALL)
    acc = report.accuracy_distances
    comp = report.completeness_distances
    want_acc = np.std(acc, ddof=1) / np.sqrt(len(acc))
    want_comp = np.std(comp, ddof=1) / np.sqrt(len(comp))
    assert np.isclose(report.accuracy_mean_se_m, want_acc, rtol=1e-12)
    assert np.isclose(report.completeness_mean_se_m, want_comp, rtol=1e-12)
    assert np.isclose(report.chamfer_se_m, 0.5 * np.hypot(want_acc, want_comp), rtol=1e-12)
    assert report.chamfer_se_m > 0
    # A cloud is scored point by point: its accuracy has no sampling error.
    cloud = score(bumpy.vertices, truth, **SMALL)
    assert cloud.accuracy_mean_se_m == 0.0
    assert np.isclose(cloud.chamfer_se_m, 0.5 * cloud.completeness_mean_se_m, rtol=1e-12)


def test_standard_error_predicts_the_spread_over_seeds():
    """Chamfer distances of one mesh over 12 seeds scatter by about the stated error."""
    truth = as_mesh(trimesh.creation.icosphere(3, radius=10.0))
    test = trimesh.creation.icosphere(1, radius=10.3)
    reports = [score((test.vertices, test.faces), truth, seed=seed, **SMALL)
               for seed in range(12)]
    spread = np.std([r.chamfer_m for r in reports], ddof=1)
    stated = np.median([r.chamfer_se_m for r in reports])
    assert stated / 3 < spread < 3 * stated
