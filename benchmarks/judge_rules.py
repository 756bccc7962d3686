"""Offline harness of ``-m auto``'s choice rule and of the truth-free estimate, on a finished suite.

    python benchmarks/judge_rules.py collect --suite benchmarks/out/suite --work /tmp/judge
    python benchmarks/judge_rules.py misses  --suite benchmarks/out/suite --work /tmp/judge
    python benchmarks/judge_rules.py openings --suite benchmarks/out/suite --work /tmp/judge
    python benchmarks/judge_rules.py rules   --suite benchmarks/out/suite --work /tmp/judge
    python benchmarks/judge_rules.py evidence --suite benchmarks/out/suite --work /tmp/judge
    python benchmarks/judge_rules.py estimate --suite benchmarks/out/suite --work /tmp/judge

The auto suite (``benchmarks/suite.py``) leaves, per cloud, every compare run's true scores
(``results.jsonl``), its mesh (``meshes/``) and the simulated strike log (``logs/``). This
script reads them (never writes there) so that a choice rule or an estimate can be tried in
seconds instead of a suite run:

- ``collect``: per cloud, ``recon.surfaces.auto.choose`` fits a fixed, wide candidate set
  (``candidate_runs``: the ladder and a few grid runs of the compare; on a ``NATURAL`` cloud
  also the completion auto fits there, ``auto.NATURAL_COMPLETION``) on the K folds and keeps, per
  candidate, the held-out costs of every tested strike, their blocks, the per-strike arrays of
  its held-out checks (``PER_STRIKE``: ``rules --statistic`` replays other statistics from
  them; among them the size of the opening of the fold's surface each missed held-out beam
  passed, ``opening_of``) and the per-candidate figures (``WORK/folds/CLOUD.npz`` and
  ``.json``);
- ``misses``: per cloud, the log's missed beams as auto draws them and each collected
  candidate's fraction of them cut on the compare's mesh (``WORK/misses``), for
  ``rules --miss-rate``;
- ``openings``: per cloud and collected candidate, which missed held-out beams passed a crack
  of the compare's mesh of the run (``judge.RING_RAYS``; ``WORK/openings``), for ``rules
  --statistic closest-cracks``;
- ``rules``: replays ``auto.select`` (the paired band, the hole test over the ``n_checked``
  strikes, the carved twins, the smallest model, the band's floor in metres on a log without
  range noise, ``--metric-floor``) and the ladder's stop on those figures,
  restricted to the ladder, and compares the choice with the truth (a carved choice by
  ``carved_truth``: the compare's mesh of its run carved as auto carves it, scored): within
  ``F_TOLERANCE`` of the best F-score and ``CHAMFER_TOLERANCE`` of the best Chamfer of all
  compare runs, not below the median run;
  the modelled time counts the collection's folds (``collect --holdout 0.3333``: 3 folds);
  the ``NATURAL`` clouds are told ``target_kind="natural"`` (``--no-prior``: every cloud
  "unknown"): the natural prior, and the completion where auto fits it (``auto.completed``;
  a collection without it replays no completion); ``--statistic``, ``--band``,
  ``--miss-rate``, ``--holes-first``, ``--holes-one-count``, ``--extra``, ``--weights area``
  (each held-out strike weighed by the area it stands for, ``strike_weights``) and
  ``--floor-admits`` (which candidates the band's floor lets in stay there,
  ``floor_admitting``) replay rules that are not auto's;
- ``evidence``: truth-free evidence beside the held-out statistic, measured on the compare's
  meshes (fitted on all strikes): the beams a candidate cuts or leaves in holes (collected),
  its area beyond the strikes' reach (where no strike constrains it) and its distance to the
  other candidates (their consensus, everywhere and where no strike is); each is tried as the
  choice among the candidates within ``EVIDENCE_BANDS`` paired standard errors of the best,
  against the truth as ``rules``;
- ``estimate``: ``recon.surfaces.estimate.estimate`` on every compare mesh of every cloud of the
  suite (in-sample, as the suite calls it; ``--per-cloud``: only the runs ``--labels`` names),
  against its true Chamfer: Spearman over all runs and within each cloud, and the band's
  coverage and width (high / low) for auto's choice in the suite, estimated as ``recon
  reconstruct -m auto`` reports it, with the chosen candidate's held-out residuals
  (``--heldout`` fits auto's ladder once per cloud to collect them, in ``WORK/heldout``).

``collect``, ``misses``, ``openings``, ``rules`` and ``evidence`` read the suite's tuning
clouds only; ``--held-out`` adds its held-out ones, for after their evaluation.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from contextlib import contextmanager
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import suite as suite_clouds  # noqa: E402  (the suite's clouds, beside this script)

F_TOLERANCE, CHAMFER_TOLERANCE = 0.05, 0.10
# The ladder (recon.surfaces.auto.LADDER) and grid runs that the truth finds best on some suite
# clouds, by the compare's labels: the rule may be tried on any subset without refitting.
EXTRA = ("visibility beta=0.1", "poisson depth=7", "planes threshold=2", "apss filter_scale=4")


def records(suite: Path, cloud: str) -> list[dict]:
    """The compare's successful, scored runs of ``cloud``."""
    rows = [json.loads(line) for line in
            (suite / cloud / "results.jsonl").read_text().splitlines() if line.strip()]
    return [r for r in rows if r.get("status") == "ok" and r.get("chamfer_m") is not None]


# The clouds the rules were tuned on: the suite's tuning clouds (``suite.TUNING``). The held-out
# ones (``suite.HELD_OUT``) are read only with ``--held-out`` (``clouds_of``), once their
# evaluation is done and they are looked at.
TUNING = suite_clouds.TUNING
HELD_OUT = suite_clouds.HELD_OUT


# The clouds whose target a user would state as a natural body (``auto.choose``'s
# ``target_kind``): the suite's own statement of each cloud (``SuiteCloud.target_kind``).
NATURAL = tuple(name for name in suite_clouds.CLOUDS
                if suite_clouds.CLOUDS[name].target_kind == "natural")


def target_of(cloud: str, prior: bool = True) -> str:
    """The ``target`` auto is told for ``cloud`` (``"unknown"`` without ``prior``)."""
    return "natural" if prior and cloud in NATURAL else "unknown"


def clouds_of(suite: Path, names, held_out: bool = False) -> list[str]:
    """The tuning clouds (``TUNING``; with ``held_out`` also the held-out ones, ``HELD_OUT``)
    with results in ``suite``, restricted to ``names``."""
    return [c for c in TUNING + HELD_OUT * held_out if (suite / c / "results.jsonl").exists()
            and (not names or c in names)]


def collected(args) -> list[str]:
    """The clouds of ``clouds_of`` whose folds ``collect`` has kept in ``WORK/folds``."""
    return [c for c in clouds_of(args.suite, args.clouds, getattr(args, "held_out", False))
            if (args.work / "folds" / f"{c}.json").exists()]


def pending(args, folder: str, suffix: str):
    """The collected clouds whose ``WORK/FOLDER/CLOUD.SUFFIX`` is still to be measured (every
    one with ``--force``), each with that path and its collected auto record."""
    out = args.work / folder
    out.mkdir(parents=True, exist_ok=True)
    for cloud in collected(args):
        path = out / f"{cloud}.{suffix}"
        if args.force or not path.exists():
            yield cloud, path, json.loads((args.work / "folds" / f"{cloud}.json").read_text())[
                "auto"]


def load_cloud(suite: Path, cloud: str):
    from recon.registration.ingest import ingest

    return ingest(suite / "logs" / f"{cloud}.h5")


def candidate_runs(rows: list[dict]) -> list:
    """The ladder's runs and ``EXTRA``, bound with the compare's parameters where it ran them."""
    from recon.surfaces import auto
    from recon.surfaces.methods import bind

    runs = [run for level in auto.ladder() for run in level]
    keys = {run.key for run in runs}
    for r in rows:
        if r["label"] in EXTRA and r["key"] not in keys:
            runs.append(bind(r["method"], r["params"]))
            keys.add(r["key"])
    return runs


