"""--memory-limit bounds the method, not recon's own checking and scoring (issue 13, item 7)."""

from __future__ import annotations

import recon_fake_methods  # noqa: F401  (registers the test-only methods)

from recon.surfaces.isolation import run_isolated
from recon.surfaces.prepare import prepare
from tests.recon.conftest import sphere_mesh, sphere_points

# Below what scoring 3e5 truth samples needs on top of the child's imports (it failed with a
# MemoryError at this limit before), above what the methods here need.
LIMIT_MB = 1400


def test_scoring_runs_outside_the_methods_memory_limit():
    points, view, _ = sphere_points(3000)
    cloud = prepare(points, view_points=view)
    result = run_isolated("convex-hull", cloud, truth=sphere_mesh(), memory_mb=LIMIT_MB,
                          score_options={"n_truth_samples": 300_000, "edges": False})
    assert result["status"] == "ok", result["reason"]
    assert result["scores"]["n_truth_samples"] == 300_000
    # The same limit still stops a method that allocates past it.
    hog = run_isolated("test-hog", cloud, {"megabytes": 3000}, memory_mb=LIMIT_MB)
    assert (hog["status"], hog["failure"]) == ("failed", "memory")
