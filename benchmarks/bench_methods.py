"""Every surface method at its defaults on paper-scale clouds: fit time, faces, score time.

    python benchmarks/bench_methods.py                     # the three clouds (~20 min here)
    python benchmarks/bench_methods.py --clouds rso-a --methods plane,poisson
    python benchmarks/bench_methods.py --quick             # small clouds (~4 min here)

Each method runs as ``recon reconstruct -m METHOD INPUT`` runs it: the strike log read and
prepared by ``recon.surfaces.prepare.load_prepared`` (ingest, oriented normals, spacing, noise,
the recorded uncertainty), then the method at its defaults in a warm isolated worker
(``recon.surfaces.isolation.run_isolated``, the CLI's limits). Its fit time is the worker's
``wall_time_s`` (the method alone); the first run of each method is also scored against the
simulator's truth with ``metrics.score``'s defaults (what ``recon score`` does, edge metric
included) in the worker, the truth built beforehand (``warm_truth``), so the score time is the
mesh's own: checking plus scoring. Fits under ``CHEAP_S`` are repeated (``--repeats``, >= 3) and
the median quoted; a fit over ``CHEAP_S`` runs once (marked ``x1``). Each fit is also given as
a ratio to Open3D Poisson at its defaults on the same cloud (the machine is shared: only ratios
travel).

Clouds (each simulated with seed 0, then ingested):

- ``lidar``: the ``asteroid-lidar`` preset (the paper's ellipsoid, 20 x 20 deg scanning LIDAR
  at 750 m) with the paper's LIDAR errors (``suite.LIDAR_ERRORS``: 1 m range and 0.2 deg angle
  3-sigma, 2 m pose, pulse dilation), thinned to a 5 x 5 beam grid for 14.2 rotations:
  336,333 points, the size of the issue's 336k-point LIDAR cloud (the preset's 32 x 32 beams
  for 15 rotations would give about 15 million);
- ``rso-a`` and ``asteroid``: ``bench_compare.CLOUDS``, the ``rso-a-lrf`` and ``asteroid-lrf``
  presets with the paper's 0.3 m 3-sigma LRF range error (77,400 shots).

Results go to ``--out`` (default ``benchmarks/out/methods``) as ``results.json`` and
``results.md``, and the table is printed. The fit times of a full run are the table behind
``recon reconstruct --list-methods`` (``recon.surfaces.methods.DEFAULT_FIT_S``) and the cost
stated in ``recon reconstruct --help`` and ``recon compare --help``
(``recon.surfaces.fit_times.cost_help``): ``--update-defaults`` writes them to
``recon/surfaces/fit_times.json`` (say where and how it ran in docs/decisions.md).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_compare import BASELINE, CLOUDS, simulate  # noqa: E402
from suite import LIDAR_ERRORS  # noqa: E402

# 5 x 5 beams for 14.2 rotations: 336,333 points after ingest (seed 0), the cloud size.
LIDAR = ("asteroid-lidar", [*LIDAR_ERRORS, "sensor.resolution=[5, 5]", "time.rotations=14.2"])
SCENES = {"lidar": LIDAR, **{k: CLOUDS[k] for k in ("rso-a", "asteroid")}}
# The quick form: the same scenes for a few rotations (7,740 LRF shots, ~23k LIDAR points).
QUICK = {"time.rotations": "5", "lidar": "1"}
# Fits longer than this [s] run once: their median would cost minutes for nothing.
CHEAP_S = 60.0


def quick_scenes() -> dict:
    """``SCENES`` shortened to a few rotations (``QUICK``)."""
    out = {}
    for name, (preset, overrides) in SCENES.items():
        rotations = QUICK["lidar"] if name == "lidar" else QUICK["time.rotations"]
        kept = [o for o in overrides if not o.startswith("time.rotations")]
        out[f"{name}-quick"] = (preset, [*kept, f"time.rotations={rotations}"])
    return out


def bench_cloud(name: str, scenes: dict, methods: list[str], args) -> dict:
    """Every method of ``methods`` at its defaults on cloud ``name``: a summary dict."""
    from formats import StrikeLog
    from recon.surfaces.isolation import run_isolated, start_workers, warm_truth
    from recon.surfaces.methods import bind
    from recon.surfaces.prepare import load_prepared

    log = simulate(name, args.out, scenes)
    start = time.perf_counter()
    _, prepared = load_prepared(log)
    prepare_s = time.perf_counter() - start
    with StrikeLog(log) as reader:
        truth = reader.truth_mesh()
    print(f"{name}: {len(prepared.points):,} points, spacing {prepared.spacing:.3g} m, noise "
          f"{prepared.noise:.3g} m (prepared in {prepare_s:.0f} s); load average "
          f"{os.getloadavg()[0]:.1f}", flush=True)
    rows = []
    for method in methods:
        run = bind(method)
        start_workers(1)
        warm_truth(truth)
        first = run_isolated(run, prepared, truth=truth, timeout_s=args.timeout)
        row = {"method": method, "status": first["status"], "failure": first.get("failure"),
               "reason": first.get("reason"), "fits_s": [first.get("wall_time_s")]}
        if first["status"] == "ok":
            while first["wall_time_s"] < CHEAP_S and len(row["fits_s"]) < args.repeats:
                again = run_isolated(run, prepared, timeout_s=args.timeout)
                if again["status"] != "ok":
                    break
                row["fits_s"].append(again["wall_time_s"])
            scores = first["scores"]
            row.update(fit_s=statistics.median(row["fits_s"]), n_faces=first["n_faces"],
                       score_s=first["score_time_s"], chamfer_m=scores["chamfer_m"],
                       fscore=scores["fscore"], peak_memory_mb=first.get("peak_memory_mb"))
        rows.append(row)
        print("  " + format_row(row), flush=True)
    base = next((r for r in rows if r["method"] == BASELINE[0] and "fit_s" in r), None)
    for row in rows:
        if base and "fit_s" in row:
            row["ratio_to_poisson"] = row["fit_s"] / base["fit_s"]
    return {"cloud": name, "n_points": len(prepared.points), "spacing_m": prepared.spacing,
            "noise_m": prepared.noise, "truth_faces": len(truth[1]), "runs": rows}


def format_row(row: dict) -> str:
    if "fit_s" not in row:
        return f"{row['method']:<22} {row['failure']}: {row['reason']}"
    repeats = len(row["fits_s"])
    return (f"{row['method']:<22} fit {row['fit_s']:8.2f} s (x{repeats}) "
            f"faces {row['n_faces']:>9,} score {row['score_s']:7.1f} s "
            f"Chamfer {row['chamfer_m']:.4g} m F {row['fscore']:.3f}")


def markdown(summaries: list[dict], command: str) -> str:
    lines = ["# Methods at their defaults", "", f"`{command}`", ""]
    for s in summaries:
        lines += [f"## {s['cloud']}: {s['n_points']:,} points, spacing {s['spacing_m']:.3g} m, "
                  f"noise {s['noise_m']:.3g} m", "",
                  "| method | fit s | repeats | / poisson | faces | score s | Chamfer m | "
                  "F-score |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in s["runs"]:
            if "fit_s" not in r:
                lines.append(f"| {r['method']} | {r['failure']} | | | | | | "
                             f"{(r['reason'] or '')[:60]} |")
                continue
            ratio = r.get("ratio_to_poisson")
            lines.append(f"| {r['method']} | {r['fit_s']:.2f} | {len(r['fits_s'])} | "
                         f"{'' if ratio is None else f'{ratio:.2g}'} | {r['n_faces']:,} | "
                         f"{r['score_s']:.1f} | {r['chamfer_m']:.4g} | {r['fscore']:.3f} |")
        lines.append("")
    return "\n".join(lines)


def main() -> int:
    from recon.surfaces.methods import available

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clouds", default=",".join(SCENES),
                        help=f"comma-separated subset of {', '.join(SCENES)}")
    parser.add_argument("--methods", help="comma-separated methods (default: all listed)")
    parser.add_argument("--repeats", type=int, default=3,
                        help=f"fits of each method under {CHEAP_S:g} s (median; default 3)")
    parser.add_argument("--timeout", type=float, default=600.0,
                        help="limit of each fit, seconds (recon reconstruct's default)")
    parser.add_argument("--quick", action="store_true", help="the clouds of a few rotations")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "methods")
    parser.add_argument("--update-defaults", action="store_true",
                        help="write the fit times to recon/surfaces/fit_times.json (a full run "
                             "over the lidar and rso-a clouds)")
    args = parser.parse_args()
    if args.update_defaults and (args.quick or not {"lidar", "rso-a"} <= set(
            args.clouds.split(","))):
        parser.error("--update-defaults needs a full run over the lidar and rso-a clouds")
    if args.repeats < 3:
        parser.error("--repeats must be >= 3 (medians)")
    names = [n for n in args.clouds.split(",") if n]
    unknown = sorted(set(names) - set(SCENES))
    if unknown:
        parser.error(f"unknown cloud(s) {unknown}; choose from {sorted(SCENES)}")
    methods = args.methods.split(",") if args.methods else available()
    if BASELINE[0] not in methods:
        methods.insert(0, BASELINE[0])
    scenes = quick_scenes() if args.quick else SCENES
    if args.quick:
        names = [f"{n}-quick" for n in names]
    args.out.mkdir(parents=True, exist_ok=True)
    summaries = [bench_cloud(name, scenes, methods, args) for name in names]
    command = "python benchmarks/bench_methods.py " + " ".join(sys.argv[1:])
    (args.out / "results.json").write_text(json.dumps(
        {"command": command, "clouds": summaries}, indent=2, default=str) + "\n")
    if args.update_defaults:
        from recon.surfaces import fit_times

        fit_times.TABLE.write_text(json.dumps(fit_times.table_of(summaries), indent=2) + "\n")
        print(f"wrote {fit_times.TABLE}")
    text = markdown(summaries, command.strip())
    (args.out / "results.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
