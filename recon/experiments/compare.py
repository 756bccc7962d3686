"""``recon compare``: every method on one cloud, scored on the truth.

By default every method runs at its defaults (``grid="defaults"``): the Pareto front across
methods in minutes on a paper-scale cloud, with an estimate of how long the full grid would
take (``full_grid``); ``grid="full"`` adds each method's parameter grid. Each run (a ``Run``
from ``recon.experiments.cases.variants``) is isolated (``recon.surfaces.isolation``: a warm
worker process with time and memory limits, which also scores the mesh), runs on a local
thread per core or on Dask (``recon.experiments.sweep``) and streams to
``DIR/results.jsonl``. Finishing writes

- ``DIR/results.csv`` and ``DIR/results.json``: per run the method, parameters, status and
  failure reason, wall time of the method, peak memory of its process, face and vertex counts,
  the model's free parameters (``n_params``: 9 for an ellipsoid, 3 per plane, 3 per vertex of a
  free mesh; ``Method.parameter_count``),
  watertightness and every score of ``metrics.score`` (Chamfer, F-score, ...);
- ``DIR/speed_accuracy.png``: time (log axis) against Chamfer and against F-score, one marker
  per method, the Pareto front drawn and labelled;
- ``DIR/meshes/*.ply``: the meshes (unless ``keep_meshes=False``);
- with the strikes given (``strikes``), the truth-free prediction of every successful run
  (``recon.surfaces.estimate.estimate`` on its mesh, in-sample): ``predicted_chamfer_m``,
  ``predicted_chamfer_low_m``, ``predicted_chamfer_high_m``, ``predicted_fscore`` and
  ``predicted_by`` (``ESTIMATE_VERSION``: which estimate made them, so a reader can tell a
  stale prediction from a current one);

and the ranked table (by Chamfer, failures last with their reasons) is returned as text.
``compare`` takes a prepared cloud and a truth mesh; ``recon.api.compare`` takes what a user
names (files, or data in memory), and with ``auto=True`` also writes ``DIR/auto.json``: where
``-m auto``'s choice ranks on the truth (``agreement``).
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from formats.atomic import write_text_atomically
from formats.errors import ParameterError
from formats.geometry import Cloud
from recon.experiments import charts
from recon.experiments.cases import (
    BASE_COLUMNS,
    CHAMFER,
    FSCORE,
    SWEEP_THREADS,
    as_runs,
    full_grid_estimate,
    pareto_front,
    rank,
    variants,
    write_csv,
)
from recon.experiments.sweep import default_workers, run_sweep, to_jsonable
from recon.surfaces.isolation import DEFAULT_MEMORY_MB, DEFAULT_TIMEOUT_S, run_isolated
from recon.surfaces.methods import MethodInput, Run


def _slug(label: str, key: str) -> str:
    text = re.sub(r"[^A-Za-z0-9.=,-]+", "_", label).strip("_")
    return f"{text}-{hashlib.sha1(key.encode()).hexdigest()[:6]}"


def run_case(*, run: Run, cloud: MethodInput, truth, timeout_s: float, memory_mb: int | None,
             score_options: dict | None) -> dict:
    """One isolated, scored run (the task each sweep worker executes).

    ``run`` goes to the isolated child as it is; the worker itself never looks the method up.
    """
    from recon.experiments.progress import isolated_stage

    return run_isolated(run, cloud, truth=truth, score_options=score_options,
                        timeout_s=timeout_s, memory_mb=memory_mb, threads=SWEEP_THREADS,
                        on_wait=isolated_stage)


def estimate_version() -> str:
    """Which truth-free estimate predicts: a digest of the sources of ``recon.surfaces.estimate``
    and of ``recon.surfaces.judge``, whose checks it calls, 12 hex digits."""
    import inspect

    from recon.surfaces import estimate, judge

    source = inspect.getsource(estimate) + inspect.getsource(judge)
    return hashlib.sha1(source.encode()).hexdigest()[:12]


def predicted_columns(vertices: np.ndarray, faces: np.ndarray, strikes: Cloud, misses=None
                      ) -> dict:
    """The truth-free prediction of one surface as record columns (``recon.surfaces.estimate.
    estimate``, in-sample: the fit saw every strike).

    Parameters
    ----------
    vertices : (v, 3) float64, metres
    faces : (f, 3) int
    strikes : Cloud
        The strikes with their view points and recorded uncertainty columns.
    misses : recon.registration.misses.MissedBeams, optional
        The strike log's missed beams (``estimate``'s).

    Returns
    -------
    dict
        ``predicted_chamfer_m``, ``predicted_chamfer_low_m``, ``predicted_chamfer_high_m``
        (metres), ``predicted_fscore``, ``predicted_by`` (``estimate_version``) and
        ``predicted_misses`` (how many missed beams the estimate was given: its prediction
        depends on them); when the estimate cannot judge these strikes (e.g. all in one
        plane), ``predicted_by``, ``predicted_misses`` and ``prediction_failed`` (why) only:
        the run itself stands.
    """
    from recon.surfaces.estimate import estimate

    made_by = {"predicted_by": estimate_version(), "predicted_misses": n_misses(misses)}
    try:
        e = estimate((vertices, faces), strikes, misses=misses)
    except (ValueError, RuntimeError) as exc:   # e.g. strikes too flat for their hull
        return made_by | {"prediction_failed": f"{exc}"[:200]}
    return {"predicted_chamfer_m": e.chamfer_m, "predicted_chamfer_low_m": e.chamfer_low_m,
            "predicted_chamfer_high_m": e.chamfer_high_m, "predicted_fscore": e.fscore,
            **made_by}


def n_misses(misses) -> int:
    """How many missed beams ``misses`` holds (0 for None)."""
    return 0 if misses is None else len(misses)


def flatten(run: Run, result: dict, *, mesh_dir: Path | None, strikes: Cloud | None = None,
            misses=None) -> dict:
    """A result of ``run_isolated`` for ``run`` as one flat record (mesh written, arrays
    dropped; with ``strikes`` (and a log's ``misses``), the truth-free prediction columns,
    ``predicted_columns``)."""
    from formats.mesh_io import write_mesh

    record: dict[str, Any] = {"label": run.label, "method": run.method, "params": run.params,
                              "kind": run.kind}
    for column in BASE_COLUMNS[5:]:
        record[column] = result.get(column)
    if result.get("status") == "ok":
        record["n_params"] = run.method_spec().parameter_count(result["vertices"],
                                                               result["faces"])
    if result.get("status") == "ok" and mesh_dir is not None:
        mesh_dir.mkdir(parents=True, exist_ok=True)
        path = mesh_dir / f"{_slug(run.label, run.key)}.ply"
        write_mesh(path, result["vertices"], result["faces"], source=f"recon compare: {run.label}")
        record["mesh"] = str(Path(mesh_dir.name) / path.name)
    if result.get("status") == "ok" and strikes is not None:
        record.update(predicted_columns(result["vertices"], result["faces"], strikes, misses))
    record.update(result.get("scores") or {})
    return record


def format_table(ranked: list[dict]) -> str:
    """The ranked table ``recon compare`` prints."""
    head = (f"{'#':>3}  {'run':<38} {'time s':>8} {'peak MB':>8} {'faces':>9} {'params':>8} "
            f"{'closed':>6} {'Chamfer m':>10} {'F-score':>7}")
    lines = [head, "-" * len(head)]
    position = 0
    for r in ranked:
        if r.get("status") == "ok" and r.get(CHAMFER) is not None:
            position += 1
            lines.append(f"{position:>3}  {r['label'][:38]:<38} {r['wall_time_s']:>8.2f} "
                         f"{r.get('peak_memory_mb') or 0:>8.0f} {r['n_faces']:>9d} "
                         f"{r.get('n_params') or 0:>8d} "
                         f"{'yes' if r['watertight'] else 'no':>6} {r[CHAMFER]:>10.4g} "
                         f"{r.get(FSCORE, float('nan')):>7.3f}")
        else:
            lines.append(f"{'-':>3}  {r['label'][:38]:<38} FAILED ({r.get('failure')}): "
                         f"{(r.get('reason') or '')[:90]}")
    return "\n".join(lines)


def agreement(records: list[dict], key: str, *, metric: str = CHAMFER) -> dict:
    """Where the run ``key`` (e.g. ``-m auto``'s choice) ranks among ``records`` on the truth.

    Parameters
    ----------
    records : list of dict
    key : str
        ``Run.key`` of the run.
    metric : str
        Truth score ranked on, lower better (default Chamfer; ``accuracy_mean_m`` ranks on the
        test-to-truth distance alone, the half of Chamfer a held-out check can see).

    Returns
    -------
    dict
        ``metric``, ``rank`` (1 = lowest; None when that run failed or is absent),
        ``n_ranked``, ``best_label``, ``label``, ``same_run`` (it is the best),
        ``same_method`` (same method as the best), ``ratio`` (its score over the best's; also
        as ``chamfer_ratio`` when ranking on Chamfer).
    """
    ranked = sorted((r for r in records if r.get("status") == "ok"
                     and r.get(metric) is not None), key=lambda r: r[metric])
    mine = next((r for r in ranked if r.get("key") == key), None)
    out = {"metric": metric, "rank": None, "n_ranked": len(ranked), "best_label": None,
           "label": None, "same_run": False, "same_method": False, "ratio": float("nan")}
    if ranked:
        best = ranked[0]
        out["best_label"] = best["label"]
        if mine is not None:
            out.update(rank=ranked.index(mine) + 1, label=mine["label"], same_run=mine is best,
                       same_method=mine["method"] == best["method"],
                       ratio=mine[metric] / best[metric] if best[metric] > 0 else float("inf"))
    if metric == CHAMFER:
        out["chamfer_ratio"] = out["ratio"]
    return out


def compare(cloud: MethodInput, truth: tuple[np.ndarray, np.ndarray], out_dir, *,
            names: Sequence[str] | None = None, grid: bool | str = "defaults",
            runs: Sequence[Run] | None = None, timeout_s: float = DEFAULT_TIMEOUT_S,
            memory_mb: int | None = DEFAULT_MEMORY_MB,
            scheduler: str | None = None, n_workers: int | None = None, resume: bool = False,
            keep_meshes: bool = True, score_options: dict | None = None,
            fingerprint: dict | None = None, title: str = "", strikes: Cloud | None = None,
            misses=None) -> dict:
    """Run, score and rank every method variant on one prepared cloud.

    Parameters
    ----------
    cloud : MethodInput
        Prepared points (``recon.surfaces.reconstruct.prepare``), metres, body frame.
    truth : (vertices, faces)
        Truth mesh, metres, same frame.
    out_dir : str or Path
    names : sequence of str, optional
        Methods to run (default: all listed). Hidden test methods may be named.
    grid : {"defaults", "full"} or bool
        ``"full"`` (True) runs each method's parameter grid besides its defaults.
    runs : sequence of Run, optional
        The runs themselves (``recon.experiments.cases.variants``), instead of ``names`` and
        ``grid``.
    timeout_s, memory_mb
        Limits of each isolated run.
    scheduler, n_workers, resume
        See ``recon.experiments.sweep.run_sweep``; no scheduler means ``"threads"`` (one
        thread per core waiting on its isolated worker: no Dask cluster to start locally).
    keep_meshes : bool
        Write each mesh to ``DIR/meshes``.
    score_options : dict, optional
        Keyword arguments of ``metrics.score``.
    fingerprint : dict, optional
        Extra identity of the input for ``--resume`` checks (e.g. the input path).
    title : str
        Chart title.
    strikes : Cloud, optional
        The strikes before preparation, with view points and recorded uncertainty: every
        successful run's record then carries its truth-free prediction (``predicted_columns``).
    misses : recon.registration.misses.MissedBeams, optional
        The strike log's missed beams, for those predictions.

    Returns
    -------
    dict
        ``records`` (ranked), ``table`` (text), ``pareto_chamfer`` and ``pareto_fscore``
        (labels), ``full_grid`` (``cases.full_grid_estimate``: the full grid's remaining runs
        and their estimated time), and the paths written.
    """
    out_dir = Path(out_dir)
    runs = variants(names, grid=grid) if runs is None else as_runs(runs)
    scheduler = scheduler or "threads"
    cases = {run.key: {"run": run} for run in runs}
    ident = {"n_points": len(cloud.points), "spacing": cloud.spacing, "seed": cloud.seed,
             "points_sha1": hashlib.sha1(np.ascontiguousarray(cloud.points)).hexdigest(),
             "truth_faces": len(truth[1]), "timeout_s": timeout_s, "memory_mb": memory_mb,
             "score_options": score_options or {}} | dict(fingerprint or {})
    mesh_dir = out_dir / "meshes" if keep_meshes else None
    charts.preload()
    done = run_sweep(run_case, cases, out_dir,
                     shared={"cloud": cloud, "truth": truth, "timeout_s": timeout_s,
                             "memory_mb": memory_mb, "score_options": score_options},
                     fingerprint=ident, scheduler=scheduler, n_workers=n_workers, resume=resume,
                     on_result=lambda key, result: flatten(cases[key]["run"], result,
                                                           mesh_dir=mesh_dir, strikes=strikes,
                                                           misses=misses),
                     desc="compare", outputs=("results.csv", "results.json",
                                              "speed_accuracy.png", "auto.json"))
    records = [done[key] for key in cases if key in done]
    estimate = full_grid_estimate(records, list(dict.fromkeys(run.method for run in runs)),
                                  workers=n_workers or default_workers())
    report = finish(records, out_dir, title=title,
                    extra={"input": ident, "full_grid": estimate})
    report["full_grid"] = estimate
    return report


def finish(records: list[dict], out_dir, *, title: str = "", extra: dict | None = None) -> dict:
    """Rank records and write results.csv, results.json and speed_accuracy.png."""
    out_dir = Path(out_dir)
    ranked = rank(records)
    ok = [r for r in ranked if r.get("status") == "ok" and r.get(CHAMFER) is not None
          and r.get("wall_time_s")]
    fronts = {}
    for metric, minimize in ((CHAMFER, True), (FSCORE, False)):
        runs = [r for r in ok if r.get(metric) is not None]
        if runs:
            idx = pareto_front(np.array([r["wall_time_s"] for r in runs]),
                               np.array([r[metric] for r in runs]), minimize=minimize)
            fronts[metric] = [{"label": runs[i]["label"], "wall_time_s": runs[i]["wall_time_s"],
                               CHAMFER: runs[i][CHAMFER], FSCORE: runs[i].get(FSCORE)}
                              for i in idx]
        else:
            fronts[metric] = []
    csv_path = write_csv(ranked, out_dir / "results.csv")
    summary = {"runs": ranked, "pareto_chamfer": fronts[CHAMFER],
               "pareto_fscore": fronts[FSCORE], **(extra or {})}
    json_path = write_text_atomically(out_dir / "results.json",
                                      json.dumps(to_jsonable(summary), indent=2) + "\n",
                                      error=ParameterError)
    png_path = charts.speed_accuracy(ranked, out_dir / "speed_accuracy.png", title=title)
    return {"records": ranked, "table": format_table(ranked),
            "pareto_chamfer": fronts[CHAMFER], "pareto_fscore": fronts[FSCORE],
            "csv": csv_path, "json": json_path, "png": png_path}


def format_full_grid(estimate: dict) -> str:
    """One line: how long ``--grid full`` would take (``cases.full_grid_estimate``)."""
    if not estimate["runs"]:
        return "full grid: every run done"
    if estimate["estimate_s"] is None:
        return (f"full grid: {estimate['runs']} more runs (no default run succeeded to time "
                "them); --grid full runs them")
    minutes = estimate["estimate_s"] / 60.0
    unknown = (f"; not counting {', '.join(estimate['unknown'])}, whose defaults failed"
               if estimate["unknown"] else "")
    return (f"full grid: {estimate['runs']} more runs, about {minutes:.1f} min here (each "
            f"variant timed as its method's defaults, scoring included{unknown}); --grid full "
            "runs them")


def format_agreement(verdict: dict) -> str:
    """One line: where ``-m auto``'s choice ranks on the truth (``agreement``'s result)."""
    return (f"auto vs truth: auto's choice ranks {verdict['rank']} of {verdict['n_ranked']} on "
            f"Chamfer (best: {verdict['best_label']}); same run: "
            f"{'yes' if verdict['same_run'] else 'no'}, same method: "
            f"{'yes' if verdict['same_method'] else 'no'}, Chamfer ratio to the best: "
            f"{verdict['chamfer_ratio']:.3g}")
