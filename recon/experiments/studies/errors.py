"""Error models: analogues of the paper's Tables 1 (ellipsoid) and 2 (RSO).

Three configurations (scanning LIDAR, cross and zigzag multi-beam LRFs), three error scenarios:

- no error;
- stochastic: the Jenoptik LIDAR's 1 m range and 0.2 deg azimuth and elevation errors (3 sigma),
  or for the fixed, well-characterised LRFs a 0.3 m range error and no angle error; on the
  ellipsoid also the paper's 2 m (3 sigma) error of the origin (our ``position_sigma3``: the
  recorded sensor position), which the paper states for the ellipsoid only;
- pulse dilation, paper Eq. (1): alpha = 0.0002, 30 sub-rays in a 0.6 mrad cone, alone (the
  paper: "Only the pulse dilation error model is considered"); N/A for the LIDAR, as in the
  paper.

Durations follow the paper's no-error runs: the ellipsoid's cross and zigzag 2 rotations (their
15,674 and 16,125 strikes), its LIDAR 15 rotations; on RSO-A the 1.2 x 1.2 deg cross and zigzag
129 h (the cross's 0.1576 "after 129 hours"), and the LIDAR (not described in the paper; our
16 x 16 grid over 6 x 6 deg) as long. Noisy scenarios run several seeds.
"""

from __future__ import annotations

import numpy as np

from recon.experiments import charts
from recon.experiments.studies import runner
from recon.experiments.studies.runner import claim, rotations

NAME = "errors"
TITLE = "Error models on the ellipsoid and RSO-A (paper Tables 1 and 2)"

HOUR = 3600.0
CONFIGS = ("LIDAR", "cross LRF", "zigzag LRF")
SCENARIOS = ("no error", "stochastic", "pulse dilation")
# Paper, Tables 1 and 2: edge scores by (configuration, scenario).
PAPER = {
    "ellipsoid": {("LIDAR", "stochastic"): 0.2984, ("LIDAR", "no error"): 0.0200,
                  ("cross LRF", "stochastic"): 0.1457, ("cross LRF", "pulse dilation"): 0.1503,
                  ("cross LRF", "no error"): 0.0789,
                  ("zigzag LRF", "stochastic"): 0.1445, ("zigzag LRF", "pulse dilation"): 0.1428,
                  ("zigzag LRF", "no error"): 0.0833},
    "rso-a": {("LIDAR", "stochastic"): 0.2984, ("LIDAR", "no error"): 0.1100,
              ("cross LRF", "stochastic"): 0.2457, ("cross LRF", "pulse dilation"): 0.2098,
              ("cross LRF", "no error"): 0.1576,
              ("zigzag LRF", "stochastic"): 0.2415, ("zigzag LRF", "pulse dilation"): 0.2272,
              ("zigzag LRF", "no error"): 0.1980},
}
TABLE_NAME = {"ellipsoid": "table1", "rso-a": "table2"}
TARGET_LABEL = {"ellipsoid": "ellipsoid (asteroid)", "rso-a": "RSO-A"}
# Scenes: (target, configuration) -> (preset, overrides).
SCENES = {
    ("ellipsoid", "LIDAR"): ("asteroid-lidar", ("sensor.resolution=[5, 5]",)),
    ("ellipsoid", "cross LRF"): ("asteroid-cross", ()),
    ("ellipsoid", "zigzag LRF"): ("asteroid-zigzag", ()),
    ("rso-a", "LIDAR"): ("rso-a-lrf", ("sensor.pattern=grid", "sensor.field_of_view_deg=[6.0, 6.0]",
                                       "sensor.resolution=[16, 16]", "sensor.range_max=5000.0")),
    ("rso-a", "cross LRF"): ("rso-a-cross", ()),
    ("rso-a", "zigzag LRF"): ("rso-a-cross", ("sensor.pattern=zigzag",)),
}
# Error overrides: (target, configuration kind, scenario) -> overrides.
LIDAR_STOCHASTIC = ("errors.range_sigma3=1.0", "errors.azimuth_sigma3_deg=0.2",
                    "errors.elevation_sigma3_deg=0.2")