def collect(args) -> None:
    """``collect`` (module docstring): on a ``NATURAL`` cloud the completion auto fits after
    the ladder (``auto.complete_prior``) is fitted on the same folds by a second ``choose`` and
    joins the record, so that the coverage stays the one auto measures on the ladder's
    candidates (a closed completion would otherwise be its best closed candidate)."""
    from formats.errors import MethodFailed
    from recon.surfaces import auto
    from recon.surfaces.methods import bind

    out = args.work / "folds"
    out.mkdir(parents=True, exist_ok=True)
    for cloud in clouds_of(args.suite, args.clouds, getattr(args, "held_out", False)):
        if (out / f"{cloud}.json").exists() and not args.force:
            continue
        rows = records(args.suite, cloud)
        points = load_cloud(args.suite, cloud)
        start = time.perf_counter()
        beams = auto.misses_near(args.suite / "logs" / f"{cloud}.h5", points.points, seed=0)
        choices = []
        for runs in [candidate_runs(rows)] + [[bind(auto.NATURAL_COMPLETION)]] * (
                cloud in NATURAL):
            try:
                with recording_checks():
                    choices.append(auto.choose(
                        points.points, view_points=points.view_points,
                        uncertainty=points.attributes, candidates=runs, holdout=args.holdout,
                        seed=args.seed, n_workers=args.workers, misses=beams))
            except MethodFailed as exc:
                if not choices:   # the ladder itself: nothing to collect
                    raise
                # The completion failed on every fold (auto keeps it as a failed candidate):
                # the record replays no completion.
                print(f"{cloud}: no completion ({exc})", flush=True)
        elapsed = time.perf_counter() - start
        candidates = [c for choice in choices for c in choice.candidates]
        table = [c.to_dict() | {"key": c.key} for c in candidates]
        arrays = {f"cost/{c.key}": c.cost for c in candidates if c.cost is not None}
        arrays |= per_strike_arrays(candidates)
        folds = choices[0].folds
        block = np.concatenate([folds.block[folds.test(f)] for f in range(folds.k)])
        np.savez_compressed(out / f"{cloud}.npz", block=block, **arrays)
        (out / f"{cloud}.json").write_text(json.dumps(
            {"cloud": cloud, "seconds": elapsed, "auto": choices[0].to_dict() | {
                "candidates": table}}, indent=1, default=str))
        print(f"{cloud}: {len(table)} candidates on {folds.k} folds in {elapsed:.0f} s",
              flush=True)


# The per-strike arrays of a candidate's held-out checks (``judge.Check``) that ``collect``
# keeps beside its cost, for the statistics that are not functions of the cost alone (``crack``:
# the missed held-out beam passed a crack of the fold's surface, ``judge.check``'s own;
# ``opening``, the opening's size, ``opening_of``; ``front``, the beam met the surface before its
# strike, and ``cos``, the |cos| of its incidence there, ``beam_side``).
PER_STRIKE = ("distance", "tolerance", "sigma", "missed", "violated", "crack", "opening",
              "front", "cos")


@contextmanager
def recording_checks():
    """While active, every candidate ``auto.choose`` judges gets ``held_checks``: the
    ``judge.Check`` of each fold's tested strikes, folds in order, each with its ``opening``
    array (``opening_of`` at the context's ``miss_reach``) and its beam side (``beam_side``).
    Auto makes a fold's held-out check (``auto.held_out_check``) as the fold's fit arrives or
    when the run is judged, and ``auto.judge_candidate`` gathers them (``auto._held_checks``):
    each check is recorded where it is made, and the candidate keeps the list its judging
    gathered. ``per_strike_arrays`` keeps them only where their costs are the candidate's (so
    a change of that order is caught, not replayed wrongly)."""
    from dataclasses import dataclass

    from recon.surfaces import auto, judge

    @dataclass(frozen=True)
    class Recorded(judge.Check):
        opening: np.ndarray | None = None
        front: np.ndarray | None = None
        cos: np.ndarray | None = None

    gathered: list = []
    held_out_check, held_checks, judge_candidate = (auto.held_out_check, auto._held_checks,
                                                    auto.judge_candidate)

    def recorded_held_out_check(fold, caster, context):
        result = held_out_check(fold, caster, context)
        return Recorded(**vars(result),
                        opening=opening_of(fold.test, caster, result, context.miss_reach),
                        **beam_side(fold.test, caster))

    def recorded_held_checks(*args, **kwargs):
        result = held_checks(*args, **kwargs)
        gathered[:] = [result]
        return result

    def recorded_judge(*args, **kwargs):
        gathered.clear()
        candidate = judge_candidate(*args, **kwargs)
        candidate.held_checks = gathered[0] if gathered else []
        return candidate

    auto.held_out_check, auto._held_checks, auto.judge_candidate = (
        recorded_held_out_check, recorded_held_checks, recorded_judge)
    try:
        yield
    finally:
        auto.held_out_check, auto._held_checks, auto.judge_candidate = (
            held_out_check, held_checks, judge_candidate)


def beam_side(strikes, caster) -> dict[str, np.ndarray | None]:
    """Per strike: whether its beam meets ``caster``'s surface before the strike (``front``)
    and the |cos| of the beam's incidence there (``cos``; 1 for a miss); None without view
    points."""
    if strikes.view is None:
        return {"front": None, "cos": None}
    t_hit, beam_range, cos, _ = caster.beams(strikes.view, strikes.points)
    return {"front": t_hit < beam_range, "cos": cos}


# The ring radii, in miss_reach, at which ``opening_of`` sizes a missed beam's opening.
OPENING_SCALES = (0.25, 0.5, 1.0, 2.0, 4.0)


def opening_of(strikes, caster, result, radius: float) -> np.ndarray:
    """Per strike of ``result``: the smallest of ``OPENING_SCALES`` times ``radius`` [m] at
    which ``ring_share`` reaches ``RING_SHARE`` for a missed beam, in units of ``radius``
    (inf when none does; 0 for a beam that met the surface)."""
    from recon.surfaces import judge

    opening = np.zeros(len(result.missed))
    missed = np.flatnonzero(result.missed)
    if strikes.view is None or not len(missed):
        return opening
    opening[missed] = np.inf
    for scale in OPENING_SCALES[::-1]:
        share = judge.ring_share(caster, strikes.view[missed], strikes.points[missed],
                                 scale * radius, result.tolerance[missed] + scale * radius)
        opening[missed[share >= judge.RING_SHARE]] = scale
    return opening


def per_strike_arrays(candidates: list) -> dict[str, np.ndarray]:
    """``PER_STRIKE`` arrays of each scored candidate's held-out strikes, keyed
    ``NAME/KEY`` (``recording_checks``), for the candidates whose recorded costs are theirs."""
    out = {}
    for c in candidates:
        held = getattr(c, "held_checks", None)
        if c.cost is None or not held or not np.array_equal(
                np.concatenate([h.cost for h in held]), c.cost):
            continue
        out |= {f"{name}/{c.key}": np.concatenate([getattr(h, name) for h in held])
                for name in PER_STRIKE if getattr(held[0], name) is not None}
    return out


def closest_cost(per: dict[str, np.ndarray], where: np.ndarray) -> np.ndarray:
    """Each held-out strike's cost with, where ``where``, the beam's residual (or the cap of a
    beam cut or missed) replaced by the closest-point distance, capped at the tolerance, in the
    same recorded sigma: ``(min(distance, tolerance) / sigma)^2``."""
    closest = (np.minimum(per["distance"], per["tolerance"]) / per["sigma"]) ** 2
    return np.where(where, closest, per["cost"])


# Other held-out statistics ``rules --statistic`` may replay in place of the capped chi-square
# (each a function of a strike's cost, the capped squared distance in recorded sigmas, and the
# per-strike arrays ``collect`` keeps): the mean chi (L1, less led by the strikes at the cap),
# the chi-square capped at 3 and 5 sigma, the fraction of strikes at the cap; and the
# closest-point residual in place of the beam's for the beams that miss the fold's surface
# (``closest-missed``: a pass held out leaves a local surface a gap there that the surface
# refitted on all strikes does not have), for those and the beams cut before their strike
# (``closest-cut-missed``), or for every strike (``closest``: no ray in the statistic); for the
# missed beams that passed a crack, narrower than ``auto.miss_reach``, of the compare's mesh
# (``closest-cracks``, ``openings``) or of the fold's own surface (``closest-fold-cracks``,
# ``collect``); and with those, for every beam that meets the surface within tolerance
# (``closest-hits-fold-cracks``: the closest-point distance, as the truth's Chamfer measures,
# not the beam's residual that a grazing beam stretches) or only beyond its strike
# (``closest-behind-fold-cracks``: a surface met before the strike stays the beam's evidence).
STATISTICS = {"chi2": None, "chi": lambda c, p: np.sqrt(c),
              "cap9": lambda c, p: np.minimum(c, 9.0),
              "cap25": lambda c, p: np.minimum(c, 25.0),
              "capped": lambda c, p: (c >= 0.999 * c.max()).astype(float),
              "closest-missed": lambda c, p: closest_cost(p, p["missed"]),
              "closest-cut-missed": lambda c, p: closest_cost(p, p["missed"] | p["violated"]),
              "closest": lambda c, p: closest_cost(p, np.ones(len(c), dtype=bool)),
              "closest-cracks": lambda c, p: closest_cost(p, p["missed"] & p["crack"]),
              "closest-fold-cracks": lambda c, p: closest_cost(p, p["missed"] & p["crack"]),
              "closest-hits-fold-cracks": lambda c, p: closest_cost(
                  p, p["missed"] & p["crack"] | ~p["missed"] & ~p["violated"]),
              "closest-behind-fold-cracks": lambda c, p: closest_cost(
                  p, p["missed"] & p["crack"] | ~p["missed"] & ~p["violated"] & ~p["front"])}
