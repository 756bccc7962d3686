"""What the gap-seeking planner costs against the simulation it steers, on the closed-loop
study's scenes.

For each target of ``recon study closed-loop`` (the same presets, overrides and seed 0), the
gap-seeking law is simulated for ``--hours`` (default: as long as the full study runs it, 96 h;
the map, and with it the planner's work, grows over the run) with the time spent in its planner
(``GapSeeker.command`` and ``GapSeeker.observe``: the voxel map, the frontier, the predicted
visibility, the plan) summed apart. **The simulation's time** is the closed-loop run's time
without the planner's: everything else the run does (poses, ray casts, errors, the log writer,
one replanning interval at a time). The interval's poses are computed once, by the simulation,
and handed to the planner (the law knows its orbit and the target's spin: the same values).
Both are measured as the CPU time of the run's thread (``time.thread_time``: the closed loop
runs in one thread, and time other processes take from it is not counted) and as wall time;
the target, planner / simulation <= 0.10, is judged on the CPU times. Beside it, the same scene
under the paper's fixed 2 deg slew (no planner, no interval-by-interval loop) is simulated as a
second baseline. Each target is run ``--repeats`` times (default 3); the printed figures are
medians over the repeats with the 1-minute load average before and after each target, and
``--out`` (default ``benchmarks/out/planner.json``) holds every run.

The planner's kernels are compiled (numba, sim/planner_kernels.py), so a process pays once,
before its first plan, for the numba import and for loading the compiled kernels from numba's
cache, or for compiling them where there is no cache yet (the first run after an install or a
change of the kernels' source). Those **one-time costs** are measured apart, each in a fresh
process with a cache directory of its own (first with it empty: the compile; then again: the
load), and the steady-state figures above come after a warm-up run in this process.

A change meant to make the planner cheaper without changing a decision is checked with
``--save-logs DIR`` (before it: every target's gap-seeking log of the last repeat, as
``DIR/<target>-<hours>h.h5``) and ``--identical-to DIR`` (after it: each run's log against that
one; every dataset and attribute must be equal, byte for byte, but for the file's creation
time): the run fails on the first difference.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_planner.py
    PYTHONPATH=. .venv/bin/python benchmarks/bench_planner.py --hours 6 --targets rso-a
    PYTHONPATH=. .venv/bin/python benchmarks/bench_planner.py --hours 24 --repeats 1 \
        --skip-one-time --identical-to DIR
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

TARGET_RATIO = 0.10          # planner time / simulation time
# Root attributes that differ between two runs of the same scene and seed.
_RUN_ATTRS = ("created_utc",)


def log_differences(a: Path, b: Path) -> list[str]:
    """Where the strike logs ``a`` and ``b`` differ: the names of the groups, datasets and
    attributes not equal byte for byte (dtype, shape and values), but for the root's
    ``_RUN_ATTRS``; empty when the logs record the same run."""
    import h5py
    import numpy as np

    def objects(f):
        found = {"/": f}

        def add(name, obj):        # returns None: visititems stops at anything else
            found["/" + name] = obj

        f.visititems(add)
        return found

    def same(x, y):
        x, y = np.asarray(x), np.asarray(y)
        return x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()

    with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
        oa, ob = objects(fa), objects(fb)
        out = [f"{name}: in one log only" for name in sorted(set(oa) ^ set(ob))]
        for name in sorted(set(oa) & set(ob)):
            x, y = oa[name], ob[name]
            skip = _RUN_ATTRS if name == "/" else ()
            out += [f"{name} attribute {key}" for key in sorted(set(x.attrs) | set(y.attrs))
                    if key not in skip and (key not in x.attrs or key not in y.attrs
                                            or not same(x.attrs[key], y.attrs[key]))]
            if isinstance(x, h5py.Dataset) and not (isinstance(y, h5py.Dataset)
                                                    and same(x[()], y[()])):
                out.append(f"{name}: values differ")
    return out


class _Timed:
    """Wraps a method of GapSeeker, adding its wall time to ``seconds`` and its thread CPU time
    to ``cpu_seconds``."""

    def __init__(self, method):
        self.method, self.seconds, self.cpu_seconds = method, 0.0, 0.0

    def __get__(self, obj, owner):
        def call(*args, **kwargs):
            start, cpu = time.perf_counter(), time.thread_time()
            try:
                return self.method(obj, *args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - start
                self.cpu_seconds += time.thread_time() - cpu
        return call


def measure(preset: str, overrides: list[str], hours: float, tmp: Path) -> dict:
    """Planner and simulation times of one run of one target (see the module docstring); its
    gap-seeking log is left as ``tmp / "gaps.h5"``."""
    import sim
    from sim import gap_seeking

    duration = f"time.duration={hours * 3600:g}"
    fixed = sim.load_scene(preset, [*overrides, "slew.amplitude_deg=2", duration])
    start = time.perf_counter()
    sim.simulate(fixed, tmp / "fixed.h5", seed=0, progress=False, workers=1)
    fixed_s = time.perf_counter() - start
    scene = sim.load_scene(preset, [*overrides, "attitude.mode=gaps", duration])
    command, observe = gap_seeking.GapSeeker.command, gap_seeking.GapSeeker.observe
    timed = [_Timed(command), _Timed(observe)]
    gap_seeking.GapSeeker.command, gap_seeking.GapSeeker.observe = timed
    try:
        start, cpu = time.perf_counter(), time.thread_time()
        summary = sim.simulate(scene, tmp / "gaps.h5", seed=0, progress=False, workers=1)
        loop_s, loop_cpu_s = time.perf_counter() - start, time.thread_time() - cpu
    finally:
        gap_seeking.GapSeeker.command, gap_seeking.GapSeeker.observe = command, observe
    planner_s = sum(t.seconds for t in timed)
    planner_cpu_s = sum(t.cpu_seconds for t in timed)
    simulation_s, simulation_cpu_s = loop_s - planner_s, loop_cpu_s - planner_cpu_s
    intervals = math.ceil(hours * 3600 / scene["attitude.replan_s"])
    return {"shots": summary["shots"], "intervals": intervals, "planner_s": planner_s,
            "command_s": timed[0].seconds, "observe_s": timed[1].seconds,
            "closed_loop_s": loop_s, "simulation_s": simulation_s, "fixed_law_s": fixed_s,
            "planner_cpu_s": planner_cpu_s, "simulation_cpu_s": simulation_cpu_s,
            "planner_over_simulation": planner_cpu_s / simulation_cpu_s,
            "planner_over_simulation_wall": planner_s / simulation_s,
            "planner_share": planner_s / loop_s,
            "planner_ms_per_interval": 1e3 * planner_cpu_s / intervals,
            "simulation_ms_per_interval": 1e3 * simulation_cpu_s / intervals,
            "planner_ms_per_shot": 1e3 * planner_cpu_s / summary["shots"]}


# A fresh process: the numba import, the kernels' import, then the same short closed-loop run
# twice; the first pays for loading (or compiling) the kernels, the second does not.
_ONE_TIME = """
import json, sys, time
from pathlib import Path
import sim
preset, overrides, hours, tmp = json.loads(sys.argv[1])
duration = f"time.duration={hours * 3600:g}"
scene = sim.load_scene(preset, [*overrides, "attitude.mode=gaps", duration])
start = time.perf_counter()
import numba
numba_s = time.perf_counter() - start
start = time.perf_counter()
import sim.planner_kernels
module_s = time.perf_counter() - start
runs = []
for name in ("first.h5", "second.h5"):
    start = time.perf_counter()
    sim.simulate(scene, Path(tmp) / name, seed=0, progress=False, workers=1)
    runs.append(time.perf_counter() - start)
