"""``-m auto``: the simplest method and resolution the data support, chosen without the truth.

The rule (hold-out validation with Breiman's one-standard-error rule, model size in faces):

1. Hold out a seeded random ``holdout`` fraction of the points (10%); prepare the rest
   (normals, spacing, noise) and fit every candidate (method, parameters) on it, each isolated
   like ``recon compare``'s runs (a crash or a timeout only removes that candidate).
2. For every fitted surface predict each held-out measurement (``heldout_residuals``): the
   held-out strike's beam, from its view point (the sensor) through the point, is intersected
   with the surface, and the residual is the measured range minus the surface's range along
   the beam. The held-out error ``e`` is the mean absolute residual. A surface that smooths
   away real shape, leaves holes, or bridges concavities predicts those ranges badly; one that
   chases the noise gains nothing on points it never saw. The beam matters: on the single-beam
   LRF clouds of RSO-A the points are 3 cm apart along a track and scattered by 10 cm along
   the beam, so a surface interpolating the noisy training points is a fine sawtooth that
   passes within 2 cm of any held-out point (closest-point distance) while predicting its range
   no better than the noise allows. A beam that misses the surface counts the point's
   closest-point distance to it (a lower bound on that error); clouds without view points use
   closest-point distances throughout (``metrics.distance.point_mesh_distance``).
3. The best candidate has the lowest ``e``. Its standard error ``se = std(d) / sqrt(n_held)``
   is the noise of that estimate: every candidate with ``e <= e_best + se`` fits the held-out
   points as well as the best, to within what this cloud can tell apart.
4. Face count is the penalty: among those candidates the one with the fewest faces wins (ties:
   lower ``e``). The penalty is lexicographic, not a weighted sum, so no exchange rate between
   metres and faces has to be invented; a 12-face box beats a 50,000-face Poisson surface only
   when the Poisson surface is not measurably better.

The chosen candidate is then refitted on all points by the caller (``recon reconstruct -m auto``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from formats.errors import ReconError
from formats.paths import check_destination
from recon.surfaces.isolation import DEFAULT_MEMORY_MB, DEFAULT_TIMEOUT_S, Limits
from recon.surfaces.methods import MethodFailed, Run
from recon.surfaces.normals import DEFAULT_K, Fallback
from recon.surfaces.prepare import InputError, Preparation

# Fraction of points held out: 10% leaves the fit 90% of the density (a Poisson depth or a grid
# cell chosen on 90% suits 100%) and gives ~1e4 held-out points on a 1e5-point cloud, so the
# standard error of the mean distance is ~1% of the noise.
HOLDOUT_FRACTION = 0.1
# Fewest held-out points for the standard error to mean anything.
MIN_HELD_OUT = 30
# Candidates of the default automatic choice: every listed method at its defaults and its
# parameter grid (recon.experiments.cases.variants), as in ``recon compare``.


class AutoError(ReconError, ValueError):
    """Bad options of the automatic choice."""


@dataclass
class AutoChoice:
    """What ``choose`` picked and why.

    Attributes
    ----------
    run : Run
        The chosen method and its resolved parameters (``method``, ``params`` and ``label``
        read from it).
    reason : str
        One paragraph: the best candidate, the band, the choice.
    candidates : list of dict
        Per candidate: ``label``, ``method``, ``params``, ``kind``, ``status``, ``reason``,
        ``heldout_mean_m`` (mean absolute held-out residual), ``heldout_se_m``, ``beam_hits``
        (fraction of held-out beams that hit the surface), ``n_faces``, ``eligible``,
        ``chosen``.
    threshold_m : float
        ``e_best + se_best``: the band's upper edge.
    """

    run: Run
    reason: str
    candidates: list[dict] = field(default_factory=list)
    threshold_m: float = float("nan")

    @property
    def method(self) -> str:
        return self.run.method

    @property
    def params(self) -> dict[str, Any]:
        return self.run.params

    @property
    def label(self) -> str:
        return self.run.label

    def to_dict(self) -> dict:
        return {"method": self.method, "params": self.params, "label": self.label,
                "reason": self.reason, "threshold_m": self.threshold_m,
                "candidates": self.candidates}


def select(candidates: list[dict]) -> tuple[int, float, str]:
    """Apply the rule of the module docstring to scored candidates.

    Parameters
    ----------
    candidates : list of dict
        Each with ``distances`` ((n_held,) float64 metres, or None for a failed fit),
        ``n_faces`` and ``label``.

    Returns
    -------
    chosen : int
        Index of the choice.
    threshold : float, metres
        ``e_best + se_best``.
    reason : str
    """
    scored = [i for i, c in enumerate(candidates) if c.get("distances") is not None]
    if not scored:
        raise MethodFailed("auto: every candidate failed: " + "; ".join(
            f"{c['label']}: {c.get('reason')}" for c in candidates))
    mean = {i: float(np.mean(candidates[i]["distances"])) for i in scored}
    best = min(scored, key=lambda i: (mean[i], candidates[i]["n_faces"]))
    d_best = candidates[best]["distances"]
    se = float(np.std(d_best, ddof=1) / np.sqrt(len(d_best))) if len(d_best) > 1 else 0.0
    threshold = mean[best] + se
    eligible = [i for i in scored if mean[i] <= threshold]
    chosen = min(eligible, key=lambda i: (candidates[i]["n_faces"], mean[i]))
    c, b = candidates[chosen], candidates[best]
    if chosen == best:
        reason = (f"chose {c['label']} ({c['n_faces']} faces): the lowest held-out error, "
                  f"{mean[best]:.4g} m mean distance; "
                  + (f"the other {len(eligible) - 1} candidate(s) within one standard error "
                     f"({se:.2g} m) have more faces" if len(eligible) > 1 else
                     f"no other candidate is within one standard error ({se:.2g} m)"))
    else:
        reason = (f"chose {c['label']} ({c['n_faces']} faces): held-out error {mean[chosen]:.4g} "
                  f"m, within one standard error ({se:.2g} m) of the best, {b['label']} "
                  f"({mean[best]:.4g} m, {b['n_faces']} faces); of the {len(eligible)} "
                  f"candidates within that band it has the fewest faces")
    return chosen, threshold, reason


def heldout_residuals(points: np.ndarray, view_points: np.ndarray | None, vertices: np.ndarray,
                      faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Absolute range residuals of held-out strikes against a surface.

    Parameters
    ----------
    points : (n, 3) float64, metres, body frame
        Held-out points.
    view_points : (n, 3) float64, metres, or None
        Their sensor positions; None gives closest-point distances.
    vertices : (v, 3) float64, metres
    faces : (f, 3) int64

    Returns
    -------
    residual : (n,) float64, metres
        ``| |p - v| - t |`` with ``t`` the range along the beam v -> p to its first hit on the
        surface (exact, float64, on the triangle Embree's float32 cast found); for beams that
        miss, and without view points, the closest-point distance to the surface.
    hit : (n,) bool
        Whether the beam hit the surface (all False without view points).
    """
    from metrics.distance import point_mesh_distance

    residual = np.empty(len(points))
    hit = np.zeros(len(points), dtype=bool)
    if view_points is not None:
        import open3d as o3d

        centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor((vertices - centre).astype(np.float32)),
                            o3d.core.Tensor(faces.astype(np.uint32)))
        ray = points - view_points
        measured = np.linalg.norm(ray, axis=1)
        direction = ray / np.maximum(measured, 1e-300)[:, None]
        rays = np.hstack([view_points - centre, direction]).astype(np.float32)
        cast = scene.cast_rays(o3d.core.Tensor(rays))
        triangle = cast["primitive_ids"].numpy().astype(np.int64)
        hit = np.isfinite(cast["t_hit"].numpy()) & (triangle < len(faces))
        a, b, c = (vertices[faces[triangle[hit], i]] for i in range(3))
        normal = np.cross(b - a, c - a)
        along = np.einsum("ij,ij->i", normal, direction[hit])
        t = np.einsum("ij,ij->i", normal, a - view_points[hit]) / np.where(along == 0, 1e-300,
                                                                            along)
        residual[hit] = np.abs(measured[hit] - t)
    miss = ~hit
    if miss.any():
        residual[miss] = point_mesh_distance(points[miss], (vertices, faces))[0]
    return residual, hit


