"""``recon stability``: where each method fails, over noise x point density x outlier fraction.

Every cell of the grid is a degraded copy of one cloud (or one simulated scene); every method
runs on it isolated (``recon.surfaces.isolation``), so a crash, a timeout, an empty or degenerate
mesh is recorded as that cell's failure and the sweep goes on. Results stream to
``DIR/results.jsonl`` on Dask (``recon.experiments.sweep``; ``resume`` skips finished cells).
``stability`` starts from clouds and a truth mesh (``recon.api.stability`` from what a user
names: a scene, a cloud or a log, and decides the truth). Finishing writes

- ``DIR/stability.csv`` and ``DIR/stability.json``: one row per (method, cell) with the status,
  failure kind and reason, time (the fit's, and the whole job's with its scoring), memory,
  faces and scores;
- ``DIR/<method>_failures.png``: the failure map (a panel per outlier fraction, noise against
  density, each cell coloured by its outcome, an accuracy collapse included);
- ``DIR/<method>_accuracy.png``: the Chamfer heatmap on the same grid (failed cells hatched).

A cell fails on a crash, a timeout, an empty or degenerate mesh (``recon.surfaces.isolation``)
and also on an **accuracy collapse** (``mark_collapses``): a mesh whose Chamfer distance exceeds
``COLLAPSE_RATIO`` times the same method's on the clean cell (the first noise, density and
outlier levels: no noise, all points, no outliers by default) plus the cell's added noise (1
sigma), i.e. far worse than the noise alone can explain. Such a cell keeps its scores, is
recorded with ``failure = "collapse"`` and counts in the failure rate. (``plane`` with 5%
outliers on a satellite cloud went from 0.11 to 0.49 m: a collapse; noise that raises an
interpolating surface's error by its own size is not.)

How a cell is made (each from its own seed, ``SeedSequence((seed, i_noise, i_density,
i_outlier))``, so every method sees the same points):

noise
    The 3-sigma range error in metres, the paper's unit (0.3 m for its LRF, 1 m for the
    Jenoptik LIDAR). For a scene, each level is a fresh simulation with ``errors.range_sigma3``
    set to it (a real range error along each beam). For a cloud, Gaussian noise of sigma =
    level / 3 is added along each point's line of sight (from its view point), or isotropically
    when the cloud has no view points.
density
    The fraction of the points kept (a seeded subsample without replacement).
outliers
    Extra points, as a fraction of the kept ones (0 to ``MAX_OUTLIERS``, 1: as many outliers as
    real points), uniform in the cloud's bounding box; each takes the view point of a random real
    point (a spurious return along a real shot).

A sweep's cost is estimated before anything is read or simulated (``check_grid``): its runs
(cells x methods) at ``RUN_S`` plus ``SAMPLE_S`` per scoring sample each, the least a run takes,
shared among the workers; a grid estimated at more than ``MAX_SWEEP_S``, or of more than
``MAX_RUNS`` runs, is refused.

A log's missed beams (free space no degradation changes) reach every cell's methods, as they
reach ``recon compare``'s: the visibility method's cut respects them.
"""

from __future__ import annotations

import hashlib
import json
import math
import threading
from collections import OrderedDict
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from formats import sigma_from_sigma3
from formats.atomic import write_text_atomically
from formats.errors import ParameterError, ReconError
from recon.experiments import charts
from recon.experiments.cases import SWEEP_THREADS, variants, write_csv
from recon.experiments.sweep import (
    default_workers,
    run_sweep,
    to_jsonable,
)
from recon.surfaces.isolation import (
    DEFAULT_MEMORY_MB,
    DEFAULT_TIMEOUT_S,
    run_isolated,
)
from recon.surfaces.methods import MethodInput, Run

if TYPE_CHECKING:
    from recon.registration.misses import MissedBeams