# ``rules --opening S``: with ``closest-fold-cracks``, a crack is an opening of at most S times
# ``auto.miss_reach`` (one of ``OPENING_SCALES``; 1 as fixed before the replay).
OPENING = 1.0


def replayed_cost(statistic: str, cost: np.ndarray, arrays, key: str, name: str,
                  cracks=None) -> np.ndarray:
    """``STATISTICS[statistic]`` of the candidate ``key``'s held-out ``cost`` and its
    per-strike ``arrays`` (``collect``'s npz) and ``cracks`` (``openings``'s npz: a candidate
    without a compare mesh has none, and its missed beams stay holes); ``name`` names it in the
    error of a collection without the arrays a statistic needs."""
    per = {field: arrays[f"{field}/{key}"] for field in PER_STRIKE
           if f"{field}/{key}" in arrays} | {"cost": cost}
    if cracks is not None:
        per["crack"] = cracks[f"crack/{key}"] if f"crack/{key}" in cracks else \
            np.zeros(len(cost), dtype=bool)
    if statistic.endswith("fold-cracks"):
        if "opening" not in per:
            raise SystemExit(f"{name} was collected without the opening arrays --statistic "
                             f"{statistic} needs; collect it again (--force)")
        per["crack"] = per["missed"] & (per["opening"] <= OPENING)
    if statistic.startswith("closest") and len(per) == 1:
        raise SystemExit(f"{name} was collected without the per-strike arrays --statistic "
                         f"{statistic} needs; collect it again (--force)")
    return STATISTICS[statistic](cost, per)


def candidates_of(work: Path, cloud: str, extra: bool, statistic: str = "chi2",
                  suite: Path | None = None, weight: np.ndarray | None = None
                  ) -> tuple[list, np.ndarray, float, float, int]:
    """The collected candidates of ``cloud`` as ``auto.Candidate`` (on the ladder's levels; with
    ``extra``, the ``EXTRA`` runs join the level of their method's ladder run, else they are left
    out), the tested strikes' blocks, the coverage, tau [m] and the strikes their ``holes`` were
    counted over (``checked_count``). A ``span`` not collected (older collections) is measured,
    given ``suite``, on the compare's mesh of the run (fitted on all strikes, not fold 0's) for
    the natural prior's model. ``weight`` (k,): each tested strike's weight, mean 1
    (``strike_weights``; None: every strike 1): each candidate's cost is the statistic's times
    it (``weighted``), so the mean, the block means, the paired standard errors, the race and
    the floor (``beneath``) all weigh the strikes so."""
    from dataclasses import fields

    from recon.surfaces import auto, judge
    from recon.surfaces.methods import bind

    data = json.loads((work / "folds" / f"{cloud}.json").read_text())["auto"]
    arrays = np.load(work / "folds" / f"{cloud}.npz")
    cracks = None
    if statistic == "closest-cracks":
        path = work / "openings" / f"{cloud}.npz"
        if not path.exists():
            raise SystemExit(f"{cloud}: --statistic {statistic} needs the openings command first")
        cracks = np.load(path)
    names = {f.name for f in fields(auto.Candidate)} - {"run", "level", "heldout", "cost", "mesh"}
    level_of = _levels(extra)
    out = []
    for row in data["candidates"]:
        level = level_of(row)
        if level is None:
            continue
        candidate = auto.Candidate(bind(row["method"], row["params"]), level,
                                   **{k: row[k] for k in names if k in row})
        candidate.cost = arrays.get(f"cost/{row['key']}")
        if candidate.span is None and suite is not None and candidate.scored and \
                row["method"] == auto.NATURAL_MODEL:
            candidate.span = compare_span(suite, cloud, row["key"])
        if STATISTICS[statistic] is not None and candidate.cost is not None:
            candidate.cost = replayed_cost(statistic, candidate.cost, arrays, row["key"],
                                           f"{cloud}: {row['label']}", cracks)
            candidate.chi2, candidate.chi2_se = judge.block_mean_se(candidate.cost,
                                                                    arrays["block"])
        if weight is not None and candidate.cost is not None:
            candidate.cost = weighted(candidate.cost, weight)
            candidate.chi2, candidate.chi2_se = judge.block_mean_se(candidate.cost,
                                                                    arrays["block"])
        out.append(candidate)
    return (out, arrays["block"], data["coverage"], data["tau_m"],
            data.get("n_checked") or checked_count(work, suite, cloud))


def _levels(extra: bool):
    """The ladder level a collected candidate's row replays on (``candidates_of``): its run's
    (a carved twin's run's), the completion's after the ladder, an ``EXTRA`` run's method's
    with ``extra``, else None (left out)."""
    from recon.surfaces import auto

    levels = {run.key: depth for depth, level in enumerate(auto.ladder()) for run in level}
    method_level = {}
    for depth, level in enumerate(auto.ladder()):
        for run in level:
            method_level.setdefault(run.method, depth)

    def level_of(row: dict) -> int | None:
        level = levels.get(row["key"].removesuffix(" carved"))
        if level is not None:
            return level
        if row["method"] == auto.NATURAL_COMPLETION:
            return len(auto.LADDER)   # after the ladder, as auto fits it (``replay``)
        return method_level.get(row["method"], len(auto.LADDER) - 1) if extra else None

    return level_of


def with_misses(work: Path, cloud: str, candidates: list) -> int:
    """Set each candidate's ``misses_cut`` from ``misses``'s record of ``cloud`` (when it has
    one; else 0 missed beams: the step is skipped); returns the missed beams cast."""
    path = work / "misses" / f"{cloud}.json"
    if not path.exists():
        return 0
    data = json.loads(path.read_text())
    for c in candidates:
        c.misses_cut = data["cut"].get(c.run.key, 0.0 if c.scored else None)
    return data["n_misses"]


def free_space(candidates: list, n_misses: int, rate: float, ses: float) -> list:
    """The rule ``rules --miss-rate`` tries (not auto's): before the band, every scored
    candidate that cuts more missed beams than ``ses`` binomial standard errors above the larger
    of ``rate`` and the fewest any scored candidate cuts is left out (its level stays fitted,
    so the ladder's stop is unchanged when one remains)."""
    scored = [c for c in candidates if c.scored and c.misses_cut is not None]
    if not n_misses or not scored:
        return candidates
    reference = max(rate, min(c.misses_cut for c in scored))
    limit = reference + ses * np.sqrt(reference * (1 - reference) / n_misses)
    return [c for c in candidates if not (c.scored and (c.misses_cut or 0.0) > limit)]


def holes_first(candidates: list, n_checked: int) -> list:
    """The rule ``rules --holes-first`` tries (not auto's): before the band, every scored
    candidate leaving more strikes in holes than ``auto.HOLE_SES`` binomial standard errors
    above the larger of ``auto.HOLE_RATE`` and the fewest any scored candidate leaves is left
    out (``auto.hole_limit`` over all of them, not the band's), unless none would remain."""
    from recon.surfaces import auto

    scored = [c for c in candidates if c.scored]
    if not scored:
        return candidates
    limit = auto.hole_limit([c.holes for c in scored], n_checked)
    kept = [c for c in candidates if not (c.scored and c.holes > limit)]
    return kept if any(c.scored for c in kept) else candidates


def one_count_hole_limit(holes, n_checked: int) -> float:
    """The hole test's limit before it counted the error of both fractions (``rules
    --holes-one-count``; not auto's): ``auto.HOLE_SES`` binomial standard errors of one count
    above the larger of ``auto.HOLE_RATE`` and the band's fewest (``auto.hole_limit``'s
    arguments)."""
    from recon.surfaces import auto

    reference = max(auto.HOLE_RATE, min(holes))
    return reference + auto.HOLE_SES * np.sqrt(reference * (1.0 - reference) / max(n_checked, 1))


# ``rules --floor-admits``: which of the candidates step 3's floor lets into the band
# (``auto.band``'s ``floored``: beyond ``auto.BAND_SES`` paired standard errors of the best, their
# mean squared held-out residual within the floor of the best's) stay in it. ``method``: those
# of the best's method (a coarser setting of the same reconstruction, or a carved twin: the
# resolution the strikes cannot judge; auto's); ``race``: none (the floor keeps runs in the race
# only; its candidates never win).
FLOOR_ADMITS = ("method", "race")


def floor_admitting(admits: str):
    """``auto.band`` with the floor's candidates kept as ``admits`` says (``FLOOR_ADMITS``);
    the same arguments and returns (the band, those of it the floor let in)."""
    from recon.surfaces import auto

    if admits not in FLOOR_ADMITS:
        raise ValueError(f"admits must be one of {FLOOR_ADMITS}, got {admits!r}")
    band = auto.band
    if admits == "method":
        return band

    def unfloored(candidates, scored, best, gaps, scale, floor):
        eligible, floored = band(candidates, scored, best, gaps, scale, floor)
        return tuple(i for i in eligible if i not in floored), ()

    return unfloored


