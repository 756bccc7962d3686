"""The refinement's time against its estimate (``recon.registration.refine.refine_seconds``).

Whole refinements of a log (``refine`` at its defaults, ``--refine-interval`` set to make each
knot count, every size once per round, rounds interleaved) beside the model's estimate; and,
with ``--solve-knots``, the first dense steps (``_solve``) of larger problems, coarse and fine,
whose whole refinements take hours: where the model's p^2 and p^3 terms were fitted.

Target: the model within a factor 2 of every median (it is what ``recon ingest --refine`` says
before it starts, and what its time limit refuses on).

    .venv/bin/python benchmarks/bench_refine_time.py LOG [--knots 1,5,20,50,100]
        [--points 30000] [--repeats 3] [--solve-knots 200,400,600]

The constants beside ``STEP_POINT_S`` were fitted to this run on the suite's
polyhedron-50m-lidar-noisy.h5 (30,000 and 10,000 points) and satellite-j-cross-noisy.h5
(docs/decisions.md, "the refinement's time estimate").
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without relying on the installed package


def _interval(log, knots: int) -> float | None:
    """The interval that makes ``knots`` knots over ``log`` (None: constant errors)."""
    from formats import StrikeLog

    if knots == 1:
        return None
    with StrikeLog(log) as opened:
        span = float(opened.shots(opened.n_shots - 1).time[0] - opened.shots(0, 1).time[0])
    return span / (knots - 1) * (1 + 1e-9)


def _fitted(log, points: int) -> tuple[int, bool]:
    """Strikes a refinement of ``log`` fits, and whether its target spins (a coarse stage)."""
    from formats import StrikeLog
    from recon.registration.refine import spin_of

    with StrikeLog(log) as opened:
        return min(points, (opened.n_strikes + 1) // 2), spin_of(opened.shots())[1] > 0


def whole(log, knots: list[int], points: int, repeats: int) -> list[tuple]:
    """Rows (knots, seconds of each run, model) of whole refinements."""
    from recon.registration.refine import refine, refine_seconds

    n_fit, coarse = _fitted(log, points)
    runs = {k: [] for k in knots}
    for _ in range(repeats):
        for k in knots:
            start = time.perf_counter()
            refine(log, interval=_interval(log, k), max_points=points)
            runs[k].append(time.perf_counter() - start)
    return [(k, runs[k], refine_seconds(n_fit, k, coarse=coarse)) for k in knots]


class _Enough(Exception):
    pass


def first_steps(log, knots: int, points: int, calls: int) -> dict[str, list[float]]:
    """Seconds of the first ``calls`` dense steps (``_solve``) of the coarse and the fine stage
    of a refinement with ``knots`` knots, then stopped."""
    from recon.registration import refine as module

    solve, seconds = module._solve, {}
    for stage in ("coarse", "fine"):
        times = seconds.setdefault(stage, [])

        def timed(*args, times=times):
            if len(times) >= calls:
                raise _Enough
            start = time.perf_counter()
            out = solve(*args)
            times.append(time.perf_counter() - start)
            return out

        module._solve = timed
        try:
            problem = module._problem(log, _interval(log, knots), False, points, 0)
            if stage == "coarse":
                module._coarse_start(problem)
            else:
                module._fine(problem, problem.zero)
        except _Enough:
            pass
        finally:
            module._solve = solve
    return seconds


def main(argv=None) -> int:
    from recon.registration.refine import COARSE_THIN, STEP_KNOT_S, STEP_POINT_S, step_seconds

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log", type=Path)
    parser.add_argument("--knots", default="1,5,20,50,100")
    parser.add_argument("--points", type=int, default=30_000, help="max_points")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--solve-knots", default="", help="knots of the first-steps timing")
    args = parser.parse_args(argv)
    knots = [int(k) for k in args.knots.split(",") if k]
    n_fit, coarse = _fitted(args.log, args.points)
    print(f"{args.log.name}: {n_fit:,} fitted strikes, "
          f"{'a coarse stage' if coarse else 'no coarse stage'}")
    met = True
    for k, runs, model in whole(args.log, knots, args.points, args.repeats):
        median = statistics.median(runs)
        ok = 0.5 <= model / median <= 2.0
        met &= ok
        print(f"  {k:4d} knots: runs {' / '.join(f'{t:.1f}' for t in runs)} s, median "
              f"{median:.1f} s, model {model:.1f} s ({model / median:.2f})"
              + ("" if ok else "  MISSED"))
    for k in [int(k) for k in args.solve_knots.split(",") if k]:
        for stage, times in first_steps(args.log, k, args.points, 2).items():
            m = -(-n_fit // COARSE_THIN) if stage == "coarse" else n_fit
            dense = step_seconds(m, k) - m * (STEP_POINT_S + STEP_KNOT_S * k)
            print(f"  {k:4d} knots, {stage} step of {m:,} strikes, its dense algebra: "
                  f"{' / '.join(f'{t:.2f}' for t in times)} s, model {dense:.2f} s")
    print(f"target (model within a factor 2 of every median): {'met' if met else 'MISSED'}")
    return 0 if met else 1


if __name__ == "__main__":
    sys.exit(main())