# Default grid. Noise: none, the paper's LRF (0.3 m 3-sigma) and its LIDAR (1 m 3-sigma).
# Density: all points, 30% and 10%. Outliers: none and 2% (a few percent of spurious returns is
# typical of space LIDAR data in sunlight; a stress level, not a measured one).
DEFAULT_NOISE = (0.0, 0.3, 1.0)
DEFAULT_DENSITY = (1.0, 0.3, 0.1)
DEFAULT_OUTLIERS = (0.0, 0.02)
# The range-error key of sim scenes (sim/defaults.py, [errors] range_sigma3).
SCENE_NOISE_KEY = "errors.range_sigma3"
# Fewest points a degraded cell may keep.
MIN_CELL_POINTS = 32
# Most outliers a cell may add, as a fraction of its kept points: 1 makes half of the cell's
# points spurious. Beyond it the outliers outnumber the surface's points (no method here is meant
# to find a surface then; space LIDAR data in sunlight has a few percent), and every level above
# 1 multiplies the cell's memory.
MAX_OUTLIERS = 1.0
# The least one run of a cell takes (``check_grid``): RUN_S to hand the cell to its isolated
# worker and take the result back, plus SAMPLE_S per surface sample scored on each side; the
# method's own fit comes on top. Half the fastest runs measured (convex-hull; docs/decisions.md,
# "Measurements behind the defaults"), so the estimate stays below what a sweep takes.
RUN_S = 0.05
SAMPLE_S = 3e-5
# Longest sweep accepted, by that estimate: a week. The default grid takes minutes; a grid that
# needs a week at the least is a list of levels written where a few were meant (1000 x 1000 cells
# is 2 million runs), or a job for more workers (a Dask cluster with ``n_workers`` counting them)
# or for a grid split into sweeps.
MAX_SWEEP_S = 7 * 86400.0
# Most runs a sweep may have, whatever their time: each keeps its case and its record in this
# process, about 3 kB (docs/decisions.md, "Measurements behind the defaults"), so 200,000 runs
# hold about 0.6 GB besides their stability.json; a 300 x 300 x 2 grid of one method fits.
MAX_RUNS = 200_000
# Accuracy collapse (module docstring): Chamfer above 3x the clean cell's plus the added noise.
# 3x: a method that merely degrades with its input stays within 2x here (measured: Poisson and
# plane at 30% density and 0.3 m noise on the asteroid), the reported plane collapse was 4.5x.
COLLAPSE_RATIO = 3.0
COLLAPSE_RULE = (f"collapse: Chamfer > {COLLAPSE_RATIO:g} x the clean cell's + the added noise "
                 "(1 sigma)")
# Cells whose prepared clouds a process keeps (``_CellCache``): the cases run cell by cell, so
# the cells in flight are at most one per worker plus the next; 4 covers 2 workers with room.
CELL_CACHE = 4
# Points sampled per side when a cell's mesh is scored (``samples`` overrides), derived from the
# precision a cell needs: its Chamfer decides a collapse at COLLAPSE_RATIO x the clean cell's, so
# a standard error of CHAMFER_PRECISION (2%) of it is ample. With both sides' distances spread
# DISTANCE_CV times their mean (the largest coefficient of variation measured over the default
# sweep of a 10,000-point asteroid cloud, 5.2, is a completeness; a typical one is 1.4), the
# Chamfer's relative error is sqrt(2) / 2 * DISTANCE_CV / sqrt(samples). Each record carries the
# error it achieved (``chamfer_se_m``). The edge score of a mesh is measured on its samples,
# so it is that of 31,250 samples, not of the 200,000 metrics draws by default.
CHAMFER_PRECISION = 0.02
DISTANCE_CV = 5.0
STABILITY_SAMPLES = math.ceil(0.5 * (DISTANCE_CV / CHAMFER_PRECISION) ** 2)


class StabilityCloud(NamedTuple):
    """A cloud the sweep degrades: the strikes as loaded, before any cell's degradation.

    Attributes
    ----------
    points : (n, 3) float64, metres, body frame
    view_points : (n, 3) float64 or None
        Each strike's sensor position.
    noisy : bool
        Whether the points already carry the level's range noise (a simulated level) or the
        cell adds it (a cloud given as it is).
    misses : recon.registration.misses.MissedBeams or None
        The log's missed beams near the strikes (``recon.surfaces.auto.misses_near``): free
        space that no cell's degradation changes, passed to every cell's methods.
    """

    points: np.ndarray
    view_points: np.ndarray | None
    noisy: bool
    misses: MissedBeams | None = None