def checked_count(work: Path, suite: Path | None, cloud: str) -> int:
    """The strikes ``auto.choose`` counts ``violated`` and ``holes`` over on ``cloud`` (a
    seeded subsample of ``judge.MAX_CHECKED``), for collections older than ``n_checked`` in
    ``auto.AutoChoice.to_dict``: read from the cloud once, kept in ``WORK/n_checked.json``."""
    from recon.surfaces.judge import MAX_CHECKED

    path = work / "n_checked.json"
    known = json.loads(path.read_text()) if path.exists() else {}
    if cloud not in known:
        if suite is None:
            raise ValueError(f"{cloud}: the collection has no n_checked; pass the suite")
        known[cloud] = min(len(load_cloud(suite, cloud).points), MAX_CHECKED)
        path.write_text(json.dumps(known, indent=1))
    return known[cloud]


def compare_span(suite: Path, cloud: str, key: str) -> float | None:
    """``auto.span`` of the compare's mesh of run ``key`` on ``cloud`` (None without one)."""
    from formats.mesh_io import read_mesh
    from recon.surfaces import auto

    row = next((r for r in records(suite, cloud) if r["key"] == key and r.get("mesh")), None)
    if row is None:
        return None
    mesh = read_mesh(suite / cloud / row["mesh"])
    return auto.span(mesh.vertices, load_cloud(suite, cloud).points)


def replay(candidates: list, block: np.ndarray, coverage: float, tau: float, n_checked: int,
           target: str = "unknown", scale: np.ndarray | None = None, floor: float = 0.0):
    """``auto``'s ladder and choice on collected candidates: the levels in order, stopping as
    ``auto.climb`` does, and the natural-body prior and its completion for a ``"natural"``
    target (``auto.complete_prior``: the completion, collected after the ladder's levels, joins
    the fitted ones where auto fits it); returns the chosen candidate and the fitted ones.
    ``scale``, ``floor``: the band's floor in metres (``floor_of``; 0: none)."""
    from recon.surfaces import auto

    completion = [c for c in candidates if c.level == len(auto.LADDER)]
    candidates = [c for c in candidates if c.level < len(auto.LADDER)]
    depth_of = sorted({c.level for c in candidates})
    fitted: list = []
    for n, depth in enumerate(depth_of):
        before = auto._best(fitted)
        fitted += [c for c in candidates if c.level == depth]
        if n + 1 >= auto.ALWAYS_LEVELS and n + 1 < len(depth_of) and \
                auto._stops(fitted, before, depth):
            break
    selection = auto.select(fitted, block, n_checked, scale=scale, floor=floor)
    if target == "natural":
        selection = auto.natural_prior(fitted, selection, coverage, tau)
        if completion and (selection.prior or coverage < auto.NATURAL_COVERAGE):
            fitted = fitted + completion
            selection = auto.completed(fitted, selection, len(fitted) - len(completion), block)
    return fitted[selection.chosen], fitted


def floor_of(work: Path, cloud: str) -> tuple[np.ndarray | None, float]:
    """Step 3's floor on ``cloud`` as ``auto.choose`` sets it (``auto.metric_floor`` of the
    collection's tau and noise length, at ``auto.METRIC_FLOOR``, which ``rules --metric-floor``
    sets) and each tested strike's squared sigma [m^2] (``judge.sigma_along``: the same for
    every candidate, read from any candidate's collected ``sigma``; None and 0 in a collection
    without them)."""
    from recon.surfaces import auto

    data = json.loads((work / "folds" / f"{cloud}.json").read_text())["auto"]
    arrays = np.load(work / "folds" / f"{cloud}.npz")
    key = next((k for k in arrays.files if k.startswith("sigma/")), None)
    if key is None:
        return None, 0.0
    return arrays[key] ** 2, auto.metric_floor(data["tau_m"], data["noise_m"])


# ``rules --weights area``: each held-out strike's cost weighs by the area of the surface it
# stands for, one over the strikes within the support reach around it (the truth-free
# estimate's ``recon.surfaces.estimate._area_weights``, over all the cloud's strikes, at the
# collection's ``miss_reach_m``: the same max(tau, SIGMAS noise, COVERAGE_SPACINGS spacing)),
# instead of 1 each: the truth's Chamfer and F-score are means over its area, the held-out
# statistic a mean over strikes, which a densely struck region (a track crossing, the nadir)
# outweighs a sparsely struck one (a grazing face, an edge) in. ``--weight-cap C``: no strike
# weighs more than C times the tested strikes' median weight (a lone strike, or one at an
# edge of the strikes, otherwise weighs as much as a whole patch).


def strike_weights(points: np.ndarray, tested: np.ndarray, reach: float,
                   cap: float | None = None) -> np.ndarray:
    """The weight of each tested strike for ``rules --weights area``.

    Parameters
    ----------
    points : (n, 3) float64, metres, body frame
        All the cloud's strikes (the density is counted over all of them).
    tested : (k,) int64
        Indices into ``points`` of the held-out strikes, in the order of the costs.
    reach : float, metres
        The support reach the strikes are counted within.
    cap : float, optional
        The largest weight, in multiples of the tested strikes' median weight (None: no cap).

    Returns
    -------
    (k,) float64
        One over the strikes within ``reach`` of each tested strike (``estimate._area_weights``),
        capped, scaled to mean 1 (a uniformly struck cloud: every weight 1).
    """
    from recon.surfaces.estimate import _area_weights

    return capped(_area_weights(np.asarray(points, dtype=float), reach)[np.asarray(tested)],
                  cap)


def capped(weight: np.ndarray, cap: float | None) -> np.ndarray:
    """``weight`` (k,) > 0 capped at ``cap`` times its median (None: not capped), scaled to
    mean 1 (``strike_weights``)."""
    if cap is not None and not cap >= 1.0:
        raise ValueError(f"cap must be at least 1 (the median weight), got {cap}")
    weight = weight / np.median(weight)
    if cap is not None:
        weight = np.minimum(weight, cap)
    return weight / weight.mean()


