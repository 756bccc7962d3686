"""Closed-loop imaging: the gap-seeking attitude law against nadir and the paper's fixed slews.

The paper's future work is "closed loop attitude control to close coverage gaps"; ours is the
``attitude.mode = "gaps"`` law of sim/gap_seeking.py (it plans from its own recorded strikes,
the known spin and its orbit, within a slew-rate and an angle limit). Six targets: the paper's
asteroid at the near-optimal 85 deg and the suboptimal 60 deg, RSO-A and RSO-B at 85 deg (250 m),
and two satellites generated from seeds inside the study (sim/procedural.py: bus, dish, boom with
a box at its end, thin solar panels) on RSO-A's orbit. Four laws on each: nadir, the paper's two
fixed sinusoidal slews (2 deg, its choice at 85 deg, and 5 deg, at 60 deg), and the gap-seeking
law with its defaults (1 deg/s, 30 deg, replanning every 300 s), held against the better slew.

Per case: coverage (and every standard score) against time, the hours to 90 % and 95 %
coverage (linear between scored times), the edge score and the F-score of the best of a few
reconstructed surfaces at fixed times, and the slew effort: the total angle between the
commanded attitudes of consecutive shots, read from the log (it includes the ~14 deg/h by which
even nadir pointing turns to follow a 25 h orbit). Per target: the coverage ceiling, the
coverage of every truth point some direction sees from far away (``coverage_ceiling``), which no
law can pass.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence

import numpy as np

from formats import scratch
from recon.experiments import charts
from recon.experiments.studies import runner
from recon.experiments.studies.runner import claim

NAME = "closed-loop"
TITLE = "Closed-loop gap-seeking attitude against nadir and the paper's fixed slews"

HOUR = 3600.0
# (preset, overrides, label). The generated satellites (sim/procedural.py) are made inside the
# study from their seeds, at RSO-A's orbit (250 m, 85 deg).
TARGETS = {
    "rso-a": ("rso-a-lrf", (), "RSO-A, 85 deg"),
    "rso-b": ("rso-b-lrf", (), "RSO-B, 85 deg"),
    "satellite-1": ("rso-a-lrf", ("target.kind=satellite", "target.seed=1"),
                    "generated satellite (seed 1), 85 deg"),
    "satellite-2": ("rso-a-lrf", ("target.kind=satellite", "target.seed=2"),
                    "generated satellite (seed 2), 85 deg"),
    "asteroid-85": ("asteroid-lrf", ("orbit.inclination_deg=85",), "asteroid, 85 deg"),
    "asteroid-60": ("asteroid-lrf", ("orbit.inclination_deg=60",), "asteroid, 60 deg"),
}
# The paper's fixed sinusoidal slews: 2 deg (its choice at 85 deg) and 5 deg (at 60 deg). Every
# target takes both, and gap-seeking is held against the better of the two.
SLEWS = {"slew-2": 2.0, "slew-5": 5.0}
LAWS = ("nadir", *SLEWS, "gaps")
LAW_STYLE = {"nadir": {"color": "0.45", "ls": "--"}, "slew-2": {"color": "tab:blue"},
             "slew-5": {"color": "tab:cyan", "ls": "-."}, "gaps": {"color": "tab:red"}}
LAW_NAME = {"nadir": "nadir", "slew-2": "the paper's 2 deg slew",
            "slew-5": "the paper's 5 deg slew", "gaps": "gap-seeking (closed loop)"}
LEVELS = (0.90, 0.95)
# The target: gap-seeking reaches 95 % at least this many times sooner than the better fixed
# slew, and its coverage is not below that slew's at any time both report from this hour on.
TARGET_SPEEDUP, TARGET_FROM_HOURS = 2.0, 24.0
TARGET_COVERAGE = 0.95


def target_level(ceiling: float) -> float:
    """The coverage the target claim times: ``TARGET_COVERAGE``, or that share of the target's
    ceiling (``coverage_ceiling``) where the ceiling is below it and no law can reach it."""
    return TARGET_COVERAGE if ceiling >= TARGET_COVERAGE else TARGET_COVERAGE * ceiling

_HOURS_FIXED = (12, 24, 48, 72, 96, 120, 144, 192, 240, 288, 336, 384, 430)
_HOURS_RSO = (12, 24, 48, 72, 96, 129)
_HOURS_GAPS = (4, 8, 12, 16, 20, 24, 30, 36, 48, 60, 72, 96)
_QUICK = (4, 8)
PLAN = {
    # Fixed laws run 100 rotations (asteroid) or the paper's 129 h (spacecraft); gap-seeking 96 h.
    "full": {"hours": {"nadir": _HOURS_FIXED, "slew-2": _HOURS_FIXED, "slew-5": _HOURS_FIXED,
                       "gaps": _HOURS_GAPS},
             "rso_hours": {"nadir": _HOURS_RSO, "slew-2": _HOURS_RSO, "slew-5": _HOURS_RSO,
                           "gaps": _HOURS_GAPS},
             "surface_at": (24, 96), "methods": ("poisson", "ball-pivoting"),
             "overrides": (), "score": runner.CURVE_SCORE},
    "quick": {"hours": {law: _QUICK for law in LAWS},
              "rso_hours": {law: _QUICK for law in LAWS},
              "surface_at": (8,), "methods": ("poisson",),
              "overrides": ("target.subdivisions=4",),
              "score": {"n_truth_samples": 20_000, "coverage_points": 40_000}},
    # The tiny size builds surfaces of one target only (every law): the tests' end-to-end run.
    "tiny": {"hours": {law: (0.5, 1) for law in LAWS},
             "rso_hours": {law: (0.5, 1) for law in LAWS}, "surface_at": (1,),
             "surface_targets": ("asteroid-60",), "methods": ("poisson",),
             "overrides": ("target.subdivisions=3",),
             "score": {"n_truth_samples": 4000, "coverage_points": 8000}},
}


# The coverage ceiling: a cloud of every point of the truth that some far-away direction sees is
# the most any law can strike. Directions on a Fibonacci sphere; points sampled by area, this many
# per disc of radius tau on average (a uniform sample then leaves e^-10 of the seen area farther
# than tau from every point).
CEILING_DIRECTIONS = 200
CEILING_PER_DISC = 10.0


def _law_overrides(law: str) -> list[str]:
    if law == "gaps":
        return ["attitude.mode=gaps"]
    return [f"slew.amplitude_deg={SLEWS.get(law, 0.0):g}"]


def cases(size: str) -> dict[str, dict]:
    """Every (target, law): a scene run to its last scored time."""
    plan = PLAN[runner.check_size(size)]
    out = {}
    for target, (preset, overrides, label) in TARGETS.items():
        is_rso = preset.startswith("rso")
        for law in LAWS:
            hours = (plan["rso_hours"] if is_rso else plan["hours"])[law]
            extra = [o for o in plan["overrides"] if not (is_rso and o.startswith("target."))]
            out[f"{target} {law}"] = {
                "scene": preset,
                "overrides": [*overrides, *_law_overrides(law),
                              f"time.duration={max(hours) * HOUR:g}", *extra],
                "seed": 0, "prefixes_s": [h * HOUR for h in hours],
                "surface_at_s": [h * HOUR for h in plan["surface_at"] if h <= max(hours)
                                 and target in plan.get("surface_targets", TARGETS)],
                "methods": list(plan["methods"]), "score_options": dict(plan["score"]),
                "tags": {"target": target, "law": law, "label": label,
                         "slew_deg": SLEWS.get(law, 0.0)}}
    return out


def slew_effort(sensor_attitude: np.ndarray) -> np.ndarray:
    """Cumulative angle [deg] turned between consecutive commanded attitudes.

    Parameters
    ----------
    sensor_attitude : (n, 4) float64, quaternions (x, y, z, w), S->I, as the log records them

    Returns
    -------
    (n,) float64: the angle turned from the first shot to each shot.
    """
    from scipy.spatial.transform import Rotation

    r = Rotation.from_quat(sensor_attitude)
    if len(r) < 2:
        return np.zeros(len(r))
    return np.degrees(np.concatenate([[0.0], np.cumsum((r[:-1].inv() * r[1:]).magnitude())]))


def best_surface(points: np.ndarray, view: np.ndarray, truth, *, methods: Sequence[str],
                 seed: int, score_options: Mapping) -> dict:
    """The F-score of the best of ``methods``' surfaces of a cloud (in-process), and its name."""
    from metrics.score import score
    from recon.surfaces.methods import bind
    from recon.surfaces.prepare import prepare
    from recon.surfaces.reconstruct import reconstruct

    prepared = prepare(points, view_points=view, seed=seed)
    best = {"surface_fscore": None, "surface_method": None}
    for method in methods:
        try:
            surface = reconstruct(prepared, method=bind(method, None), isolate=False)
        except Exception as exc:   # a method failing on a sparse cloud is a result, not a crash
            best.setdefault("surface_failures", []).append(f"{method}: {exc}")
            continue
        f = score(surface, truth, seed=seed, edges=False, **score_options).fscore
        if best["surface_fscore"] is None or f > best["surface_fscore"]:
            best = best | {"surface_fscore": f, "surface_method": method}
    return best