def _check_levels(name: str, levels: Sequence[float], low: float, high: float | None
                  ) -> tuple[float, ...]:
    levels = tuple(float(v) for v in levels)
    if not levels:
        raise ParameterError(f"{name} needs at least one level", argument=name)
    for v in levels:
        if not np.isfinite(v) or v < low or (high is not None and v > high):
            limit = f"[{low:g}, {high:g}]" if high is not None else f">= {low:g}"
            raise ParameterError(f"{name} level {v:g} is out of range (must be {limit})",
                                 argument=name)
    if len(set(levels)) != len(levels):
        raise ParameterError(f"{name} levels repeat: {levels}", argument=name)
    return levels


def check_grid(noise: Sequence[float], density: Sequence[float], outliers: Sequence[float],
               n_methods: int, *, samples: int, workers: int
               ) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
    """The grid's levels, checked, and its cost estimated before any work.

    Parameters
    ----------
    noise, density, outliers : sequence of float
        Grid levels (module docstring).
    n_methods : int
        Methods run on every cell.
    samples : int
        Surface samples scored per side in each run.
    workers : int
        Runs at once.

    Returns
    -------
    noise, density, outliers : tuple of float

    Raises
    ------
    ParameterError
        A level out of range or repeated, or a grid of more than ``MAX_RUNS`` runs or whose
        runs would take more than ``MAX_SWEEP_S`` at the least (``RUN_S`` and ``SAMPLE_S`` a
        run).
    """
    noise = _check_levels("noise", noise, 0.0, None)
    density = _check_levels("density", density, 1e-9, 1.0)
    outliers = _check_levels("outliers", outliers, 0.0, MAX_OUTLIERS)
    cells = len(noise) * len(density) * len(outliers)
    runs = cells * n_methods
    per_run = RUN_S + SAMPLE_S * samples
    estimate = runs * per_run / max(1, workers)
    if estimate > MAX_SWEEP_S or runs > MAX_RUNS:
        raise ParameterError(
            f"noise, density and outliers make {cells:,} cells; with {n_methods} method(s) that "
            f"is {runs:,} runs, at least {estimate / 86400:.3g} days on {workers} worker(s) "
            f"({per_run:.2g} s a run scoring {samples:,} samples per side); a sweep may have "
            f"at most {MAX_RUNS:,} runs and take at most {MAX_SWEEP_S / 86400:g} days: use "
            "fewer levels or methods, fewer samples or more workers")
    return noise, density, outliers


def degrade(points: np.ndarray, view_points: np.ndarray | None, *, noise_sigma3: float,
            density: float, outliers: float, seed_sequence: np.random.SeedSequence
            ) -> tuple[np.ndarray, np.ndarray | None]:
    """One cell's cloud: noise (if ``noise_sigma3`` > 0), subsampling, then outliers.

    Parameters
    ----------
    points : (n, 3) float64, metres, body frame
    view_points : (n, 3) float64, metres, optional
    noise_sigma3 : float, metres
        3-sigma of Gaussian noise along each line of sight (isotropic without view points).
    density : float
        Fraction of the points kept, in (0, 1].
    outliers : float
        Uniform points added, as a fraction of the kept points.
    seed_sequence : numpy.random.SeedSequence

    Returns
    -------
    points : (m, 3) float64
    view_points : (m, 3) float64 or None
    """
    rng = np.random.default_rng(seed_sequence)
    n = len(points)
    if noise_sigma3 > 0:
        if view_points is not None:
            ray = points - view_points
            ray /= np.maximum(np.linalg.norm(ray, axis=1, keepdims=True), 1e-300)
            points = points + ray * rng.normal(0.0, sigma_from_sigma3(noise_sigma3), (n, 1))
        else:
            points = points + rng.normal(0.0, sigma_from_sigma3(noise_sigma3), (n, 3))
    keep = np.sort(rng.choice(n, size=max(1, round(density * n)), replace=False))
    points = points[keep]
    view_points = None if view_points is None else view_points[keep]
    extra = round(outliers * len(points))
    if extra:
        low, high = points.min(axis=0), points.max(axis=0)
        fake = rng.uniform(low, high, (extra, 3))
        points = np.concatenate([points, fake])
        if view_points is not None:
            view_points = np.concatenate([view_points,
                                          view_points[rng.integers(0, len(view_points), extra)]])
    return points, view_points