LRF_STOCHASTIC = ("errors.range_sigma3=0.3",)
ORIGIN = ("errors.position_sigma3=2.0",)
DILATION = ("errors.dilation_alpha=0.0002",)
PLAN = {
    "full": {"duration": {("ellipsoid", "LIDAR"): rotations(15),
                          ("ellipsoid", "cross LRF"): rotations(2),
                          ("ellipsoid", "zigzag LRF"): rotations(2),
                          ("rso-a", "LIDAR"): rotations(30), ("rso-a", "cross LRF"): rotations(30),
                          ("rso-a", "zigzag LRF"): rotations(30)},
             "seeds": (0, 1, 2), "overrides": (), "score": runner.TABLE_SCORE},
    "quick": {"duration": {("ellipsoid", "LIDAR"): rotations(3),
                           ("ellipsoid", "cross LRF"): rotations(2),
                           ("ellipsoid", "zigzag LRF"): rotations(2),
                           ("rso-a", "LIDAR"): rotations(5), ("rso-a", "cross LRF"): rotations(10),
                           ("rso-a", "zigzag LRF"): rotations(10)},
              "seeds": (0,), "overrides": (), "score": runner.CURVE_SCORE},
    "tiny": {"duration": {("ellipsoid", "LIDAR"): rotations(0.25),
                          ("ellipsoid", "cross LRF"): rotations(0.5),
                          ("ellipsoid", "zigzag LRF"): rotations(0.5),
                          ("rso-a", "LIDAR"): 2 * HOUR, ("rso-a", "cross LRF"): rotations(1),
                          ("rso-a", "zigzag LRF"): rotations(1)},
             "seeds": (0,), "overrides": {"ellipsoid": ("target.subdivisions=3",)},
             "score": runner.TINY_SCORE},
}
# A noisy cloud "stays usable" when it keeps this fraction of its noise-free F-score.
USABLE_F_FRACTION = 0.8


def errors_for(target: str, config: str, scenario: str) -> tuple[str, ...] | None:
    """Error overrides of a scenario (None: not run, as in the paper)."""
    if scenario == "no error":
        return ()
    if scenario == "pulse dilation":
        return None if config == "LIDAR" else DILATION
    base = LIDAR_STOCHASTIC if config == "LIDAR" else LRF_STOCHASTIC
    return base + (ORIGIN if target == "ellipsoid" else ())


def _key(target: str, config: str, scenario: str, seed: int) -> str:
    return f"{target} | {config} | {scenario} | seed {seed}"


def cases(size: str) -> dict[str, dict]:
    plan = PLAN[runner.check_size(size)]
    out = {}
    for (target, config), (preset, scene_overrides) in SCENES.items():
        duration = plan["duration"][(target, config)]
        extra = plan["overrides"].get(target, ()) if isinstance(plan["overrides"], dict) else ()
        for scenario in SCENARIOS:
            errs = errors_for(target, config, scenario)
            if errs is None:
                continue
            for seed in (plan["seeds"] if errs else plan["seeds"][:1]):
                out[_key(target, config, scenario, seed)] = runner.scene_case(
                    preset, [*scene_overrides, f"time.duration={duration:g}", *errs, *extra],
                    prefixes_s=[duration], seed=seed, score_options=plan["score"],
                    tags={"target": target, "configuration": config, "scenario": scenario})
    out.update(_cause_cases(plan))
    return out


# Runs that show why two Table 1 claims differ (ours, not the paper's): the pulse-dilation alpha
# at which the ellipsoid's score rises as in the paper, and the ellipsoid's stochastic scenario
# without the 2 m origin error and at equal imaging time (15 rotations) for LIDAR and cross.
DILATION_ALPHAS = {"full": (0.0005, 0.001, 0.002), "quick": (0.001,), "tiny": (0.001,)}
CAUSE_ROTATIONS = {"full": 15.0, "quick": 3.0, "tiny": 0.25}


