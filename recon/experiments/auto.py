"""``-m auto``: the simplest model the data support, chosen without the truth.

What a strike log knows besides its points is used: each strike's view point (the beam), the
sensor's recorded error model (``recon.surfaces.uncertainty``) and how much of the target the
strikes cover. The rule:

1. **Hold out** a seeded random ``holdout`` fraction of the strikes (10%); prepare the rest
   (normals, spacing, noise, per-point uncertainty) and fit candidates on it, each isolated
   like ``recon compare``'s runs (a crash or a timeout only removes that candidate).
2. **Cast every held-out beam** (``heldout_errors``, ``heldout_geometry``): the held-out
   strike's beam, from its view point through the point, is cast against the surface. Where it
   hits, the strike's error is its distance to the surface, truncated at the strike's tolerance
   ``cap = max(tau, 3 sigma)``: ``tau`` is 1% of the cloud's bounding-box diagonal (the F-score
   threshold of ``metrics``, ``TAU_FRACTION``), ``sigma`` the strike's recorded 1-sigma
   uncertainty along the normal of the surface it hits (``recon.surfaces.uncertainty``: the
   range error head-on, the angle and pose errors at grazing incidence). **A beam that misses
   the surface costs the full cap**: a mesh with holes predicts nothing there (the old rule
   counted its closest-point distance, a lower bound, so holes looked good). The held-out error
   ``e`` is the mean: about the Chamfer distance where the surface is good, about the F-score
   where it is not. (The range residual along the beam, which an earlier rule used, ranked a
   smooth Poisson surface above the truth's best runs on the suite's RSO-A cloud: at grazing
   incidence it multiplies a small surface error by 1 / cos.)
3. **One standard error**: the best candidate has the lowest ``e``; its standard error ``se``
   is the noise of that estimate, and every candidate with ``e <= e_best + max(se,
   TAU_SLACK tau)`` fits the held-out strikes as well as the best, to within what this cloud
   can tell apart and what a score at the resolution ``tau`` can see (on the sparse clean
   asteroid the exact 9-parameter ellipsoid was 7 mm, 0.1% of ``tau``, behind a 17,000-
   parameter interpolating surface that is 600 times worse where there are no strikes).
4. **Model size is the penalty**: among those, the fewest free parameters wins
   (``Method.parameter_count``: 9 for an ellipsoid, 3 per plane, 3 per vertex of a free mesh),
   then lower ``e``. **Coverage**: when the strikes cover less than ``COMPLETE_COVERAGE`` of the
   surface of the best closed candidate (no edge bordering a single face; area within ``tau``,
   3 noise or 2 spacings of a strike), closed candidates
   come first within the band: where there are no strikes no open surface can be right, and a
   closed model is the honest guess.

**Coarse to fine** (``LADDER``): the candidates come in levels, models of a few numbers first
(an ellipsoid, a polyhedron of planes), then coarse smooth and local surfaces, then the
defaults, then fine ones. The first ``ALWAYS_LEVELS`` levels always run; after that the search
stops as soon as a level's best is not measurably better (by ``se``) than the best before it.
The ladder holds ``MAX_FITS`` fits in all, a quarter of ``recon compare``'s ~45 runs, and each
fit is cheaper than a compare run (no truth to score).

The chosen candidate is then refitted on all points by the caller (``recon reconstruct -m
auto``).
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
from recon.surfaces.uncertainty import COLUMNS as SIGMA_COLUMNS
from recon.surfaces.uncertainty import sigma_at_incidence

# Fraction of points held out: 10% leaves the fit 90% of the density (a Poisson depth or a grid
# cell chosen on 90% suits 100%) and gives ~1e3 held-out points on a 1e4-point cloud, so the
# standard error of the mean residual is ~3% of it.
HOLDOUT_FRACTION = 0.1
# Fewest held-out points for the standard error to mean anything.
MIN_HELD_OUT = 30
# The F-score threshold of the truth scores (metrics/defaults.py TAU_FRACTION): 1% of the
# bounding-box diagonal, here of the cloud's (the truth's is unknown).
TAU_FRACTION = 0.01
# Differences of held-out error below 1% of tau are below what any score at tau resolves: the
# band of step 3 is at least this wide.
TAU_SLACK = 0.01
# Strike tolerance in recorded sigmas: 3 sigma, the paper's unit of error.
SIGMAS = 3.0
# Below this fraction of the best closed surface near a strike, coverage is incomplete and
# closed candidates come first (module docstring, step 4). 0.9: a 10% unseen cap of the target.
COMPLETE_COVERAGE = 0.9
# A surface point counts as covered within max(tau, 3 noise, 2 spacings) of a strike: between
# two strikes of a uniformly sampled patch no point is farther than about one spacing.
COVERAGE_SPACINGS = 2.0
# Surface samples of the coverage estimate (its standard error < 0.5 / sqrt(n) = 0.5%).
COVERAGE_SAMPLES = 10_000
# The candidate ladder, coarse to fine (module docstring). Level 0: models of a few numbers;
# level 1: coarse smooth and local surfaces; level 2: the defaults and a fine Poisson; level 3:
# the MLS and ball-pivoting surfaces. The runs come from ``benchmarks/suite.py``: the truth's
# best runs on its clouds are among them. Levels hold an even number of fits (2 workers).
LADDER: tuple[tuple[tuple[str, dict], ...], ...] = (
    (("ellipsoid", {}), ("planes", {})),
    (("poisson", {"depth": 6}), ("plane", {"cell": 2.0})),
    (("plane", {}), ("delaunay-balls", {}), ("screened-poisson", {}), ("poisson", {"depth": 9})),
    (("rimls", {}), ("ball-pivoting", {})),
)
MAX_FITS = sum(len(level) for level in LADDER)
# Levels fitted whatever the earlier ones gave: the primitives, the coarse surfaces and the
# defaults (on the suite's RSO-A cloud the truth's best was a level-2 run whose level-1
# predecessors were no better than the level-0 polyhedron).
ALWAYS_LEVELS = 3


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
        One paragraph: the best candidate, the band, the coverage, the choice, the ladder.
    candidates : list of dict
        Per candidate: ``label``, ``method``, ``params``, ``kind``, ``level``, ``status``
        ("ok", "failed" or "skipped": a level the ladder did not need), ``reason``,
        ``heldout_mean_m`` (mean truncated held-out residual), ``heldout_se_m``, ``beam_hits``
        (fraction of held-out beams that hit the surface), ``n_faces``, ``n_params``,
        ``closed``, ``fit_s`` (the isolated fit's process time), ``eligible``, ``chosen``.
    threshold_m : float
        ``e_best + max(se_best, TAU_SLACK tau)``: the band's upper edge.
    coverage : float
        Fraction of the best closed candidate's surface within a strike's tolerance (NaN when
        no closed candidate succeeded).
    """

    run: Run
    reason: str
    candidates: list[dict] = field(default_factory=list)
    threshold_m: float = float("nan")
    coverage: float = float("nan")

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
                "coverage": self.coverage, "candidates": self.candidates}