def cell_cloud(clouds: dict, *, noise_key: str, noise_sigma3: float, density: float,
               outliers: float, cell: tuple[int, int, int], seed: int
               ) -> MethodInput | dict:
    """One cell's cloud, degraded and prepared; or, when it cannot be, the failure every
    method records for the cell (a dict with ``failure``, ``reason`` and ``n_points``)."""
    from recon.surfaces.prepare import prepare

    points, view_points, noisy, misses = clouds[noise_key]
    sequence = np.random.SeedSequence((seed, *cell))
    points, view_points = degrade(points, view_points,
                                  noise_sigma3=0.0 if noisy else noise_sigma3,
                                  density=density, outliers=outliers, seed_sequence=sequence)
    if len(points) < MIN_CELL_POINTS:
        return {"status": "failed", "failure": "empty",
                "reason": f"only {len(points)} points left in this cell", "n_points": len(points)}
    try:
        return prepare(points, view_points=view_points, seed=seed, misses=misses)
    except ReconError as exc:
        return {"status": "failed", "failure": "error",
                "reason": f"preparing the cloud failed: {exc}", "n_points": len(points)}


class _CellCache:
    """The last ``CELL_CACHE`` cells' clouds of this process, each built once.

    The cases run cell by cell (every method of a cell, then the next cell), so the methods of
    a cell find its cloud here instead of degrading and preparing it again; a thread asking for
    a cell another thread is building waits for it.
    """

    def __init__(self, size: int):
        self.size = size
        self.entries: OrderedDict = OrderedDict()
        self.lock = threading.Lock()

    def get(self, key, build):
        with self.lock:
            entry = self.entries.get(key)
            if entry is None:
                entry = self.entries[key] = {"lock": threading.Lock(), "value": None}
                while len(self.entries) > self.size:
                    self.entries.popitem(last=False)
            self.entries.move_to_end(key)
        with entry["lock"]:
            if entry["value"] is None:
                entry["value"] = build()
            return entry["value"]


_CELLS = _CellCache(CELL_CACHE)


def run_cell(*, run: Run, clouds: dict, source: str, truth, noise_key: str,
             noise_sigma3: float, density: float, outliers: float, cell: tuple[int, int, int],
             seed: int, timeout_s: float, memory_mb: int | None, score_options: dict | None
             ) -> dict:
    """Run ``run`` on one cell's cloud (``cell_cloud``, built once per cell in this process and
    ``source``, the clouds' digest), isolated and scored."""
    cloud = _CELLS.get((source, noise_key, noise_sigma3, density, outliers, cell, seed),
                       lambda: cell_cloud(clouds, noise_key=noise_key, noise_sigma3=noise_sigma3,
                                          density=density, outliers=outliers, cell=cell,
                                          seed=seed))
    if isinstance(cloud, dict):
        return {"method": run.method, "params": run.params, **cloud}
    from recon.experiments.progress import isolated_stage

    result = run_isolated(run, cloud, truth=truth, score_options=score_options,
                          timeout_s=timeout_s, memory_mb=memory_mb, threads=SWEEP_THREADS,
                          on_wait=isolated_stage)
    result.pop("vertices", None)
    result.pop("faces", None)
    result["n_points"] = len(cloud.points)
    return result


def simulate_levels(scene: str, noise: Sequence[float], out_dir, *, overrides=(), seed: int = 0
                    ) -> tuple[dict, tuple[np.ndarray, np.ndarray]]:
    """Simulate ``scene`` once per noise level and ingest each log.

    Returns
    -------
    clouds : dict
        ``{noise_key: StabilityCloud}``, each with its log's missed beams.
    truth : (vertices, faces)
        The scene's truth mesh, metres, body frame.
    """
    import sim
    from formats import StrikeLog
    from recon.registration.ingest import ingest
    from recon.surfaces.auto import misses_near

    noise = _check_levels("noise", noise, 0.0, None)   # before simulating anything
    logs = Path(out_dir) / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    clouds, truth = {}, None
    for level in noise:
        scene_obj = sim.load_scene(scene, [*overrides, f"{SCENE_NOISE_KEY}={level:g}"])
        path = logs / f"noise-{level:g}.h5"
        if not path.exists():
            sim.simulate(scene_obj, path, seed=seed)
        cloud = ingest(path)
        clouds[_noise_key(level)] = StabilityCloud(cloud.points, cloud.view_points, True,
                                                   misses_near(path, cloud.points, seed=seed))
        if truth is None:
            with StrikeLog(path) as log:
                truth = log.truth_mesh()
    return clouds, truth