def _fit(*, run: Run, cloud, timeout_s, memory_mb) -> dict:
    from recon.experiments.cases import SWEEP_THREADS
    from recon.surfaces.isolation import run_isolated

    return run_isolated(run, cloud, timeout_s=timeout_s, memory_mb=memory_mb,
                        threads=SWEEP_THREADS)


def choose(points: np.ndarray, *, view_points: np.ndarray | None = None,
           candidates: Sequence[Run | tuple[str, dict]] | None = None,
           holdout: float = HOLDOUT_FRACTION, seed: int = 0, k: int = DEFAULT_K,
           fallback: Fallback = "centroid", timeout_s: float = DEFAULT_TIMEOUT_S,
           memory_mb: int | None = DEFAULT_MEMORY_MB, scheduler: str | None = "threads",
           n_workers: int | None = None) -> AutoChoice:
    """Choose a method and resolution by held-out error, without the truth.

    Parameters
    ----------
    points : (n, 3) float64, metres, body frame
    view_points : (n, 3) float64, metres, optional
        Sensor positions (orient the normals).
    candidates : sequence of Run or of (method, params), optional
        Default: ``recon.experiments.cases.variants()`` (every listed method and its grid).
        Pairs are resolved once here.
    holdout : float
        Fraction of points held out, in (0, 0.5].
    seed : int
        Seed of the split (and of the methods).
    k, fallback
        Normal estimation (``recon.surfaces.reconstruct.prepare``).
    timeout_s, memory_mb
        Limits of each isolated fit.
    scheduler, n_workers
        Where the fits run (``recon.experiments.sweep``; default: a local thread pool, each fit in
        its own
        process).

    Returns
    -------
    AutoChoice
    """
    from tqdm import tqdm

    from recon.experiments.cases import as_runs, variants
    from recon.experiments.sweep import iterate
    from recon.surfaces.prepare import prepare

    if not 0 < holdout <= 0.5:
        raise AutoError(f"holdout must be in (0, 0.5], got {holdout}")
    points = np.asarray(points, dtype=np.float64)
    n_held = round(holdout * len(points))
    if n_held < MIN_HELD_OUT:
        raise AutoError(f"auto needs at least {MIN_HELD_OUT} held-out points; {holdout:g} of "
                        f"{len(points)} points is {n_held}")
    runs = as_runs(candidates) if candidates else variants()
    order = np.random.default_rng(seed).permutation(len(points))
    held, train = np.sort(order[:n_held]), np.sort(order[n_held:])
    cloud = prepare(points[train], view_points=None if view_points is None else
                    view_points[train], k=k, fallback=fallback, seed=seed)
    cases = {run.key: {"run": run} for run in runs}
    results: dict[str, dict] = {}
    with tqdm(total=len(cases), desc="auto", unit="fit", disable=None, leave=False) as bar:
        for key, result in iterate(_fit, cases, shared={"cloud": cloud, "timeout_s": timeout_s,
                                                        "memory_mb": memory_mb},
                                   scheduler=scheduler, n_workers=n_workers):
            results[key] = result
            bar.update(1)
    table = []
    for key, case in cases.items():
        result = results[key]
        run = case["run"]
        entry = {"label": run.label, "method": run.method, "params": run.params,
                 "kind": run.kind, "run": run,
                 "status": result.get("status", "failed"), "reason": result.get("reason", ""),
                 "n_faces": result.get("n_faces"), "distances": None, "beam_hits": None}
        if entry["status"] == "ok":
            entry["distances"], hits = heldout_residuals(
                points[held], None if view_points is None else view_points[held],
                result["vertices"], result["faces"])
            entry["beam_hits"] = float(hits.mean())
        table.append(entry)
    chosen, threshold, reason = select(table)
    runs_of = [entry.pop("run") for entry in table]
    for i, entry in enumerate(table):
        d = entry.pop("distances")
        entry["heldout_mean_m"] = None if d is None else float(np.mean(d))
        entry["heldout_se_m"] = None if d is None else float(np.std(d, ddof=1) / np.sqrt(len(d)))
        entry["eligible"] = d is not None and float(np.mean(d)) <= threshold
        entry["chosen"] = i == chosen
    return AutoChoice(runs_of[chosen], reason, table, threshold)


