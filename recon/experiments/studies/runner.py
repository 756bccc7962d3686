"""What every study shares: one case = simulate, ingest, score time prefixes; run them on Dask.

A case is a scene (a preset plus ``section.key=value`` overrides) and a seed. ``run_case``, the
task each Dask worker executes, simulates the scene into a temporary strike log, registers it
into the body frame (``recon.registration.ingest``), deletes the log, and scores the cloud against
the truth
mesh at every requested time prefix: the points of shots fired before ``T``. A shot fires at
``t = k * step`` for ``k < duration / step`` (sim/scene.py) and every error model draws from
streams keyed by seed and chunk, so the prefix ``time < T`` of a long run is exactly the run of
duration ``T`` with the same seed: one simulation gives a whole curve against time.

Records keep only numbers (scores per prefix, the simulation summary, and where asked the
per-face coverage or a small sample of the points for a picture);
``recon.experiments.sweep.run_sweep``
streams them to ``results.jsonl``, so ``--resume`` skips finished cases.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from formats import scratch
from formats.atomic import write_text_atomically
from formats.errors import ParameterError

# Study sizes: ``full`` reproduces the paper's durations, ``quick`` is for CI (every study in a
# few minutes together), ``tiny`` only exercises the code in the tests.
SIZES = ("tiny", "quick", "full")

# The paper's asteroid and RSOs spin every 15480 s (4.3 h); the unit of its time axes.
ROTATION_S = 15480.0
# The same in hours, as the paper's time axes and the studies' labels give it.
ROTATION_H = ROTATION_S / 3600.0

# Score options of the curves (many prefixes per case): a quarter of metrics.score's fixed-count
# truth samples (200,000) and coverage lattice (400,000). On the 100-rotation asteroid cloud this
# moves coverage by 1e-4 and F-score by 7e-4 (measured), far below the differences between the
# cases compared, at half the cost. Every study writes the options it used into its data.
CURVE_SCORE = {"n_truth_samples": 50_000, "coverage_points": 100_000}
# Table studies (one score per case) use metrics.score's defaults: counts sized from its stated
# precision (metrics/precision.py).
TABLE_SCORE: dict[str, Any] = {}
# The tiny size of every study (tests only): a fiftieth of metrics.score's samples, enough for
# every metric to be computed, not for its value to mean anything.
TINY_SCORE = {"n_truth_samples": 4000, "coverage_points": 8000}

# The fewest points scored: the edge metric needs k = 16 neighbours (metrics/defaults.py).
MIN_SCORED_POINTS = 16
# Scalars kept from each ScoreReport, and from its edge report.
SCORE_KEYS = ("edge_score", "fscore", "precision", "recall", "chamfer_m", "coverage",
              "accuracy_mean_m", "completeness_mean_m", "hausdorff_m", "tau_m")
EDGE_KEYS = ("false_edge_rate", "missed_edge_rate", "feature_missed_rate", "n_edge_points")
# What the claims about "the score" are decided on: the paper's edge score first (metrics/edges.py,
# informative on the asteroid since it reads the whole triangulation), coverage and F-score beside
# it; each with True when lower is better.
CLAIM_METRICS = (("edge_score", True), ("coverage", False), ("fscore", False))
# Decimals of the per-face coverage kept in records (a 20,480-face map is ~120 kB of JSON).
FACE_COVERAGE_DECIMALS = 3

RESULTS_CSV = "results.csv"
SUMMARY_JSON = "summary.json"


# --------------------------------------------------------------------------- one case


def rotations(n: float) -> float:
    """``n`` target rotations in seconds (the paper's 4.3 h spin)."""
    return float(n) * ROTATION_S


def scene_case(scene: str, overrides: Sequence[str] = (), *, prefixes_s: Sequence[float],
               seed: int = 0, score_options: Mapping | None = None,
               keep_coverage: bool = False, keep_points: int = 0,
               points_at: Sequence[float] = (), tags: Mapping | None = None) -> dict:
    """Keyword arguments of one ``run_case`` task.

    Parameters
    ----------
    scene : str
        Preset name (``recon simulate --list``) or scene file.
    overrides : sequence of str
        ``section.key=value`` overrides; they must make the run last at least the longest
        prefix.
    prefixes_s : sequence of float, seconds
        Time prefixes to score, ascending.
    seed : int
    score_options : dict, optional
        Keyword arguments of ``metrics.score.score`` (default ``CURVE_SCORE``).
    keep_coverage : bool
        Keep the per-face coverage of every prefix (coverage maps).
    keep_points : int
        Keep a seeded random sample of at most this many points (pictures) ...
    points_at : sequence of float, seconds
        ... of these prefixes.
    tags : dict, optional
        What the case stands for (inclination, pattern, ...), copied into its record and rows.
    """
    return {"scene": scene, "overrides": list(overrides), "seed": int(seed),
            "prefixes_s": [float(t) for t in prefixes_s],
            "score_options": dict(CURVE_SCORE if score_options is None else score_options),
            "keep_coverage": bool(keep_coverage), "keep_points": int(keep_points),
            "points_at": [float(t) for t in points_at], "tags": dict(tags or {})}


@contextmanager
def simulated_log(scene: str, overrides: Sequence[str] = (), *, seed: int = 0,
                  sim_workers: int | None = None, progress=False):
    """Simulate a scene into a temporary log, deleted on leaving the block (``progress``:
    ``sim.simulate``'s, e.g. a case's ``recon.experiments.progress.within``).

    Yields
    ------
    log : Path
        The strike log, while the block runs.
    truth : (vertices (v, 3) float64 metres, faces (f, 3) int64)
    summary : dict
        ``sim.simulate``'s summary and ``spin_period_s``.
    """
    import sim

    the_scene = sim.load_scene(scene, list(overrides))
    with scratch.directory("recon-study-") as tmp:
        log = tmp / "run.h5"
        summary = sim.simulate(the_scene, log, seed=seed, progress=progress,
                               workers=sim_workers)
        summary = dict(summary, spin_period_s=float(the_scene["target.spin_period"]))
        yield log, (the_scene.vertices, the_scene.faces), summary


def simulate_cloud(scene: str, overrides: Sequence[str] = (), *, seed: int = 0,
                   sim_workers: int | None = None, progress=False):
    """Simulate a scene (``simulated_log``) and ingest its log.

    Returns
    -------
    cloud : formats.cloud_io.Cloud
        Body frame, with ``time`` and the view points.
    truth : (vertices (v, 3) float64 metres, faces (f, 3) int64)
    summary : dict
        ``sim.simulate``'s summary (its ``path`` no longer exists) and ``spin_period_s``.
    """
    from recon.registration.ingest import ingest

    with simulated_log(scene, overrides, seed=seed, sim_workers=sim_workers,
                       progress=progress) as (log, truth, summary):
        return ingest(log), truth, summary


def score_row(points: np.ndarray, truth, *, seed: int, score_options: Mapping) -> tuple[dict, Any]:
    """Scores of one cloud: the ``SCORE_KEYS`` and ``EDGE_KEYS`` scalars, and the report."""
    from metrics.score import score

    report = score(points, truth, seed=seed, **score_options)
    row = {key: getattr(report, key) for key in SCORE_KEYS}
    edge = report.edge
    for key in EDGE_KEYS:
        row[key] = None if edge is None else getattr(edge, key)
    return row, report


def run_case(*, scene: str, overrides: Sequence[str], seed: int, prefixes_s: Sequence[float],
             score_options: Mapping, keep_coverage: bool = False, keep_points: int = 0,
             points_at: Sequence[float] = (), tags: Mapping | None = None,
             sim_workers: int | None = 1) -> dict:
    """Simulate one scene, ingest it and score every time prefix (the task of a study sweep).

    Parameters
    ----------
    scene, overrides, seed, prefixes_s, score_options, keep_coverage, keep_points, points_at,
    tags
        See ``scene_case``.
    sim_workers : int or None
        Threads of the simulator (1 in a sweep: the parallelism is across cases).

    Returns
    -------
    dict
        ``status`` ("ok"), ``tags``, ``scene``, ``overrides``, ``seed``, ``sim`` (shots,
        pulses, strikes, orbit period, duration, wall time), ``spin_period_s``, ``prefixes``
        (one dict per prefix: ``time_s``, ``hours``, ``rotations``, ``n_points`` and the
        scores, or ``scored`` False when too few points) and ``wall_time_s``.
    """
    from metrics.score import Truth
    from recon.experiments import progress

    start = time.perf_counter()
    # Progress: the simulation the first half, the prefixes scored the second.
    cloud, truth, summary = simulate_cloud(scene, overrides, seed=seed, sim_workers=sim_workers,
                                           progress=progress.within(0.0, 0.5))
    truth = Truth(truth)  # built once, reused by every prefix's score
    spin = float(summary["spin_period_s"])
    shot_time = cloud.attributes["time"]
    rng = np.random.default_rng([seed, 2])
    rows = []
    for index, t in enumerate(prefixes_s):
        progress.step(len(prefixes_s) + index, 2 * len(prefixes_s))
        mask = shot_time < t
        n = int(mask.sum())
        row: dict[str, Any] = {"time_s": t, "hours": t / 3600.0,
                               "rotations": t / spin if math.isfinite(spin) else None,
                               "n_points": n, "scored": n >= MIN_SCORED_POINTS}
        if row["scored"]:
            points = cloud.points[mask]
            scores, report = score_row(points, truth, seed=seed, score_options=score_options)
            row.update(scores)
            if keep_coverage:
                row["face_coverage"] = np.round(report.face_coverage, FACE_COVERAGE_DECIMALS)
            if keep_points and any(math.isclose(t, s) for s in points_at):
                pick = rng.choice(n, size=min(n, keep_points), replace=False)
                row["points"] = np.round(points[np.sort(pick)], 3)
        rows.append(row)
    keep = ("shots", "pulses", "strikes", "beams", "pattern", "target", "duration_s",
            "orbit_period_s", "mu", "inclination_change_s", "wall_time_s")
    return {"status": "ok", "tags": dict(tags or {}), "scene": scene,
            "overrides": list(overrides), "seed": seed, "spin_period_s": spin,
            "sim": {k: summary[k] for k in keep}, "score_options": dict(score_options),
            "prefixes": rows, "wall_time_s": time.perf_counter() - start}


# --------------------------------------------------------------------------- running


def check_size(size: str) -> str:
    if size not in SIZES:
        raise ParameterError(f"size must be one of {', '.join(SIZES)}, got {size!r}")
    return size


def fingerprint(study: str, size: str, cases: Mapping[str, Mapping]) -> dict:
    """Identity of a study's results: resuming with other cases is refused
    (``recon.experiments.sweep``)."""
    from recon.experiments.sweep import to_jsonable

    text = json.dumps(to_jsonable(cases), sort_keys=True)
    return {"study": study, "size": size, "n_cases": len(cases),
            "cases_sha1": hashlib.sha1(text.encode()).hexdigest()}


def drop_failed(out_dir: Path) -> int:
    """Remove failed records from ``results.jsonl`` so that ``--resume`` runs them again.

    Returns the number removed.
    """
    from recon.experiments.sweep import RESULTS_NAME, read_results

    path = Path(out_dir) / RESULTS_NAME
    done = read_results(path)
    kept = [r for r in done.values() if r.get("status") == "ok"]
    if len(kept) < len(done):
        write_text_atomically(path, "".join(json.dumps(r) + "\n" for r in kept))
    return len(done) - len(kept)


def execute(study: str, cases: Mapping[str, Mapping], out_dir, *, size: str,
            scheduler: str | None = None, resume: bool = False, n_workers: int | None = None,
            func: Callable[..., dict] = run_case, shared: Mapping | None = None
            ) -> dict[str, dict]:
    """Run a study's cases with ``recon.experiments.sweep.run_sweep``; return the records by key.

    On ``resume``, finished cases are kept and failed ones run again.
    """
    from recon.experiments.sweep import run_sweep

    out_dir = Path(out_dir)
    if resume:
        drop_failed(out_dir)
    return run_sweep(func, cases, out_dir, shared=shared,
                     fingerprint=fingerprint(study, size, cases), scheduler=scheduler,
                     n_workers=n_workers, resume=resume, desc=f"study {study}",
                     outputs=(RESULTS_CSV, SUMMARY_JSON))


# --------------------------------------------------------------------------- tables


def ok(records: Mapping[str, dict]) -> dict[str, dict]:
    """The successful records."""
    return {k: r for k, r in records.items() if r.get("status") == "ok"}


def failures(records: Mapping[str, dict]) -> list[dict]:
    """``{"key", "reason"}`` of every failed case."""
    return [{"key": k, "reason": r.get("reason", "unknown")} for k, r in records.items()
            if r.get("status") != "ok"]


def rows(records: Mapping[str, dict]) -> list[dict]:
    """One flat row per (case, prefix): the case's tags, its strikes and every score."""
    out = []
    for key, record in ok(records).items():
        for prefix in record["prefixes"]:
            row = {"case": key, **record["tags"], "seed": record["seed"],
                   "scene": record["scene"], "overrides": " ".join(record["overrides"])}
            row.update({k: v for k, v in prefix.items() if k not in ("face_coverage", "points")})
            out.append(row)
    return out


def write_csv(table: Sequence[Mapping], path) -> Path:
    """Write rows as CSV; columns in first-seen order, missing values empty."""
    columns = list(dict.fromkeys(k for row in table for k in row))
    out = io.StringIO(newline="")
    writer = csv.writer(out)
    writer.writerow(columns)
    for row in table:
        values = []
        for c in columns:
            v = row.get(c)
            if isinstance(v, float):
                v = f"{v:.6g}"
            values.append("" if v is None else v)
        writer.writerow(values)
    return write_text_atomically(path, out.getvalue())


def series(records: Mapping[str, dict], key: str, metric: str, *, x: str = "rotations"
           ) -> tuple[np.ndarray, np.ndarray]:
    """``x`` and ``metric`` of one case's scored prefixes, as arrays (None becomes NaN)."""
    record = records[key]
    pts = [p for p in record["prefixes"] if p.get("scored")]
    xs = np.array([p[x] for p in pts], dtype=float)
    ys = np.array([np.nan if p.get(metric) is None else p[metric] for p in pts], dtype=float)
    return xs, ys


def at(records: Mapping[str, dict], key: str, time_s: float) -> dict | None:
    """The prefix of case ``key`` at ``time_s`` (None when the case failed or lacks it)."""
    record = records.get(key)
    if record is None or record.get("status") != "ok":
        return None
    for p in record["prefixes"]:
        if math.isclose(p["time_s"], time_s, rel_tol=1e-9) and p.get("scored"):
            return p
    return None


def first_time_reaching(xs: np.ndarray, ys: np.ndarray, level: float, *,
                        higher_better: bool = True) -> float | None:
    """The first ``x`` at which ``ys`` reaches ``level`` (None if it never does)."""
    hit = ys >= level if higher_better else ys <= level
    return float(xs[np.argmax(hit)]) if hit.any() else None


def goodness(metric: str, values):
    """``values`` of a ``CLAIM_METRICS`` metric turned higher-is-better (the edge score negated),
    so one comparison serves all three."""
    lower = dict(CLAIM_METRICS)[metric]
    return -np.asarray(values, dtype=float) if lower else np.asarray(values, dtype=float)


def claim(cid: str, figure: str, claim_text: str, paper: str, ours: str, verdict: str,
          note: str = "") -> dict:
    """One checked claim of the paper, as it goes into ``summary.json`` and the report.

    ``verdict`` is ``reproduced``, ``partly``, ``not reproduced`` or ``not tested``: decided
    by a stated rule on our numbers (``note``); docs/paper-reproduction.md discusses each.
    """
    if verdict not in ("reproduced", "partly", "not reproduced", "not tested"):
        raise ValueError(f"verdict must be reproduced, partly, not reproduced or not tested, "
                         f"got {verdict!r}")
    return {"id": cid, "figure": figure, "claim": claim_text, "paper": paper, "ours": ours,
            "verdict": verdict, "rule": note}


def write_summary(out_dir, *, study: str, title: str, size: str, records: Mapping[str, dict],
                  claims: Sequence[dict], files: Sequence[str], extra: Mapping | None = None,
                  wall_time_s: float | None = None) -> Path:
    """Write ``summary.json``: what was run, the claims checked, the files, the failures.

    A reduced run (``size`` not ``full``) cannot refute a claim: its "not reproduced" verdicts
    are written as "not tested", with ``found`` saying what the reduced run saw.
    """
    from recon.experiments.sweep import to_jsonable

    if size != "full":
        claims = [c | {"verdict": "not tested", "found": "not reproduced at this size"}
                  if c["verdict"] == "not reproduced" else c for c in claims]

    done = ok(records)
    options = {json.dumps(r.get("score_options", {}), sort_keys=True) for r in done.values()}
    summary = {"study": study, "title": title, "size": size, "n_cases": len(records),
               "n_failed": len(records) - len(done), "failures": failures(records),
               "claims": list(claims), "files": list(files),
               "score_options": [json.loads(text) for text in sorted(options)],
               "case_wall_time_s": sum(r.get("wall_time_s", 0.0) for r in done.values()),
               "wall_time_s": wall_time_s, **dict(extra or {})}
    return write_text_atomically(Path(out_dir) / SUMMARY_JSON,
                                 json.dumps(to_jsonable(summary), indent=2) + "\n")
