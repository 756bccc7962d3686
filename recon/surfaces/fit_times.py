"""What each surface method costs at its defaults: its fit time [s] on the two clouds of
benchmarks/bench_methods.py, read from ``fit_times.json`` beside this module.

The table is the benchmark's output (``python benchmarks/bench_methods.py --update-defaults``
rewrites it from a full run); how and where it was measured is kept in docs/decisions.md
("Measurements behind the defaults"). Other machines: compare the ratios to ``poisson``. Plain
JSON and no numpy, so that ``recon --help`` can state the cost without loading the methods.
"""

from __future__ import annotations

import json
import math
from functools import cache
from pathlib import Path

TABLE = Path(__file__).with_name("fit_times.json")
# The two clouds of the table, in the order of each method's pair of times.
CLOUDS = ("lidar", "rso-a")


@cache
def _table() -> dict:
    return json.loads(TABLE.read_text(encoding="utf-8"))


def fit_s() -> dict[str, tuple[float, float]]:
    """Method -> fit time at its defaults [s] on (the LIDAR cloud, the LRF cloud)."""
    return {name: (float(a), float(b)) for name, (a, b) in _table()["fit_s"].items()}


def cost_points() -> tuple[int, int]:
    """Points of the two clouds the times were measured on."""
    clouds = _table()["clouds"]
    return tuple(int(clouds[c]["points"]) for c in CLOUDS)


def source() -> str:
    """The benchmark that measured the table."""
    return _table()["source"]


def cost_help() -> str:
    """One sentence for ``--help``: the slowest default fit on each cloud, and Poisson's."""
    times = fit_s()
    clouds = _table()["clouds"]
    slowest = max(times, key=lambda name: times[name][0])
    lrf = max(t for _, t in times.values())
    return (f"At their defaults the methods fit a {clouds['lidar']['label']} cloud in at most "
            f"{math.ceil(times[slowest][0])} s each ({slowest}; Open3D Poisson "
            f"{times['poisson'][0]:.2g} s) and a {clouds['rso-a']['label']} cloud in at most "
            f"{math.ceil(lrf)} s ({source()}).")


def table_of(summaries: list[dict]) -> dict:
    """The table's content from benchmarks/bench_methods.py's per-cloud summaries (a full run
    over both clouds): every method that fitted on both."""
    by_cloud = {s["cloud"]: s for s in summaries}
    missing = [c for c in CLOUDS if c not in by_cloud]
    if missing:
        raise ValueError(f"the fit-time table needs a run over the clouds {', '.join(missing)}")
    fits = [{r["method"]: r["fit_s"] for r in by_cloud[c]["runs"] if "fit_s" in r}
            for c in CLOUDS]
    labels = {"lidar": "asteroid LIDAR", "rso-a": "RSO-A LRF"}
    return {"source": source(),
            "clouds": {c: {"points": by_cloud[c]["n_points"],
                           "label": f"{by_cloud[c]['n_points'] // 1000}k-point {labels[c]}"}
                       for c in CLOUDS},
            "fit_s": {m: [round(fits[0][m], 3), round(fits[1][m], 3)]
                      for m in fits[0] if m in fits[1]}}
