"""``-m auto``: the simplest surface the strikes support, chosen without the truth.

What a strike log knows besides its points is used (``recon.surfaces.judge``): when and by
which beam each strike was taken, its sensor position, and its recorded error model. The rule:

1. **K-fold over time blocks** (``judge.pass_folds``): the log's time line is cut into blocks
   of contiguous shots, dealt to ``1 / holdout`` folds (4 by default); each fold's blocks are
   tested only in their interiors, so no tested strike has a training strike of its own track
   within two noise lengths, and every strike is held out once. For each fold the other folds
   are prepared (normals, spacing, the recorded noise) and every candidate is fitted on them,
   each isolated like ``recon compare``'s runs (a crash or a timeout on any fold removes that
   candidate).
2. **Judge each candidate on the held-out strikes** (``judge.check``): each held-out beam is
   cast against the surface; the strike's cost is its capped chi-square, distance over its
   recorded 1-sigma error along the surface normal, squared, capped at the tolerance
   ``max(tau, 3 sigma)``. **A beam the surface cuts before its strike, or misses, costs the
   full cap**: the ray evidence enters the statistic; except a beam that slipped through a
   crack of the surface, an opening narrower than ``miss_reach`` (``judge.through_cracks``: a
   fine grid of local cells has cracks between its cells that the strikes cannot resolve and
   that cost no recall), which costs its strike's closest-point distance. The statistic
   ``chi2`` is the mean cost over every fold's tested strikes, about 1 for the true surface;
   its standard error comes from the spread of the held-out blocks' means. Reported beside
   it: ``chi_fit`` (the same on the training strikes: well below 1 for a surface that follows
   the noise), and over all strikes (fold 0's surface) the fraction of beams the surface cuts
   before their strike (``violated``) and of strikes with no surface within their tolerance
   (``holes``).
   **Missed beams** (given a strike log: ``misses_near``, ``recon.registration.misses``): a
   (shot, beam) pair with no strike crossed free space. Each candidate's fold-0 surface is cast
   against a seeded subsample of the misses near the strikes; ``misses_cut`` is the fraction
   it cuts farther than ``miss_reach`` from every strike (``judge.cut_misses``). A surface at
   the truth cuts almost none; a closed membrane across a spacecraft's gaps or unseen side
   cuts many. A candidate that cuts any (``fills_free_space``: a few beams across a large face
   in free space can carry much of a surface's error) joins the ladder a second time
   **carved**: each
   fold's surface without the faces the misses cut (``judge.carve``), judged like any other
   (held-out strikes, cuts, holes); when it is chosen, the surface refitted on all strikes is
   carved the same way (``AutoChoice.carve``). **An uncarved candidate that cuts more than
   ``MISS_REFUTES`` of the missed beams leaves the choice** when its carved twin was scored
   (``refuted``): the sensor saw through the space it fills too often for the held-out strikes,
   all taken where the surface is right, to outweigh it; its carved twin competes in its place.
   Without a strike log (a cloud file) there are no misses and no carved candidates.
3. **One paired standard error** (``paired_gaps``): every candidate tested on the same strikes
   as the best, whose chi-square exceeds the best's by at most ``BAND_SES`` standard errors
   of that difference (from the spread of the blocks' mean differences), fits the held-out
   passes as well as the best, to within what these passes can tell apart. **A floor in
   metres** (``metric_floor``, ``beneath``) where the log has no range noise (``judge.SIGMAS``
   noise lengths below ``METRIC_FLOOR`` tau): there the standard errors shrink with the
   noise, and a finer surface wins by differences far below tau that the truth's scores do not
   weigh; a candidate whose mean squared held-out residual (each strike's cost times its
   squared sigma) exceeds the best's by at most ``(METRIC_FLOOR tau)^2`` is in the band too
   when it is of the best's method (a coarser setting of it, or its carved twin). On a log
   whose three noise lengths reach ``METRIC_FLOOR`` tau the floor is 0 and the band is the
   standard errors' alone.
4. **Strikes the surface leaves in holes** (``hole_test``): a strike with no surface within its
   tolerance (``holes``, closest-point: the beam's angle does not enter) is what a surface at
   the truth leaves only in the noise's tail beyond ``judge.SIGMAS`` sigma (``HOLE_RATE``,
   0.27 % for Gaussian noise). A candidate in the band that leaves more, by more than
   ``HOLE_SES`` binomial standard errors over the strikes checked, than that rate or the
   band's fewest (whichever limit is larger; above the band's fewest, the standard error of
   the difference of two counts) drops out of the band: it misses surface the strikes show.
   The band's fewest is taken over its candidates within ``BAND_SES`` paired standard errors:
   one step 3's floor let in may drop out, but is no reference (the held-out strikes tell it
   from the best).
   Beams cut before their strike (``violated``) do not enter: along a grazing beam a
   surface a fraction of the tolerance off the strikes' surface cuts it (docs/decisions.md).
5. **Model size is the penalty**: among the rest, the fewest free parameters wins
   (``Method.parameter_count``: 9 for an ellipsoid, 3 per plane, 3 per vertex of a free mesh),
   then the lower ``chi2``. Open and closed surfaces compete alike: on the suite's clouds,
   preferring closed ones where the strikes cover little of the body chose worse surfaces
   (docs/decisions.md). The coverage of the best closed candidate is reported.
6. **What the caller knows of the target** (``target_kind``, ``TARGET_KINDS``): the held-out
   passes all lie where strikes are, so they cannot judge what a surface does where none is. For a
   ``"natural"`` body (an asteroid, a comet: a closed solid whose large-scale shape is
   smooth) seen over less than ``NATURAL_COVERAGE`` of the best closed candidate, the
   ellipsoid (``NATURAL_MODEL``) is chosen when it holds where the strikes are and is not
   extrapolated beyond them: its held-out strikes lie within ``NATURAL_FIT`` tau of it on
   average, and along each of its principal axes it reaches at most ``NATURAL_SPAN`` times
   the strikes' extent (``span``). It then stands for the unseen far side, where an open
   surface leaves the body out and a hull cuts inside it (``natural_prior``). Its completion
   (``NATURAL_COMPLETION``, fitted on the folds only then, and only on the ladder: not among
   candidates the caller lists) is the Poisson surface of the strikes with the ellipsoid where
   none is: it takes the ellipsoid's place when the held-out strikes find it better by more
   than ``BAND_SES`` paired standard errors (a cratered body: the strikes resolve more than
   the ellipsoid holds; ``complete_prior``); when the missed beams refute it, its carved twin
   competes in its place, as in step 2. Where the ellipsoid does not hold, the completion is
   fitted all the same for a body seen over less than ``NATURAL_COVERAGE``, and takes the
   place of steps 1-5's choice on the same terms, or when it fits the held-out strikes as well
   as that choice (within ``BAND_SES`` paired standard errors) and the strikes bracket the
   body: the ellipsoid reaches at most ``NATURAL_BRACKETED`` times their extent along each of
   its axes, so the unseen part lies between seen parts (``completed``).
   For an ``"unknown"`` target (the default) steps 1-5 alone decide.

**Coarse to fine** (``LADDER``): models of a few numbers first (an ellipsoid, a polyhedron of
planes, the convex hull), then coarse smooth and local surfaces, then the defaults (with the
visibility graph cut when that method is registered), then fine ones. The first
``ALWAYS_LEVELS`` levels always run, and are fitted together (the models of a few numbers
first, then the finest level: the workers stay busy while the main process judges each run as
soon as its folds are in; behind them the next level's racing folds, which the main process's
last judging would otherwise leave the workers waiting for, dropped if the ladder stops); after
that the
search stops as soon as a level's best is not measurably better (by ``se``) than the best
before it. **Racing** (``RACE_STAGES``): the runs of a level are fitted on the first fold, and
a run whose held-out chi-square there is more than three band widths (paired standard errors)
above the best's (of every run fitted so far; for a closed surface, also above the best closed
one's), and with step 3's floor its mean squared residual more than the floor by three band
widths of that excess, is not fitted on the other folds and leaves the choice
(``outpaced``): far outside the band, it could not be chosen; the others are fitted on the
second fold and raced again on both at two band widths, and those left in are fitted on
every fold. The models of a few numbers are fitted on every fold. The ladder leaves out the
methods that cost the most for what they add on the suite's clouds (``delaunay-balls``,
``screened-poisson``: a few seconds a fit, where the visibility cut and Poisson take one;
``rimls``, ``ball-pivoting``: never the held-out best nor in the band there).

The chosen run is then refitted on all points by the caller (``recon.api.reconstruct``), and
``judge.estimate`` predicts its Chamfer distance and F-score from the chosen candidate's
held-out residuals.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from formats.errors import ParameterError
from formats.geometry import Cloud
from recon.surfaces import judge
from recon.surfaces.isolation import DEFAULT_MEMORY_MB, DEFAULT_TIMEOUT_S, Limits
from recon.surfaces.methods import MethodFailed, MethodInput, Run, closed
from recon.surfaces.normals import DEFAULT_K, Fallback
from recon.surfaces.prepare import Preparation

# Fraction of shots each fold holds out: 20%, five folds (every strike held out once), each fit
# on 80% of the density (a Poisson depth or a grid cell chosen on 80% suits 100%).
HOLDOUT_FRACTION = 0.25
# Fewest tested strikes for the standard error to mean anything.
MIN_HELD_OUT = 30
# The band: a candidate whose held-out chi-square exceeds the best's by at most this many
# standard errors of the paired difference fits the held-out passes as well (2: chosen on the
# suite's 18 tuning clouds, docs/decisions.md).
BAND_SES = 2.0
# Step 4: a band member leaving strikes in holes beyond HOLE_SES standard errors above
# HOLE_RATE (the fraction of Gaussian noise beyond judge.SIGMAS sigma, two-sided: what a surface
# at the truth leaves) or above the band's fewest, whichever limit is larger, drops out of the
# band (3: the usual significance; chosen on the suite's tuning clouds, docs/decisions.md;
# above the band's fewest, the standard error of a difference of two counts, ``hole_limit``).
HOLE_SES = 3.0
HOLE_RATE = math.erfc(judge.SIGMAS / math.sqrt(2.0))
# Step 3's floor in metres (``metric_floor``): on a log whose judge.SIGMAS noise lengths are below
# METRIC_FLOOR tau (no range noise: the chi-square's unit is then far finer than any difference the
# truth's scores weigh), a candidate whose held-out mean squared residual exceeds the best's by at
# most (METRIC_FLOOR tau)^2 is in the band however many paired standard errors that is. Set on the
# suite's six clean tuning clouds (docs/decisions.md): Poisson depth 6, the truth's best ladder run
# on comet-cross-clean and spot-cross-clean, is 0.096 and 0.116 tau (the square root of the excess)
# above depth 9 there (the ladder's fine Poisson then), 8.2 and 7.6 paired standard errors; every
# floor from 0.12 to 0.20 made the same choices on the six, 0.21 let rso-b-cross-clean's `plane
# cell=2` (0.209 tau, the smaller model) in. The gate: the clean tuning clouds' noise lengths (their
# local-plane scatter) are 0.0035-0.023 tau, the noisy ones' 0.104 tau and above. The floor lets in
# only runs of the best candidate's method (a coarser setting of the same reconstruction, or its
# carved twin): a difference of resolution the scores do not weigh. Between methods the held-out
# gaps the floor bridged were real: on two clean clouds held out until then it let `plane cell=2` in
# 22 and 9 paired standard errors above `visibility`, and the smaller model won (spot under the
# LIDAR, Chamfer 2.46 times the best; the comet under the slew, F 0.48); restricted so, 9 of the 14
# clean clouds within both tolerances against 8, and fewer runs kept in the race
# (docs/decisions.md).
METRIC_FLOOR = 0.15
# The candidate ladder, coarse to fine (module docstring). Level 0: models of a few numbers;
# level 1: coarse smooth and local surfaces; level 2: the defaults (Poisson's is depth 8), the
# visibility graph cut and a wide-kernel APSS (the truth's best on a faceted body); level 3: a
# fine local-plane grid (the truth's best on satellites of flat panels seen all around). The
# fine Poisson was depth 9 until, on the suite's 116 tuning clouds, it was never chosen nor
# within both tolerances of the truth's best, yet took 27 % of the ladder's fit time (the most
# of any run) and on satellite W stayed in the race to the end; it served as the band's best
# (the reference the others are measured from) on four clouds. Depth 8 there made the same
# choice on every one of the 116 (docs/decisions.md). RIMLS
# and ball pivoting left level 3: on the suite's 46 tuning clouds neither was ever the held-out
# statistic's best, in the band or chosen, and RIMLS's four fold fits were a seventh of auto's
# time on the satellites (docs/decisions.md). The runs come from
# ``benchmarks/suite.py``: the truth's best runs on its clouds are among them. A method that is
# not registered (``visibility`` where it is not installed) is left out.
LADDER: tuple[tuple[tuple[str, dict], ...], ...] = (
    (("ellipsoid", {}), ("planes", {}), ("convex-hull", {})),
    (("poisson", {"depth": 6}), ("plane", {"cell": 2.0})),
    (("plane", {}), ("poisson", {}), ("visibility", {}), ("apss", {"filter_scale": 4})),
    (("plane", {"cell": 0.5}),),
)
MAX_FITS = sum(len(level) for level in LADDER)
# Levels fitted whatever the earlier ones gave: the primitives, the coarse surfaces and the
# defaults.
ALWAYS_LEVELS = 3
# What the caller may know of the target (step 5 of the module docstring).
TARGET_KINDS = ("unknown", "natural")
# A natural body's prior acts when the strikes cover less than this fraction of the best closed
# candidate: most of the body is unseen. Its model, the smooth closed surface of a few numbers,
# stands for the body when its mean held-out distance is within NATURAL_FIT tau and it reaches
# at most NATURAL_SPAN times the strikes' extent along each of its axes (chosen on the auto
# suite's clouds, docs/decisions.md; NATURAL_SPAN 1.5 until a cratered asteroid seen along a
# cross, 1.67, was left a patchwork 14 times the ellipsoid's Chamfer distance: 1.8 keeps out
# a hemisphere seen alone, 2, and Itokawa under the cross, 2.17).
NATURAL_COVERAGE = 0.5
NATURAL_MODEL = "ellipsoid"
NATURAL_FIT = 0.5
NATURAL_SPAN = 1.8
# The prior's second model (``complete_prior``): the Poisson surface of the strikes completed by
# the ellipsoid where none is. It replaces the bare ellipsoid when its held-out chi-square is
# lower by more than BAND_SES paired standard errors: the strikes resolve more of the body than
# the ellipsoid holds, and the ellipsoid stands only for what nobody saw. Where the prior does
# not act on a body seen over less than NATURAL_COVERAGE, it replaces the ladder's choice on the
# same terms (bennu-lidar-noisy: 2.4 paired standard errors below Poisson depth 6, true Chamfer
# 19.0 m against 52.2 m; no other natural tuning cloud changed, docs/decisions.md).
NATURAL_COMPLETION = "completed-poisson"
# The completion also takes the place of steps 1-5's choice when it fits the held-out strikes as
# well (within BAND_SES paired standard errors) and the strikes bracket the body: its ellipsoid
# reaches at most NATURAL_BRACKETED times their extent along each of its axes, so the unseen
# part lies between seen parts, where the ellipsoid interpolates rather than extrapolates
# (set between the suite's natural tuning clouds, docs/decisions.md: Ryugu and Eros under the
# slew, 1.05 and 1.16, the completion the best run; the cratered asteroid under the cross and
# Itokawa under the LIDAR, 1.34 and 1.37, the completion F 0.91 and 0.82 of the best; every
# value from 1.2 to 1.3 makes the same choices there).
NATURAL_BRACKETED = 1.25
# Step 2: the share of the missed beams near the strikes an uncarved candidate may cut before
# free space refutes it (``refuted``; one beam in ten: fixed after rso-b-cross-clean, where the
# visibility cut chosen cut 39 % and its carved twin was the better surface; every share from
# 2 % to 30 % made the same choices on the suite's tuning clouds, docs/decisions.md).
MISS_REFUTES = 0.1
# Missed beams (``recon.registration.misses``) are drawn where their free span passes within
# MISS_BOX of the strikes' bounding-box diagonal of the box: a membrane a candidate spans
# beyond the strikes lies there. A missed beam's crossing of a surface counts as a cut only
# farther than ``miss_reach`` from every strike (judge.cut_misses).
MISS_BOX = 0.1
# Racing (successive halving, in stages): every run of a level is fitted on the first folds of
# the first stage of RACE_STAGES, (folds, standard errors) pairs; a run whose held-out
# chi-square there exceeds the best's (among every run fitted so far) by more than the stage's
# paired standard errors is not fitted on more folds and leaves the choice (``outpaced``); the
# others are fitted up to the next stage's folds, and so on, then on every fold. One stage,
# two folds at three times BAND_SES, was fixed before any replay on the tuning clouds; the
# replay of the race on the 67 tuning clouds of a collection made the same choices, and left
# the same best closed candidate, with a first look after one fold at three times BAND_SES and
# two folds at twice BAND_SES: the fine Poisson (depth 9 then) and APSS leave the satellites
# where they were a third of auto's time, the runs far from the best leave after one fit
# (docs/decisions.md).
# The models of a few numbers (levels before RACE_LEVEL) are fitted on every fold: they cost
# little, and the natural body's model is among them.
RACE_STAGES = ((1, 3.0 * BAND_SES), (2, 2.0 * BAND_SES))
RACE_LEVEL = 1
# Threads of each isolated fit: one, as ``recon compare``'s runs, so parallel fits do not
# compete for the cores.
FIT_THREADS = 1


@dataclass
class Candidate:
    """One candidate of the choice and how it fared (module docstring).

    Attributes
    ----------
    run : Run
    level : int
        Its level on the ladder.
    status : {"ok", "failed", "skipped", "outpaced"}
        "skipped": a level the ladder did not need; "outpaced": far worse than the best on the
        first folds, not fitted on the others (``outpaced``).
    reason : str
        Why it failed (empty otherwise).
    fit_s : float or None
        The isolated fits' job time [s]: hand-over to result in their workers, summed over
        the folds (``run_isolated``'s ``process_time_s``; elapsed, not CPU).
    folds : int or None
        For an outpaced run, the folds it was fitted on.
    n_faces, n_params : int or None
    closed : bool or None
        No edge borders a single face.
    chi2, chi2_se : float or None
        Held-out statistic (mean capped chi-square of the tested strikes) and its block-level
        standard error.
    chi_heldout, chi_fit : float or None
        ``sqrt(chi2)`` and the same RMS on the training strikes.
    heldout_mean_m : float or None
        Mean capped held-out distance [m].
    beam_misses : float or None
        Fraction of held-out beams that miss the surface.
    violated, holes : float or None
        Over all strikes (a seeded subsample of ``judge.MAX_CHECKED``): fraction of beams the
        surface cuts before their strike, and of strikes with no surface within tolerance.
    misses_cut : float or None
        Fraction of the log's missed beams near the strikes that the surface cuts away from
        every strike (``judge.cut_misses``; None without a strike log's misses).
    carved : bool
        The run's surfaces with the faces cut by missed beams removed (``judge.carve``).
    span : float or None
        How far the surface reaches beyond the strikes (``span``; 1: no farther).
    eligible, holed, chosen : bool
        Within the band (step 3); left out for its holes (step 4), for the free space its
        carved twin in the band leaves open or that the missed beams refute (step 2); chosen.
    """

    run: Run
    level: int
    status: str
    reason: str = ""
    fit_s: float | None = None
    folds: int | None = None
    n_faces: int | None = None
    n_params: int | None = None
    closed: bool | None = None
    chi2: float | None = None
    chi2_se: float | None = None
    chi_heldout: float | None = None
    chi_fit: float | None = None
    heldout_mean_m: float | None = None
    beam_misses: float | None = None
    violated: float | None = None
    holes: float | None = None
    misses_cut: float | None = None
    span: float | None = None
    eligible: bool = False
    holed: bool = False
    chosen: bool = False
    carved: bool = False
    heldout: judge.HeldOut | None = field(default=None, repr=False)
    cost: np.ndarray | None = field(default=None, repr=False)
    mesh: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    @property
    def label(self) -> str:
        return self.run.label + (" carved" if self.carved else "")

    @property
    def key(self) -> str:
        """The run's key, with " carved" for a carved candidate."""
        return self.run.key + (" carved" if self.carved else "")

    @property
    def scored(self) -> bool:
        return self.chi2 is not None

    def to_dict(self) -> dict:
        """The JSON-ready record: the attributes, with ``label``, ``method``, ``params`` and
        ``kind`` of the run (the residual arrays and the mesh left out)."""
        out = {f.name: getattr(self, f.name) for f in fields(self)
               if f.name not in ("run", "heldout", "cost", "mesh")}
        return {"label": self.label, "method": self.run.method, "params": self.run.params,
                "kind": self.run.kind} | out


@dataclass
class AutoChoice:
    """What ``choose`` picked and why.

    Attributes
    ----------
    run : Run
        The chosen method and its resolved parameters (``method``, ``params`` and ``label``
        read from it).
    reason : str
        One paragraph: what was chosen (open or closed), the statistic, the band, the coverage,
        the ladder.
    candidates : list of Candidate
    threshold : float
        ``chi2_best + se_best``: the band's upper edge.
    coverage : float
        Fraction of the best closed candidate's surface near a strike (NaN when no closed
        candidate succeeded).
    folds : judge.Folds
        The held-out blocks and their folds.
    noise_m, tau_m : float, metres
        The recorded noise length (or the local-plane scatter without one) and the tolerance
        floor.
    target_kind : str
        What was known of the target (``TARGET_KINDS``).
    n_checked : int
        Strikes the candidates' ``violated`` and ``holes`` were counted over.
    n_misses : int
        Missed beams the candidates' ``misses_cut`` was counted over (0: no strike log).
    miss_reach_m : float, metres
        How near a strike a missed beam's crossing is no evidence (``miss_reach``).
    misses : recon.registration.misses.MissedBeams or None
        The missed beams (``carve`` cuts the refitted surface with them).
    """

    run: Run
    reason: str
    candidates: list[Candidate]
    threshold: float
    coverage: float
    folds: judge.Folds
    noise_m: float
    tau_m: float
    target_kind: str = "unknown"
    n_checked: int = 0
    n_misses: int = 0
    miss_reach_m: float = 0.0
    misses: Any = field(default=None, repr=False)

    @property
    def method(self) -> str:
        return self.run.method

    @property
    def params(self) -> dict[str, Any]:
        return self.run.params

    @property
    def label(self) -> str:
        return self.chosen.label

    @property
    def carved(self) -> bool:
        """The chosen surface is carved by the missed beams (``judge.carve``, ``carve``)."""
        return self.chosen.carved

    @property
    def chosen(self) -> Candidate:
        return next(c for c in self.candidates if c.chosen)

    def carve(self, vertices: np.ndarray, faces: np.ndarray, points: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        """The chosen run's surface refitted on all strikes ``points`` (n, 3) [m], carved by
        the missed beams as its folds were when the chosen candidate is carved
        (``judge.carve``); else unchanged. ``vertices`` (v, 3) [m], ``faces`` (f, 3)."""
        if not self.carved:
            return vertices, faces
        return judge.carve(vertices, faces, self.misses, points, self.miss_reach_m)

    def to_dict(self) -> dict:
        folds = self.folds
        return {"method": self.method, "params": self.params, "label": self.label,
                "carved": self.carved,
                "reason": self.reason, "threshold": self.threshold, "coverage": self.coverage,
                "noise_m": self.noise_m, "tau_m": self.tau_m, "target_kind": self.target_kind,
                "n_checked": self.n_checked, "n_misses": self.n_misses,
                "miss_reach_m": self.miss_reach_m,
                "folds": {"k": folds.k, "n_tested": int(folds.tested.sum()),
                          "n_blocks": folds.n_blocks, "block_shots": folds.block_shots,
                          "margin_shots": folds.margin, "step_m": folds.step_m},
                "candidates": [c.to_dict() for c in self.candidates]}


@dataclass(frozen=True)
class _Fold:
    """One fold: the prepared training strikes, the tested strikes and their blocks, and a
    subsample of the training strikes (for ``chi_fit``). ``ready``: the prepared strikes as
    a future (``_context`` prepares the folds after the first while the fits on it run);
    ``prepared`` waits for it."""

    ready: Future
    test: judge.Strikes
    block: np.ndarray
    train: judge.Strikes

    @property
    def prepared(self) -> MethodInput:
        """The prepared training strikes (waits for their preparation; raises its error)."""
        return self.ready.result()


@dataclass(frozen=True)
class _Context:
    """What every candidate is fitted on and judged against: the folds, a subsample of all
    strikes (fold 0's surface against them: cuts and holes), tau and the noise length, and the
    log's missed beams near the strikes (None without a log) with the reach of a strike
    (``miss_reach``); ``scale``, each tested strike's squared sigma [m^2], folds in order (a
    cost times it is the capped squared residual), and ``floor``, step 3's floor [m^2]
    (``metric_floor``)."""

    folds: list[_Fold]
    checked: judge.Strikes
    tau: float
    noise: float
    points: np.ndarray | None = None
    misses: Any = None
    miss_reach: float = 0.0
    scale: np.ndarray | None = None
    floor: float = 0.0

    @property
    def block(self) -> np.ndarray:
        """The block of every tested strike, folds in order (each candidate's ``cost``)."""
        return np.concatenate([f.block for f in self.folds])

    @property
    def prepared(self) -> MethodInput:
        return self.folds[0].prepared


@dataclass(frozen=True)
class Selection:
    """``select``'s answer: the chosen index, the best's, the band's upper edge (the largest
    chi-square in it), the candidates within the band, and each scored candidate's chi-square
    above the best's with its paired standard error; ``holed``: the band's candidates that
    leave too many strikes in holes (``hole_test``) and ``hole_limit`` the fraction they
    exceed; ``filled``: the band's candidates whose carved twin is in it (``fills_in_band``);
    ``refuted``: the candidates free space refutes (``refuted``), left out before the best;
    ``prior``: the natural-body prior (``natural_prior``) made the choice; ``completes``: the
    candidate (the prior's ellipsoid, or the choice of steps 1-5) in whose place the completion
    (``complete_prior``) was chosen, with ``completion``, the completion's held-out chi-square
    above that candidate's and its paired standard error; ``bracketed``: the natural model's
    ``span`` when the completion was chosen within the band of that candidate (``completed``);
    ``floored``: the band's candidates beyond ``BAND_SES`` paired standard errors that step 3's
    ``floor`` [m^2] let in (``metric_floor``)."""

    chosen: int
    best: int
    threshold: float
    eligible: tuple[int, ...]
    gaps: dict[int, tuple[float, float]]
    holed: tuple[int, ...] = ()
    hole_limit: float = 1.0
    filled: tuple[int, ...] = ()
    refuted: tuple[int, ...] = ()
    prior: bool = False
    completes: int | None = None
    completion: tuple[float, float] | None = None
    bracketed: float | None = None
    floored: tuple[int, ...] = ()
    floor: float = 0.0


def span(vertices: np.ndarray, points: np.ndarray) -> float:
    """How far a surface reaches beyond the strikes: the largest ratio, over the principal axes
    of its vertices, of its extent along the axis to the strikes' extent along it.

    Parameters
    ----------
    vertices : (v, 3) float64, metres
    points : (n, 3) float64, metres
    """
    centre = vertices.mean(axis=0)
    _, _, axes = np.linalg.svd(vertices - centre, full_matrices=False)
    extent = np.ptp((vertices - centre) @ axes.T, axis=0)
    return float(np.max(extent / np.maximum(np.ptp((points - centre) @ axes.T, axis=0),
                                            1e-300)))


def coverage_of(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray, reach: float,
                *, seed: int = 0) -> float:
    """Fraction of a surface's area within ``reach`` [m] of a strike (uniform area samples)."""
    from scipy.spatial import cKDTree

    from metrics import Mesh, sample_surface

    samples, _ = sample_surface(Mesh(vertices, faces), judge.SURFACE_SAMPLES, seed=seed)
    distance, _ = cKDTree(points).query(samples, workers=-1)
    return float(np.mean(distance <= reach))


def ladder(methods: Sequence[str] | None = None, *, natural: bool = False) -> list[list[Run]]:
    """The levels of ``LADDER`` as runs, restricted to ``methods`` and to the registered methods
    (each named method not on the ladder joins the last level at its defaults; for a
    ``natural`` target not ``NATURAL_COMPLETION``, which the prior fits itself)."""
    from recon.surfaces.methods import available, bind

    known = set(available())
    levels = [[bind(name, params) for name, params in level
               if name in known and (methods is None or name in methods)] for level in LADDER]
    if methods is not None:
        listed = {name for level in LADDER for name, _ in level}
        levels[-1] += [bind(name) for name in methods if name not in listed
                       and not (natural and name == NATURAL_COMPLETION)]
    return [level for level in levels if level]


def _columns(attributes: dict | None) -> dict[str, np.ndarray]:
    """The attributes ``choose`` reads: uncertainty columns and ``time``/``shot``/``beam``."""
    from recon.surfaces.uncertainty import COLUMNS

    wanted = (*COLUMNS, "time", "shot", "beam")
    return {k: np.asarray(v) for k, v in (attributes or {}).items() if k in wanted}


def _fold(strikes: judge.Strikes, folds: judge.Folds, f: int, *, seed: int, ready: Future
          ) -> _Fold:
    """Gather fold ``f``'s tested strikes and its training subsample (step 1); ``ready``: the
    preparation of its training strikes (``_prepare_fold``), made or under way."""
    rows = folds.train(f)
    test = folds.test(f)
    fit_rows = rows[judge.subsample(len(rows), judge.MAX_CHECKED // folds.k, seed)]
    return _Fold(ready, strikes.take(test), folds.block[test], strikes.take(fit_rows))


def _prepare_fold(cloud: Cloud, folds: judge.Folds, f: int, *, k: int, fallback: Fallback,
                  seed: int, misses=None) -> MethodInput:
    """Fold ``f``'s training strikes prepared (normals, spacing, the recorded noise), with the
    log's ``misses``, which the ``visibility`` method uses."""
    from recon.surfaces.prepare import prepare

    train = cloud.subset(folds.train(f))
    return prepare(train.points, view_points=train.view_points, k=k, fallback=fallback,
                   seed=seed, uncertainty=train.attributes, misses=misses)


def _context(cloud: Cloud, folds: judge.Folds, *, k: int, fallback: Fallback, seed: int,
             misses=None, then: Callable[[], Any] | None = None) -> _Context:
    """Every fold (step 1); ``misses``: the log's missed beams (``misses_near``). The first
    fold is prepared here (its noise and spacing set the tolerances); the others in a thread,
    one after the other, while the first fold's fits run (each fit waits for its fold): the
    same preparation, off the path to the first fit (docs/decisions.md). ``then``: called
    without arguments in that thread after the folds."""
    from concurrent.futures import ThreadPoolExecutor

    strikes = judge.Strikes.of(cloud)
    options = {"k": k, "fallback": fallback, "seed": seed, "misses": misses}
    first: Future = Future()
    first.set_result(_prepare_fold(cloud, folds, 0, **options))
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="recon-folds")
    later = [pool.submit(_prepare_fold, cloud, folds, f, **options) for f in range(1, folds.k)]
    if then is not None:
        pool.submit(then)
    pool.shutdown(wait=False)   # its thread ends once the folds are prepared
    every = [_fold(strikes, folds, f, seed=seed, ready=ready)
             for f, ready in enumerate([first, *later])]
    all_rows = judge.subsample(len(strikes), judge.MAX_CHECKED, seed)
    tau, noise = judge.tau_of(cloud.points), every[0].prepared.noise
    scale = np.concatenate([judge.sigma_along(f.test, tau=tau, noise=noise) for f in every])**2
    return _Context(folds=every, checked=strikes.take(all_rows), tau=tau, noise=noise,
                    points=cloud.points, misses=misses,
                    miss_reach=miss_reach(tau, noise, every[0].prepared.spacing),
                    scale=scale, floor=metric_floor(tau, noise))


@dataclass
class _Made:
    """What is made of a run's fold surfaces ahead of its judging, each None until made
    (``_Race.arrived``, ``_Race.make_next``): per fold its built surface (``casters``), its
    ``held_out_check`` (``held``) and its check on the training strikes (``fit``); the first
    fold's checks over all strikes and against the missed beams (``overall``,
    ``_overall``, with that fold's cast of the missed beams, the first pass of its carving);
    and for a run that fills free space, the same of its carved twin (``twin``, whose
    ``results`` are the folds' carved surfaces: a fold's own result where the carving
    removed nothing, ``_carved``, whose surface, checks included, the twin shares,
    ``_share_uncarved``). ``judge_candidate`` makes what is missing, and keeps it here:
    the same checks of the same surfaces, made earlier."""

    casters: list
    held: list
    fit: list
    overall: tuple | None = None
    results: list | None = None
    twin: _Made | None = None

    @classmethod
    def empty(cls, k: int) -> _Made:
        return cls([None] * k, [None] * k, [None] * k)


class _Race:
    """The fits of ``_fit_and_judge`` and what is known of each run: its results, what is
    made of its folds' surfaces (``_Made``: a fold's held-out check as its fit arrives, the
    race and the judging share them; the judging's other checks while the workers fit,
    ``make_next``), and its candidates once judged. The race goes in stages
    (``RACE_STAGES``): ``first`` is how many folds the runs still raced are fitted on. A run
    is a job ``(i, j)``: run ``j`` of the ``i``-th (depth, runs) pair."""

    def __init__(self, levels: list[tuple[int, list[Run]]], context: _Context):
        self.levels, self.context = levels, context
        k = len(context.folds)
        self.stages = [(folds, ses) for folds, ses in RACE_STAGES if folds < k]
        self.stage = 0
        self.first = self.stages[0][0] if self.stages else k
        # the finest level first (module docstring)
        self.jobs = [(i, j) for i in reversed(range(len(levels))) for j in range(len(levels[i][1]))]
        self.results = {job: [None] * k for job in self.jobs}
        self.made = {job: _Made.empty(k) for job in self.jobs}
        self.judged: dict[tuple[int, int], list[Candidate]] = {}
        self.shut: dict[tuple[int, int], bool] = {}

    def run(self, job: tuple[int, int]) -> Run:
        return self.levels[job[0]][1][job[1]]

    def level(self, job: tuple[int, int]) -> int:
        return self.levels[job[0]][0]

    @property
    def racing(self) -> bool:
        """Whether a stage of the race is still to be run."""
        return self.stage < len(self.stages)

    def arrived(self, job: tuple[int, int], f: int, result: dict) -> None:
        """Fold ``f``'s fit of ``job`` is in: its surface is built and checked (the fits still
        outstanding go on meanwhile); a failure on the folds fitted so far fails the run; its
        judging once all its folds are in waits for ``judge_next``."""
        results = self.results[job]
        results[f] = result
        if job in self.judged:
            return
        if result.get("status") == "ok":
            made = self.made[job]
            made.casters[f] = judge.Caster(result["vertices"], result["faces"])
            made.held[f] = held_out_check(self.context.folds[f], made.casters[f], self.context)
        if all(r is not None for r in results[:self.first]) and \
                any(r.get("status") != "ok" for r in results[:self.first]):
            self.judged[job] = [judge_candidate(self.run(job), self.level(job),
                                                [r for r in results if r is not None],
                                                self.context)]

    def judge_next(self) -> bool:
        """Judge (``_judged``) one run whose folds are all fitted and that is not judged yet;
        whether there was one. One at a time: between two, the caller takes in the fits
        that arrived and races when a stage is complete, so the workers do not wait for the
        judging of runs the race does not need."""
        for job in self.jobs:
            results = self.results[job]
            if job not in self.judged and all(r is not None for r in results):
                made = self.made[job]
                self.judged[job] = _judged(self.run(job), self.level(job), results,
                                           self.context, made)
                # the race reads its held-out checks; its surfaces are not cast against again
                self.made[job] = _Made.empty(len(results))
                self.made[job].held = made.held
                return True
        return False

    def make_next(self) -> bool:
        """Make one fold's checks ahead of a run's judging (``_Made``, ``_make_fold``), for a
        run that will be judged (not raced, or the race is over) and has not failed so far;
        whether there was one to make. The judging that follows the run's last fit then has
        little left to do."""
        if self.racing and any(self.raced(job) for job in self.jobs):
            sure = [job for job in self.jobs if not self.raced(job)]
        else:
            sure = self.jobs
        for job in sure:
            results = self.results[job]
            if job in self.judged or any(r is not None and r.get("status") != "ok"
                                         for r in results):
                continue
            for f, result in enumerate(results):
                if result is not None and _make_fold(self.made[job], f, result, self.context):
                    return True
        return False

    def opening_fits(self) -> list[tuple[tuple[int, int], int]]:
        """The (job, fold) fits handed out first, fold by fold (the later folds are still
        being prepared, ``_context``): on each, the runs not raced (the models of a few
        numbers, fitted on every fold), then, on the first stage's folds, the raced ones, in
        ``jobs``' order (the finest level's long fits start early, the quick models' later
        folds fill in beside them)."""
        k = len(self.context.folds)
        return [(job, f) for f in range(k) for raced in (False, True) for job in self.jobs
                if self.raced(job) == raced and (not raced or f < self.first)]

    def raced(self, job: tuple[int, int]) -> bool:
        """Whether the run may leave the race (its level is raced, ``RACE_LEVEL``); the others
        are fitted on every fold at once."""
        return self.level(job) >= RACE_LEVEL and bool(self.stages)

    def race(self, reference: Sequence[Candidate]) -> list[tuple[tuple[int, int], int]]:
        """This stage of the race: ``outpaced`` over the runs fitted on its folds and the
        ``reference`` candidates (scored, fitted before, uncarved), at its standard errors;
        the runs that leave are judged "outpaced". Returns the (job, fold) fits of the runs
        still in up to the next stage's folds (every fold after the last stage), the longest
        runs first."""
        n, ses = self.stages[self.stage]
        folds = self.context.folds[:n]
        m = sum(len(f.block) for f in folds)
        block = np.concatenate([f.block for f in folds])
        pool = self._pool(n)
        partial = [c.cost[:m] for c in reference] + [
            np.concatenate([c.cost for c in self.made[job].held[:n]]) for job in pool]
        racing = [False] * len(reference) + [self.raced(job) for job in pool]
        shut = [bool(c.closed) for c in reference] + [self._closed(job) for job in pool]
        scale = None if self.context.scale is None else self.context.scale[:m]
        methods = [c.run.method for c in reference] + [self.run(job).method for job in pool]
        leaves = outpaced(partial, block, racing, shut, ses=ses, scale=scale,
                          floor=self.context.floor, methods=methods)[len(reference):]
        for job, gap in zip(pool, leaves, strict=True):
            if gap is not None:
                self.judged[job] = [self._outpaced(job, *gap, ses)]
                del self.made[job]   # its surfaces' scenes are not cast against again
        self.stage += 1
        start, self.first = n, (self.stages[self.stage][0] if self.racing
                                else len(self.context.folds))
        # the longest first, by their fitted folds' times: the workers finish together
        going = sorted((job for job in self.jobs if self.raced(job) and job not in self.judged),
                       key=lambda job: -self._fit_s(job))
        return [(job, f) for job in going for f in range(start, self.first)]

    def _closed(self, job: tuple[int, int]) -> bool:
        """Whether the run's first fold's surface is ``closed`` (made once: each stage of the
        race reads it)."""
        if job not in self.shut:
            self.shut[job] = closed(self.results[job][0]["faces"])
        return self.shut[job]

    def _pool(self, n: int) -> list[tuple[int, int]]:
        """The runs in the race at a stage of ``n`` folds: fitted on those folds, none of their
        fits failed (a run fitted on every fold may have failed on a later one), not left at
        an earlier stage."""
        return [job for job in self.jobs if not self._left(job)
                and all(c is not None for c in self.made[job].held[:n])
                and all(r is None or r.get("status") == "ok" for r in self.results[job])]

    def _left(self, job: tuple[int, int]) -> bool:
        """Whether the run left the race at an earlier stage."""
        return job in self.judged and self.judged[job][0].status == "outpaced"

    def _fit_s(self, job: tuple[int, int]) -> float:
        """The run's fit time on the folds it was fitted on [s, job time: hand-over to
        result]."""
        return sum(r.get("process_time_s") or 0.0 for r in self.results[job] if r is not None)

    def _outpaced(self, job: tuple[int, int], gap: float, se: float, ses: float) -> Candidate:
        n = sum(r is not None for r in self.results[job])
        return Candidate(self.run(job), self.level(job), status="outpaced",
                         fit_s=self._fit_s(job), folds=n,
                         reason=f"on the first {n} fold(s) its held-out chi-square was "
                                f"{gap:.3g} +- {se:.2g} above the best's (more than "
                                f"{ses:g} standard errors): not fitted on the others")

    def candidates(self) -> dict[int, list[list[Candidate]]]:
        """Per depth and run in order, the run's candidate and its carved twin if any."""
        return {depth: [self.judged[i, j] for j in range(len(runs))]
                for i, (depth, runs) in enumerate(self.levels)}


def fit_workers(n_workers: int | None = None) -> int:
    """The fits run at once: ``n_workers``, default the usable cores."""
    return n_workers or max(1, len(os.sched_getaffinity(0)))


def start_workers(n_workers: int | None = None) -> None:
    """Start the fit workers (``fit_workers``, each with ``FIT_THREADS`` threads) now, without
    waiting for their imports: they warm up while the caller reads and prepares the cloud, so
    the first fits do not wait for them. The choice's isolated fits and, refitted with the same
    threads, the chosen run's fit on every strike take them from the pool."""
    from recon.surfaces.isolation import start_workers as start

    start(fit_workers(n_workers), FIT_THREADS)


def _fit_and_judge(levels: list[tuple[int, list[Run]]], context: _Context, *, limits: Limits,
                   n_workers: int | None, reference: Sequence[Candidate] = (),
                   ahead: tuple[list[Run], dict] | None = None,
                   given: dict[tuple[int, int], dict] | None = None
                   ) -> dict[int, list[list[Candidate]]]:
    """Fit every run of ``levels`` ((depth, runs) pairs) on the first stage's folds
    (``RACE_STAGES``), then the runs the race leaves in (``outpaced``, against each other and
    the ``reference`` candidates) on the next stage's folds, and so on, then on the other folds
    (a run of a level not raced on every fold at once), each
    fit in its own limited process, a few at a time; each
    run is judged (``_judged``) as soon as its folds are fitted, while the other fits go on.
    The runs not raced are handed out first, on every fold (the models of a few numbers: quick
    to fit, and judged, each fold's surface cast against the strikes, while the workers fit the
    rest: the race, which waits for them, does not wait for their judging too), then the
    finest level's fits (they take the longest: the workers stay busy, and the largest surfaces
    are judged while the small ones are fitted), and on the other folds the runs that took
    longest on the first ones. Returns, per depth
    and run in order, the run's candidate and its carved twin if any.

    ``ahead``: (runs, out): the runs of the next level, fitted on the first stage's folds once
    every other fit is handed out, while the main process judges the last runs (the workers
    would otherwise wait for it), or earlier, as soon as fewer fits are outstanding than there
    are workers (a stage of the race waiting for its last fit, or one run left in it: a worker
    would wait for the next stage); their results go to ``out`` by (run, fold), the next
    call's ``given``. ``given``: for a single level, its runs' results already fitted, by
    (run, fold). A fit is the same fit whenever it is made: the candidates and the race are those of
    fitting every run here."""
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    from tqdm import tqdm

    from recon.surfaces.isolation import run_isolated

    workers = fit_workers(n_workers)
    folds = context.folds
    state = _Race(levels, context)
    given = given or {}
    depths = ", ".join(str(depth) for depth, _ in levels)
    with ThreadPoolExecutor(max_workers=workers) as pool, \
            tqdm(total=len(state.jobs) * len(folds), desc=f"auto level {depths}", unit="fit",
                 disable=None, leave=False) as bar:
        def submit(run, f):   # the fit's thread waits for its fold's preparation
            return pool.submit(_fit_fold, run_isolated, run, folds[f], threads=FIT_THREADS,
                               **limits.kwargs())

        def hand_out(pairs):
            return {submit(state.run(job), f): (job, f) for job, f in pairs
                    if (job[1], f) not in given}

        pending = hand_out(state.opening_fits())
        _arrive_given(state, given, bar)
        opening = state.first   # the first stage's folds (every fold without a race)
        spare: dict = {}
        while True:
            if not pending and state.racing:
                pending = hand_out(_next_stage(state, reference, bar, len(folds)))
                continue   # the fits handed out may all be given: the next stage then
            # behind every fit, or beside a stage of the race that leaves a worker idle
            if ahead is not None and not spare and _worker_spare(state, len(pending), workers):
                spare = {submit(run, f): (j, f) for j, run in enumerate(ahead[0])
                         for f in range(opening)}
            done = {future for future in pending if future.done()}
            # fits that arrived, then a race, come before the judging
            if not done and _use_the_wait(state, len(pending), workers):
                continue
            if not done:
                if not pending:
                    break
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                state.arrived(*pending.pop(future), future.result())
                bar.update(1)
            _drop_decided(state, pending, bar)
        if ahead is not None:
            ahead[1].update({key: future.result() for future, key in spare.items()})
    return state.candidates()


def _arrive_given(state: _Race, given: dict[tuple[int, int], dict], bar) -> None:
    """The fits already made (``given``: results by (run, fold) of the first level) arrive."""
    for (j, f), result in given.items():
        state.arrived((0, j), f, result)
        bar.update(1)


def _drop_decided(state: _Race, pending: dict, bar) -> None:
    """Cancel the fits not started yet of the runs already judged: a run that failed on the
    folds fitted so far (``_Race.arrived``; the first failure in fold order is its status and
    reason) is judged at once, and its other folds' fits could not change it (an ellipsoid
    that does not converge on a satellite's strikes fails on every fold). The progress ``bar``
    loses them."""
    dropped = [future for future, (job, _) in pending.items()
               if job in state.judged and future.cancel()]
    for future in dropped:
        del pending[future]
    if dropped:
        bar.total -= len(dropped)
        bar.refresh()


def _next_stage(state: _Race, reference: Sequence[Candidate], bar, n_folds: int) -> list:
    """The race's next stage (``_Race.race``): the (job, fold) fits it hands out; the progress
    ``bar`` loses the fits of the runs it leaves out."""
    fitted = state.first
    racing = {job for job in state.jobs if state.raced(job)} - set(state.judged)
    fits = state.race(reference)
    bar.total -= (len(racing) - len({job for job, _ in fits})) * (n_folds - fitted)
    bar.refresh()
    return fits


def _worker_spare(state: _Race, n_pending: int, workers: int) -> bool:
    """Whether a worker would wait: every fit is handed out, or a stage of the race has fewer
    fits outstanding than there are workers."""
    return not state.racing or n_pending < workers


def _use_the_wait(state: _Race, n_pending: int, workers: int) -> bool:
    """Judge the next run or make the next check of a fold's surface while the workers fit;
    not while the last fits of a race's stage run (the next race's moment is near). Whether
    anything was done."""
    if state.racing and n_pending <= workers:
        return False
    return state.judge_next() or state.make_next()


def _fit_fold(fit: Callable, run: Run, fold: _Fold, **kwargs) -> dict:
    """``fit(run, fold.prepared, **kwargs)`` (``run_isolated``), once the fold is prepared."""
    return fit(run, fold.prepared, **kwargs)


def _judged(run: Run, level: int, results: list[dict], context: _Context,
            made: _Made | None = None) -> list[Candidate]:
    """A run fitted on every fold, judged (``judge_candidate``), and its carved twin when it
    fills free space (``fills_free_space``). ``made``: what is already made of its folds'
    surfaces (``_Made``; the rest is made here). Each fold's surface is built for the casts
    once: the twin is carved on the scenes its candidate was judged on."""
    made = made or _Made.empty(len(results))
    if all(r.get("status") == "ok" for r in results):
        made.casters = [b or judge.Caster(r["vertices"], r["faces"])
                        for r, b in zip(results, made.casters, strict=True)]
    candidate = judge_candidate(run, level, results, context, made=made)
    if not fills_free_space(candidate):
        return [candidate]
    twin = made.twin = made.twin or _Made.empty(len(results))
    twin.results = [carved or _carved(result, context, caster, made.overall[2] if f == 0
                                      else None)
                    for f, (carved, result, caster) in enumerate(zip(
                        twin.results or [None] * len(results), results, made.casters,
                        strict=True))]
    for f, result in enumerate(results):
        _share_uncarved(made, f, result)
    return [candidate, judge_candidate(run, level, twin.results, context, carved=True,
                                       made=twin)]


def _share_uncarved(made: _Made, f: int, result: dict) -> None:
    """Where the carving removed nothing from fold ``f``'s surface (``result``: ``_carved``
    gave it back), the twin's surface there is the uncarved one: the twin shares its built
    surface and the checks made of it (``made``), instead of building and casting it again."""
    twin = made.twin
    if twin is not None and twin.results is not None and twin.results[f] is result:
        twin.casters[f] = twin.casters[f] or made.casters[f]
        twin.held[f] = twin.held[f] or made.held[f]
        twin.fit[f] = twin.fit[f] or made.fit[f]


def _make_fold(made: _Made, f: int, result: dict, context: _Context) -> bool:
    """Make the next missing check of fold ``f``'s surface (``result``, fitted) in ``made``:
    its surface, its held-out check, its check on the training strikes, the first fold's
    overall checks; then, when the first fold's surface cuts missed beams (the run fills
    free space, ``fills_free_space``), the same of the fold's carved surface. Whether one
    was missing."""
    if made.casters[f] is None:
        made.casters[f] = judge.Caster(result["vertices"], result["faces"])
    elif made.held[f] is None:
        made.held[f] = held_out_check(context.folds[f], made.casters[f], context)
    elif made.fit[f] is None:
        made.fit[f] = _fit_check(context.folds[f], made.casters[f], context)
    elif f == 0 and made.overall is None:
        made.overall = _overall(made.casters[0], context)
    elif made.overall is None or not made.overall[1] or made.results is not None:
        return False   # the twin's are made of the twin's own ``_Made``, or not at all
    else:
        twin = made.twin = made.twin or _Made.empty(len(made.casters))
        twin.results = twin.results or [None] * len(made.casters)
        if twin.results[f] is None:
            twin.results[f] = _carved(result, context, made.casters[f],
                                      made.overall[2] if f == 0 else None)
            _share_uncarved(made, f, result)
            return True
        return _make_fold(twin, f, twin.results[f], context)
    return True


def _fit_check(fold: _Fold, caster: judge.Caster, context: _Context) -> judge.Check:
    """A fold's training strikes (a subsample) against its surface: ``chi_fit``."""
    return judge.check(fold.train, caster, fitted=True, tau=context.tau, noise=context.noise)


def _overall(caster: judge.Caster, context: _Context
             ) -> tuple[judge.Check, float | None, tuple | None]:
    """The first fold's surface against all strikes (a subsample: cuts and holes), the
    fraction of the missed beams it cuts (None without them) and their cast
    (``judge.cast_misses``, the first pass of the fold's carving; None without them)."""
    everywhere = judge.check(context.checked, caster, tau=context.tau, noise=context.noise)
    misses_cut = cast = None
    if context.misses is not None and len(context.misses):
        cast = judge.cast_misses(context.misses, caster, context.points, context.miss_reach)
        misses_cut = float(cast[2].mean())
    return everywhere, misses_cut, cast


def judge_candidate(run: Run, level: int, results: list[dict], context: _Context,
                    carved: bool = False, made: _Made | None = None) -> Candidate:
    """Step 2 of the module docstring for one run fitted on every fold (``run_isolated``
    results, folds in order): a fold that failed fails the candidate. ``made``: the checks
    of its folds' surfaces already made (``_Made``; the others are made here)."""
    failed = next((r for r in results if r.get("status", "failed") != "ok"), None)
    candidate = Candidate(run, level, status="ok" if failed is None else
                          failed.get("status", "failed"),
                          reason="" if failed is None else failed.get("reason", "") or "",
                          fit_s=sum(r.get("process_time_s") or 0.0 for r in results),
                          carved=carved)
    if failed is not None:
        return candidate
    made = made or _Made.empty(len(results))
    made.casters = [b or judge.Caster(r["vertices"], r["faces"])
                    for r, b in zip(results, made.casters, strict=True)]
    casters = made.casters
    held = made.held = _held_checks(casters, context, made.held)
    fit = made.fit = _fit_checks(casters, context, made.fit)
    cost = np.concatenate([h.cost for h in held])
    distance = np.concatenate([h.distance for h in held])
    tolerance = np.concatenate([h.tolerance for h in held])
    chi2, se = judge.block_mean_se(cost, context.block)
    vertices, faces = results[0]["vertices"], results[0]["faces"]
    made.overall = made.overall or _overall(casters[0], context)
    everywhere, misses_cut, _ = made.overall
    return replace(candidate, n_faces=len(faces),
                   n_params=run.method_spec().parameter_count(vertices, faces),
                   closed=closed(faces), chi2=chi2, chi2_se=se, chi_heldout=float(np.sqrt(chi2)),
                   chi_fit=float(np.sqrt(np.mean(np.concatenate([c.cost for c in fit])))),
                   heldout_mean_m=float(np.mean(np.minimum(distance, tolerance))),
                   beam_misses=float(np.mean(np.concatenate([h.missed for h in held]))),
                   violated=float(everywhere.violated.mean()),
                   holes=float(everywhere.hole.mean()), misses_cut=misses_cut,
                   span=span(vertices, context.checked.points),
                   heldout=judge.HeldOut(distance, np.concatenate([h.sigma_normal for h in held]),
                                         context.block),
                   cost=cost, mesh=(vertices, faces))


def _held_checks(casters: list, context: _Context, held: list | None) -> list[judge.Check]:
    """Each fold's ``held_out_check`` against its surface (``casters``), those ``held``
    already made (None where not) kept."""
    held = held or [None] * len(casters)
    return [made if made is not None else held_out_check(fold, caster, context)
            for made, caster, fold in zip(held, casters, context.folds, strict=True)]


def _fit_checks(casters: list, context: _Context, fit: list) -> list[judge.Check]:
    """Each fold's ``_fit_check`` against its surface (``casters``), those in ``fit`` already
    made (None where not) kept."""
    return [made or _fit_check(fold, caster, context)
            for made, caster, fold in zip(fit, casters, context.folds, strict=True)]


def held_out_check(fold: _Fold, caster: judge.Caster, context: _Context) -> judge.Check:
    """A fold's tested strikes against the surface fitted on the others (step 2 of the module
    docstring): what every candidate's statistic, raced or judged, is made of."""
    return judge.check(fold.test, caster, tau=context.tau, noise=context.noise,
                       crack=context.miss_reach)


def fills_free_space(candidate: Candidate) -> bool:
    """Whether a scored, uncarved candidate cuts any missed beam (``misses_cut``): it joins the
    ladder carved, and the held-out strikes judge between the two. A threshold on the rate
    (1 % plus three binomial standard errors until it was measured) left uncarved a visibility
    cut whose 1.2 % of cut beams crossed 32 large faces bridging a satellite's parts, half of
    its Chamfer distance (docs/decisions.md)."""
    return bool(candidate.misses_cut) and not candidate.carved


def _carved(result: dict, context: _Context, caster: judge.Caster,
            cast: tuple | None = None) -> dict:
    """A fold's surface (``result``, built: ``caster``) carved by the missed beams
    (``judge.carve``; ``cast``: the missed beams' cast against it when made, ``_overall``)
    as the surface refitted on all strikes will be: a crossing within reach of any strike,
    held out or not, is no evidence (carving fits nothing to the held-out strikes; spared
    near them only by a fold's training strikes, a silhouette a beam grazed past would be
    cut open where the final surface is not). ``result`` itself when the carving leaves the
    same arrays (no face removed, every vertex used): the twin's surface there is the
    uncarved one (``_share_uncarved``)."""
    vertices, faces = judge.carve(result["vertices"], result["faces"], context.misses,
                                  context.points, context.miss_reach, caster=caster, cast=cast)
    if _same_arrays((vertices, faces), (result["vertices"], result["faces"])):
        return result
    return result | {"vertices": vertices, "faces": faces}


def _same_arrays(made: tuple, given: tuple) -> bool:
    """Whether the arrays of ``made`` equal those of ``given`` in shape, type and value."""
    return all(a.shape == np.shape(b) and a.dtype == np.asarray(b).dtype
               and np.array_equal(a, b) for a, b in zip(made, given, strict=True))


def _best(candidates: list[Candidate]) -> Candidate | None:
    return min((c for c in candidates if c.scored), key=lambda c: c.chi2, default=None)


def _stops(candidates: list[Candidate], before: Candidate | None, depth: int) -> bool:
    """Whether level ``depth`` was not measurably better than the best before it."""
    level_best = _best([c for c in candidates if c.level == depth])
    return before is not None and (level_best is None
                                   or level_best.chi2 > before.chi2 - before.chi2_se)


def climb(levels: list[list[Run]], context: _Context, *, limits: Limits,
          n_workers: int | None) -> tuple[list[Candidate], str]:
    """Fit and judge the ladder's levels, coarse to fine, until one is not measurably better
    (module docstring). The levels fitted whatever the earlier ones gave (``ALWAYS_LEVELS``)
    are fitted together; each later one once the ladder has not stopped before it. Returns
    the candidates and a note on the runs the race left out and where the ladder stopped."""
    candidates: list[Candidate] = []
    # the next level's racing folds are fitted while the last of these are judged
    ahead: dict[tuple[int, int], dict] = {}
    fitted = _fit_and_judge(list(enumerate(levels[:ALWAYS_LEVELS])), context, limits=limits,
                            n_workers=n_workers, ahead=(levels[ALWAYS_LEVELS], ahead)
                            if len(levels) > ALWAYS_LEVELS else None)
    for depth, level in enumerate(levels):
        before = _best(candidates)
        if depth not in fitted:
            fitted |= _fit_and_judge([(depth, level)], context, limits=limits,
                                     n_workers=n_workers, reference=[
                                         c for c in candidates if c.scored and not c.carved],
                                     given=ahead if depth == ALWAYS_LEVELS else None)
        candidates += [c for judged in fitted[depth] for c in judged]
        rest = levels[depth + 1:]
        if depth + 1 >= ALWAYS_LEVELS and rest and _stops(candidates, before, depth):
            candidates += [Candidate(run, later, status="skipped")
                           for later, runs in enumerate(rest, start=depth + 1) for run in runs]
            return candidates, _race_note(candidates) + (
                f"the ladder stopped after level {depth} of {len(levels) - 1} "
                f"({sum(map(len, rest))} finer candidates not fitted): it was not measurably "
                "better than the levels before it")
    return candidates, _race_note(candidates).removesuffix("; ")


def _race_note(candidates: list[Candidate]) -> str:
    """The runs the race left out, for the reason (empty, or ending in "; ")."""
    out = [f"{c.label} on {c.folds} fold{'s' if c.folds > 1 else ''}" for c in candidates
           if c.status == "outpaced"]
    return (f"{len(out)} of them fitted on the first fold(s) only, far worse than the best "
            f"there ({', '.join(out)}); ") if out else ""


def _far(partial: Sequence[np.ndarray | None], block: np.ndarray, among: Sequence[bool],
         ses: float, scale: np.ndarray | None = None, floor: float = 0.0,
         methods: Sequence[str] | None = None) -> list[tuple[float, float] | None]:
    """Per run of ``among`` (``outpaced``), its excess over the lowest mean cost of ``among``
    and the paired standard error of that excess when it exceeds ``ses`` of them and, with a
    ``floor`` [m^2] and for a run of the best's method (``methods``: each run's; None: every
    run's the same), its mean squared residual's excess less ``ses`` of its paired standard
    errors exceeds the floor (``beneath``; ``scale``: each strike's squared sigma [m^2])."""
    means = [float(np.mean(p)) if p is not None and a else np.inf
             for p, a in zip(partial, among, strict=True)]
    out: list[tuple[float, float] | None] = [None] * len(partial)
    best = int(np.argmin(means)) if means else 0
    if not means or not np.isfinite(means[best]):
        return out
    for i in np.flatnonzero(np.isfinite(means)):
        gap, se = judge.block_mean_se(partial[i] - partial[best], block)
        kin = methods is None or methods[i] == methods[best]
        if se > 0.0 and gap > ses * se and not (
                kin and beneath(partial[i], partial[best], scale, floor, block, ses)):
            out[i] = (gap, se)
    return out


def metric_floor(tau: float, noise: float) -> float:
    """Step 3's floor [m^2] on a cloud of tolerance floor ``tau`` and noise length ``noise``
    [m]: ``(METRIC_FLOOR tau)^2`` when ``judge.SIGMAS`` noise lengths are below ``METRIC_FLOOR
    tau`` (a log without range noise: its noise lies within the floor), else 0 (no floor: the
    band is the paired standard errors alone)."""
    reach = METRIC_FLOOR * tau
    return reach**2 if judge.SIGMAS * noise < reach else 0.0


def beneath(cost: np.ndarray, reference: np.ndarray, scale: np.ndarray | None,
            floor: float, block: np.ndarray | None = None, ses: float = 0.0) -> bool:
    """Whether the mean squared residual of ``cost`` (k,) exceeds that of ``reference`` (k,),
    held-out costs of the same strikes, by at most ``floor`` [m^2] (> 0); with ``ses``, by at
    most the floor plus ``ses`` paired standard errors of that excess (``block`` (k,): each
    strike's block), as the race asks of a run it keeps. ``scale`` (k,) [m^2]: each strike's
    squared sigma (a cost times it is the capped squared residual). Always False without a
    floor or a scale."""
    if floor <= 0.0 or scale is None:
        return False
    excess = (cost - reference) * scale
    if not ses:
        return float(np.mean(excess)) <= floor
    mean, se = judge.block_mean_se(excess, block)
    return mean - ses * se <= floor


def outpaced(partial: Sequence[np.ndarray | None], block: np.ndarray,
             racing: Sequence[bool], closed: Sequence[bool], *, ses: float | None = None,
             scale: np.ndarray | None = None, floor: float = 0.0,
             methods: Sequence[str] | None = None) -> list[tuple[float, float] | None]:
    """A stage of the race (``RACE_STAGES``): which runs leave the choice after the first
    folds.

    A raced run leaves when its mean held-out cost exceeds the best run's by more than
    ``ses`` paired standard errors (and, with step 3's ``floor``, when it is of the best's
    method, its mean squared residual the best's by more than the floor, by ``ses`` paired
    standard errors of that excess: it could not be in the band); a closed one only when it
    also exceeds the best closed run's so (the best closed candidate measures the coverage,
    ``choose``).

    Parameters
    ----------
    partial : sequence of (m,) float64 or None
        Each run's held-out costs on the racing folds' tested strikes (the same strikes, in
        the same order, for every run); None: the run failed there.
    block : (m,) int64
        The block of each of those strikes.
    racing : sequence of bool
        Whether each run may leave (its level is raced, ``RACE_LEVEL``).
    closed : sequence of bool
        Whether each run's surface on the first fold is closed (``closed``).
    ses : float, optional
        The stage's paired standard errors (default: the last stage's).
    scale : (m,) float64, m^2, optional
        Each strike's squared sigma (``_Context.scale``), with ``floor``.
    floor : float, m^2
        Step 3's floor (``metric_floor``; 0: none).
    methods : sequence of str, optional
        Each run's method: the floor keeps only runs of the best's (``band``); None: every
        run is of one method.

    Returns
    -------
    list of (float, float) or None
        Per run that leaves, its mean cost's excess over the best's and the paired standard
        error of that excess; None for the others.
    """
    ses = RACE_STAGES[-1][1] if ses is None else ses
    every = _far(partial, block, [True] * len(partial), ses, scale, floor, methods)
    enclosing = _far(partial, block, closed, ses, scale, floor, methods)
    return [gap if raced and gap is not None and (not shut or enclosing[i] is not None)
            else None
            for i, (gap, raced, shut) in enumerate(zip(every, racing, closed, strict=True))]


def paired_gaps(candidates: list[Candidate], best: int, block: np.ndarray
                ) -> dict[int, tuple[float, float]]:
    """Each scored candidate's held-out chi-square above the best's, measured on the same
    tested strikes, and its standard error from the spread of the blocks' mean differences
    (a paired comparison: what the blocks share, the two surfaces' common error, cancels)."""
    reference = candidates[best].cost
    return {i: judge.block_mean_se(c.cost - reference, block)
            for i, c in enumerate(candidates) if c.scored}


def hole_limit(holes: Sequence[float], n_checked: int) -> float:
    """Step 4 of the module docstring: the largest fraction of strikes in holes that a band
    member may leave (``holes``, fractions of the ``n_checked`` strikes checked): at most
    ``HOLE_SES`` standard errors above ``HOLE_RATE`` or above the band's fewest, whichever
    limit is larger. The band's fewest is always within it.

    Above ``HOLE_RATE``, a rate the noise model fixes, the standard error is the binomial one
    of the member's own count at that rate. Above the band's fewest, itself a count over as
    many strikes, it is that of the difference of two such counts, ``sqrt(2)`` times larger:
    one count's error (until it was measured) took the visibility cut, the truth's best run,
    out of a satellite's band at 1.00 % of 4,184 strikes against a fewest of 0.55 %; the
    block-paired error of such differences on held-out strikes was a median 2.2 times one
    count's over 1,997 pairs of the suite's tuning clouds (docs/decisions.md)."""
    n = max(n_checked, 1)
    fewest = min(holes)
    return max(HOLE_RATE + HOLE_SES * math.sqrt(HOLE_RATE * (1.0 - HOLE_RATE) / n),
               fewest + HOLE_SES * math.sqrt(2.0 * fewest * (1.0 - fewest) / n))


def band(candidates: list[Candidate], scored: list[int], best: int,
         gaps: dict[int, tuple[float, float]], scale: np.ndarray | None, floor: float
         ) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Step 3 of the module docstring: the ``scored`` candidates in the band of the ``best``
    (``gaps``: ``paired_gaps``), and those of them beyond ``BAND_SES`` paired standard errors
    that the ``floor`` [m^2] lets in (``beneath``; ``scale`` (k,) [m^2], each tested strike's
    squared sigma): runs of the best's method only (``METRIC_FLOOR``)."""
    method = candidates[best].run.method
    floored = tuple(i for i in scored if gaps[i][0] > BAND_SES * gaps[i][1]
                    and candidates[i].run.method == method
                    and beneath(candidates[i].cost, candidates[best].cost, scale, floor))
    return tuple(i for i in scored if gaps[i][0] <= BAND_SES * gaps[i][1] or i in floored), \
        floored


def select(candidates: list[Candidate], block: np.ndarray, n_checked: int, *,
           scale: np.ndarray | None = None, floor: float = 0.0) -> Selection:
    """Steps 3 to 5 of the module docstring; ``block`` (k,) is the block of each tested
    strike, in the order of the candidates' ``cost``; ``n_checked`` the strikes the
    candidates' ``holes`` were counted over; ``scale`` (k,) [m^2] each tested strike's squared
    sigma and ``floor`` [m^2] step 3's floor (``metric_floor``; 0: none).

    Raises
    ------
    MethodFailed
        No candidate was scored.
    """
    if not any(c.scored for c in candidates):
        raise MethodFailed("auto: every candidate failed: " + "; ".join(
            f"{c.label}: {c.reason}" for c in candidates if c.status != "skipped"))
    out = refuted(candidates)
    scored = [i for i, c in enumerate(candidates) if c.scored and i not in out]
    best = min(scored, key=lambda i: (candidates[i].chi2, candidates[i].n_params))
    gaps = paired_gaps(candidates, best, block)
    eligible, floored = band(candidates, scored, best, gaps, scale, floor)
    threshold = max(candidates[i].chi2 for i in eligible)
    # the floor's candidates may drop out for their holes, but do not set the band's fewest
    limit = hole_limit([candidates[i].holes for i in eligible if i not in floored],
                       n_checked)
    holed = tuple(i for i in eligible if candidates[i].holes > limit)
    filled = fills_in_band(candidates, [i for i in eligible if i not in holed])
    chosen = min((i for i in eligible if i not in holed and i not in filled),
                 key=lambda i: (candidates[i].n_params, candidates[i].chi2))
    return Selection(chosen, best, threshold, eligible, gaps, holed, limit, filled, out,
                     floored=floored, floor=floor)


def refuted(candidates: list[Candidate]) -> tuple[int, ...]:
    """Step 2 of the module docstring: the scored, uncarved candidates that cut more than
    ``MISS_REFUTES`` of the missed beams and whose carved twin was scored; they leave the
    choice, the twin stays."""
    twins = {c.run.key for c in candidates if c.carved and c.scored}
    return tuple(i for i, c in enumerate(candidates)
                 if c.scored and not c.carved and c.run.key in twins
                 and (c.misses_cut or 0.0) > MISS_REFUTES)


def fills_in_band(candidates: list[Candidate], kept: list[int]) -> tuple[int, ...]:
    """The candidates among ``kept`` (band members that hold the strikes) whose carved twin
    is kept too: the same surface without the faces free space refutes fits the held-out
    passes as well, so the uncarved one drops out (step 2 of the module docstring)."""
    twins = {candidates[i].run.key for i in kept if candidates[i].carved}
    return tuple(i for i in kept if not candidates[i].carved and candidates[i].run.key in twins)


def natural_prior(candidates: list[Candidate], selection: Selection, coverage: float,
                  tau: float) -> Selection:
    """Step 5 of the module docstring for a natural body: ``selection`` with the
    ``NATURAL_MODEL`` candidate chosen when the strikes cover less than ``NATURAL_COVERAGE`` of
    the best closed candidate (``coverage``; NaN: nothing closed to judge by), its mean
    held-out distance is within ``NATURAL_FIT`` ``tau`` [m] and its ``span`` at most
    ``NATURAL_SPAN``; else ``selection`` unchanged."""
    model = next((i for i, c in enumerate(candidates)
                  if c.scored and c.run.method == NATURAL_MODEL), None)
    if model is None or model == selection.chosen or model in selection.refuted or \
            not coverage < NATURAL_COVERAGE:
        return selection
    c = candidates[model]
    if c.heldout_mean_m > NATURAL_FIT * tau or c.span is None or c.span > NATURAL_SPAN:
        return selection
    return replace(selection, chosen=model, prior=True)


def complete_prior(candidates: list[Candidate], selection: Selection, context: _Context,
                   coverage: float, *, limits: Limits, n_workers: int | None
                   ) -> tuple[list[Candidate], Selection]:
    """Step 6's completion: when the natural prior chose the ellipsoid, or the strikes cover
    less than ``NATURAL_COVERAGE`` of the best closed candidate (``coverage``), fit the
    completion (``NATURAL_COMPLETION``: the Poisson surface of the strikes, the ellipsoid where
    none is) on the folds and judge it like any candidate (``completed`` decides). Returns the
    candidates, the completion's appended (with its carved twin when it fills free space), and
    the selection."""
    from recon.surfaces.methods import available, bind

    if not (selection.prior or coverage < NATURAL_COVERAGE) or \
            NATURAL_COMPLETION not in available():
        return candidates, selection
    level = len(LADDER)
    judged = _fit_and_judge([(level, [bind(NATURAL_COMPLETION)])], context, limits=limits,
                            n_workers=n_workers)[level][0]
    candidates = candidates + judged
    return candidates, completed(candidates, selection, len(candidates) - len(judged),
                                 context.block)


def completed(candidates: list[Candidate], selection: Selection, index: int,
              block: np.ndarray) -> Selection:
    """``selection`` with the completion ``candidates[index]`` (``complete_prior``; its carved
    twin in its place when the missed beams refute it, ``MISS_REFUTES``) chosen in the place of
    its choice when its held-out chi-square is lower by more than ``BAND_SES`` paired standard
    errors (``block``: each tested strike's block), or, for a choice the natural prior did not
    make, not higher by more than ``BAND_SES`` paired standard errors while the strikes bracket
    the body: the ``NATURAL_MODEL`` candidate's ``span`` is at most ``NATURAL_BRACKETED``;
    else ``selection`` unchanged."""
    completion = candidates[index]
    if completion.scored and (completion.misses_cut or 0.0) > MISS_REFUTES:
        twin = next((i for i, c in enumerate(candidates) if c.carved and c.scored
                     and c.run.key == completion.run.key), None)
        if twin is None:
            return selection
        selection = replace(selection, refuted=(*selection.refuted, index))
        index, completion = twin, candidates[twin]
    if not completion.scored:
        return selection
    gap = judge.block_mean_se(completion.cost - candidates[selection.chosen].cost, block)
    if gap[0] < -BAND_SES * gap[1]:
        return replace(selection, chosen=index, completes=selection.chosen, completion=gap)
    model = next((c for c in candidates if c.scored and not c.carved
                  and c.run.method == NATURAL_MODEL), None)
    if selection.prior or gap[0] > BAND_SES * gap[1] or model is None or \
            model.span is None or model.span > NATURAL_BRACKETED:
        return selection
    return replace(selection, chosen=index, completes=selection.chosen, completion=gap,
                   bracketed=model.span)


def _prior_reason(candidates: list[Candidate], selection: Selection, coverage: float) -> str:
    """The reason of a choice the natural-body prior made."""
    model = selection.chosen if selection.completes is None else selection.completes
    c, b = candidates[model], candidates[selection.best]
    gap, se = selection.gaps[model]
    text = (f"; the target is a natural body and the strikes cover {coverage:.0%} of the best "
            f"closed surface: held-out passes, all where strikes are, cannot judge the rest. "
            f"The ellipsoid holds where they are (held-out strikes "
            f"{c.heldout_mean_m:.3g} m from it on average, within {NATURAL_FIT:g} tau) and "
            f"reaches {c.span:.2f} times their extent (at most {NATURAL_SPAN:g}), so it stands "
            f"for the unseen part; {gap:.2g} +- {se:.2g} above the best on the held-out "
            f"strikes, {b.label} ({b.chi2:.3g}, {b.n_params:,} parameters, "
            f"{'closed' if b.closed else 'open'})")
    if selection.completion is not None:
        gap, se = selection.completion
        text += (f"; completed by the Poisson surface of the strikes where they are: "
                 f"{-gap:.2g} +- {se:.2g} below the bare ellipsoid on the held-out strikes "
                 f"(more than {BAND_SES:g} paired standard errors), so the strikes resolve "
                 f"more of the body than the ellipsoid holds")
    return text


def _completion_reason(candidates: list[Candidate], selection: Selection,
                       coverage: float) -> str:
    """The reason of a completion chosen in the place of steps 1-5's choice (not the prior's
    ellipsoid)."""
    replaced = candidates[selection.completes]
    gap, se = selection.completion
    text = (f"; the target is a natural body and the strikes cover {coverage:.0%} of the best "
            f"closed surface: held-out passes, all where strikes are, cannot judge the rest, "
            f"so the Poisson surface of the strikes completed by their ellipsoid where none is "
            f"was fitted too. ")
    against = (f"{replaced.label} ({replaced.chi2:.3g}, "
               f"{'closed' if replaced.closed else 'open'}), the choice among the other "
               f"candidates, on the same held-out strikes")
    if selection.bracketed is None:
        return text + (f"It is {-gap:.2g} +- {se:.2g} below {against} (more than "
                       f"{BAND_SES:g} paired standard errors)")
    return text + (f"It is {gap:+.2g} +- {se:.2g} from {against} (within {BAND_SES:g} paired "
                   f"standard errors: it fits them as well), and the ellipsoid reaches at most "
                   f"{selection.bracketed:.2f} times the strikes' extent along each of its axes "
                   f"(at most {NATURAL_BRACKETED:g}): the strikes bracket the body, so the "
                   f"ellipsoid fills the unseen part between seen parts")


def _holes_reason(candidates: list[Candidate], selection: Selection) -> str:
    """What the hole test (step 4) took out of the band."""
    named = ", ".join(f"{candidates[i].label} ({candidates[i].holes:.2%})"
                      for i in selection.holed)
    return (f"; left out of the band for the strikes they leave in holes (no surface within "
            f"tolerance), more than the recorded noise or the band's best explain "
            f"(at most {selection.hole_limit:.2%}): {named}")


def _band_reason(candidates: list[Candidate], selection: Selection) -> str:
    """What decided among the candidates in the band (steps 3 to 5)."""
    b = candidates[selection.best]
    band = f"within {BAND_SES:g} paired standard error(s) of the best"
    if selection.floored:
        band += (f" or, on a log without range noise, of the best's method with a mean "
                 f"squared held-out residual at most ({math.sqrt(selection.floor):.3g} m)^2 "
                 f"above the best's ({METRIC_FLOOR:g} tau: a difference the strikes resolve "
                 f"and the scores do not weigh)")
    kept = len(selection.eligible) - len(selection.holed) - len(selection.filled)
    holding = "that hold the strikes " if selection.holed else ""
    if selection.chosen != selection.best:
        gap, se = selection.gaps[selection.chosen]
        return (f"; {gap:.2g} +- {se:.2g} above the best, {b.label} ({b.chi2:.3g}, "
                f"{b.n_params:,} parameters), on the same held-out strikes: {band}; of the "
                f"{kept} candidates in that band {holding}it is the smallest model")
    if kept > 1:
        return (f"; the lowest held-out statistic; the {kept - 1} other candidate(s) {band} "
                f"{holding}are larger models")
    if not selection.holed and not selection.filled:
        return f"; the lowest held-out statistic; no other candidate is {band}"
    return "; the lowest held-out statistic"


def _free_space_reason(candidates: list[Candidate], selection: Selection) -> str:
    """What the missed beams did (step 2): the candidates they refute, and the chosen one's
    carving."""
    c = candidates[selection.chosen]
    text = ""
    others = [i for i in selection.refuted if candidates[i].run.key != c.run.key]
    if others:
        text += (f"; left out, the missed beams refute them (each cuts more than "
                 f"{MISS_REFUTES:.0%}; their carved twins competed): " + ", ".join(
                     f"{candidates[i].label} ({candidates[i].misses_cut:.1%})" for i in others))
    if c.carved:
        whole = next(i for i, o in enumerate(candidates)
                     if o.run.key == c.run.key and not o.carved)
        dropped = (", and drops out of the band, where its carved twin is"
                   if whole in selection.filled else
                   f", more than {MISS_REFUTES:.0%}: the beams refute it"
                   if whole in selection.refuted else "")
        text += (f"; carved: the uncarved surface cuts {candidates[whole].misses_cut:.1%} of "
                 f"the missed beams near the strikes (free space it fills){dropped}; the faces "
                 f"they cross away from every strike are removed ({c.misses_cut:.1%} left)")
    return text


def explain(candidates: list[Candidate], selection: Selection, coverage: float) -> str:
    """The reason in words: what was chosen, open or closed, the statistic and the band, and
    what decided among the candidates in the band (only what the rule actually did)."""
    c = candidates[selection.chosen]
    shape = "a closed" if c.closed else "an open"
    text = (f"chose {c.label}, {shape} surface ({c.n_params:,} parameters, {c.n_faces:,} "
            f"faces, fitted on a fold's training strikes): held-out chi-square {c.chi2:.3g} "
            f"per strike (1 = at the recorded noise), {c.violated:.1%} of beams cut before "
            f"their strike, {c.holes:.1%} of strikes in holes")
    if selection.prior:
        text += _prior_reason(candidates, selection, coverage)
    elif selection.completes is not None:
        text += _completion_reason(candidates, selection, coverage)
    else:
        text += _band_reason(candidates, selection)
    if selection.holed and not selection.prior:
        text += _holes_reason(candidates, selection)
    text += _free_space_reason(candidates, selection)
    if c.chi_fit is not None and c.chi_fit < 0.5 < c.chi2:
        text += (f". On its own training strikes its chi is {c.chi_fit:.2g}, well below 1: "
                 "it follows part of the noise")
    if np.isfinite(coverage) and not selection.prior and selection.completes is None:
        # the prior's and the completion's reasons say it
        text += f". The strikes cover {coverage:.0%} of the best closed surface"
    return text


def miss_reach(tau: float, noise: float, spacing: float) -> float:
    """How far from the strikes a missed beam's crossing of a surface is no evidence [m]:
    the reach of a supported surface point (``judge.COVERAGE_SPACINGS`` spacings, ``SIGMAS``
    noise lengths, at least ``tau``). A beam that grazed past a silhouette meets a surface at
    the truth within the spacing of its neighbours' strikes and the noise."""
    return max(tau, judge.SIGMAS * noise, judge.COVERAGE_SPACINGS * spacing)


def misses_near(log_path, points: np.ndarray, *, seed: int = 0):
    """The missed beams of the strike log ``log_path`` whose free span passes within
    ``MISS_BOX`` of the diagonal of the bounding box of ``points`` (n, 3) [m, body frame]
    (``recon.registration.misses.missed_beams``)."""
    from recon.registration.misses import missed_beams

    low, high = points.min(axis=0), points.max(axis=0)
    margin = MISS_BOX * float(np.linalg.norm(high - low))
    return missed_beams(log_path, low=low - margin, high=high + margin, seed=seed)


def _coverage(candidates: list[Candidate], points: np.ndarray, context: _Context, seed: int
              ) -> float:
    enclosing = [c for c in candidates if c.scored and c.closed]
    if not enclosing:
        return float("nan")
    best = min(enclosing, key=lambda c: c.chi2)
    reach = max(context.tau, judge.SIGMAS * context.noise,
                judge.COVERAGE_SPACINGS * context.prepared.spacing)
    return coverage_of(*best.mesh, points, reach, seed=seed)


def choose(points: np.ndarray, *, view_points: np.ndarray | None = None,
           uncertainty: dict[str, np.ndarray] | None = None,
           candidates: Sequence[Run | tuple[str, dict]] | None = None,
           methods: Sequence[str] | None = None, holdout: float = HOLDOUT_FRACTION,
           seed: int = 0, k: int = DEFAULT_K, fallback: Fallback = "centroid",
           timeout_s: float = DEFAULT_TIMEOUT_S, memory_mb: int | None = DEFAULT_MEMORY_MB,
           n_workers: int | None = None, target_kind: str = "unknown",
           misses=None, then: Callable[[], Any] | None = None) -> AutoChoice:
    """Choose a method and resolution by held-out passes and the sensor rays, without the truth.

    Parameters
    ----------
    points : (n, 3) float64, metres, body frame
    view_points : (n, 3) float64, metres, optional
        Sensor positions (orient the normals, aim the beams).
    uncertainty : dict of str to (n,) arrays, optional
        The cloud's attributes as ingest writes them: the recorded uncertainty columns
        (``recon.surfaces.uncertainty``) and ``time``, ``shot``, ``beam``, which order the
        held-out passes (without them the points' order is taken as the time order); other keys
        are ignored.
    candidates : sequence of Run or of (method, params), optional
        Fit these, all at once, instead of the ladder.
    methods : sequence of str, optional
        Restrict the ladder to these methods (``ladder``).
    holdout : float
        Fraction of the shots held out, in (0, 0.5].
    seed : int
        Seed of the blocks' places (and of the methods).
    k, fallback
        Normal estimation (``recon.surfaces.prepare.prepare``).
    timeout_s, memory_mb
        Limits of each isolated fit.
    n_workers : int, optional
        Fits run at once (default: the usable cores), each in its own process.
    target_kind : {"unknown", "natural"}
        What is known of the target (step 5 of the module docstring): ``"natural"`` for an
        asteroid or a comet.
    misses : recon.registration.misses.MissedBeams, optional
        The log's missed beams near the strikes (``misses_near``), in the body frame: each
        candidate's ``misses_cut``, and a carved candidate for each that fills free space
        (module docstring, step 2). None: neither (a cloud file records no misses).
    then : callable, optional
        Called without arguments in the thread that prepares the folds, once they are
        prepared, while the fits run (``recon reconstruct`` prepares every strike there for
        the chosen run's refit); not called when the options or the cloud are refused first.

    Returns
    -------
    AutoChoice
    """
    from recon.surfaces.methods import bind

    if not 0 < holdout <= 0.5:
        raise ParameterError(f"holdout must be in (0, 0.5], got {holdout}")
    if target_kind not in TARGET_KINDS:
        raise ParameterError(f"target_kind must be one of {', '.join(TARGET_KINDS)}, "
                             f"got {target_kind!r}")
    attributes = _columns(uncertainty)
    if view_points is not None:
        attributes |= dict(zip(("view_x", "view_y", "view_z"), np.asarray(view_points).T,
                               strict=True))
    cloud = Cloud(np.asarray(points, dtype=np.float64), attributes)
    folds = judge.pass_folds(cloud, max(2, round(1 / holdout)), seed=seed)
    tested = min(len(folds.test(f)) for f in range(folds.k))
    if tested < MIN_HELD_OUT:
        raise ParameterError(f"auto needs at least {MIN_HELD_OUT} held-out points a fold; "
                        f"{len(cloud)} points in {folds.k} folds of {folds.n_blocks} blocks test "
                        f"{tested} in the smallest fold")
    levels = ([[bind(*r) if isinstance(r, tuple) else bind(r) for r in candidates]]
              if candidates else ladder(methods, natural=target_kind == "natural"))
    context = _context(cloud, folds, k=k, fallback=fallback, seed=seed, misses=misses,
                       then=then)
    limits = Limits(timeout_s=timeout_s, memory_mb=memory_mb)
    table, note = climb(levels, context, limits=limits, n_workers=n_workers)
    coverage = _coverage(table, cloud.points, context, seed) if cloud.view_points is not None \
        else float("nan")
    selection = select(table, context.block, len(context.checked), scale=context.scale,
                       floor=context.floor)
    if target_kind == "natural":
        selection = natural_prior(table, selection, coverage, context.tau)
        if not candidates and (methods is None or NATURAL_COMPLETION in methods):
            table, selection = complete_prior(table, selection, context, coverage,
                                              limits=limits, n_workers=n_workers)
    for i, c in enumerate(table):
        c.eligible = i in selection.eligible
        c.holed = i in selection.holed or i in selection.filled or i in selection.refuted
        c.chosen = i == selection.chosen
    fitted = sum(c.status != "skipped" for c in table)
    reason = (explain(table, selection, coverage)
              + f"; {fitted} candidate fit(s) of {len(table)}" + (f"; {note}" if note else "")
              + ".")
    return AutoChoice(table[selection.chosen].run, reason, table, selection.threshold,
                      coverage, folds, context.noise, context.tau, target_kind,
                      len(context.checked), 0 if misses is None else len(misses),
                      context.miss_reach, misses)


def format_choice(choice: AutoChoice) -> str:
    """The candidates table and the reason, as ``recon reconstruct -m auto`` prints them."""
    lines = [f"{'':2}{'candidate':<30} {'lvl':>3} {'kind':<13} {'chi2':>7} {'+-se':>6} "
             f"{'chi fit':>7} {'cut':>6} {'holes':>6} {'free':>6} {'params':>8} {'faces':>8}",
             "-" * 111]
    ranked = sorted(choice.candidates, key=lambda c: (not c.scored, c.chi2 or 0.0))
    for c in ranked:
        mark = "*" if c.chosen else ("x" if c.holed else "~" if c.eligible else " ")
        start = f"{mark:2}{c.label[:30]:<30} {c.level:>3} {c.run.kind:<13}"
        if c.status == "skipped":
            lines.append(f"{start} not fitted (the ladder stopped before its level)")
        elif c.status == "outpaced":
            lines.append(f"{start} left after {c.folds} fold(s), far worse than the best")
        elif not c.scored:
            lines.append(f"{start} FAILED: {c.reason[:50]}")
        else:
            free = "-" if c.misses_cut is None else f"{c.misses_cut:.1%}"
            lines.append(f"{start} {c.chi2:>7.3g} {round(c.chi2_se, 9):>6.2g} {c.chi_fit:>7.2g} "
                         f"{c.violated:>6.1%} {c.holes:>6.1%} {free:>6} {c.n_params:>8d} "
                         f"{c.n_faces:>8d}")
    folds = choice.folds
    floor = metric_floor(choice.tau_m, choice.noise_m)
    floored = (f" or, of its method, a mean squared residual at most ({math.sqrt(floor):.3g} "
               f"m)^2 above its ({METRIC_FLOOR:g} tau, a log without range noise)") if floor \
        else ""
    lines.append(f"(chi2: held-out chi-square per strike over {folds.k} folds, "
                 f"{folds.n_blocks} blocks of {folds.block_shots} shots, "
                 f"{int(folds.tested.sum())} strikes tested; +-se: its block standard error; "
                 "chi fit: on the training strikes; cut: beams cut before their strike; "
                 f"free: of {choice.n_misses} missed beams near the strikes, those the surface "
                 "cuts away from every strike (free space it fills); "
                 f"* chosen, ~ within {BAND_SES:g} paired standard error(s) of the best"
                 f"{floored}, x "
                 "left out: within them but with strikes in holes beyond the noise or its "
                 "carved twin within them, or refuted by the missed beams (more than "
                 f"{MISS_REFUTES:.0%} cut); carved: without the faces the missed beams cut)")
    lines.append(choice.reason)
    return "\n".join(lines)


def choose_for(cloud: Cloud, *, methods: Sequence[str] | None = None,
               holdout: float = HOLDOUT_FRACTION, preparation: Preparation | None = None,
               limits: Limits | None = None, target_kind: str = "unknown",
               misses=None, then: Callable[[], Any] | None = None) -> AutoChoice:
    """``choose`` on a cleaned ``Cloud`` (``Preparation.apply``) with a preparation's normals
    options and a run's limits: the choice ``-m auto`` makes.

    Parameters
    ----------
    cloud : Cloud
        Metres, body frame; its view points aim the beams, its ``time``/``shot``/``beam`` and
        uncertainty attributes shape the hold-out.
    methods : sequence of str, optional
        Restrict the ladder to these methods (``ladder``; default: the whole ladder).
    holdout : float
    preparation : Preparation, optional
    limits : Limits, optional
    target_kind : {"unknown", "natural"}
        What is known of the target (``choose``).
    misses : recon.registration.misses.MissedBeams, optional
        The log's missed beams (``choose``).
    then : callable, optional
        As ``choose``.
    """
    preparation = preparation or Preparation()
    return choose(cloud.points, view_points=cloud.view_points, uncertainty=cloud.attributes,
                  methods=methods, holdout=holdout, seed=preparation.seed, k=preparation.k,
                  fallback=preparation.fallback, target_kind=target_kind, misses=misses,
                  then=then,
                  **(limits or Limits()).kwargs())