def _cause_cases(plan) -> dict[str, dict]:
    size = next(k for k, v in PLAN.items() if v is plan)
    extra = plan["overrides"].get("ellipsoid", ()) if isinstance(plan["overrides"], dict) else ()
    out = {}
    cross, cross_overrides = SCENES[("ellipsoid", "cross LRF")]
    duration = plan["duration"][("ellipsoid", "cross LRF")]
    for alpha in DILATION_ALPHAS[size]:
        out[f"ellipsoid | cross LRF | pulse dilation alpha {alpha:g} | seed 0"] = \
            runner.scene_case(cross, [*cross_overrides, f"time.duration={duration:g}",
                                      f"errors.dilation_alpha={alpha:g}", *extra],
                              prefixes_s=[duration], score_options=plan["score"],
                              tags={"check": "dilation alpha", "dilation_alpha": alpha})
    long = rotations(CAUSE_ROTATIONS[size])
    for config, preset, overrides, errs in (
            ("LIDAR", *SCENES[("ellipsoid", "LIDAR")], LIDAR_STOCHASTIC),
            ("cross LRF", cross, cross_overrides, ()),
            ("cross LRF", cross, cross_overrides, LRF_STOCHASTIC)):
        scenario = "stochastic without origin error" if errs else "no error"
        out[f"ellipsoid | {config} | {scenario}, {CAUSE_ROTATIONS[size]:g} rotations"] = \
            runner.scene_case(preset, [*overrides, f"time.duration={long:g}", *errs, *extra],
                              prefixes_s=[long], score_options=plan["score"],
                              tags={"check": "origin error", "configuration": config,
                                    "scenario": scenario})
    return out


def table(records: dict, target: str) -> list[dict]:
    """Mean and standard deviation over seeds of every score, per configuration and scenario."""
    rows = []
    for config in CONFIGS:
        for scenario in SCENARIOS:
            runs = [r["prefixes"][-1] for r in records.values()
                    if r["tags"] == {"target": target, "configuration": config,
                                     "scenario": scenario} and r["prefixes"][-1].get("scored")]
            if not runs:
                continue
            row = {"target": target, "configuration": config, "scenario": scenario,
                   "seeds": len(runs), "paper_edge_score": PAPER[target].get((config, scenario)),
                   "strikes": int(np.mean([p["n_points"] for p in runs]))}
            for metric in (*(m for m, _, _ in charts.METRICS), "false_edge_rate",
                           "missed_edge_rate", "precision", "recall", "accuracy_mean_m"):
                values = np.array([np.nan if p.get(metric) is None else p[metric]
                                   for p in runs], dtype=float)
                row[metric] = float(np.mean(values))
                row[f"{metric}_std"] = float(np.std(values))
            rows.append(row)
    return rows


def finish(records: dict, out_dir, size: str) -> dict:
    files, tables = [], {}
    for target in ("ellipsoid", "rso-a"):
        rows = table(records, target)
        tables[target] = rows
        if not rows:
            continue
        name = TABLE_NAME[target]
        runner.write_csv(rows, out_dir / f"{name}.csv")
        values = {(m, r["configuration"], r["scenario"]): r[m]
                  for r in rows for m, _, _ in charts.METRICS}
        errs = {(m, r["configuration"], r["scenario"]): r[f"{m}_std"]
                for r in rows for m, _, _ in charts.METRICS}
        seeds = max(r["seeds"] for r in rows)
        charts.grouped_bars(
            CONFIGS, SCENARIOS, values, out_dir / f"{name}.png", errors=errs,
            paper=PAPER[target],
            title=f"{TARGET_LABEL[target]}: scores under the error models (paper Table "
                  f"{name[-1]})",
            note=f"bars: mean over {seeds} seed(s) of the noisy scenarios, error bars: standard "
                 "deviation; diamonds: the paper's edge scores")
        files += [f"{name}.csv", f"{name}.png"]
    dilation = sorted(((r["tags"]["dilation_alpha"], r["prefixes"][-1]) for r in records.values()
                       if r["tags"].get("check") == "dilation alpha"
                       and r["prefixes"][-1].get("scored")), key=lambda q: q[0])
    origin = {(r["tags"]["configuration"], r["tags"]["scenario"]): r["prefixes"][-1]
              for r in records.values() if r["tags"].get("check") == "origin error"
              and r["prefixes"][-1].get("scored")}
    claims = [_claim_increase(tables["ellipsoid"]), _claim_dilation_scale(tables, dilation),
              _claim_lidar_worst(tables), _claim_lidar_worst_cause(origin),
              _claim_rso_order(tables["rso-a"]), _claim_usable(tables)]
    return {"claims": claims, "files": files,
            "extra": {"tables": tables,
                      "dilation_alpha": [{"alpha": a, **_scores(p)} for a, p in dilation],
                      "without_origin_error": [{"configuration": c, "scenario": s_, **_scores(p)}
                                               for (c, s_), p in origin.items()]}}