def format_choice(choice: AutoChoice) -> str:
    """The candidates table and the reason, as ``recon reconstruct -m auto`` prints them."""
    lines = [f"{'':2}{'candidate':<38} {'kind':<13} {'held-out m':>11} {'faces':>9}",
             "-" * 76]
    ranked = sorted(choice.candidates, key=lambda c: (c["heldout_mean_m"] is None,
                                                      c["heldout_mean_m"] or 0.0))
    for c in ranked:
        mark = "*" if c["chosen"] else ("~" if c["eligible"] else " ")
        if c["heldout_mean_m"] is None:
            lines.append(f"{mark:2}{c['label'][:38]:<38} {c['kind']:<13} FAILED: "
                         f"{(c['reason'] or '')[:60]}")
        else:
            lines.append(f"{mark:2}{c['label'][:38]:<38} {c['kind']:<13} "
                         f"{c['heldout_mean_m']:>11.4g} {c['n_faces']:>9d}")
    lines.append("(* chosen, ~ within one standard error of the best)")
    lines.append(choice.reason)
    return "\n".join(lines)


def choose_for(cloud, *, methods: Sequence[str] | None = None, holdout: float = HOLDOUT_FRACTION,
               preparation: Preparation | None = None, limits: Limits | None = None
               ) -> AutoChoice:
    """``choose`` on a cleaned ``Cloud`` (``Preparation.apply``) with a preparation's normals
    options and a run's limits: the choice ``-m auto`` makes.

    Parameters
    ----------
    cloud : Cloud
        Metres, body frame; its view points, when present, aim the held-out beams.
    methods : sequence of str, optional
        Candidate methods, each with its grid (default: every listed method).
    holdout : float
    preparation : Preparation, optional
    limits : Limits, optional
    """
    from recon.experiments.cases import variants

    preparation = preparation or Preparation()
    return choose(cloud.points, view_points=cloud.view_points,
                  candidates=variants(methods) if methods else None, holdout=holdout,
                  seed=preparation.seed, k=preparation.k, fallback=preparation.fallback,
                  **(limits or Limits()).kwargs())


