"""Closed-loop imaging: the gap-seeking attitude law against nadir and the paper's fixed slews.

The paper's future work is "closed loop attitude control to close coverage gaps"; ours is the
``attitude.mode = "gaps"`` law of sim/gap_seeking.py (it plans from its own recorded strikes,
the known spin and its orbit, within a slew-rate and an angle limit). Three targets: the paper's
asteroid at the near-optimal 85 deg and the suboptimal 60 deg, and RSO-A at 85 deg (250 m).
Three laws on each: nadir, the paper's fixed sinusoidal slew (2 deg at 85 deg, 5 deg at 60 deg;
the paper gives no amplitude for the RSO, so RSO-A takes its 85-deg choice, 2 deg), and the
gap-seeking law with its defaults (1 deg/s, 30 deg, replanning every 300 s).

Per case: coverage (and every standard score) against time, the hours to 90 % and 95 %
coverage (linear between scored times), the edge score and the F-score of the best of a few
reconstructed surfaces at fixed times, and the slew effort: the total angle between the
commanded attitudes of consecutive shots, read from the log (it includes the ~14 deg/h by which
even nadir pointing turns to follow a 25 h orbit).
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
# (preset, overrides, label, the paper's fixed slew amplitude [deg]).
TARGETS = {
    "asteroid-85": ("asteroid-lrf", ("orbit.inclination_deg=85",), "asteroid, 85 deg", 2.0),
    "asteroid-60": ("asteroid-lrf", ("orbit.inclination_deg=60",), "asteroid, 60 deg", 5.0),
    "rso-a": ("rso-a-lrf", (), "RSO-A, 85 deg", 2.0),
}
LAWS = ("nadir", "slew", "gaps")
LAW_STYLE = {"nadir": {"color": "0.45", "ls": "--"}, "slew": {"color": "tab:blue"},
             "gaps": {"color": "tab:red"}}
LEVELS = (0.90, 0.95)
# Issue 16's target: gap-seeking reaches 95 % at least this many times sooner than the fixed
# slew, with at most this multiple of its total slew angle.
TARGET_SPEEDUP, TARGET_EFFORT = 2.0, 1.5
TARGET_CASES = ("asteroid-60", "rso-a")

_HOURS_FIXED = (12, 24, 48, 72, 96, 120, 144, 192, 240, 288, 336, 384, 430)
_HOURS_GAPS = (4, 8, 12, 16, 20, 24, 30, 36, 48, 60, 72, 96)
PLAN = {
    # Fixed laws run 100 rotations (asteroid) or the paper's 129 h (RSO); gap-seeking 96 h.
    "full": {"hours": {"nadir": _HOURS_FIXED, "slew": _HOURS_FIXED, "gaps": _HOURS_GAPS},
             "rso_hours": {"nadir": (12, 24, 48, 72, 96, 129), "slew": (12, 24, 48, 72, 96, 129),
                           "gaps": _HOURS_GAPS},
             "surface_at": (24, 96), "methods": ("poisson", "ball-pivoting"),
             "overrides": (), "score": runner.CURVE_SCORE},
    "quick": {"hours": {law: (6, 12, 18, 24) for law in LAWS},
              "rso_hours": {law: (6, 12, 18, 24) for law in LAWS},
              "surface_at": (24,), "methods": ("poisson",),
              "overrides": ("target.subdivisions=4",),
              "score": {"n_truth_samples": 20_000, "coverage_points": 40_000}},
    "tiny": {"hours": {law: (0.5, 1) for law in LAWS},
             "rso_hours": {law: (0.5, 1) for law in LAWS}, "surface_at": (1,),
             "methods": ("poisson",), "overrides": ("target.subdivisions=3",),
             "score": {"n_truth_samples": 4000, "coverage_points": 8000}},
}


def _law_overrides(law: str, amplitude: float) -> list[str]:
    if law == "gaps":
        return ["attitude.mode=gaps"]
    return [f"slew.amplitude_deg={amplitude if law == 'slew' else 0.0:g}"]


def cases(size: str) -> dict[str, dict]:
    """Every (target, law): a scene run to its last scored time."""
    plan = PLAN[runner.check_size(size)]
    out = {}
    for target, (preset, overrides, label, amplitude) in TARGETS.items():
        is_rso = target.startswith("rso")
        for law in LAWS:
            hours = (plan["rso_hours"] if is_rso else plan["hours"])[law]
            extra = [o for o in plan["overrides"] if not (is_rso and o.startswith("target."))]
            out[f"{target} {law}"] = {
                "scene": preset,
                "overrides": [*overrides, *_law_overrides(law, amplitude),
                              f"time.duration={max(hours) * HOUR:g}", *extra],
                "seed": 0, "prefixes_s": [h * HOUR for h in hours],
                "surface_at_s": [h * HOUR for h in plan["surface_at"] if h <= max(hours)],
                "methods": list(plan["methods"]), "score_options": dict(plan["score"]),
                "tags": {"target": target, "law": law, "label": label,
                         "slew_deg": amplitude if law == "slew" else 0.0}}
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
    from recon.registration.ingest import ingest

    start = time.perf_counter()
    the_scene = sim.load_scene(scene, list(overrides))
    truth = (the_scene.vertices, the_scene.faces)
    with scratch.directory("recon-closed-loop-") as tmp:
        log_path = tmp / "run.h5"
        summary = sim.simulate(the_scene, log_path, seed=seed, progress=False, workers=1)
        with StrikeLog(log_path) as log:
            shots = log.shots()
        cloud = ingest(log_path)
    effort = slew_effort(shots.sensor_attitude)
    shot_time = cloud.attributes["time"]
    rows = []
    for t in prefixes_s:
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


def finish(records: dict, out_dir, size: str) -> dict:
    plan = PLAN[size]
    panels = []
    for target, (_, _, label, amplitude) in TARGETS.items():
        curves = []
        for law in LAWS:
            key = f"{target} {law}"
            if key not in records:
                continue
            x, coverage = runner.series(records, key, "coverage", x="hours")
            name = {"nadir": "nadir", "slew": "the paper's fixed slew",
                    "gaps": "gap-seeking (closed loop)"}[law]
            curves.append({"label": name, "x": x, "coverage": coverage,
                           "slew_deg": runner.series(records, key, "slew_deg", x="hours")[1],
                           "style": LAW_STYLE[law]})
        panels.append({"title": f"{label} (fixed slew ±{amplitude:g} deg)", "curves": curves})
    charts.coverage_and_effort(
        panels, out_dir / "coverage_vs_time.png", levels=LEVELS,
        title="Single-beam LRF: coverage and slew effort, nadir vs the paper's fixed slew vs "
              "closed-loop gap-seeking")
    rows = table(records, plan)
    runner.write_csv(rows, out_dir / "closed_loop.csv")
    claims = [_claim_target(records, target) for target in TARGETS]
    return {"claims": claims, "files": ["coverage_vs_time.png", "closed_loop.csv"],
            "extra": {"table": rows, "surface_methods": list(plan["methods"])}}


def _claim_target(records: Mapping, target: str) -> dict:
    label = TARGETS[target][2]
    text = (f"{label}: gap-seeking reaches 95 % coverage at least {TARGET_SPEEDUP:g}x sooner "
            f"than the paper's fixed slew, with at most {TARGET_EFFORT:g}x its total slew angle")
    gaps, slew = f"{target} gaps", f"{target} slew"
    figure = "issue 16 target" if target in TARGET_CASES else "(not in the target)"
    if gaps not in records or slew not in records:
        return claim(f"closed-loop-{target}", figure, text, "-", "no data", "not tested")
    h_gaps, h_slew = hours_to(records, gaps, 0.95), hours_to(records, slew, 0.95)
    slew_end = records[slew]["prefixes"][-1]["hours"]
    e_gaps = effort_at(records, gaps, h_gaps)
    # The fixed slew's effort up to its 95 % time; when it never gets there, up to its last
    # time, a lower bound of what it would need (so the comparison favours the fixed slew).
    e_slew = effort_at(records, slew, h_slew)
    if h_gaps is None:
        ours = (f"gap-seeking does not reach 95 % within {records[gaps]['prefixes'][-1]['hours']:g}"
                f" h (coverage {records[gaps]['prefixes'][-1]['coverage']:.3f})")
        return claim(f"closed-loop-{target}", figure, text, "-", ours, "not reproduced",
                     "gap-seeking never reached 95 %")
    speedup = (h_slew / h_gaps) if h_slew is not None else slew_end / h_gaps
    bound = "" if h_slew is not None else ">= "
    ours = (f"95 % after {h_gaps:.1f} h (gap-seeking) against "
            + (f"{h_slew:.1f} h" if h_slew is not None else
               f"not within {slew_end:g} h (coverage "
               f"{records[slew]['prefixes'][-1]['coverage']:.3f})")
            + f" (fixed slew): {bound}{speedup:.1f}x sooner; slew angle {e_gaps:,.0f} deg against "
            f"{bound}{e_slew:,.0f} deg ({e_gaps / e_slew:.2f}x{' at most' if bound else ''})")
    met = speedup >= TARGET_SPEEDUP and e_gaps <= TARGET_EFFORT * e_slew
    verdict = "reproduced" if met else ("partly" if speedup >= TARGET_SPEEDUP or
                                        e_gaps <= TARGET_EFFORT * e_slew else "not reproduced")
    return claim(f"closed-loop-{target}", figure, text,
                 f">= {TARGET_SPEEDUP:g}x sooner, <= {TARGET_EFFORT:g}x slew angle", ours,
                 verdict, "reproduced when both hold (a fixed slew that never reaches 95 % "
                          "counts at its last time, which understates the speed-up and its "
                          "effort); partly when one holds.")