def _noise_key(level: float) -> str:
    return f"{level:g}"


def stability(out_dir, *, clouds: dict, truth, names: Sequence[str] | None = None,
              noise: Sequence[float] = DEFAULT_NOISE, density: Sequence[float] = DEFAULT_DENSITY,
              outliers: Sequence[float] = DEFAULT_OUTLIERS, seed: int = 0,
              timeout_s: float = DEFAULT_TIMEOUT_S, memory_mb: int | None = DEFAULT_MEMORY_MB,
              scheduler: str | None = None, n_workers: int | None = None, resume: bool = False,
              score_options: dict | None = None, fingerprint: dict | None = None) -> dict:
    """Run every method at its defaults on every cell of the grid; write maps and data.

    Parameters
    ----------
    out_dir : str or Path
    clouds : dict
        ``{noise_key: StabilityCloud}`` (or its fields as a tuple): one entry ``"base"`` (a
        cloud; noise is added per level) or one per noise level (``simulate_levels``).
    truth : (vertices, faces)
        Truth mesh, metres, body frame.
    names : sequence of str, optional
        Methods (default: all listed), each at its defaults.
    noise, density, outliers : sequence of float
        Grid levels (module docstring).
    seed : int
    timeout_s, memory_mb, scheduler, n_workers, resume, score_options
        As in ``recon.experiments.compare.compare`` (no scheduler: ``"threads"``, one thread
        per core waiting on its isolated worker).
    fingerprint : dict, optional
        Extra identity of the source for ``--resume`` checks.

    Returns
    -------
    dict
        ``records`` and the paths written.
    """
    clouds = {name: StabilityCloud(*cloud) for name, cloud in clouds.items()}
    runs = variants(names, grid=False)
    noise, density, outliers = check_grid(
        noise, density, outliers, len(runs),
        samples=(score_options or {}).get("n_test_samples", STABILITY_SAMPLES),
        workers=n_workers or default_workers())
    scheduler = scheduler or "threads"
    cases = {}  # cell by cell, so that a cell's methods share its cloud (``_CellCache``)
    for i, nz in enumerate(noise):
        for j, dn in enumerate(density):
            for k, ol in enumerate(outliers):
                for run in runs:
                    key = f"{run.method} noise={nz:g} density={dn:g} outliers={ol:g}"
                    cases[key] = {"run": run,
                                  "noise_key": "base" if "base" in clouds else _noise_key(nz),
                                  "noise_sigma3": nz, "density": dn, "outliers": ol,
                                  "cell": (i, j, k)}
    digest = hashlib.sha1()
    for name in sorted(clouds):
        digest.update(np.ascontiguousarray(clouds[name].points).tobytes())
        misses = clouds[name].misses
        if misses is not None:   # the free space each cell's methods see is part of the source
            for array in (misses.origin, misses.direction):
                digest.update(np.ascontiguousarray(array).tobytes())
    source = digest.hexdigest()
    ident = {"points_sha1": source, "seed": seed, "timeout_s": timeout_s,
             "memory_mb": memory_mb, "score_options": score_options or {}} | dict(
        fingerprint or {})

    def keep(key, result):
        case = cases[key]
        record = {"label": case["run"].label, "method": case["run"].method,
                  "noise_sigma3_m": case["noise_sigma3"], "density": case["density"],
                  "outliers": case["outliers"]}
        for column in ("status", "failure", "reason", "wall_time_s", "process_time_s",
                       "load_time_s", "score_time_s", "peak_memory_mb", "n_points", "n_faces",
                       "watertight"):
            record[column] = result.get(column)
        # The scores' own n_points counts the samples drawn on the mesh, not the cell's points.
        record.update({k: v for k, v in (result.get("scores") or {}).items() if k not in record})
        return record

    charts.preload()
    done = run_sweep(run_cell, cases, out_dir,
                     shared={"clouds": clouds, "source": source, "truth": truth, "seed": seed,
                             "timeout_s": timeout_s, "memory_mb": memory_mb,
                             "score_options": score_options},
                     fingerprint=ident, scheduler=scheduler, n_workers=n_workers,
                     resume=resume, on_result=keep, desc="stability",
                     outputs=("stability.csv", "stability.json"))
    records = []
    order = {run.key: i for i, run in enumerate(runs)}  # method by method, as before
    for key, case in sorted(cases.items(), key=lambda item: order[item[1]["run"].key]):
        record = dict(done[key])
        record.setdefault("method", case["run"].method)
        record.setdefault("noise_sigma3_m", case["noise_sigma3"])
        record.setdefault("density", case["density"])
        record.setdefault("outliers", case["outliers"])
        records.append(record)
    return finish(records, out_dir, noise=noise, density=density, outliers=outliers)


