"""Start-up time of the ``recon`` command and of ``import recon.api``, in fresh processes.

Each command runs ``--repeats`` times (default 7) in a new interpreter; printed: the median and
the fastest wall time of each, the median of a bare interpreter (``python -c pass``, the baseline
measured in the same run) and each median's excess over it, the median CPU time (user + system,
which other processes on the machine do not inflate as they inflate the wall time), and the load
average. The target: ``recon --help`` and ``recon COMMAND
--help`` under ``TARGET_S`` (median).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_startup.py
    PYTHONPATH=. .venv/bin/python benchmarks/bench_startup.py --repeats 11 --json
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
TARGET_S = 0.3
# (label, interpreter arguments): what a user starts, and the interpreter alone as the baseline.
COMMANDS = (
    ("python -c pass (baseline)", ["-c", "pass"]),
    ("recon --help", ["-m", "recon", "--help"]),
    ("recon simulate --help", ["-m", "recon", "simulate", "--help"]),
    ("recon reconstruct --help", ["-m", "recon", "reconstruct", "--help"]),
    ("recon compare --help", ["-m", "recon", "compare", "--help"]),
    ("recon study --help", ["-m", "recon", "study", "--help"]),
    ("import recon.api", ["-c", "import recon.api"]),
)
TARGETED = {"recon --help", "recon simulate --help", "recon reconstruct --help",
            "recon compare --help", "recon study --help"}


def time_command(args: list[str], repeats: int) -> tuple[list[float], list[float]]:
    """Wall times and CPU times (user + system) [s] of ``repeats`` fresh interpreters running
    ``args`` (each must succeed). The CPU time is what the start costs whatever else runs on
    the machine; the wall time is what a user waits."""
    env = os.environ | {"PYTHONPATH": str(REPO)}
    walls, cpus = [], []
    for _ in range(repeats):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        subprocess.run([sys.executable, *args], cwd=REPO, env=env, check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        walls.append(time.perf_counter() - start)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return walls, cpus


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="runs per command (default 7)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args(argv)
    if args.repeats < 5:
        parser.error(f"--repeats must be at least 5 for a median, got {args.repeats}")
    load_before = os.getloadavg()
    rows = []
    for label, command in COMMANDS:
        walls, cpus = time_command(command, args.repeats)
        rows.append({"command": label, "median_s": statistics.median(walls),
                     "min_s": min(walls), "cpu_median_s": statistics.median(cpus)})
    base = rows[0]["median_s"]
    for row in rows:
        row["over_baseline_s"] = row["median_s"] - base
        row["ratio_to_baseline"] = row["median_s"] / base
        row["within_target"] = row["median_s"] < TARGET_S if row["command"] in TARGETED else None
    result = {"repeats": args.repeats, "target_s": TARGET_S, "rows": rows,
              "load_average_before": load_before, "load_average_after": os.getloadavg()}
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"{'command':<28} {'median s':>9} {'min s':>7} {'over base':>10} {'x base':>7} "
          f"{'cpu s':>6}  target {TARGET_S:g} s")
    for row in rows:
        verdict = {True: "yes", False: "NO", None: ""}[row["within_target"]]
        print(f"{row['command']:<28} {row['median_s']:9.3f} {row['min_s']:7.3f} "
              f"{row['over_baseline_s']:10.3f} {row['ratio_to_baseline']:7.2f} "
              f"{row['cpu_median_s']:6.3f}  {verdict}")
    print("load average (1, 5, 15 min) before: " + ", ".join(f"{x:.2f}" for x in load_before)
          + "; after: " + ", ".join(f"{x:.2f}" for x in result["load_average_after"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