def weighted(cost: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Per-strike ``cost`` (k,) times ``weight`` (k,), mean 1 (``strike_weights``): its plain
    mean is the weighted mean of ``cost``, the difference of two candidates' the weighted
    difference, so auto's means, paired standard errors (``judge.block_mean_se``, as
    ``estimate._error_band`` takes its weighted one) and race read it unchanged."""
    if cost.shape != weight.shape:
        raise ValueError(f"weight must match the costs {cost.shape}, got {weight.shape}")
    return cost * weight


def area_weights_of(args, cloud: str) -> np.ndarray | None:
    """``strike_weights`` of ``cloud``'s collected tested strikes at ``args.weight_cap``
    (None with ``--weights strikes``): the folds rebuilt as ``collect`` dealt them
    (``tested_order``, checked against the collected blocks); the uncapped weights are kept
    in ``WORK/weights/CLOUD.npz`` with the seed they were dealt by (``capped`` divides by the
    median first, so capping them later is capping the raw weights)."""
    if args.weights == "strikes":
        return None
    path = args.work / "weights" / f"{cloud}.npz"
    if not path.exists() or int(np.load(path).get("seed", -1)) != args.seed:
        data = json.loads((args.work / "folds" / f"{cloud}.json").read_text())["auto"]
        block = np.load(args.work / "folds" / f"{cloud}.npz")["block"]
        points, folds, order = tested_order(args.suite, cloud, 1.0 / data["folds"]["k"],
                                            args.seed)
        if not np.array_equal(folds.block[order], block):
            raise SystemExit(f"{cloud}: the folds rebuilt differ from the collected ones "
                             "(wrong --seed?)")
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, reach=data["miss_reach_m"], seed=args.seed,
                            weight=strike_weights(points.points, order, data["miss_reach_m"]))
    return capped(np.load(path)["weight"], args.weight_cap)


def fold_of(block: np.ndarray, folds: dict, seed: int) -> np.ndarray:
    """The fold of each collected tested strike, from its ``block`` (k,), the collection's
    ``folds`` record and its seed (the blocks' deal, ``judge.pass_folds``)."""
    k, n_blocks = folds["k"], folds["n_blocks"]
    rng = np.random.default_rng(seed)
    deal = np.concatenate([rng.permutation(k) for _ in range(-(-n_blocks // k))])[:n_blocks]
    fold = deal[block]
    if np.any(np.diff(fold) < 0):
        raise SystemExit("the collection's tested strikes are not in fold order: wrong --seed?")
    return fold


def race(candidates: list, block: np.ndarray, folds: dict, seed: int,
         scale: np.ndarray | None = None, floor: float = 0.0) -> tuple[list, list]:
    """``auto``'s race (``auto.outpaced``, stage by stage of ``auto.RACE_STAGES``) replayed on
    collected candidates: the levels fitted together (``auto.ALWAYS_LEVELS``) race at once,
    each later level against the runs left before it; ``folds``: the collection's ``folds``
    record, ``seed`` its seed (``fold_of``); ``scale``, ``floor``: step 3's floor
    (``floor_of``). Returns the candidates left (a run that leaves
    takes its carved twin with it; in its place the run, unscored, with the status "outpaced"
    and the folds it was fitted on) and the runs that left. The completion (after the ladder's
    levels, ``replay``) is fitted alone on every fold, as auto fits it: it does not race."""
    from recon.surfaces import auto

    fold = fold_of(block, folds, seed)
    kept, gone = [], []
    for group in race_groups(candidates):
        members = [c for c in candidates if c.level in group]
        after = race_stages([c for c in kept if c.scored and not c.carved], members, fold,
                            block, scale, floor)
        gone += [c for c in members if c.run.key in after and not c.carved]
        kept += [c if c.run.key not in after else
                 auto.Candidate(c.run, c.level, "outpaced", folds=after[c.run.key])
                 for c in members if c.run.key not in after or not c.carved]
    return kept + [c for c in candidates if c.level == len(auto.LADDER)], gone


def race_groups(candidates: list) -> list[list[int]]:
    """The ladder's levels of ``candidates`` that race together (``race``): those fitted at
    once (``auto.ALWAYS_LEVELS``), then each later level alone."""
    from recon.surfaces import auto

    depths = sorted({c.level for c in candidates if c.level < len(auto.LADDER)})
    return [[d for d in depths if d < auto.ALWAYS_LEVELS]] + [
        [d] for d in depths if d >= auto.ALWAYS_LEVELS]


def race_stages(before: list, members: list, fold: np.ndarray, block: np.ndarray,
                scale: np.ndarray | None = None, floor: float = 0.0) -> dict[str, int]:
    """The runs among ``members`` that leave at a stage of ``auto.RACE_STAGES`` ((folds,
    standard errors) pairs, those with fewer folds than the collection's; ``race_group`` at
    each against the runs still in and those left ``before``; ``fold``: each tested strike's
    fold), by key, with the folds of that stage."""
    from recon.surfaces import auto

    after: dict[str, int] = {}
    for n, ses in auto.RACE_STAGES:
        if n > fold.max():   # as many folds as the collection's: no stage
            break
        out = race_group(before, [c for c in members if c.run.key not in after], fold < n,
                         block, ses, None if scale is None else scale[fold < n], floor)
        after |= dict.fromkeys(out, n)
    return after


def race_group(before: list, members: list, first: np.ndarray, block: np.ndarray,
               ses: float, scale: np.ndarray | None = None, floor: float = 0.0) -> set:
    """The keys of the runs among ``members`` (one race: levels fitted together) that
    ``auto.outpaced`` takes out at ``ses`` standard errors against each other and the runs
    left ``before``; ``first``: the tested strikes of the stage's folds; ``scale`` (theirs)
    and ``floor``: step 3's floor (``floor_of``)."""
    from recon.surfaces import auto

    pool = before + [c for c in members if not c.carved]
    racing = [False] * len(before) + [c.level >= auto.RACE_LEVEL for c in pool[len(before):]]
    partial = [c.cost[first] if c.scored else None for c in pool]
    closed = [bool(c.closed) for c in pool]
    leaves = auto.outpaced(partial, block[first], racing, closed, ses=ses, scale=scale,
                           floor=floor, methods=[c.run.method for c in pool])
    return {c.run.key for c, left in zip(pool, leaves, strict=True) if left is not None}


def raced(args, cloud: str, candidates: list, block: np.ndarray, replayed,
          scale: np.ndarray | None = None, floor: float = 0.0) -> list:
    """``race`` on ``cloud``'s candidates, printing the runs that left before the ladder's stop
    and whether the best closed candidate (the coverage's, not replayed) moved; ``replayed``:
    ``replay`` with the cloud's other arguments."""
    whole = best_closed(replayed(candidates)[1])
    candidates, _ = race(candidates, block, json.loads(
        (args.work / "folds" / f"{cloud}.json").read_text())["auto"]["folds"], args.seed,
        scale, floor)
    fitted = replayed(candidates)[1]
    left = ", ".join(c.label for c in fitted if c.status == "outpaced")
    moved = "" if best_closed(fitted) == whole else \
        f"; best closed {whole} -> {best_closed(fitted)} (coverage not replayed)"
    print(f"{cloud:30} raced out: {left or '-'}{moved}")
    return candidates


def best_closed(candidates: list) -> str | None:
    """The label of the scored closed candidate of lowest chi-square (auto's coverage)."""
    closed = [c for c in candidates if c.scored and c.closed]
    return min(closed, key=lambda c: c.chi2).label if closed else None


def verdict(rows: list[dict], key: str, extra: list[dict] = ()) -> dict:
    """Where the run ``key`` stands against the truth (as ``benchmarks/suite.py`` judges),
    looked up in ``rows`` and ``extra`` (a carved candidate, ``carved_truth``: not a compare run,
    so not in the best or the median)."""
    best_c = min(r["chamfer_m"] for r in rows)
    best_f = max(r.get("fscore") or 0.0 for r in rows)
    median_c = statistics.median(r["chamfer_m"] for r in rows)
    median_f = statistics.median(r.get("fscore") or 0.0 for r in rows)
    mine = next((r for r in [*rows, *extra] if r["key"] == key), None)
    if mine is None:
        return {"found": False}
    f, c = mine.get("fscore") or 0.0, mine["chamfer_m"]
    return {"found": True, "f_ratio": f / best_f, "c_ratio": c / best_c,
            "ok": f >= (1 - F_TOLERANCE) * best_f and c <= (1 + CHAMFER_TOLERANCE) * best_c,
            "median": c <= median_c and f >= median_f}


def rules(args) -> None:
    from recon.surfaces import auto

    global OPENING
    if args.band is not None:
        auto.BAND_SES = args.band
    if args.holes_one_count:
        auto.hole_limit = one_count_hole_limit
    if args.metric_floor is not None:
        auto.METRIC_FLOOR = args.metric_floor
    auto.band = floor_admitting(getattr(args, "floor_admits", "method"))
    OPENING = args.opening
    names = collected(args)
    good = median = 0
    seconds = []
    for cloud in names:
        rows = records(args.suite, cloud)
        candidates, block, coverage, tau, n_checked = candidates_of(
            args.work, cloud, args.extra, args.statistic, args.suite,
            area_weights_of(args, cloud))
        n_misses = with_misses(args.work, cloud, candidates)
        scale, floor = floor_of(args.work, cloud)
        if args.miss_rate is not None:
            candidates = free_space(candidates, n_misses, args.miss_rate, args.miss_ses)
        if args.holes_first:
            candidates = holes_first(candidates, n_checked)
        if args.race:
            candidates = raced(args, cloud, candidates, block, partial(
                replay, block=block, coverage=coverage, tau=tau, n_checked=n_checked,
                target=target_of(cloud, not args.no_prior), scale=scale, floor=floor),
                scale, floor)
        chosen, fitted = replay(candidates, block, coverage, tau, n_checked,
                                target_of(cloud, not args.no_prior), scale, floor)
        v = verdict(rows, chosen.key, carved_truth(args, cloud, chosen.key))
        good += v.get("ok", False)
        median += v.get("median", False)
        fit_s = sum(c.fit_s or 0.0 for c in fitted)
        compare_s = json.loads((args.suite / cloud / "timing.json").read_text())["compare_s"]
        # Load-free: the compare's own wall time of each fitted run, times the folds and
        # their share of the strikes (a fit's time grows about linearly with the strikes); a
        # carved candidate is no fit (its carving is timed by ``misses``' casts, not here).
        # The folds are the collection's (``collect --holdout``), not this command's option.
        wall = {r["key"]: r.get("wall_time_s") or 0.0 for r in rows}
        folds = json.loads((args.work / "folds" / f"{cloud}.json").read_text()
                           )["auto"]["folds"]["k"]
        # a run raced out (``--race``) was fitted on the folds of the stage it left at
        modelled = sum(wall.get(c.run.key, 0.0) * (
            c.folds / folds if c.status == "outpaced" else 1.0)
            for c in fitted if not c.carved) * (folds - 1)
        seconds.append(modelled / compare_s)
        print(f"{cloud:30} {chosen.label[:26]:26} F {v.get('f_ratio', 0):.3f} "
              f"C {v.get('c_ratio', 0):6.3f} {'ok ' if v.get('ok') else 'NO '}"
              f"{'' if v.get('median') else 'BELOW-MEDIAN '}"
              f"{'floor ' if floor else ''}fits {len(fitted)} "
              f"fits {fit_s:.0f} s here; modelled auto/compare {modelled / compare_s:.3f}")
    print(f"agreement {good}/{len(names)} = {good / max(len(names), 1):.0%}; not below the "
          f"median {median}/{len(names)}; modelled auto/compare time: median "
          f"{statistics.median(seconds):.3f}, worst {max(seconds):.3f}")


# Bands (paired standard errors) within which the ``evidence`` tie-breaks choose; consensus is
# taken over the candidates whose held-out chi-square is at most ``CONSENSUS_CHI2`` x the best's.
EVIDENCE_BANDS = (2.0, 4.0, 8.0)
CONSENSUS_CHI2 = 4.0
EVIDENCE_SAMPLES = 6000


def mesh_evidence(args, cloud: str, keys: list[str], rows: list[dict], reach: float
                  ) -> dict[str, dict]:
    """Per candidate key (with a compare mesh): ``area`` [m^2], ``unsupported`` (fraction of
    its area farther than ``reach`` from every strike) and ``to`` (other key -> mean distance
    of this surface to it, everywhere and over the unsupported samples only, and back) [m]."""
    from scipy.spatial import cKDTree

    from formats.mesh_io import read_mesh
    from metrics import Mesh, sample_surface

    mesh_of = {r["key"]: r["mesh"] for r in rows if r.get("mesh")}
    strikes = cKDTree(load_cloud(args.suite, cloud).points)
    samples, out = {}, {}
    for key in (k for k in keys if k in mesh_of):
        mesh = read_mesh(args.suite / cloud / mesh_of[key])
        tri = mesh.vertices[mesh.faces]
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]),
                                    axis=1).sum()
        samples[key] = sample_surface(Mesh(mesh.vertices, mesh.faces), EVIDENCE_SAMPLES,
                                      seed=0)[0]
        far = strikes.query(samples[key], workers=-1)[0] > reach
        out[key] = {"area": float(area), "unsupported": float(far.mean()), "far": far}
    trees = {k: cKDTree(s) for k, s in samples.items()}
    for key, e in out.items():
        e["to"] = {}
        for other, tree in trees.items():
            if other != key:
                d = tree.query(samples[key], workers=-1)[0]
                back = trees[key].query(samples[other], workers=-1)[0]
                e["to"][other] = (0.5 * (d.mean() + back.mean()),
                                  float(d[e["far"]].mean()) if e["far"].any() else 0.0)
    return out


def _tie_breaks(evidence: dict[str, dict], pool: list):
    """The evidence tie-breaks: each maps the band's candidates to the one it chooses."""
    def consensus(part: int):
        def key(c):
            gaps = [evidence[c.run.key]["to"][o.run.key][part] for o in pool
                    if o is not c and o.run.key in evidence]
            return (np.median(gaps) if gaps else np.inf, c.chi2)
        return key
    return {
        "free space (fewest beams cut or in holes)": lambda c: (c.violated + c.holes, c.chi2),
        "least area beyond the strikes": lambda c: (
            evidence[c.run.key]["area"] * evidence[c.run.key]["unsupported"], c.chi2),
        "most area beyond the strikes": lambda c: (
            -evidence[c.run.key]["area"] * evidence[c.run.key]["unsupported"], c.chi2),
        "consensus everywhere": consensus(0),
        "consensus beyond the strikes": consensus(1),
        "closed first, then smallest": lambda c: (not c.closed, c.n_params, c.chi2)}


def evidence(args) -> None:
    from recon.surfaces import auto
    from recon.surfaces.judge import COVERAGE_SPACINGS, SIGMAS

    tally: dict[tuple[str, float], list] = {}
    for cloud in collected(args):
        rows = records(args.suite, cloud)
        candidates, block, coverage, tau, n_checked = candidates_of(
            args.work, cloud, args.extra, suite=args.suite)
        scale, floor = floor_of(args.work, cloud)
        chosen, fitted = replay(candidates, block, coverage, tau, n_checked,
                                target_of(cloud, not args.no_prior), scale, floor)
        data = json.loads((args.work / "folds" / f"{cloud}.json").read_text())["auto"]
        points = load_cloud(args.suite, cloud).points
        spacing = float(np.median(nearest_gaps(points)))
        reach = max(data["tau_m"], SIGMAS * data["noise_m"], COVERAGE_SPACINGS * spacing)
        scored = [c for c in fitted if c.scored]
        found = mesh_evidence(args, cloud, [c.run.key for c in scored], rows, reach)
        selection = auto.select(fitted, block, n_checked, scale=scale, floor=floor)
        best = fitted[selection.best]
        pool = [c for c in scored if c.chi2 <= CONSENSUS_CHI2 * best.chi2]
        for band in EVIDENCE_BANDS:
            within = [c for i, c in enumerate(fitted) if c.scored and c.run.key in found
                      and selection.gaps[i][0] <= band * selection.gaps[i][1]]
            for name, key in _tie_breaks(found, pool).items():
                pick = min(within, key=key) if within else chosen
                tally.setdefault((name, band), []).append(
                    (cloud, pick.label, verdict(rows, pick.run.key)))
        print(f"{cloud}: reach {reach:.3g} m; " + "; ".join(
            f"{c.label} chi2 {c.chi2:.3g} unsupported {found[c.run.key]['unsupported']:.2f}"
            for c in sorted(scored, key=lambda c: c.chi2)[:4] if c.run.key in found), flush=True)
    print_tally(tally)


def misses(args) -> None:
    """``collect``'s companion for the missed beams: per cloud, the log's missed beams near
    the strikes (``recon.registration.misses``, as ``recon reconstruct -m auto`` draws them) and
    the fraction each collected candidate cuts (``recon.surfaces.judge.cut_misses``), measured
    on the compare's mesh of the run (fitted on all strikes; auto measures fold 0's); kept in
    ``WORK/misses/CLOUD.json`` for ``rules``."""
    from formats.mesh_io import read_mesh
    from recon.surfaces import auto, judge

    for cloud, path, data in pending(args, "misses", "json"):
        rows = records(args.suite, cloud)
        points = load_cloud(args.suite, cloud).points
        start = time.perf_counter()
        beams = auto.misses_near(args.suite / "logs" / f"{cloud}.h5", points, seed=0)
        spacing = float(np.median(nearest_gaps(points)))
        reach = auto.miss_reach(data["tau_m"], data["noise_m"], spacing)
        drawn = time.perf_counter() - start
        mesh_of = {r["key"]: r["mesh"] for r in rows if r.get("mesh")}
        cut, cast_s = {}, {}
        for row in data["candidates"]:
            if row["key"] not in mesh_of or row.get("chi2") is None:
                continue
            mesh = read_mesh(args.suite / cloud / mesh_of[row["key"]])
            start = time.perf_counter()
            hits = judge.cut_misses(beams, judge.Caster(mesh.vertices, mesh.faces), points,
                                    reach)
            cast_s[row["key"]] = time.perf_counter() - start
            cut[row["key"]] = float(hits.mean()) if len(hits) else 0.0
        path.write_text(json.dumps({"n_misses": len(beams), "n_missed": beams.n_missed,
                                    "reach_m": reach, "draw_s": drawn, "cast_s": cast_s,
                                    "cut": cut}, indent=1))
        ranked = sorted((r for r in data["candidates"] if r["key"] in cut),
                        key=lambda r: r["chi2"])
        print(f"{cloud}: {len(beams)} misses ({beams.n_missed} in the log), reach {reach:.3g} m, "
              f"draw {drawn:.1f} s; " + "; ".join(f"{r['label']} chi2 {r['chi2']:.3g} cut "
                                               f"{cut[r['key']]:.2%}" for r in ranked[:6]),
              flush=True)


# ``openings``: a held-out beam that misses its fold's surface passed through an opening of
# it. The opening counts as a crack (the surface is there; ``rules --statistic closest-cracks``
# then charges the beam its closest-point residual) when, on the compare's mesh of the run
# (fitted on all strikes, carved as auto carves for a carved candidate), the beam itself meets
# the surface near its strike or at least RING_SHARE of RING_RAYS parallel beams offset by the
# radius ``auto.miss_reach`` around it do: an opening narrower than the reach of a supported
# surface point (2 strike spacings, 3 recorded noise lengths, tau) on both sides. "Near": the
# hit within the strike's tolerance plus that radius along the beam (a face tilted up to 45
# degrees to the beam). Set before any replay of the statistic.
# (``judge.RING_RAYS``, ``judge.RING_SHARE``, ``judge.ring_share``: the product's crack test.)


def tested_order(suite: Path, cloud: str, holdout: float, seed: int = 0):
    """The cloud as ``collect`` handed it to ``auto.choose`` and the indices of the tested
    strikes in ``collect``'s order (fold 0's, then fold 1's, ...)."""
    from formats.geometry import Cloud
    from recon.surfaces import auto, judge

    points = load_cloud(suite, cloud)
    attributes = auto._columns(points.attributes) | dict(
        zip(("view_x", "view_y", "view_z"), np.asarray(points.view_points).T, strict=True))
    folds = judge.pass_folds(Cloud(points.points, attributes), max(2, round(1 / holdout)),
                             seed=seed)
    return points, folds, np.concatenate([folds.test(f) for f in range(folds.k)])


def openings(args) -> None:
    """``collect``'s companion for ``rules --statistic closest-cracks``: per cloud and
    collected candidate, which of its missed held-out beams passed a crack (``judge.RING_RAYS``),
    measured on the compare's mesh of the run; kept in ``WORK/openings/CLOUD.npz``."""
    from formats.mesh_io import read_mesh
    from recon.surfaces import auto, judge

    for cloud, path, data in pending(args, "openings", "npz"):
        arrays = np.load(args.work / "folds" / f"{cloud}.npz")
        points, folds, order = tested_order(args.suite, cloud, args.holdout, args.seed)
        if not np.array_equal(folds.block[order], arrays["block"]):
            raise SystemExit(f"{cloud}: the folds rebuilt differ from the collected ones")
        mesh_of = {r["key"]: r["mesh"] for r in records(args.suite, cloud) if r.get("mesh")}
        radius = data["miss_reach_m"]
        beams = None
        cracks, shares = {}, []
        for row in data["candidates"]:
            key, base = row["key"], row["key"].removesuffix(" carved")
            if f"missed/{key}" not in arrays or base not in mesh_of:
                continue
            mesh = read_mesh(args.suite / cloud / mesh_of[base])
            vertices, faces = mesh.vertices, mesh.faces
            if key != base:
                if beams is None:
                    beams = auto.misses_near(args.suite / "logs" / f"{cloud}.h5",
                                             points.points, seed=0)
                vertices, faces = judge.carve(vertices, faces, beams, points.points, radius)
            missed = np.flatnonzero(arrays[f"missed/{key}"])
            rows = order[missed]
            view, strike = points.view_points[rows], points.points[rows]
            window = arrays[f"tolerance/{key}"][missed] + radius
            caster = judge.Caster(vertices, faces)
            t_hit, beam_range, _, _ = caster.beams(view, strike)
            share = judge.ring_share(caster, view, strike, radius, window)
            crack = np.zeros(len(order), dtype=bool)
            crack[missed] = (np.abs(t_hit - beam_range) <= window) | (share >= judge.RING_SHARE)
            cracks[f"crack/{key}"] = crack
            shares.append(f"{row['label']} missed "
                          f"{len(missed) / len(order):.1%}, cracks {crack[missed].mean():.0%}"
                          if len(missed) else f"{row['label']} missed 0")
        np.savez_compressed(path, **cracks)
        print(f"{cloud} (radius {radius:.3g} m): " + "; ".join(shares), flush=True)


def carved_truth(args, cloud: str, key: str) -> list[dict]:
    """The true scores of carved candidate ``key`` (``recon.api.score`` against the log's
    truth mesh, as the compare scores its runs): the compare's mesh of its run carved by the
    missed beams as auto carves (``judge.carve`` at the collected reach), as a record; cached
    in ``WORK/carved/CLOUD.json``. [] when ``key`` is not carved or its run has no mesh."""
    from formats.mesh_io import read_mesh
    from recon import api
    from recon.surfaces import auto, judge

    base = key.removesuffix(" carved")
    mesh = next((r["mesh"] for r in records(args.suite, cloud) if r["key"] == base
                 and r.get("mesh")), None)
    if base == key or mesh is None:
        return []
    path = args.work / "carved" / f"{cloud}.json"
    cache = json.loads(path.read_text()) if path.exists() else {}
    if key not in cache:
        data = json.loads((args.work / "folds" / f"{cloud}.json").read_text())["auto"]
        points = load_cloud(args.suite, cloud).points
        beams = auto.misses_near(args.suite / "logs" / f"{cloud}.h5", points, seed=0)
        mesh = read_mesh(args.suite / cloud / mesh)
        vertices, faces = judge.carve(mesh.vertices, mesh.faces, beams, points,
                                      data["miss_reach_m"])
        report = api.score((vertices, faces),
                           truth=args.suite / "logs" / f"{cloud}.h5").to_dict()
        cache[key] = {"fscore": report["fscore"], "chamfer_m": report["chamfer_m"],
                      "n_faces": len(faces)}
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(cache, indent=1))
    return [{"key": key, "label": key, **cache[key]}]


def print_tally(tally: dict[tuple[str, float], list]) -> None:
    """``evidence``'s summary: per tie-break and band, agreement with the truth and misses."""
    for (name, band), picks in tally.items():
        ok = sum(v.get("ok", False) for _, _, v in picks)
        median = sum(v.get("median", False) for _, _, v in picks)
        missed = ", ".join(f"{cloud} ({label})" for cloud, label, v in picks if not v.get("ok"))
        print(f"{name:42} band {band:g}: agreement {ok}/{len(picks)}, not below the median "
              f"{median}/{len(picks)}; missed {missed}")


def nearest_gaps(points: np.ndarray) -> np.ndarray:
    """Each point's distance to its nearest other point [m]."""
    from scipy.spatial import cKDTree

    return cKDTree(points).query(points, k=2, workers=-1)[0][:, 1]


def estimate_digest() -> str:
    """A digest of the estimate's sources (``recon.surfaces.estimate`` and the checks of
    ``recon.surfaces.judge`` it calls): a cached estimate is reused only under the same one."""
    import hashlib
    import inspect

    from recon.surfaces import estimate, judge

    source = inspect.getsource(estimate) + inspect.getsource(judge)
    return hashlib.sha1(source.encode()).hexdigest()


def estimates(args, cloud: str, rows: list[dict], chosen: str) -> dict[str, dict]:
    """``recon.surfaces.estimate.estimate`` of every run's mesh of ``cloud``, in-sample, and
    of auto's choice ``chosen`` with its held-out residuals (``heldout_of``) under the key
    ``"held-out " + chosen``; cached in ``WORK/estimates`` under ``estimate_digest``."""
    from formats.geometry import Mesh
    from formats.mesh_io import read_mesh
    from recon.surfaces import estimate

    digest = estimate_digest()
    path = args.work / "estimates" / f"{cloud}.json"
    cache = json.loads(path.read_text()) if path.exists() else {}
    runs = cache.get("runs", {}) if cache.get("digest") == digest else {}
    wanted = [r for r in rows if r.get("mesh")]
    if args.per_cloud:
        wanted = [r for r in wanted if r["label"] in args.labels or r["key"] == chosen]
    heldout = heldout_of(args.work, cloud, chosen)
    jobs = [(r["key"], r, None) for r in wanted]
    jobs += [("held-out " + r["key"], r, heldout) for r in wanted
             if r["key"] == chosen and heldout is not None]
    points = None
    for key, r, held in jobs:
        if key in runs:
            continue
        points = points or load_cloud(args.suite, cloud)
        mesh = read_mesh(args.suite / cloud / r["mesh"])
        kind = "unknown" if held is None else target_of(cloud, not args.no_prior)
        runs[key] = estimate.estimate(Mesh(mesh.vertices, mesh.faces), points,
                                      heldout=held, target_kind=kind).to_dict()
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"digest": digest, "runs": runs}, default=float))
    return runs