def run_case(*, scene: str, overrides: Sequence[str], seed: int, prefixes_s: Sequence[float],
             surface_at_s: Sequence[float], methods: Sequence[str], score_options: Mapping,
             tags: Mapping) -> dict:
    """Simulate one (target, law), then score every prefix and its slew effort (Dask task)."""
    import sim
    from formats import StrikeLog
    from recon.experiments import progress
    from recon.registration.ingest import ingest

    start = time.perf_counter()
    the_scene = sim.load_scene(scene, list(overrides))
    truth = (the_scene.vertices, the_scene.faces)
    with scratch.directory("recon-closed-loop-") as tmp:
        log_path = tmp / "run.h5"   # progress: the simulation half, the prefixes the other
        summary = sim.simulate(the_scene, log_path, seed=seed, workers=1,
                               progress=progress.within(0.0, 0.5))
        with StrikeLog(log_path) as log:
            shots = log.shots()
        cloud = ingest(log_path)
    effort = slew_effort(shots.sensor_attitude)
    shot_time = cloud.attributes["time"]
    rows = []
    for index, t in enumerate(prefixes_s):
        progress.step(len(prefixes_s) + index, 2 * len(prefixes_s))
        mask = shot_time < t
        n = int(mask.sum())
        done = shots.time < t
        row = {"time_s": t, "hours": t / HOUR, "n_points": n,
               "slew_deg": float(effort[done][-1]) if done.any() else 0.0,
               "scored": n >= runner.MIN_SCORED_POINTS}
        if row["scored"]:
            row.update(runner.score_row(cloud.points[mask], truth, seed=seed,
                                        score_options=score_options)[0])
            if any(math.isclose(t, s) for s in surface_at_s):
                row.update(best_surface(cloud.points[mask], cloud.view_points[mask], truth,
                                        methods=methods, seed=seed,
                                        score_options=score_options))
        rows.append(row)
    return {"status": "ok", "tags": dict(tags), "scene": scene, "overrides": list(overrides),
            "seed": seed, "sim": {k: summary[k] for k in ("shots", "strikes", "duration_s",
                                                          "wall_time_s")},
            "score_options": dict(score_options), "prefixes": rows,
            "wall_time_s": time.perf_counter() - start}


