"""Self-calibration of pose knowledge (``recon ingest --refine``) against its targets (issue 15).

For the paper's asteroid with its single-beam LRF (``asteroid-lrf``, 50 rotations) and RSO-A
(``rso-a-lrf``), both with the paper's 0.3 m (3 sigma) LRF range noise, two logs with the same
seed (so the same range noise): perfect pose knowledge, and a 0.05 deg boresight misalignment
(rotation vector (0.03, 0.04, 0) deg in S) plus a 1 m position bias (inertial, along x_I, in the
orbit plane). Printed side by side: the Chamfer distance and F-score of the perfect-pose, the
un-refined and the refined clouds (``metrics.score``, clouds against the truth mesh), and the
estimated misalignment against the true one.

Targets:

- refined Chamfer within 20 % of the perfect-pose cloud's;
- estimated misalignment within 10 % of the true one (the vector error over its size);
- refinement of the error-free log moves no point by more than the range noise (0.3 m, 3 sigma);
- refinement of the demo log (``asteroid-lrf-slew``, seed 0) costs less than its
  reconstruction (the demo's screened Poisson, isolated): medians of 3, interleaved.

    .venv/bin/python benchmarks/bench_refine.py
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without relying on the installed package

SCENES = {"asteroid (single-beam LRF)": "asteroid-lrf", "RSO-A (single-beam LRF)": "rso-a-lrf"}
NOISE = ("errors.range_sigma3=0.3",)
MISALIGNMENT_DEG = np.array([0.03, 0.04, 0.0])
BIAS = ("errors.boresight_misalignment_deg=[0.03, 0.04, 0.0]",
        "errors.position_bias_inertial=[1.0, 0.0, 0.0]")
RANGE_SIGMA3 = 0.3
TARGET_CHAMFER = 1.2
TARGET_MISALIGNMENT = 0.1
REPEATS = 3
SCORE = {"n_truth_samples": 100_000, "coverage_points": 100_000, "edges": False}


def simulate(scene: str, path: Path, overrides=()) -> Path:
    import sim

    sim.simulate(sim.load_scene(scene, [*NOISE, *overrides]), path, seed=0, progress=False)
    return path


def chamfer_and_f(points, truth) -> tuple[float, float]:
    from metrics.score import score

    report = score(points, truth, seed=0, **SCORE)
    return report.chamfer_m, report.fscore


def accuracy_targets(tmp: Path) -> bool:
    from formats import StrikeLog
    from recon.registration.ingest import ingest
    from recon.registration.refine import refine

    ok = True
    print(f"{'scene':<28} {'cloud':<14} {'Chamfer m':>10} {'F-score':>8}")
    for label, scene in SCENES.items():
        clean = simulate(scene, tmp / f"{scene}-clean.h5")
        posed = simulate(scene, tmp / f"{scene}-posed.h5", BIAS)
        with StrikeLog(clean) as log:
            truth = log.truth_mesh()
        start = time.perf_counter()
        result = refine(posed)
        spent = time.perf_counter() - start
        clouds = {"perfect pose": ingest(clean).points, "un-refined": ingest(posed).points,
                  "refined": ingest(posed, correction=result.correction).points}
        scores = {name: chamfer_and_f(points, truth) for name, points in clouds.items()}
        for name, (chamfer, f) in scores.items():
            print(f"{label:<28} {name:<14} {chamfer:10.4f} {f:8.4f}")
        ratio = scores["refined"][0] / scores["perfect pose"][0]
        estimate = np.degrees(result.correction.misalignment[0])
        error = np.linalg.norm(estimate - MISALIGNMENT_DEG) / np.linalg.norm(MISALIGNMENT_DEG)
        size = np.linalg.norm(estimate) / np.linalg.norm(MISALIGNMENT_DEG) - 1
        sigma = np.degrees(result.sigma.misalignment[0])
        print(f"  refined / perfect Chamfer = {ratio:.3f} (target <= {TARGET_CHAMFER}); "
              f"un-refined / perfect = {scores['un-refined'][0] / scores['perfect pose'][0]:.3f}")
        print(f"  misalignment: true {MISALIGNMENT_DEG.round(4).tolist()} deg, estimated "
              f"{estimate.round(4).tolist()} +/- {sigma.round(4).tolist()} deg; vector error "
              f"{error:.1%}, size error {size:+.1%} (target <= {TARGET_MISALIGNMENT:.0%})")
        print(f"  position bias estimated {result.correction.position[0].round(3).tolist()} m "
              f"+/- {result.sigma.position[0].round(3).tolist()} (true [1, 0, 0]); refine "
              f"{spent:.1f} s")
        ok &= ratio <= TARGET_CHAMFER and error <= TARGET_MISALIGNMENT

        start = time.perf_counter()
        still = refine(clean)
        moved = np.linalg.norm(ingest(clean, correction=still.correction).points
                               - clouds["perfect pose"], axis=1)
        print(f"  error-free log: refinement moves points by at most {moved.max():.3f} m "
              f"(median {np.median(moved):.3f} m; target < {RANGE_SIGMA3} m, the 3-sigma range "
              "noise)")
        ok &= moved.max() < RANGE_SIGMA3
    return ok


def cost_target(tmp: Path) -> bool:
    from recon import api
    from recon.demo import DEMO_METHOD, DEMO_SCENE
    from recon.registration.ingest import ingest
    from recon.registration.refine import refine

    log = tmp / "demo.h5"
    import sim

    sim.simulate(sim.load_scene(DEMO_SCENE), log, seed=0, progress=False)
    cloud = ingest(log)
    times = {"refine": [], "reconstruct": []}
    for _ in range(REPEATS):
        start = time.perf_counter()
        refine(log)
        times["refine"].append(time.perf_counter() - start)
        start = time.perf_counter()
        api.reconstruct(cloud, method=DEMO_METHOD, seed=0, isolate=True)
        times["reconstruct"].append(time.perf_counter() - start)
    median = {k: statistics.median(v) for k, v in times.items()}
    ratio = median["refine"] / median["reconstruct"]
    print(f"demo log ({DEMO_SCENE}, {len(cloud):,} strikes): refine {median['refine']:.2f} s, "
          f"reconstruct ({DEMO_METHOD}) {median['reconstruct']:.2f} s; ratio {ratio:.2f} "
          "(target < 1; medians of 3)")
    return ratio < 1.0


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="bench-refine-") as tmp:
        ok = accuracy_targets(Path(tmp))
        ok &= cost_target(Path(tmp))
    print("all targets met" if ok else "some targets missed")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