def chosen_key(args, cloud: str) -> str:
    """The run auto chooses on ``cloud``: replayed on the collected folds when there are
    some, else the suite's own choice (``auto.json``)."""
    if (args.work / "folds" / f"{cloud}.json").exists():
        candidates, block, coverage, tau, n_checked = candidates_of(
            args.work, cloud, args.extra, suite=args.suite)
        return replay(candidates, block, coverage, tau, n_checked,
                      target_of(cloud, not args.no_prior))[0].run.key
    return suite_choice(args.suite, cloud)


def collect_heldout(args, cloud: str) -> None:
    """Auto's ladder (``recon.surfaces.auto.choose``, seed 0) on ``cloud``: every fitted
    candidate's held-out residuals, kept in ``WORK/heldout/CLOUD.npz`` and ``.json`` (once)."""
    from recon.surfaces import auto

    out = args.work / "heldout"
    if (out / f"{cloud}.json").exists():
        return
    out.mkdir(parents=True, exist_ok=True)
    points = load_cloud(args.suite, cloud)
    choice = auto.choose(points.points, view_points=points.view_points,
                         uncertainty=points.attributes, seed=0, n_workers=args.workers,
                         target_kind=target_of(cloud, not args.no_prior))
    arrays, table = {}, []
    for i, c in enumerate(choice.candidates):
        table.append({"key": c.run.key, "label": c.label, "status": c.status})
        if c.heldout is not None:
            arrays |= {f"d{i}": c.heldout.distance, f"s{i}": c.heldout.sigma,
                       f"b{i}": c.heldout.block}
    np.savez_compressed(out / f"{cloud}.npz", **arrays)
    (out / f"{cloud}.json").write_text(json.dumps({"chosen": choice.run.key,
                                                   "candidates": table}, indent=1))