def choose_and_reconstruct(input, output, *, methods: Sequence[str] | None = None,
                           holdout: float = HOLDOUT_FRACTION,
                           preparation: Preparation | None = None, limits: Limits | None = None,
                           isolate: bool = True, on_wait: Callable[[str], None] | None = None,
                           say: Callable[[str], None] | None = None) -> dict:
    """``recon reconstruct -m auto``: read and prepare the input, choose, refit on all points.

    Parameters
    ----------
    input : str or Path
        Point cloud or strike log (``recon.inputs.load_cloud``).
    output : str or Path
        Mesh to write (.ply).
    methods : sequence of str, optional
        Candidate methods, each with its grid (default: every listed method).
    holdout : float
        Fraction of points held out (``choose``).
    preparation : Preparation, optional
        Cleaning, thinning and normals; its ``k``, ``fallback`` and ``seed`` serve the choice too.
    limits : Limits, optional
        Of every isolated fit.
    isolate, on_wait
        Of the final fit (``recon.surfaces.reconstruct.reconstruct_to_file``).
    say : callable, optional
        Called with the candidates table and the reason (``format_choice``) once chosen.

    Returns
    -------
    dict
        The summary of ``reconstruct_to_file`` with ``input`` and ``auto``
        (``AutoChoice.to_dict()``).
    """
    from pathlib import Path

    from recon.surfaces.prepare import load_prepared
    from recon.surfaces.reconstruct import reconstruct_to_file

    preparation = preparation or Preparation()
    limits = limits or Limits()
    check_destination(output, InputError)   # before the work, not after it
    cloud, prepared = load_prepared(input, preparation)
    choice = choose_for(cloud, methods=methods, holdout=holdout, preparation=preparation,
                        limits=limits)
    if say is not None:
        say(format_choice(choice))
    summary = reconstruct_to_file(cloud, prepared, Path(output), run=choice.run, limits=limits,
                                  isolate=isolate, on_wait=on_wait)
    return {"input": str(input), "auto": choice.to_dict()} | summary
