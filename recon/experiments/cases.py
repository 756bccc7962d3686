"""The cases of a method sweep: which runs, the metrics they are ranked on, their records as CSV.

``recon compare``, ``recon stability`` and ``-m auto`` all run a list of ``Run`` values
(``recon.surfaces.methods``: a method with its resolved parameters, keyed by ``Run.key`` and
named by ``Run.label``) and rank what comes back on the truth scores named here.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from formats.atomic import write_text_atomically
from formats.errors import ParameterError
from recon.experiments.sweep import to_jsonable
from recon.surfaces import methods
from recon.surfaces.methods import Run

# Scores charted and ranked on (metrics.score's names).
CHAMFER, FSCORE = "chamfer_m", "fscore"
# Leading columns of a results CSV, in order; the score columns follow, as metrics.score names
# them. process_time_s is the whole job (hand-over to result), load_time_s its loading in the
# worker and score_time_s its checking and scoring (recon.surfaces.isolation); the rest of
# process_time_s beyond wall_time_s is passing the job and result. peak_memory_mb is the run's
# process at its peak after the method returned (imports and the cloud included);
# baseline_memory_mb the same process just before the method started.
BASE_COLUMNS = ("key", "label", "method", "params", "kind", "status", "failure", "reason",
                "wall_time_s", "process_time_s", "load_time_s", "score_time_s",
                "peak_memory_mb", "baseline_memory_mb",
                "n_vertices", "n_faces", "watertight", "mesh")
# Threads per isolated run in a sweep: parallelism comes from the workers (one run per core).
SWEEP_THREADS = 1
# Fewest surface samples per side a score may use (--samples): below it the Chamfer distance's
# sampling error exceeds the differences between methods.
MIN_SCORE_SAMPLES = 100
# Memory of scoring one run, per surface sample per side (``metrics.score`` draws that many on
# each side and a coverage lattice of twice as many): the least measured (docs/decisions.md,
# "Measurements behind the defaults"), so that only a count that cannot fit is refused.
SCORE_BYTES_PER_SAMPLE = 600


# Grids of ``variants``: every method at its defaults (the Pareto front across methods, in
# minutes on a paper-scale cloud), or with each method's parameter grid besides.
GRIDS = ("defaults", "full")


def variants(names: Sequence[str] | None = None, *, grid: bool | str = "full") -> list[Run]:
    """The runs of a sweep: each method at its defaults, then (with the full grid) its grid.

    Parameters
    ----------
    names : sequence of str, optional
        Methods (default: every listed method). Hidden test methods may be named.
    grid : {"defaults", "full"} or bool
        ``"full"`` (or True) adds each method's parameter grid; ``"defaults"`` (or False) runs
        each method at its defaults only.

    Raises
    ------
    ParameterError
        A name that is not registered (checked before anything runs).
    """
    full = grid_name(grid) == "full"
    out = []
    for name in (list(names) if names else methods.available()):
        spec = methods.get(name)
        out.extend(spec.bind(params) for params in (spec.variants() if full else [{}]))
    return out


def grid_name(grid: bool | str) -> str:
    """``grid`` as one of ``GRIDS`` (True: "full", False: "defaults")."""
    if isinstance(grid, bool):
        return "full" if grid else "defaults"
    if grid not in GRIDS:
        raise ParameterError(f"grid must be one of {', '.join(GRIDS)}, got {grid!r}",
                             argument="grid")
    return grid


def full_grid_estimate(records: Sequence[dict], names: Sequence[str] | None = None, *,
                       workers: int = 1) -> dict:
    """How long the full grid would take, from the defaults' run times.

    Each grid variant is estimated at its method's default run time, the whole job (the fit,
    checking and scoring: ``process_time_s``; the fit alone where that is missing): a grid
    varies a resolution both ways around the default, so this is the middle of its range. The
    runs are shared among ``workers``.

    Returns
    -------
    dict
        ``runs`` (the full grid's runs not yet done), ``estimate_s`` (wall seconds, None when
        no default run succeeded), ``unknown`` (methods whose defaults failed: not counted).
    """
    done = {r["key"] for r in records if "key" in r}
    time_of = {r["method"]: r.get("process_time_s") or r["wall_time_s"] for r in records
               if r.get("status") == "ok" and r.get("wall_time_s")
               and r.get("key") == methods.bind(r["method"]).key}
    runs = [run for run in variants(names, grid="full") if run.key not in done]
    unknown = sorted({run.method for run in runs} - set(time_of))
    known = [time_of[run.method] for run in runs if run.method in time_of]
    estimate = sum(known) / max(1, workers) if known or not runs else None
    return {"runs": len(runs), "estimate_s": estimate, "unknown": unknown}


def as_runs(runs: Sequence[Run | tuple[str, dict]]) -> list[Run]:
    """``runs`` as ``Run`` values: ``(name, params)`` pairs are resolved once here."""
    return [methods.bind(*r) if isinstance(r, tuple) else methods.bind(r) for r in runs]


def score_options(samples: int | None = None, *, memory_mb: int | None = None) -> dict | None:
    """Keyword arguments of ``metrics.score`` for ``samples`` points per side.

    None keeps metrics' defaults. The coverage is estimated on twice as many truth points as
    each side's samples, as metrics' own defaults do.

    Parameters
    ----------
    samples : int, optional
    memory_mb : int, optional
        Memory limit of each scored run [MiB] (None or 0: none, this machine's memory bounds
        the samples).

    Raises
    ------
    ParameterError
        Fewer than ``MIN_SCORE_SAMPLES``, or more than the memory scoring them needs
        (``SCORE_BYTES_PER_SAMPLE`` each) fits in ``memory_mb``.
    """
    if samples is None:
        return None
    if samples < MIN_SCORE_SAMPLES:
        raise ParameterError(f"samples must be at least {MIN_SCORE_SAMPLES}, got {samples}",
                             argument="samples")
    if memory_mb:
        limit, within = memory_mb * 2**20, f"a run's memory limit ({memory_mb:,} MiB)"
    else:
        from formats.memory import total_bytes

        limit, within = total_bytes(), "this machine's memory"
    if limit is not None and samples * SCORE_BYTES_PER_SAMPLE > limit:
        raise ParameterError(
            f"samples must be at most {limit // SCORE_BYTES_PER_SAMPLE:,}, got {samples:,}: "
            f"scoring them would need about {samples * SCORE_BYTES_PER_SAMPLE / 2**30:,.1f} GiB, "
            f"more than {within}", argument="samples")
    return {"n_truth_samples": samples, "n_test_samples": samples,
            "coverage_points": 2 * samples}


def rank(records: list[dict]) -> list[dict]:
    """Successful runs by Chamfer (ties: higher F-score), then failures in run order."""
    ok = [r for r in records if r.get("status") == "ok" and r.get(CHAMFER) is not None]
    ok.sort(key=lambda r: (r[CHAMFER], -(r.get(FSCORE) or 0.0)))
    return ok + [r for r in records if r not in ok]


def pareto_front(time: np.ndarray, value: np.ndarray, *, minimize: bool = True) -> np.ndarray:
    """Indices of the Pareto-optimal runs (faster, or better than every faster one), by time.

    Parameters
    ----------
    time : (n,) float64, seconds
    value : (n,) float64
        The accuracy, lower better when ``minimize`` (Chamfer), else higher (F-score).
    """
    time = np.asarray(time, dtype=float)
    score = np.asarray(value, dtype=float) * (1 if minimize else -1)
    order = np.lexsort((score, time))
    front, best = [], np.inf
    for i in order:  # a short sorted scan over runs, not points
        if score[i] < best:
            front.append(i)
            best = score[i]
    return np.array(front, dtype=int)


def write_csv(records: list[dict], path) -> Path:
    """Write records as CSV: BASE_COLUMNS then every other column, sorted (params as JSON);
    atomically (a destination that is a directory is one line)."""
    import csv
    import io

    extra = sorted({k for r in records for k in r} - set(BASE_COLUMNS))
    out = io.StringIO(newline="")
    writer = csv.writer(out)
    writer.writerow([*BASE_COLUMNS, *extra])
    for r in records:
        row = []
        for column in (*BASE_COLUMNS, *extra):
            value = r.get(column)
            if isinstance(value, (dict, list, tuple)):
                value = json.dumps(to_jsonable(value), sort_keys=True)
            row.append("" if value is None else value)
        writer.writerow(row)
    return write_text_atomically(path, out.getvalue(), error=ParameterError)