def heldout_of(work: Path, cloud: str, key: str):
    """The held-out residuals (``recon.surfaces.judge.HeldOut``) of the candidate ``key`` that
    ``collect_heldout`` kept for ``cloud``, or None."""
    from recon.surfaces.judge import HeldOut

    path = work / "heldout" / f"{cloud}.json"
    if not path.exists():
        return None
    table = json.loads(path.read_text())["candidates"]
    arrays = np.load(work / "heldout" / f"{cloud}.npz")
    i = next((i for i, c in enumerate(table) if c["key"] == key), None)
    if i is None or f"d{i}" not in arrays:
        return None
    return HeldOut(arrays[f"d{i}"], arrays[f"s{i}"], arrays[f"b{i}"])


def suite_choice(suite: Path, cloud: str) -> str:
    """The run auto chose on ``cloud`` in the suite (``auto.json``)."""
    data = json.loads((suite / cloud / "auto.json").read_text())
    return next(f"{c['method']} {json.dumps(c['params'], sort_keys=True)}"
                for c in data["candidates"] if c["chosen"])


def estimate_all(args) -> None:
    """The estimate against the truth on every cloud of the suite (all are tuning clouds of
    the estimate): Spearman over all runs and within each cloud; for auto's choice in the
    suite, the band ``recon reconstruct -m auto`` reports (held-out when ``collect_heldout``
    kept its residuals), its coverage and width."""
    from scipy.stats import spearmanr

    pairs, within, held, ratios, sources, inside_all = [], [], 0, [], [], []
    names = sorted(p.parent.name for p in args.suite.glob("*/results.jsonl")
                   if not args.clouds or p.parent.name in args.clouds)
    for cloud in names:
        rows = records(args.suite, cloud)
        key = chosen_key(args, cloud)
        if args.heldout:
            collect_heldout(args, cloud)
        runs = estimates(args, cloud, rows, key)
        truth = {r["key"]: r["chamfer_m"] for r in rows}
        keys = [k for k in runs if k in truth]
        mine = [(runs[k]["chamfer_m"], truth[k]) for k in keys]
        pairs += mine
        inside_all += [runs[k]["chamfer_low_m"] <= truth[k] <= runs[k]["chamfer_high_m"]
                       for k in keys]
        rho = spearmanr(*np.array(mine).T).statistic if len(mine) > 2 else float("nan")
        within.append(rho)
        e = runs.get("held-out " + key, runs.get(key))
        if e is None or key not in truth:
            print(f"{cloud:30} rho {rho:5.2f} (auto's choice not estimated)")
            continue
        low, high = e["chamfer_low_m"], e["chamfer_high_m"]
        inside = low <= truth[key] <= high
        ratio = high / max(low, 1e-300)
        held += inside
        ratios.append(ratio)
        sources.append(e["source"])
        print(f"{cloud:30} rho {rho:5.2f} n {len(mine):3d} | choice {truth[key]:.4g} m: "
              f"predicted {e['chamfer_m']:.4g} [{low:.4g}, {high:.4g}] ({e['source']}) "
              f"{'in' if inside else 'OUT'} high/low {ratio:.3g}", flush=True)
    overall = spearmanr(*np.array(pairs).T).statistic
    ratio = np.array([t / p for p, t in pairs if p > 0])
    print("true / predicted Chamfer over all runs, percentiles 5, 10, 25, 50, 75, 90, 95: "
          + ", ".join(f"{q:.3g}" for q in np.percentile(ratio, [5, 10, 25, 50, 75, 90, 95]))
          + f"; the band holds {np.mean(inside_all):.1%} of all runs")
    print(f"Spearman over {len(pairs)} runs {overall:.3f}; within a cloud median "
          f"{np.nanmedian(within):.3f}; band holds auto's choice on {held}/{len(ratios)} "
          f"({sources.count('held-out')} held-out); high/low median {np.median(ratios):.3g}, "
          f"{np.mean(np.array(ratios) <= 4):.0%} at most 4")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("command", choices=("collect", "misses", "openings", "rules",
                                            "evidence", "estimate"))
    parser.add_argument("--suite", type=Path, required=True, help="a finished suite's --out")
    parser.add_argument("--work", type=Path, required=True, help="where this script writes")
    parser.add_argument("--clouds", nargs="*", help="only these clouds")
    parser.add_argument("--held-out", action="store_true",
                        help="read the suite's held-out clouds too (suite.HELD_OUT; default: "
                        "the tuning clouds only): only once their evaluation is done")
    parser.add_argument("--holdout", type=float, default=0.25,
                        help="collect, openings: auto's held-out share of the strikes, i.e. "
                             "round(1 / holdout) folds (rules reads the folds collected)")
    parser.add_argument("--seed", type=int, default=0,
                        help="collect, openings, rules --race: auto's seed (the folds' "
                             "dealing of the blocks and the checked strikes; the missed beams "
                             "keep seed 0)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--force", action="store_true", help="collect again")
    parser.add_argument("--heldout", action="store_true",
                        help="estimate: fit auto's ladder on each cloud once (cached) for the "
                        "held-out residuals of auto's choice")
    parser.add_argument("--per-cloud", action="store_true",
                        help="estimate: only the runs named by --labels")
    parser.add_argument("--labels", nargs="*", default=[
        "ellipsoid", "planes", "convex-hull", "poisson depth=6", "plane cell=2", "plane",
        "poisson", "visibility", "rimls", "ball-pivoting", *EXTRA, "delaunay-balls",
        "screened-poisson"], help="estimate: the runs --per-cloud estimates")
    parser.add_argument("--statistic", choices=tuple(STATISTICS), default="chi2",
                        help="rules: the held-out statistic replayed (default: auto's)")
    parser.add_argument("--opening", type=float, default=1.0, choices=OPENING_SCALES,
                        help="rules: with --statistic closest-fold-cracks, the widest crack in "
                        "auto.miss_reach (default 1)")
    parser.add_argument("--band", type=float, help="rules: the band in paired standard "
                        "errors (default: auto.BAND_SES)")
    parser.add_argument("--miss-rate", type=float, help="rules: leave out, before the band, "
                        "the candidates cutting missed beams beyond this rate (``free_space``; "
                        "needs ``misses``; default: auto's rule, which does not)")
    parser.add_argument("--miss-ses", type=float, default=3.0,
                        help="rules: standard errors of --miss-rate's test")
    parser.add_argument("--holes-first", action="store_true",
                        help="rules: leave out, before the band, the candidates leaving strikes "
                        "in holes beyond the noise or the fewest any candidate leaves "
                        "(``holes_first``; default: auto's rule, which tests only the band)")
    parser.add_argument("--holes-one-count", action="store_true",
                        help="rules: the hole test's limit with one count's binomial error "
                        "above the band's fewest (``one_count_hole_limit``; default: auto's, "
                        "the error of a difference of two counts)")
    parser.add_argument("--metric-floor", type=float,
                        help="rules: step 3's floor, a fraction of tau (default: "
                        "auto.METRIC_FLOOR; 0: no floor, the band of paired standard errors "
                        "alone, as before the floor; the floor reads the cost as a squared "
                        "residual in sigmas: with another --statistic, pass 0)")
    parser.add_argument("--floor-admits", choices=FLOOR_ADMITS, default="method",
                        help="rules: which candidates step 3's floor lets into the band stay "
                        "there (``floor_admitting``): method (those of the best's method, "
                        "auto's) or race (none: the floor keeps runs in the race only)")
    parser.add_argument("--weights", choices=("strikes", "area"), default="strikes",
                        help="rules: weigh each held-out strike's cost by 1 (strikes, auto's) "
                        "or by the area it stands for (area: one over the strikes within the "
                        "support reach, as the truth-free estimate weighs them) in the mean, "
                        "the block means, the paired standard errors and the race")
    parser.add_argument("--weight-cap", type=float,
                        help="rules --weights area: no strike weighs more than this many times "
                        "the median tested strike (default: no cap)")
    parser.add_argument("--extra", action="store_true",
                        help="rules: let the EXTRA runs join the ladder")
    parser.add_argument("--race", action="store_true",
                        help="rules: auto's race (``auto.outpaced``): the runs far worse than "
                        "the best on the first folds leave (needs the collection's --seed)")
    parser.add_argument("--no-prior", action="store_true",
                        help="tell auto nothing of the target (every cloud \"unknown\"; "
                        "default: the NATURAL clouds \"natural\")")
    args = parser.parse_args(argv)
    if args.weight_cap is not None and args.weights != "area":
        parser.error("--weight-cap needs --weights area")
    {"collect": collect, "misses": misses, "openings": openings, "rules": rules,
     "evidence": evidence, "estimate": estimate_all}[args.command](args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