def _mean_se(d: np.ndarray) -> tuple[float, float]:
    return float(np.mean(d)), (float(np.std(d, ddof=1) / np.sqrt(len(d))) if len(d) > 1
                               else 0.0)


def select(candidates: list[dict], *, coverage: float = float("nan"), slack: float = 0.0
           ) -> tuple[int, float, str]:
    """Apply steps 3 and 4 of the module docstring to scored candidates.

    Parameters
    ----------
    candidates : list of dict
        Each with ``distances`` ((n_held,) float64 truncated residuals in metres, or None for a
        failed or skipped fit), ``n_params``, ``closed`` and ``label``.
    coverage : float
        Fraction of the best closed surface near the strikes (NaN: unknown, taken as
        complete).
    slack : float, metres
        Least width of the band (``TAU_SLACK`` x tau).

    Returns
    -------
    chosen : int
        Index of the choice.
    threshold : float, metres
        ``e_best + max(se_best, slack)``.
    reason : str
    """
    scored = [i for i, c in enumerate(candidates) if c.get("distances") is not None]
    if not scored:
        raise MethodFailed("auto: every candidate failed: " + "; ".join(
            f"{c['label']}: {c.get('reason')}" for c in candidates))
    stats = {i: _mean_se(candidates[i]["distances"]) for i in scored}
    best = min(scored, key=lambda i: (stats[i][0], candidates[i]["n_params"]))
    mean_best, se = stats[best]
    width = max(se, slack)
    band = (f"one standard error ({se:.2g} m)" if width == se else
            f"{TAU_SLACK:.0%} of the score threshold tau ({width:.2g} m, above one standard "
            f"error)")
    threshold = mean_best + width
    eligible = [i for i in scored if stats[i][0] <= threshold]
    incomplete = bool(coverage < COMPLETE_COVERAGE)
    closed_first = incomplete and any(candidates[i].get("closed") for i in eligible)
    chosen = min(eligible, key=lambda i: (closed_first and not candidates[i].get("closed"),
                                          candidates[i]["n_params"], stats[i][0]))
    c, b = candidates[chosen], candidates[best]
    size = f"{c['n_params']:,} parameters, {c['n_faces']:,} faces"
    if chosen == best:
        reason = (f"chose {c['label']} ({size}): the lowest held-out error, "
                  f"{mean_best:.4g} m; " + (
                      f"the other {len(eligible) - 1} candidate(s) within {band} are larger "
                      "models" if len(eligible) > 1 else
                      f"no other candidate is within {band}"))
    else:
        reason = (f"chose {c['label']} ({size}): held-out error {stats[chosen][0]:.4g} m, "
                  f"within {band} of the best, {b['label']} "
                  f"({mean_best:.4g} m, {b['n_params']:,} parameters); of the {len(eligible)} "
                  "candidates within that band it is the "
                  + ("smallest closed model" if closed_first else "smallest model"))
    if np.isfinite(coverage):
        reason += (f". The strikes cover {coverage:.0%} of the best closed surface"
                   + ("; where there are no strikes a closed model is the honest guess, so "
                      "closed candidates came first" if incomplete else ""))
    return chosen, threshold, reason