def mark_collapses(records: list[dict], *, noise, density, outliers) -> list[dict]:
    """Mark accuracy collapses (module docstring) in place: ``failure = "collapse"``.

    The clean cell of a method is its record at ``noise[0]``, ``density[0]``, ``outliers[0]``;
    a method whose clean cell failed has no reference and no collapse.
    """
    from recon.experiments.cases import CHAMFER

    for method in dict.fromkeys(r["method"] for r in records):
        mine = [r for r in records if r["method"] == method]
        clean = next((r for r in mine if r["noise_sigma3_m"] == noise[0]
                      and r["density"] == density[0] and r["outliers"] == outliers[0]), None)
        if clean is None or clean.get("status") != "ok" or clean.get(CHAMFER) is None:
            continue
        for r in mine:
            if r.get("status") != "ok" or r.get(CHAMFER) is None:
                continue
            limit = COLLAPSE_RATIO * clean[CHAMFER] + sigma_from_sigma3(r["noise_sigma3_m"])
            if r[CHAMFER] > limit:
                r["failure"] = "collapse"
                r["reason"] = (f"accuracy collapse: Chamfer {r[CHAMFER]:.3g} m > "
                               f"{COLLAPSE_RATIO:g} x {clean[CHAMFER]:.3g} m (clean cell) + "
                               f"{sigma_from_sigma3(r['noise_sigma3_m']):.3g} m (noise)")
    return records


def failed(record: dict) -> bool:
    """A cell that crashed, timed out, gave no usable mesh or collapsed in accuracy."""
    return record.get("status") != "ok" or record.get("failure") == "collapse"


def finish(records: list[dict], out_dir, *, noise, density, outliers) -> dict:
    """Mark collapses; write stability.csv, stability.json and each method's two PNGs."""
    out_dir = Path(out_dir)
    mark_collapses(records, noise=noise, density=density, outliers=outliers)
    csv_path = write_csv(records, out_dir / "stability.csv")
    summary = {"noise_sigma3_m": list(noise), "density": list(density),
               "outliers": list(outliers), "records": records,
               "collapse_ratio": COLLAPSE_RATIO,
               "failure_rate": {m: float(np.mean([failed(r) for r in records
                                                  if r["method"] == m]))
                                for m in dict.fromkeys(r["method"] for r in records)}}
    json_path = out_dir / "stability.json"
    write_text_atomically(json_path, json.dumps(to_jsonable(summary), indent=2) + "\n",
                          error=ParameterError)
    pngs = []
    for method in dict.fromkeys(r["method"] for r in records):
        mine = [r for r in records if r["method"] == method]
        pngs.append(charts.failure_map(mine, out_dir / f"{method}_failures.png", method=method,
                                       noise=noise, density=density, outliers=outliers,
                                       rule=COLLAPSE_RULE))
        pngs.append(charts.accuracy_map(mine, out_dir / f"{method}_accuracy.png", method=method,
                                        noise=noise, density=density, outliers=outliers))
    return {"records": records, "csv": csv_path, "json": json_path, "pngs": pngs,
            "failure_rate": summary["failure_rate"]}