def _scores(prefix: dict) -> dict:
    return {k: prefix.get(k) for k in ("rotations", "n_points", "edge_score", "false_edge_rate",
                                       "missed_edge_rate", "coverage", "fscore")}


def _claim_dilation_scale(tables, dilation) -> dict:
    text = ("(Our check.) At what alpha does pulse dilation raise the ellipsoid's edge score as "
            "it does in the paper (0.0789 -> 0.1503 for the cross)?")
    base = _value(tables["ellipsoid"], "cross LRF", "no error")
    preset = _value(tables["ellipsoid"], "cross LRF", "pulse dilation")
    if base is None or not dilation:
        return claim("errors-dilation-scale", "Table 1", text, "-", "no data", "not tested")
    runs = [(0.0002, {"edge_score": preset}), *dilation]  # the presets' alpha first
    rises = [(a, p["edge_score"] - base) for a, p in runs if p["edge_score"] is not None]
    ours = ("cross LRF edge score minus its no-error score, by alpha: "
            + ", ".join(f"{a:g}: {d:+.4f} (3-sigma {a * 750:.2f} m x tan(theta) at 750 m)"
                        for a, d in rises))
    within = [d for a, d in rises if a * 750 <= 1.0]  # the paper: 3 sigma "less than 1 m"
    verdict = ("reproduced" if within and max(within) > 0.01 else
               "partly" if any(d > 0.01 for _, d in rises) else "not reproduced")
    return claim("errors-dilation-scale", "Table 1", text,
                 "alpha = 0.0002 gives a 3-sigma error below 1 m", ours, verdict,
                 "reproduced when some alpha whose 3-sigma error at 750 m and 45 deg incidence "
                 "stays within the paper's 1 m raises the edge score by more than 0.01; partly "
                 "when only a larger alpha does.")


def _claim_lidar_worst_cause(origin) -> dict:
    text = ("(Our check.) Without the 2 m origin error and at equal imaging time, does the "
            "LIDAR with its stochastic errors score worse than the cross LRF with its own?")
    lidar = origin.get(("LIDAR", "stochastic without origin error"))
    cross = origin.get(("cross LRF", "stochastic without origin error"))
    clean = origin.get(("cross LRF", "no error"))
    if lidar is None or cross is None:
        return claim("errors-lidar-worst-cause", "Tables 1, 2", text, "-", "no data",
                     "not tested")
    ours = "; ".join(f"{name} after {p['rotations']:g} rotations: edge {p['edge_score']:.4f} "
                     f"(false-edge rate {p['false_edge_rate']:.3f}, missed "
                     f"{p['missed_edge_rate']:.3f})"
                     for name, p in (("LIDAR, Jenoptik errors", lidar),
                                     ("cross LRF, 0.3 m range error", cross),
                                     ("cross LRF, no error", clean)) if p is not None)
    verdict = "reproduced" if lidar["edge_score"] > cross["edge_score"] else "not reproduced"
    return claim("errors-lidar-worst-cause", "Tables 1, 2", text,
                 "LIDAR stochastic 0.2984 worst", ours, verdict,
                 "reproduced when the LIDAR's edge score exceeds the cross LRF's once both run "
                 "equally long without the origin error.")


def _value(rows, config, scenario, metric="edge_score"):
    row = next((r for r in rows if r["configuration"] == config and r["scenario"] == scenario),
               None)
    return None if row is None else row[metric]


def _claim_from_parts(cid: str, figure: str, text: str, parts: list[str], verdict: str, *,
                      paper: str, rule: str, paper_without_data: str = "-") -> dict:
    """A claim whose evidence is one sentence per table or configuration.

    Parameters
    ----------
    cid, figure, text : str
        As for ``runner.claim``.
    parts : list of str
        The evidence, joined with ``"; "`` into our numbers; none: the claim is not tested.
    verdict : str
        Decided on the evidence by ``rule`` (ignored when ``parts`` is empty).
    paper : str
        The paper's numbers.
    rule : str
        How ``verdict`` was decided.
    paper_without_data : str
        The paper's numbers as stated when there is no evidence.

    Returns
    -------
    dict
        ``runner.claim``'s record.
    """
    if not parts:
        return claim(cid, figure, text, paper_without_data, "no data", "not tested")
    return claim(cid, figure, text, paper, "; ".join(parts), verdict, rule)