def heldout_geometry(points: np.ndarray, view_points: np.ndarray | None, vertices: np.ndarray,
                     faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Held-out strikes against a surface: their distances, and whether their beams hit it.

    Parameters
    ----------
    points : (n, 3) float64, metres, body frame
        Held-out points.
    view_points : (n, 3) float64, metres, or None
        Their sensor positions (beams from each view point through its point).
    vertices : (v, 3) float64, metres
    faces : (f, 3) int64

    Returns
    -------
    distance : (n,) float64, metres
        Closest-point distance of each point to the surface (Open3D's ``compute_distance`` in
        float32 about the mesh's centre: ~1e-7 of the extent).
    hit : (n,) bool
        Whether the beam hits the surface (all False without view points).
    cos_incidence : (n,) float64
        |cos| of the angle between the beam and the normal of the triangle it hits first (1
        where it misses or without view points).
    """
    import open3d as o3d

    centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor((vertices - centre).astype(np.float32)),
                        o3d.core.Tensor(faces.astype(np.uint32)))
    distance = scene.compute_distance(o3d.core.Tensor(
        (points - centre).astype(np.float32))).numpy().astype(np.float64)
    hit = np.zeros(len(points), dtype=bool)
    cos_incidence = np.ones(len(points))
    if view_points is not None:
        ray = points - view_points
        direction = ray / np.maximum(np.linalg.norm(ray, axis=1), 1e-300)[:, None]
        rays = np.hstack([view_points - centre, direction]).astype(np.float32)
        cast = scene.cast_rays(o3d.core.Tensor(rays))
        triangle = cast["primitive_ids"].numpy().astype(np.int64)
        hit = np.isfinite(cast["t_hit"].numpy()) & (triangle < len(faces))
        a, b, c = (vertices[faces[triangle[hit], i]] for i in range(3))
        normal = np.cross(b - a, c - a)
        cos_incidence[hit] = np.abs(np.einsum("ij,ij->i", normal, direction[hit])) / \
            np.maximum(np.linalg.norm(normal, axis=1), 1e-300)
    return distance, hit, cos_incidence


def strike_sigma(columns: dict[str, np.ndarray] | None, cos_incidence: np.ndarray,
                 noise: float) -> np.ndarray:
    """Each held-out strike's recorded 1-sigma uncertainty along the normal of the surface its
    beam meets (``recon.surfaces.uncertainty.sigma_at_incidence``); without an error model
    (None, or every column zero) the training cloud's robust noise scale ``noise`` [m]."""
    if columns is None or not any(np.asarray(v).any() for v in columns.values()):
        return np.full(len(cos_incidence), float(noise))
    return sigma_at_incidence(columns, cos_incidence)


def closed(faces: np.ndarray) -> bool:
    """True when no edge borders a single face: the surface encloses a volume (non-manifold
    edges of a minimum cut allowed, unlike ``recon.surfaces.checks.watertight``)."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]),
                    axis=1)
    _, count = np.unique(edges, axis=0, return_counts=True)
    return bool(len(faces)) and not np.any(count == 1)


def coverage_of(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray, reach: float,
                *, seed: int = 0) -> float:
    """Fraction of a surface's area within ``reach`` of a strike (uniform area samples)."""
    from scipy.spatial import cKDTree

    from metrics import Mesh, sample_surface

    samples, _ = sample_surface(Mesh(vertices, faces), COVERAGE_SAMPLES, seed=seed)
    distance, _ = cKDTree(points).query(samples, workers=-1)
    return float(np.mean(distance <= reach))


def _fit(*, run: Run, cloud, timeout_s, memory_mb) -> dict:
    from recon.experiments.cases import SWEEP_THREADS
    from recon.surfaces.isolation import run_isolated

    return run_isolated(run, cloud, timeout_s=timeout_s, memory_mb=memory_mb,
                        threads=SWEEP_THREADS)


def ladder(methods: Sequence[str] | None = None) -> list[list[Run]]:
    """The levels of ``LADDER`` as runs, restricted to ``methods`` (each named method not on the
    ladder joins the last level at its defaults)."""
    from recon.surfaces.methods import bind

    levels = [[bind(name, params) for name, params in level
               if methods is None or name in methods] for level in LADDER]
    if methods is not None:
        listed = {name for level in LADDER for name, _ in level}
        levels[-1] += [bind(name) for name in methods if name not in listed]
    return [level for level in levels if level]


def choose(points: np.ndarray, *, view_points: np.ndarray | None = None,
           uncertainty: dict[str, np.ndarray] | None = None,
           candidates: Sequence[Run | tuple[str, dict]] | None = None,
           methods: Sequence[str] | None = None, holdout: float = HOLDOUT_FRACTION,
           seed: int = 0, k: int = DEFAULT_K, fallback: Fallback = "centroid",
           timeout_s: float = DEFAULT_TIMEOUT_S, memory_mb: int | None = DEFAULT_MEMORY_MB,
           scheduler: str | None = "threads", n_workers: int | None = None) -> AutoChoice:
    """Choose a method and resolution by held-out beams, without the truth.

    Parameters
    ----------
    points : (n, 3) float64, metres, body frame
    view_points : (n, 3) float64, metres, optional
        Sensor positions (orient the normals, aim the held-out beams).
    uncertainty : dict of str to (n,) arrays, optional
        The strikes' recorded uncertainty columns (a ``Cloud``'s attributes as ingest writes
        them, ``recon.surfaces.uncertainty``); other keys are ignored.
    candidates : sequence of Run or of (method, params), optional
        Fit these, all at once, instead of the ladder. Pairs are resolved once here.
    methods : sequence of str, optional
        Restrict the ladder to these methods (``ladder``).
    holdout : float
        Fraction of points held out, in (0, 0.5].
    seed : int
        Seed of the split (and of the methods).
    k, fallback
        Normal estimation (``recon.surfaces.prepare.prepare``).
    timeout_s, memory_mb
        Limits of each isolated fit.
    scheduler, n_workers
        Where the fits run (``recon.experiments.sweep``; default: a local thread pool, each fit in
        its own process).

    Returns
    -------
    AutoChoice
    """
    from recon.experiments.cases import as_runs
    from recon.surfaces.prepare import prepare

    if not 0 < holdout <= 0.5:
        raise AutoError(f"holdout must be in (0, 0.5], got {holdout}")
    points = np.asarray(points, dtype=np.float64)
    n_held = round(holdout * len(points))
    if n_held < MIN_HELD_OUT:
        raise AutoError(f"auto needs at least {MIN_HELD_OUT} held-out points; {holdout:g} of "
                        f"{len(points)} points is {n_held}")
    levels = [as_runs(candidates)] if candidates else ladder(methods)
    columns = None
    if uncertainty is not None and all(key in uncertainty for key in SIGMA_COLUMNS):
        columns = {key: np.asarray(uncertainty[key]) for key in SIGMA_COLUMNS}
    order = np.random.default_rng(seed).permutation(len(points))
    held, train = np.sort(order[:n_held]), np.sort(order[n_held:])
    view = None if view_points is None else np.asarray(view_points, dtype=np.float64)
    cloud = prepare(points[train], view_points=None if view is None else view[train], k=k,
                    fallback=fallback, seed=seed,
                    uncertainty=None if columns is None else {
                        key: v[train] for key, v in columns.items()})
    tau = TAU_FRACTION * float(np.linalg.norm(np.ptp(points, axis=0)))
    held_columns = None if columns is None else {key: v[held] for key, v in columns.items()}
    shared = {"cloud": cloud, "timeout_s": timeout_s, "memory_mb": memory_mb}
    context = {"points": points[held], "view": None if view is None else view[held],
               "columns": held_columns, "noise": cloud.noise, "tau": tau}
    table: list[dict] = []
    note = ""
    for depth, level in enumerate(levels):
        before = _best(table)
        table += _fit_level(level, depth, shared, context, scheduler, n_workers)
        after = _best(table)
        if depth + 1 >= ALWAYS_LEVELS and depth + 1 < len(levels) and before is not None \
                and after is not None:
            level_best = min((e for e in table if e["level"] == depth and
                              e["distances"] is not None),
                             key=lambda e: e["mean"], default=None)
            if level_best is None or level_best["mean"] > before["mean"] - before["se"]:
                skipped = sum(len(x) for x in levels[depth + 1:])
                note = (f"; the ladder stopped after level {depth} of {len(levels) - 1} "
                        f"({skipped} finer candidates not fitted): it was not measurably "
                        "better than the levels before it")
                for later, rest in enumerate(levels[depth + 1:], start=depth + 1):
                    table += [_entry(run, later, status="skipped") for run in rest]
                break
    enclosing = [e for e in table if e["distances"] is not None and e["closed"]]
    coverage = float("nan")
    if enclosing and view is not None:
        best_closed = min(enclosing, key=lambda e: e["mean"])
        coverage = coverage_of(best_closed["vertices"], best_closed["faces"], points,
                               max(tau, SIGMAS * cloud.noise, COVERAGE_SPACINGS * cloud.spacing),
                               seed=seed)
    chosen, threshold, reason = select(table, coverage=coverage, slack=TAU_SLACK * tau)
    fitted = sum(e["status"] != "skipped" for e in table)
    reason += f"; {fitted} candidate fit(s) of {len(table)}{note}."
    runs_of = [entry.pop("run") for entry in table]
    for i, entry in enumerate(table):
        d = entry.pop("distances")
        entry.pop("vertices", None)
        entry.pop("faces", None)
        entry["heldout_mean_m"] = entry.pop("mean")
        entry["heldout_se_m"] = entry.pop("se")
        entry["eligible"] = d is not None and entry["heldout_mean_m"] <= threshold
        entry["chosen"] = i == chosen
    return AutoChoice(runs_of[chosen], reason, table, threshold, coverage)


def _entry(run: Run, level: int, *, status: str, reason: str = "") -> dict:
    return {"label": run.label, "method": run.method, "params": run.params, "kind": run.kind,
            "level": level, "run": run, "status": status, "reason": reason, "n_faces": None,
            "n_params": None, "closed": None, "fit_s": None, "distances": None,
            "beam_hits": None, "mean": None, "se": None}


def _best(table: list[dict]) -> dict | None:
    return min((e for e in table if e["distances"] is not None), key=lambda e: e["mean"],
               default=None)


def heldout_errors(context: dict, vertices: np.ndarray, faces: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray | None]:
    """Step 2 of the module docstring: each held-out strike's truncated error against a surface.

    Parameters
    ----------
    context : dict
        ``points`` (n, 3) and ``view`` ((n, 3) or None) of the held-out strikes, metres;
        ``columns`` (their uncertainty columns or None), ``noise`` and ``tau`` (metres).
    vertices : (v, 3) float64, metres
    faces : (f, 3) int64

    Returns
    -------
    error : (n,) float64, metres
        ``min(distance, cap)`` for beams that hit the surface, ``cap`` for those that miss.
    hits : (n,) bool, or None without view points
    """
    view = context["view"]
    distance, hits, cos = heldout_geometry(context["points"], view, vertices, faces)
    if view is None:
        sigma = strike_sigma(context["columns"], cos, context["noise"])
        return np.minimum(distance, np.maximum(context["tau"], SIGMAS * sigma)), None
    cap = np.maximum(context["tau"], SIGMAS * strike_sigma(context["columns"], cos,
                                                            context["noise"]))
    return np.where(hits, np.minimum(distance, cap), cap), hits


def _fit_level(level: list[Run], depth: int, shared: dict, context: dict,
               scheduler: str | None, n_workers: int | None) -> list[dict]:
    """Fit one level's runs (isolated, in parallel) and score them on the held-out strikes."""
    from tqdm import tqdm

    from recon.experiments.sweep import iterate

    cases = {run.key: {"run": run} for run in level}
    results: dict[str, dict] = {}
    with tqdm(total=len(cases), desc=f"auto level {depth}", unit="fit", disable=None,
              leave=False) as bar:
        for key, result in iterate(_fit, cases, shared=shared, scheduler=scheduler,
                                   n_workers=n_workers):
            results[key] = result
            bar.update(1)
    out = []
    for run in level:
        result = results[run.key]
        entry = _entry(run, depth, status=result.get("status", "failed"),
                       reason=result.get("reason", ""))
        entry["fit_s"] = result.get("process_time_s")
        if entry["status"] == "ok":
            vertices, faces = result["vertices"], result["faces"]
            d, hits = heldout_errors(context, vertices, faces)
            entry.update(distances=d, vertices=vertices, faces=faces, n_faces=len(faces),
                         n_params=run.method_spec().parameter_count(vertices, faces),
                         closed=closed(faces),
                         beam_hits=None if hits is None else float(hits.mean()))
            entry["mean"], entry["se"] = _mean_se(d)
        out.append(entry)
    return out


def format_choice(choice: AutoChoice) -> str:
    """The candidates table and the reason, as ``recon reconstruct -m auto`` prints them."""
    lines = [f"{'':2}{'candidate':<34} {'level':>5} {'kind':<13} {'held-out m':>11} "
             f"{'hits':>5} {'params':>8} {'faces':>8}", "-" * 92]
    ranked = sorted(choice.candidates, key=lambda c: (c["heldout_mean_m"] is None,
                                                      c["heldout_mean_m"] or 0.0))
    for c in ranked:
        mark = "*" if c["chosen"] else ("~" if c["eligible"] else " ")
        start = f"{mark:2}{c['label'][:34]:<34} {c['level']:>5} {c['kind']:<13}"
        if c["status"] == "skipped":
            lines.append(f"{start} not fitted (the ladder stopped before its level)")
        elif c["heldout_mean_m"] is None:
            lines.append(f"{start} FAILED: {(c['reason'] or '')[:50]}")
        else:
            hits = "" if c["beam_hits"] is None else f"{c['beam_hits']:.2f}"
            lines.append(f"{start} {c['heldout_mean_m']:>11.4g} {hits:>5} "
                         f"{c['n_params']:>8d} {c['n_faces']:>8d}")
    lines.append("(* chosen, ~ within the band of the best: one standard error, at least "
                 f"{TAU_SLACK:.0%} of tau)")
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
        Restrict the ladder to these methods (``ladder``; default: the whole ladder).
    holdout : float
    preparation : Preparation, optional
    limits : Limits, optional
    """
    preparation = preparation or Preparation()
    return choose(cloud.points, view_points=cloud.view_points, uncertainty=cloud.attributes,
                  methods=methods, holdout=holdout, seed=preparation.seed, k=preparation.k,
                  fallback=preparation.fallback, **(limits or Limits()).kwargs())


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
        Restrict the ladder to these methods (default: the whole ladder).
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
                                  isolate=isolate, on_wait=on_wait, source=input)
    return {"input": str(input), "auto": choice.to_dict()} | summary