print(json.dumps({"numba_import_s": numba_s, "kernels_import_s": module_s,
                  "first_run_s": runs[0], "second_run_s": runs[1],
                  "kernels_ready_s": runs[0] - runs[1]}))
"""


def one_time(preset: str, overrides: list[str], hours: float, tmp: Path) -> dict:
    """The one-time costs of a fresh process (see the module docstring): with an empty numba
    cache (``compile``) and then with the cache the first filled (``cached``)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp / "numba-cache"))
    out = {}
    for case in ("compile", "cached"):
        done = subprocess.run([sys.executable, "-c", _ONE_TIME,
                               json.dumps([preset, overrides, hours, str(tmp)])],
                              env=env, capture_output=True, text=True, check=True)
        out[case] = json.loads(done.stdout.strip().splitlines()[-1])
    return out


def main(argv: list[str] | None = None) -> int:
    from recon.experiments.studies.closed_loop import PLAN, TARGETS

    study_hours = float(max(PLAN["full"]["hours"]["gaps"]))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=study_hours,
                        help=f"simulated hours per target (default {study_hours:g}: the full "
                             f"study's gap-seeking runs)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per target (medians)")
    parser.add_argument("--targets", nargs="+", choices=list(TARGETS), default=list(TARGETS))
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "planner.json")
    parser.add_argument("--skip-one-time", action="store_true",
                        help="measure the steady state only (the one-time costs compile every "
                             "kernel in a fresh cache)")
    parser.add_argument("--save-logs", type=Path, metavar="DIR",
                        help="keep each target's gap-seeking log as DIR/<target>-<hours>h.h5")
    parser.add_argument("--identical-to", type=Path, metavar="DIR",
                        help="check every run's gap-seeking log against DIR/<target>-<hours>h.h5 "
                             "(as --save-logs writes them): same datasets and attributes, byte "
                             "for byte, but the creation time")
    args = parser.parse_args(argv)
    print(f"planner = GapSeeker.command + observe; simulation = the closed-loop run without "
          f"the planner; CPU time of the run's thread (wall time beside); target planner / "
          f"simulation <= {TARGET_RATIO:.2f}. {args.hours:g} h per target, medians of "
          f"{args.repeats} runs.", flush=True)
    rows = {}
    with tempfile.TemporaryDirectory(prefix="recon-bench-planner-") as tmp:
        preset, overrides, _ = TARGETS[args.targets[0]]
        once = {} if args.skip_one_time else one_time(preset, list(overrides), 0.5, Path(tmp))
        for case, label in (("compile", "no cache (after an install or a change of the "
                                        "kernels)"), ("cached", "from the cache")):
            if case not in once:
                continue
            o = once[case]
            total = o["numba_import_s"] + o["kernels_import_s"] + o["kernels_ready_s"]
            print(f"one-time, {label}: {total:.2f} s = numba import {o['numba_import_s']:.2f} "
                  f"s + kernels' module {o['kernels_import_s']:.2f} s + kernels ready "
                  f"{o['kernels_ready_s']:.2f} s (a first 0.5 h closed-loop run "
                  f"{o['first_run_s']:.2f} s, the same again {o['second_run_s']:.2f} s)",
                  flush=True)
        measure(preset, list(overrides), 0.5, Path(tmp))          # warm-up: kernels loaded
        for name in args.targets:
            preset, overrides, _ = TARGETS[name]
            load = [os.getloadavg()[0]]
            log = f"{name}-{args.hours:g}h.h5"
            runs = []
            for _ in range(args.repeats):
                runs.append(measure(preset, list(overrides), args.hours, Path(tmp)))
                if args.identical_to is not None:
                    differ = log_differences(args.identical_to / log, Path(tmp) / "gaps.h5")
                    if differ:
                        print(f"{name}: the log differs from {args.identical_to / log}: "
                              f"{'; '.join(differ[:5])}", flush=True)
                        return 1
            if args.save_logs is not None:
                args.save_logs.mkdir(parents=True, exist_ok=True)
                os.replace(Path(tmp) / "gaps.h5", args.save_logs / log)
            load.append(os.getloadavg()[0])
            median = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
            rows[name] = {"preset": preset, "overrides": list(overrides), "hours": args.hours,
                          "median": median, "runs": runs, "load_average": load}
            m = median
            print(f"{name:12s} planner / simulation {m['planner_over_simulation']:5.3f} CPU "
                  f"(wall {m['planner_over_simulation_wall']:.3f}; planner "
                  f"{m['planner_cpu_s']:.3f} s, simulation {m['simulation_cpu_s']:.3f} s), "
                  f"{m['planner_ms_per_interval']:.3f} ms per interval against the "
                  f"simulation's {m['simulation_ms_per_interval']:.3f}; fixed 2 deg slew "
                  f"{m['fixed_law_s']:.2f} s wall; load average {load[0]:.1f} -> {load[1]:.1f}"
                  + ("; log identical" if args.identical_to is not None else ""), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"target_ratio": TARGET_RATIO, "one_time": once,
                                    "targets": rows}, indent=1))
    print(f"wrote {args.out}")
    return 0 if all(r["median"]["planner_over_simulation"] <= TARGET_RATIO
                    for r in rows.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