def _claim_increase(rows) -> dict:
    text = "Including the error models increases the score of the ellipsoid clouds (Table 1)."
    pairs = []
    for config in CONFIGS:
        base = _value(rows, config, "no error")
        for scenario in SCENARIOS[1:]:
            noisy = _value(rows, config, scenario)
            if base is not None and noisy is not None:
                pairs.append((config, scenario, base, noisy))
    if not pairs:
        return claim("errors-increase", "Table 1", text, "-", "no data", "not tested")
    ours = "; ".join(f"{c} {s}: {n:.4f} vs {b:.4f}" for c, s, b, n in pairs)
    up = [n > b for _, _, b, n in pairs]
    verdict = "reproduced" if all(up) else "partly" if any(up) else "not reproduced"
    return claim("errors-increase", "Table 1", text,
                 "LIDAR 0.0200 -> 0.2984; cross 0.0789 -> 0.1457 / 0.1503; zigzag 0.0833 -> "
                 "0.1445 / 0.1428", "edge score with errors vs without: " + ours, verdict,
                 "reproduced when every error scenario raises the edge score of every "
                 "configuration; partly when some do.")


def _claim_lidar_worst(tables) -> dict:
    text = "The LIDAR with its stochastic errors scores worst (0.2984) in both tables."
    parts, hits = [], []
    for target, rows in tables.items():
        if not rows:
            continue
        worst = max(rows, key=lambda r: r["edge_score"])
        hits.append(worst["configuration"] == "LIDAR" and worst["scenario"] == "stochastic")
        parts.append(f"{TARGET_LABEL[target]}: worst is {worst['configuration']} "
                     f"{worst['scenario']} ({worst['edge_score']:.4f})")
    return _claim_from_parts(
        "errors-lidar-worst", "Tables 1, 2", text, parts,
        "reproduced" if all(hits) else "partly" if any(hits) else "not reproduced",
        paper="LIDAR stochastic 0.2984 in both", paper_without_data="0.2984",
        rule="reproduced when the LIDAR's stochastic scenario has the highest mean edge score "
             "in both tables; partly in one.")


def _claim_rso_order(rows) -> dict:
    text = ("On RSO-A, no error < pulse dilation < stochastic for both multi-beam LRFs "
            "(Table 2).")
    parts, ordered, base_best = [], [], []
    for config in ("cross LRF", "zigzag LRF"):
        v = [_value(rows, config, s) for s in SCENARIOS]
        if None in v:
            continue
        ordered.append(v[0] < v[2] < v[1])
        base_best.append(v[0] < min(v[1], v[2]))
        parts.append(f"{config}: none {v[0]:.4f}, dilation {v[2]:.4f}, stochastic {v[1]:.4f}")
    return _claim_from_parts(
        "errors-rso-order", "Table 2", text, parts,
        "reproduced" if all(ordered) else "partly" if any(ordered) or all(base_best)
        else "not reproduced",
        paper="cross 0.1576 < 0.2098 < 0.2457; zigzag 0.1980 < 0.2272 < 0.2415",
        rule="reproduced when both LRFs show the full ordering; partly when one does, or when "
             "both at least score best without error.")


def _claim_usable(tables) -> dict:
    text = ("The poor edge score of noisy clouds does not indicate poor point-cloud quality: "
            "they remain usable (Conclusions).")
    parts, usable = [], []
    for target, rows in tables.items():
        for config in CONFIGS:
            base = _value(rows, config, "no error", "fscore")
            for scenario in SCENARIOS[1:]:
                f = _value(rows, config, scenario, "fscore")
                if base is None or f is None or not base > 0:
                    continue
                keep = f / base
                usable.append(keep >= USABLE_F_FRACTION)
                parts.append(f"{TARGET_LABEL[target]} {config} {scenario}: F {f:.3f} "
                             f"({keep:.0%} of {base:.3f})")
    if not parts:
        return claim("errors-usable", "Conclusions", text, "-", "no data", "not tested")
    share = float(np.mean(usable))
    verdict = "reproduced" if share == 1 else "partly" if share >= 0.5 else "not reproduced"
    return claim("errors-usable", "Conclusions", text, "stated, not measured",
                 "; ".join(parts), verdict,
                 f"usable = keeps at least {USABLE_F_FRACTION:.0%} of the noise-free cloud's "
                 "F-score at tau (1 % of the diagonal); reproduced when all noisy clouds do, "
                 "partly when at least half do. The methods study tests the surfaces.")