def coverage_ceiling(vertices: np.ndarray, faces: np.ndarray, *, seed: int,
                     score_options: Mapping) -> float:
    """Coverage of a cloud of every truth point seen from some direction far away: the most
    any attitude law can reach (a point no direction sees from outside the target, such as the
    face of a part pressed against another, counts only when it lies within the coverage
    tolerance of a seen one).

    Parameters
    ----------
    vertices : (n, 3) float64, metres, B; faces : (m, 3) int
        The truth, closed and wound outward.
    seed : int
        Seed of the sampled points and of the score.
    score_options : mapping
        Keyword arguments of ``metrics.score.score`` (its default tau).

    Notes
    -----
    Points are sampled on the truth by area (``CEILING_PER_DISC`` per disc of radius tau); one
    is seen when a ray from just above it (a
    millionth of the truth's diagonal along its face's normal) along one of
    ``CEILING_DIRECTIONS`` directions in front of that face leaves the target without striking
    it.
    """
    from metrics.defaults import TAU_FRACTION
    from metrics.inputs import as_mesh
    from metrics.sampling import sample_surface
    from metrics.score import score
    from sim.raycast import EmbreeBackend

    mesh = as_mesh((vertices, faces))
    v = mesh.vertices[mesh.faces]
    normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    area = 0.5 * float(np.linalg.norm(normal, axis=1).sum())
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    diagonal = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    n = math.ceil(CEILING_PER_DISC * area / (math.pi * (TAU_FRACTION * diagonal) ** 2))
    points, face = sample_surface(mesh, n, seed=seed)
    normal = normal[face]
    origins = (points + 1e-6 * diagonal * normal).astype(np.float32)
    caster = EmbreeBackend(mesh.vertices, mesh.faces)
    k = np.arange(CEILING_DIRECTIONS) + 0.5
    z = 1.0 - 2.0 * k / CEILING_DIRECTIONS
    phi = math.pi * (3.0 - math.sqrt(5.0)) * k
    directions = np.column_stack([np.sqrt(1 - z * z) * np.cos(phi),
                                  np.sqrt(1 - z * z) * np.sin(phi), z]).astype(np.float32)
    seen = np.zeros(len(points), dtype=bool)
    for d in directions:            # one batched cast per direction
        front = np.flatnonzero(~seen & (normal @ d > 0))
        hit = caster.first_hit(origins[front], np.broadcast_to(d, (len(front), 3)).copy())
        seen[front[hit < 0]] = True
    return score(points[seen], (mesh.vertices, mesh.faces), seed=seed, edges=False,
                 **score_options).coverage


def hours_to(records: Mapping, key: str, level: float) -> float | None:
    """Hours until coverage first reaches ``level``, linear between scored times (None: never
    within the run)."""
    if key not in records:
        return None
    xs, ys = runner.series(records, key, "coverage", x="hours")
    hit = np.flatnonzero(ys >= level)
    if not len(hit):
        return None
    i = hit[0]
    if i == 0:
        return float(xs[0])
    return float(xs[i - 1] + (level - ys[i - 1]) * (xs[i] - xs[i - 1]) / (ys[i] - ys[i - 1]))


def effort_at(records: Mapping, key: str, hours: float | None) -> float | None:
    """Total slew angle [deg] at ``hours`` (linear between scored times; the run's total when
    ``hours`` is None or past its end)."""
    xs, effort = runner.series(records, key, "slew_deg", x="hours")
    if hours is None or hours >= xs[-1]:
        return float(effort[-1])
    return float(np.interp(hours, xs, effort))


def table(records: Mapping, plan: Mapping) -> list[dict]:
    """One row per case: hours to each level, effort, scores at the fixed times."""
    out = []
    for key, record in records.items():
        row = {"case": key, "target": record["tags"]["target"], "law": record["tags"]["law"],
               "run_hours": record["prefixes"][-1]["hours"]}
        for level in LEVELS:
            h = hours_to(records, key, level)
            row[f"hours_to_{level:.0%}"] = h
            row[f"slew_deg_to_{level:.0%}"] = effort_at(records, key, h)
        row["slew_deg_per_hour"] = effort_at(records, key, None) / row["run_hours"]
        for h in plan["surface_at"]:
            p = runner.at(records, key, h * HOUR)
            if p is not None:
                row[f"coverage_{h:g}h"] = p["coverage"]
                row[f"edge_score_{h:g}h"] = p["edge_score"]
                row[f"surface_fscore_{h:g}h"] = p.get("surface_fscore")
        out.append(row)
    return out


def best_slew(records: Mapping, target: str, level: float = TARGET_COVERAGE) -> str | None:
    """The fixed slew of ``target`` that reaches coverage ``level`` first (else the one of
    higher final coverage): the key of its case, None when neither ran."""
    keys = [f"{target} {law}" for law in SLEWS if f"{target} {law}" in records]
    if not keys:
        return None
    return min(keys, key=lambda k: (hours_to(records, k, level) or math.inf,
                                    -records[k]["prefixes"][-1].get("coverage", 0.0)))


def shortfalls(records: Mapping, gaps: str, slew: str) -> list[tuple[float, float, float]]:
    """``(hours, gap-seeking coverage, slew coverage)`` at every time from
    ``TARGET_FROM_HOURS`` on that both cases report and where gap-seeking is below."""
    mine = dict(zip(*runner.series(records, gaps, "coverage", x="hours"), strict=True))
    theirs = dict(zip(*runner.series(records, slew, "coverage", x="hours"), strict=True))
    return [(h, mine[h], theirs[h]) for h in sorted(set(mine) & set(theirs))
            if h >= TARGET_FROM_HOURS and mine[h] < theirs[h]]


def finish(records: dict, out_dir, size: str) -> dict:
    plan = PLAN[size]
    panels = []
    for target, (_, _, label) in TARGETS.items():
        curves = []
        for law in LAWS:
            key = f"{target} {law}"
            if key not in records:
                continue
            x, coverage = runner.series(records, key, "coverage", x="hours")
            curves.append({"label": LAW_NAME[law], "x": x, "coverage": coverage,
                           "slew_deg": runner.series(records, key, "slew_deg", x="hours")[1],
                           "style": LAW_STYLE[law]})
        panels.append({"title": label, "curves": curves})
    charts.coverage_and_effort(
        panels, out_dir / "coverage_vs_time.png", levels=LEVELS,
        title="Single-beam LRF: coverage and slew effort, nadir vs the paper's fixed slews vs "
              "closed-loop gap-seeking")
    ceiling = {target: _ceiling(cases(size)[f"{target} gaps"], plan) for target in TARGETS}
    rows = [row | {"coverage_ceiling": ceiling[row["target"]]} for row in table(records, plan)]
    runner.write_csv(rows, out_dir / "closed_loop.csv")
    claims = [_claim_target(records, target, ceiling[target]) for target in TARGETS]
    return {"claims": claims, "files": ["coverage_vs_time.png", "closed_loop.csv"],
            "extra": {"table": rows, "surface_methods": list(plan["methods"])}}


def _ceiling(case: Mapping, plan: Mapping) -> float:
    """``coverage_ceiling`` of the target of a case."""
    import sim

    scene = sim.load_scene(case["scene"], [o for o in case["overrides"]
                                           if o.startswith("target.")])
    return coverage_ceiling(scene.vertices, scene.faces, seed=0, score_options=plan["score"])


def _claim_target(records: Mapping, target: str, ceiling: float) -> dict:
    label = TARGETS[target][2]
    level = target_level(ceiling)
    goal = (f"{level:.1%} coverage ({TARGET_COVERAGE:.0%} of {ceiling:.3f}, the most any law "
            f"can reach here)" if level < TARGET_COVERAGE else f"{TARGET_COVERAGE:.0%} coverage")
    text = (f"{label}: gap-seeking reaches {goal} at least {TARGET_SPEEDUP:g}x sooner than the "
            f"better of the paper's fixed slews, and is never below its coverage at a time both "
            f"report from {TARGET_FROM_HOURS:g} h on")
    gaps, slew = f"{target} gaps", best_slew(records, target, level)
    figure = "closed-loop target"
    if gaps not in records or slew is None:
        return claim(f"closed-loop-{target}", figure, text, "-", "no data", "not tested")
    name = LAW_NAME[slew.split()[-1]]
    h_gaps, h_slew = hours_to(records, gaps, level), hours_to(records, slew, level)
    slew_end = records[slew]["prefixes"][-1]["hours"]
    below = shortfalls(records, gaps, slew)
    below_text = ("; below it at " + ", ".join(f"{h:g} h ({a:.3f} < {b:.3f})"
                                              for h, a, b in below)) if below else ""
    if h_gaps is None:
        last = records[gaps]["prefixes"][-1]
        ours = (f"gap-seeking does not reach {level:.1%} within {last['hours']:g} h (coverage "
                f"{last['coverage']:.3f}); {name}: "
                + (f"{level:.1%} after {h_slew:.1f} h" if h_slew is not None else
                   f"not within {slew_end:g} h") + below_text
                + f"; the most any law can reach here is {ceiling:.3f}")
        tested = records[gaps]["prefixes"][-1]["hours"] >= TARGET_FROM_HOURS
        return claim(f"closed-loop-{target}", figure, text, "-", ours,
                     "not reproduced" if below else ("partly" if tested else "not tested"),
                     f"gap-seeking never reached {level:.1%}; partly when it is never "
                     f"below the slew; not tested when it ran less than {TARGET_FROM_HOURS:g} h")
    speedup = (h_slew / h_gaps) if h_slew is not None else slew_end / h_gaps
    bound = "" if h_slew is not None else ">= "
    e_gaps, e_slew = effort_at(records, gaps, h_gaps), effort_at(records, slew, h_slew)
    ours = (f"{level:.1%} after {h_gaps:.1f} h (gap-seeking) against "
            + (f"{h_slew:.1f} h" if h_slew is not None else
               f"not within {slew_end:g} h (coverage "
               f"{records[slew]['prefixes'][-1]['coverage']:.3f})")
            + f" ({name}): {bound}{speedup:.1f}x sooner; slew angle {e_gaps:,.0f} deg against "
            f"{bound}{e_slew:,.0f} deg" + below_text)
    fast = speedup >= TARGET_SPEEDUP
    verdict = "reproduced" if fast and not below else ("partly" if fast or not below
                                                       else "not reproduced")
    return claim(f"closed-loop-{target}", figure, text,
                 f">= {TARGET_SPEEDUP:g}x sooner, never below after {TARGET_FROM_HOURS:g} h",
                 ours, verdict,
                 "reproduced when both hold (a fixed slew that never reaches the level counts at "
                 "its last time, which understates the speed-up); partly when one holds.")
