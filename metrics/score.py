"""Score a reconstruction (a cloud or a mesh) against a truth mesh: ``score(test, truth)``.

Definitions (d(x, Y) is the distance from x to Y; "within tau" means d < tau, as in Tanks and
Temples, Knapitsch et al. 2017, and Open3D's ``compute_metrics``):

- accuracy: d(test point, truth surface), exact point-to-triangle in float64, for every test
  point (a test mesh is first sampled uniformly by area, ``n_test_samples`` points).
- completeness: d(truth sample, test), for ``n_truth_samples`` points sampled uniformly by area on
  the truth: to a test cloud by nearest neighbour (Open3D's KD-tree), to a test mesh exactly.
- how many: with no sample count given, as many as the stated precision needs
  (``metrics.precision``: the Chamfer distance's standard error at most 2 % of it, the
  F-score's, coverage's and edge score's at most 0.005, sized from a pilot), a cloud's
  accuracy then averaged over a seeded sample of its points; with a count given, that count
  (and every point of a cloud). Every report states its standard errors (``*_se``).
- mean, RMS, median, 95th percentile and max of each; Chamfer = (mean accuracy + mean
  completeness) / 2; Hausdorff = max(max accuracy, max completeness). The median, 95th
  percentile and max of a sampled side are the sample's (the max of a sample is at most the
  whole's: a cloud's lone outlier may be left out of its sample).
- precision = fraction of test points within tau of the truth; recall = fraction of truth samples
  within tau of the test; F = 2 P R / (P + R) (0 when P + R = 0).
- coverage: fraction of the truth's area within tau of the test, by a deterministic quadrature
  (``sampling.coverage_lattice``: each face cut into equal sub-triangles whose centroids are
  tested), with the per-face fractions kept in ``face_coverage`` for mapping blind spots. Recall
  estimates the same area fraction from random samples; coverage resolves every face.
- normal consistency: mean |cos| of the angle between each test normal and the unit normal of
  the truth face holding its closest point (orientation ignored); None when the test has no
  normals (a cloud without them). A test mesh's normals are its sampled faces' normals.
- edge score: ``edges.edge_score`` on the test points (a test mesh: on its samples), the
  paper's weighted edge metric over the truth triangulation; ``edge_options={"variant":
  "feature"}`` gives the feature-edge variant.

Scoring many tests against one truth (a comparison's runs, a study's time prefixes, a stability
sweep): build ``Truth(mesh)`` once and pass it as ``truth``; its distance structure, its samples
and its coverage lattice (and both joined in Morton order, as the completeness query takes them)
are then made once and reused, and every report is the same as with a fresh truth. A test mesh's
distance structure is built on a second thread while its samples are scored against the truth.

A cloud too large to hold (a long strike log) is scored block by block with ``score_stream``, in
memory that does not grow with its size, to the same numbers:

- mean, RMS, max, the count within tau and the normals' sum of |cos| are running sums over the
  blocks (the same additions as ``score`` up to their grouping: equal to ~1e-15 relative);
- completeness and recall, coverage: the nearest distance of each truth sample and lattice point
  is the minimum over groups of blocks (``defaults.STREAM_BLOCK`` points each) of its nearest
  distance to the group (exact: the same distances);
- the accuracy median and 95th percentile are exact order statistics by radix selection
  (``_RankFinder``): the first pass counts the distances by the top bits of their float64
  patterns, and further passes over the blocks (distances recomputed, nothing stored per point)
  narrow the bins holding the wanted ranks until they are small enough to keep and sort. A
  stream of at most ``defaults.QUANTILE_KEEP`` points needs no second pass;
- the edge metric (``edges_stream.EdgeStream``): exact k-nearest neighbourhoods slab by slab
  along the truth's longest axis (``defaults.EDGE_SLAB_POINTS`` points each, one further pass
  per slab), the points whose neighbourhood crosses a slab's halo resolved by another pass;
  its score, rates and counts are the whole cloud's exactly, its per-point arrays None.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, fields
from functools import cached_property

import numpy as np

from formats import interrupt
from formats.errors import InputError, ParameterError
from formats.geometry import UNKNOWN
from metrics import defaults
from metrics.distance import MeshDistance
from metrics.edges import EdgeReport, check_options, edge_report, resolve_length
from metrics.edges_stream import EdgeStream
from metrics.errors import FrameAssumedWarning, ScaleMismatchWarning
from metrics.inputs import (
    Cloud,
    Mesh,
    as_cloud,
    as_mesh,
    as_test,
    bbox_diagonal,
    face_areas,
    face_normals,
)
from metrics.precision import (
    CLOUD_SALT,
    KeySample,
    check_precision,
    fscore_se,
    lattice_size,
    plan,
    point_keys,
    proportion_se,
    smallest_keys,
)
from metrics.sampling import coverage_lattice, sample_surface, subdivision_levels
from metrics.spatial import bounds, cloud_distance, morton_order

_STATS = ("mean", "rms", "median", "p95", "max")
_ARRAYS = ("accuracy_distances", "accuracy_faces", "test_points")  # None when streamed
_EDGE_OPTIONS = {"k", "rule", "threshold", "feature_angle_deg", "tolerance", "tolerance_fraction",
                 "variant"}


@dataclass(frozen=True)
class ScoreReport:
    """Scores of a test cloud or mesh against a truth mesh (definitions in ``metrics.score``).

    Lengths are in metres, in the frame shared by test and truth. ``to_dict()`` gives the scalars
    (JSON-ready); ``arrays()`` the per-point and per-face arrays.

    Attributes
    ----------
    n_points : int
        Test points scored (the cloud's points or the sample of them scored, or the samples
        drawn on a test mesh).
    n_truth_samples : int
    tau_m : float
    truth_diagonal_m : float
        Bounding-box diagonal of the truth.
    accuracy_mean_m, accuracy_rms_m, accuracy_median_m, accuracy_p95_m, accuracy_max_m : float
    completeness_mean_m, completeness_rms_m, completeness_median_m, completeness_p95_m,
    completeness_max_m : float
    chamfer_m, hausdorff_m : float
    accuracy_mean_se_m, completeness_mean_se_m, chamfer_se_m : float
        Standard errors of the two means and of the Chamfer distance from sampling: a mean's
        is the sample standard deviation over the square root of the samples (for a cloud's
        points, drawn without replacement, times sqrt(1 - n / N): 0 when every point is
        scored); the Chamfer's half the root sum of squares of the two.
    precision, recall, fscore : float, in [0, 1]
    coverage : float, in [0, 1]
    precision_se, recall_se, fscore_se, coverage_se : float
        Standard errors from sampling: of the two proportions (binomial, Agresti-Coull
        adjusted, ``precision.proportion_se``; 0 for the precision of a cloud whose every
        point is scored), of F by the delta method, of the coverage the
        binomial one of as many random points as the lattice has (an upper bound for a
        quadrature that places one point per cell; ``metrics.precision``).
    target_precision : float or None
        The precision the sample counts were sized for (``metrics.precision``): the Chamfer
        distance's standard error at most this fraction of it, the F-score's, coverage's and
        edge score's at most a quarter of it. None when the caller gave the sample counts.
    normal_consistency : float in [0, 1] or None
    edge_score : float in [0, 1] or None (None when not computed)
    test_kind : {"cloud", "mesh"}
    seed : int or None
    n_test_points : int or None
        A test cloud's points (``n_points`` of them scored: fewer when the precision sampled
        them, and then the accuracy's median, 95th percentile and max, and the Hausdorff
        distance, are the sample's); None for a mesh.
    accuracy_distances : (n_points,) float64, or None from ``score_stream``
    accuracy_faces : (n_points,) int64, truth face nearest each test point, or None from
        ``score_stream``
    test_points : (n_points, 3) float64, or None from ``score_stream``
    completeness_distances : (n_truth_samples,) float64
    truth_points : (n_truth_samples, 3) float64
    truth_point_faces : (n_truth_samples,) int64
    face_coverage : (n_truth_faces,) float64, in [0, 1]
        Fraction of each truth face within tau of the test.
    edge : EdgeReport or None
    """

    n_points: int
    n_truth_samples: int
    tau_m: float
    truth_diagonal_m: float
    accuracy_mean_m: float
    accuracy_rms_m: float
    accuracy_median_m: float
    accuracy_p95_m: float
    accuracy_max_m: float
    completeness_mean_m: float
    completeness_rms_m: float
    completeness_median_m: float
    completeness_p95_m: float
    completeness_max_m: float
    chamfer_m: float
    hausdorff_m: float
    accuracy_mean_se_m: float
    completeness_mean_se_m: float
    chamfer_se_m: float
    precision: float
    recall: float
    fscore: float
    coverage: float
    precision_se: float
    recall_se: float
    fscore_se: float
    coverage_se: float
    target_precision: float | None
    normal_consistency: float | None
    edge_score: float | None
    test_kind: str
    seed: int | None
    n_test_points: int | None
    accuracy_distances: np.ndarray | None = field(repr=False)
    accuracy_faces: np.ndarray | None = field(repr=False)
    test_points: np.ndarray | None = field(repr=False)
    completeness_distances: np.ndarray = field(repr=False)
    truth_points: np.ndarray = field(repr=False)
    truth_point_faces: np.ndarray = field(repr=False)
    face_coverage: np.ndarray = field(repr=False)
    edge: EdgeReport | None = field(repr=False, default=None)

    def to_dict(self) -> dict:
        """Scalar scores as plain Python numbers (and ``edge`` details as a nested dict)."""
        out = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "edge":
                out["edge"] = None if value is None else value.to_dict()
            elif not isinstance(value, np.ndarray) and f.name not in _ARRAYS:
                out[f.name] = value
        return out

    def arrays(self) -> dict[str, np.ndarray]:
        """The per-point and per-face arrays, by field name (those a streamed score keeps)."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if isinstance(getattr(self, f.name), np.ndarray)}


def _summary(distance: np.ndarray) -> dict[str, float]:
    """The ``_STATS`` of distances (n,), and ``se``, the mean's standard error as a sample's."""
    p50, p95 = np.percentile(distance, [50, 95])
    se = float(np.std(distance, ddof=1) / np.sqrt(len(distance))) if len(distance) > 1 else 0.0
    return {"mean": float(distance.mean()), "rms": float(np.sqrt(np.mean(distance**2))),
            "median": float(p50), "p95": float(p95), "max": float(distance.max()), "se": se}


def _count(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise InputError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


class Truth:
    """A truth mesh made ready once for scoring many tests against it.

    Holds what ``score`` derives from the truth alone, built on first use and reused by every
    later call: the exact-distance structure (``MeshDistance``), the surface samples per
    ``(n_truth_samples, seed)``, the coverage lattice per ``coverage_points``, both joined in
    Morton order (the completeness query) and the face areas. A report against a ``Truth`` is
    identical to one against the bare mesh.

    Parameters
    ----------
    mesh : Mesh, (vertices, faces) tuple, or object with vertices/faces
        vertices (n_v, 3) float64 metres; faces (m, 3) int, m >= 1.
    name : str
        Argument name in error messages.

    Examples
    --------
    >>> truth = Truth(mesh)                                        # doctest: +SKIP
    >>> reports = [score(surface, truth) for surface in surfaces]  # doctest: +SKIP
    """

    def __init__(self, mesh, *, name: str = "truth"):
        self.mesh = as_mesh(mesh, name)
        self.diagonal = bbox_diagonal(self.mesh.vertices)
        self.areas = face_areas(self.mesh.vertices, self.mesh.faces)
        self._distance: MeshDistance | None = None
        self._samples: dict = {}
        self._lattices: dict = {}
        self._queries: dict = {}

    @classmethod
    def of(cls, truth, name: str = "truth") -> Truth:
        """``truth`` itself when it is a ``Truth``, else a new one around the mesh."""
        return truth if isinstance(truth, Truth) else cls(truth, name=name)

    @property
    def distance(self) -> MeshDistance:
        """Exact distances to the truth surface (built on first use)."""
        if self._distance is None:
            self._distance = MeshDistance(self.mesh)
        return self._distance

    def samples(self, n: int, seed) -> tuple[np.ndarray, np.ndarray]:
        """``sampling.sample_surface(mesh, n, seed=seed)``, kept per ``(n, seed)``.

        Returns
        -------
        points : (n, 3) float64, metres
        faces : (n,) int64
        """
        key = (n, None if seed is None else tuple(np.atleast_1d(seed).tolist()))
        if seed is None:  # fresh randomness each time: nothing to keep
            return sample_surface(self.mesh, n, seed=None)
        if key not in self._samples:
            self._samples[key] = _frozen(sample_surface(self.mesh, n, seed=seed))
        return self._samples[key]

    def lattice(self, coverage_points: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The coverage lattice of about ``coverage_points`` points, kept per size.

        Returns
        -------
        levels : (m,) int64, subdivision level per face
        points : (sum(levels**2), 3) float64, metres
        faces : (sum(levels**2),) int64
        """
        if coverage_points not in self._lattices:
            levels = subdivision_levels(self.mesh, coverage_points,
                                        defaults.COVERAGE_MAX_SUBDIVISION)
            self._lattices[coverage_points] = _frozen((levels,
                                                       *coverage_lattice(self.mesh, levels)))
        return self._lattices[coverage_points]

    def queries(self, n: int, seed, coverage_points: int) -> tuple[np.ndarray, np.ndarray]:
        """The samples (``samples(n, seed)``) then the lattice points (``lattice``), in Morton
        order (``spatial.morton_order``), kept per ``(n, seed, coverage_points)``: the points
        whose distances to a test give completeness and coverage, in the order a distance query
        runs fastest (neighbours share BVH nodes and tree leaves). ``seed`` is not None: unseeded
        samples are fresh each time, so there is nothing to keep (``_Setup`` joins them itself).

        Returns
        -------
        points : (n + l, 3) float64, metres, in Morton order
        order : (n + l,) int64, ``points[i]`` is point ``order[i]`` of samples then lattice
        """
        key = (n, tuple(np.atleast_1d(seed).tolist()), coverage_points)
        if key not in self._queries:
            self._queries[key] = _frozen(_in_morton_order(self.samples(n, seed)[0],
                                                          self.lattice(coverage_points)[1]))
        return self._queries[key]


def _in_morton_order(samples: np.ndarray, lattice: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Samples then lattice points, joined and put in Morton order; and that order."""
    joined = np.concatenate([samples, lattice])
    order = morton_order(joined)
    return joined[order], order


def _frozen(arrays: tuple) -> tuple:
    """The arrays made read-only: kept by a ``Truth`` and shared by its reports."""
    for array in arrays:
        array.setflags(write=False)
    return arrays


def score(test, truth, *, tau: float | None = None, tau_fraction: float | None = None,
          n_truth_samples: int | None = None, n_test_samples: int | None = None,
          coverage_points: int | None = None, precision: float | None = None,
          seed: int | None = defaults.SEED, edges: bool = True,
          edge_options: dict | None = None, progress=None) -> ScoreReport:
    """Score a test cloud or mesh against a truth mesh.

    Parameters
    ----------
    test : (n, 3) array, Cloud, Mesh, (vertices, faces) tuple or object with vertices/faces
        The reconstruction, metres, in the truth's frame. A ``Cloud`` may carry normals (n, 3).
    truth : Truth, Mesh, (vertices, faces) tuple, or object with vertices/faces
        vertices (n_v, 3) float64 metres; faces (m, 3) int, m >= 1. A ``Truth`` reuses what
        earlier calls built from the same truth (same report, less work).
    tau : float, optional, metres
        Threshold of precision, recall, F-score and coverage.
    tau_fraction : float, optional
        tau as a fraction of the truth's bounding-box diagonal; default
        ``defaults.TAU_FRACTION`` (1 %) when neither is given. Give at most one of the two.
    n_truth_samples : int, optional
        Points sampled on the truth for completeness and recall.
    n_test_samples : int, optional
        Points sampled on a test mesh for accuracy and precision; unused for a cloud.
    coverage_points : int, optional
        Target size of the coverage quadrature lattice (at least one point per truth face).
        Given any of the three counts, the score uses them (the others at 200,000, 200,000 and
        400,000), scores every point of a cloud and runs the edge test on every point.
    precision : float, optional
        With no count given: the sample counts are sized from a pilot until the Chamfer
        distance's standard error is at most this fraction of it and the F-score's at most a
        quarter of it (default ``defaults.PRECISION``, 2 %: 0.005 on F; ``metrics.precision``);
        a cloud's accuracy is averaged over a seeded sample of its points, the coverage lattice
        sized for a standard error of a quarter of it, and the edge metric's false-edge rate
        estimated from a seeded sample of the points far from feature edges (every point near
        one tested) for an edge score's error of a quarter of it. The achieved standard errors
        are in the report.
    seed : int or None
        Seed of all sampling (``np.random.default_rng``, ``precision.point_keys``); the same
        seed gives the same report.
    edges : bool
        Compute the edge metric (``edge_score`` in the report).
    edge_options : dict, optional
        Keyword arguments for ``edges.edge_score`` (``k``, ``rule``, ``threshold``,
        ``feature_angle_deg``, ``tolerance``, ``tolerance_fraction``, ``variant``).
    progress : callable, optional
        Called with the name of each stage as it finishes (``accuracy``, ``completeness``,
        then ``edges`` when computed), e.g. to drive a progress bar.

    Returns
    -------
    ScoreReport

    Raises
    ------
    InputError
        Empty or malformed inputs, NaN/Inf coordinates, a truth with no faces, bad options.
    ParameterError
        A ``precision`` or ``coverage_points`` whose coverage lattice would take more memory
        than ``defaults.COVERAGE_MAX_BYTES`` (refused before any work).

    Warns
    -----
    ScaleMismatchWarning
        Test and truth bounding-box diagonals differ by more than ``SCALE_MISMATCH_RATIO`` (100).
    """
    setup = _Setup(truth, tau=tau, tau_fraction=tau_fraction, n_truth_samples=n_truth_samples,
                   n_test_samples=n_test_samples, coverage_points=coverage_points,
                   precision=precision, seed=seed, edge_options=edge_options)
    test = as_test(test, "test")
    setup.check_frame(test.frame)
    is_mesh = isinstance(test, Mesh)
    if edges:  # fail now rather than after the distances
        setup.check_edges(setup.n_test_samples if is_mesh else len(test.points))
    setup.check_scale(bbox_diagonal(test.vertices if is_mesh else test.points))

    report_stage = progress or (lambda stage: None)
    if setup.precision is not None:
        return _score_to_precision(setup, test, edges, report_stage)
    accuracy = _Accuracy(setup, keep=True)
    # A test mesh's distance structure is set up on a second thread while its samples are drawn
    # and scored (numpy releases the GIL in its kernels).
    with ThreadPoolExecutor(max_workers=1) as pool:
        test_distance = pool.submit(MeshDistance, test) if is_mesh else None
        if is_mesh:
            test_points, test_faces = sample_surface(test, setup.n_test_samples, seed=seed)
            test_normals = face_normals(test.vertices, test.faces)[test_faces]
        else:
            test_points, test_normals = test.points, test.normals
        accuracy.add(test_points, test_normals)
        report_stage("accuracy")
        queries = setup.queries()
        if is_mesh:
            nearest = test_distance.result().query(queries, presorted=True)[0]
        else:
            nearest = cloud_distance(test_points, queries)
    report_stage("completeness")
    edge = None
    if edges:
        edge = edge_report(test_points, setup.mesh, **setup.edge_options)
        report_stage("edges")
    distances = np.concatenate(accuracy.distances)
    return setup.report(accuracy, _summary(distances), setup.split(nearest), edge,
                        test_kind="mesh" if is_mesh else "cloud",
                        population=None if is_mesh else accuracy.n,
                        arrays={"accuracy_distances": distances,
                                "accuracy_faces": np.concatenate(accuracy.faces),
                                "test_points": test_points})


class _Pool:
    """The samples of one side, taken as prefixes of a seeded draw: the first ``n`` are the
    same whatever is taken later. ``base`` holds the first arrays (points first); ``more(n,
    offset)`` draws ``n`` more (None: the base is all there is, a cloud's sample)."""

    def __init__(self, base: tuple, more: Callable[[int, int], tuple] | None):
        self.arrays, self.more = list(base), more

    def take(self, lo: int, hi: int) -> tuple:
        have = len(self.arrays[0])
        if hi > have and self.more is not None:
            extra = self.more(hi - have, have)
            self.arrays = [np.concatenate([a, b]) for a, b in zip(self.arrays, extra,
                                                                   strict=True)]
        return tuple(None if a is None else a[lo:hi] for a in self.arrays)


def _score_to_precision(setup: _Setup, test, edges: bool, report_stage) -> ScoreReport:
    """``score`` with the sample counts sized from ``setup.precision`` (``metrics.precision``).

    A test mesh: its samples are the first of today's ``TEST_MESH_SAMPLES`` draw (the edge
    metric runs on that whole draw, its far points sampled), extended by further seeded draws
    when more are needed. A cloud: its points in ascending ``precision.point_keys``. The truth:
    the first of its ``TRUTH_SAMPLES`` draw, likewise extended. The test mesh's distance
    structure and the edge metric run on two further threads while the samples are scored (all
    three spend their time in numpy, Embree and Open3D kernels that release the GIL)."""
    seed = setup.key_seed
    is_mesh = isinstance(test, Mesh)
    accuracy = _Accuracy(setup, keep=True)
    with ThreadPoolExecutor(max_workers=2) as pool:
        if is_mesh:
            test_distance = pool.submit(MeshDistance, test)
            drawn, faces = sample_surface(test, defaults.TEST_MESH_SAMPLES, seed=setup.seed)
            normals = face_normals(test.vertices, test.faces)

            def more(n: int, at: int) -> tuple[np.ndarray, np.ndarray]:
                points, more_faces = sample_surface(test, n, seed=[seed, 2, at])
                return points, normals[more_faces]

            test_pool = _Pool((drawn, normals[faces]), more)
            population = None
        else:
            drawn = test.points
            rows = smallest_keys(point_keys(drawn, seed, CLOUD_SALT), defaults.CLOUD_SAMPLES)
            test_pool = _Pool((drawn[rows], None if test.normals is None
                               else test.normals[rows]), None)
            population = len(drawn)
        edge = (pool.submit(edge_report, drawn, setup.mesh, **setup.edge_options, seed=seed,
                            precision=setup.precision) if edges else None)
        complete = (lambda q: test_distance.result().query(q)[0]) if is_mesh else (
            lambda q: cloud_distance(drawn, q))
        completeness, lattice = _sample_to_precision(setup, test_pool, accuracy, complete,
                                                     population)
        report_stage("accuracy")
        report_stage("completeness")
        if edge is not None:
            edge = edge.result()
            report_stage("edges")
    distances = np.concatenate(accuracy.distances)
    return setup.report(accuracy, _summary(distances), (completeness, lattice), edge,
                        test_kind="mesh" if is_mesh else "cloud", population=population,
                        arrays={"accuracy_distances": distances,
                                "accuracy_faces": np.concatenate(accuracy.faces),
                                "test_points": test_pool.take(0, accuracy.n)[0]})


def _sample_to_precision(setup: _Setup, test_pool: _Pool, accuracy: _Accuracy,
                         complete: Callable[[np.ndarray], np.ndarray], population: int | None,
                         first: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Score a pilot of each side, then more samples until the plan is met (``precision.plan``,
    at most ``defaults.PRECISION_ROUNDS`` rounds).

    Parameters
    ----------
    test_pool : _Pool
        The test's samples (points, normals), added to ``accuracy``.
    complete : callable
        Nearest distances to the test of truth points (m, 3) -> (m,).
    population : int or None
        A cloud's size (its accuracy side has at most that many samples).
    first : (p + l,) float64, optional
        The distances of the pilot truth samples then the lattice, already found (a stream's
        first pass); else found here.

    Returns
    -------
    completeness : (n_c,) float64, of the first n_c truth samples (``setup.truth_pool``)
    lattice : (l,) float64, of the coverage lattice points (``setup.lattice``)
    """
    pilot = defaults.PILOT_SAMPLES
    if accuracy.n < pilot:
        accuracy.add(*test_pool.take(accuracy.n, pilot))
    truth = setup.truth_pool.take(0, pilot)[0]
    if first is None:
        first = complete(np.concatenate([truth, setup.lattice[1]]))
    completeness = [first[:len(truth)]]
    for _ in range(defaults.PRECISION_ROUNDS):
        have_a, have_c = accuracy.n, sum(map(len, completeness))
        want_a, want_c = plan(np.concatenate(accuracy.distances), np.concatenate(completeness),
                              setup.tau, setup.precision, population)
        if want_a > have_a:
            accuracy.add(*test_pool.take(have_a, want_a))
        if want_c > have_c:
            completeness.append(complete(setup.truth_pool.take(have_c, want_c)[0]))
        if (accuracy.n, sum(map(len, completeness))) == (have_a, have_c):
            break
    return np.concatenate(completeness), first[len(truth):]


Blocks = Callable[[], Iterable[np.ndarray | tuple[np.ndarray, np.ndarray | None]]]


def score_stream(blocks: Blocks, truth, *, name: str = "test", frame: str = "body",
                 tau: float | None = None,
                 tau_fraction: float | None = None,
                 n_truth_samples: int | None = None, coverage_points: int | None = None,
                 precision: float | None = None, seed: int | None = defaults.SEED,
                 edges: bool = True, edge_options: dict | None = None,
                 progress=None) -> ScoreReport:
    """Score a test cloud given block by block, in memory that does not grow with its size.

    The same report as ``score(cloud, truth, ...)`` of the whole cloud (module docstring: every
    statistic equal to ~1e-15 relative, distances exact), without its per-point arrays
    (``accuracy_distances``, ``accuracy_faces`` and ``test_points`` are None).

    Parameters
    ----------
    blocks : callable
        Called with no argument, returns an iterable of blocks, each an (b, 3) float64 array of
        points (metres, the truth's frame) or a ``(points, normals)`` pair, normals (b, 3) or
        None. Called once, and again for each further pass the exact median and 95th percentile
        of accuracy need (none when the cloud has at most ``defaults.QUANTILE_KEEP`` points);
        every call must give the same points in the same order.
    truth : Truth, Mesh, (vertices, faces) tuple, or object with vertices/faces
    name : str
        The test's name in error messages (e.g. ``"test run.h5"``: "test run.h5 points has 1
        row(s) with NaN or Inf, first at row 7"); rows are numbered across blocks.
    tau, tau_fraction, n_truth_samples, coverage_points, precision, seed, edges, edge_options,
    progress
        As ``score``. With ``edges`` the edge metric takes one further pass per
        ``defaults.EDGE_SLAB_POINTS`` points and one or more for points near slab faces
        (``metrics.edges_stream``). Scored to a precision (no count given), the sample of the
        cloud's points is kept as the blocks go by (``precision.KeySample``, at most
        ``defaults.CLOUD_SAMPLES`` points), the pilot truth samples and the lattice are queried
        in the first pass, and further truth samples, when the precision asks for them, in one
        further pass per round.

    Returns
    -------
    ScoreReport

    Raises
    ------
    InputError
        As ``score``; also a stream that gives other points on a later pass.
    """
    setup = _Setup(truth, tau=tau, tau_fraction=tau_fraction, n_truth_samples=n_truth_samples,
                   n_test_samples=None, coverage_points=coverage_points, precision=precision,
                   seed=seed, edge_options=edge_options)
    setup.check_frame(frame, name)
    edge_stream = None
    if edges:  # the options now; the point count against k once it is known
        check_options(np.iinfo(np.int64).max, setup.diagonal, **setup.edge_options)
        edge_stream = EdgeStream(setup.mesh, **setup.edge_options, precision=setup.precision,
                                 seed=setup.key_seed)
    report_stage = progress or (lambda stage: None)
    if setup.precision is not None:
        return _stream_to_precision(setup, blocks, name, edge_stream, report_stage)
    queries = setup.queries()
    nearest = np.full(len(queries), np.inf)
    accuracy = _Accuracy(setup, keep=False)
    pending = []   # points not yet queried by the truth samples and the lattice
    for points, normals in _checked_blocks(blocks, name):
        accuracy.add(points, normals)
        pending.append(points)
        if sum(map(len, pending)) >= defaults.STREAM_BLOCK:
            _reduce_nearest(nearest, pending, queries)
        if edges:
            edge_stream.add(points)
        interrupt.check()   # a swallowed Ctrl-C stops at the next block
    _reduce_nearest(nearest, pending, queries)
    n = accuracy.n
    if n == 0:
        raise InputError(f"{name} points is empty (0 rows)")
    setup.check_scale(float(np.linalg.norm(accuracy.high - accuracy.low)))
    summary = accuracy.summary(lambda: (setup.distance.query(points)[0] for points, _ in
                                        _checked_blocks(blocks, name)))
    report_stage("accuracy")
    report_stage("completeness")
    edge = None
    if edges:
        setup.check_edges(n)
        edge = edge_stream.report(lambda: (points for points, _ in
                                           _checked_blocks(blocks, name)))
        report_stage("edges")
    return setup.report(accuracy, summary, setup.split(nearest), edge, test_kind="cloud",
                        population=n, arrays=dict.fromkeys(_ARRAYS))


def _stream_to_precision(setup: _Setup, blocks: Blocks, name: str,
                         edge_stream: EdgeStream | None, report_stage) -> ScoreReport:
    """``score_stream`` with the sample counts sized from ``setup.precision``: the same report
    as ``score`` of the whole cloud (the same points sampled, the same distances)."""
    sample = KeySample(defaults.CLOUD_SAMPLES, setup.key_seed, CLOUD_SALT)
    pilot = setup.truth_pool.take(0, defaults.PILOT_SAMPLES)[0]
    first = _stream_nearest(blocks, name, np.concatenate([pilot, setup.lattice[1]]),
                            sample=sample, edge_stream=edge_stream)
    if sample.n == 0:
        raise InputError(f"{name} points is empty (0 rows)")
    setup.check_scale(float(np.linalg.norm(sample.high - sample.low)))
    if edge_stream is not None:
        setup.check_edges(sample.n)
    accuracy = _Accuracy(setup, keep=True)
    completeness, lattice = _sample_to_precision(
        setup, _Pool(sample.sample(), None), accuracy,
        lambda queries: _stream_nearest(blocks, name, queries), sample.n, first=first)
    report_stage("accuracy")
    report_stage("completeness")
    edge = None
    if edge_stream is not None:   # after the distances, not beside them: one slab at a time
        edge = edge_stream.report(lambda: (points for points, _ in
                                           _checked_blocks(blocks, name)))
        report_stage("edges")
    return setup.report(accuracy, _summary(np.concatenate(accuracy.distances)),
                        (completeness, lattice), edge, test_kind="cloud", population=sample.n,
                        arrays=dict.fromkeys(_ARRAYS))


def _stream_nearest(blocks: Blocks, name: str, queries: np.ndarray, *,
                    sample: KeySample | None = None,
                    edge_stream: EdgeStream | None = None) -> np.ndarray:
    """One pass over a stream: each query's (m, 3) nearest distance to its points (m,), in the
    queries' order; on the first pass, the blocks also go to the cloud's ``sample`` and the
    ``edge_stream``."""
    order = morton_order(queries)
    ordered = queries[order]
    nearest = np.full(len(queries), np.inf)
    pending = []
    for points, normals in _checked_blocks(blocks, name):
        if sample is not None:
            sample.add(points, normals)
        if edge_stream is not None:
            edge_stream.add(points)
        pending.append(points)
        if sum(map(len, pending)) >= defaults.STREAM_BLOCK:
            _reduce_nearest(nearest, pending, ordered)
        interrupt.check()   # a swallowed Ctrl-C stops at the next block
    _reduce_nearest(nearest, pending, ordered)
    out = np.empty_like(nearest)
    out[order] = nearest
    return out


def _checked_blocks(blocks: Blocks, name: str):
    """The blocks of a stream as validated ``(points, normals)`` pairs, rows numbered across
    blocks (``inputs.as_cloud``)."""
    start = 0
    for block in blocks():
        points, normals = block if isinstance(block, tuple) else (block, None)
        cloud = as_cloud(Cloud(points, normals=normals), name, first_row=start,
                         allow_empty=True)
        start += len(cloud.points)
        yield cloud.points, cloud.normals


def _reduce_nearest(nearest: np.ndarray, pending: list[np.ndarray], queries: np.ndarray
                    ) -> None:
    """Lower ``nearest`` (m,) to each query's distance to the points of ``pending`` (blocks,
    joined, then the list emptied) where that is nearer (``spatial.cloud_distance``, Open3D,
    as ``score`` asks of the whole cloud).

    Queries whose nearest distance so far is below their distance to the points' bounding box
    cannot come nearer and are not asked.
    """
    if not any(len(block) for block in pending):
        return
    points = np.concatenate(pending) if len(pending) > 1 else pending[0]
    pending.clear()
    lo, hi = bounds(points)
    outside = np.linalg.norm(np.maximum(0.0, np.maximum(lo - queries, queries - hi)), axis=1)
    ask = ~(nearest < outside * (1 - 1e-9))   # margin: the box distance's rounding
    if ask.any():
        np.minimum.at(nearest, np.flatnonzero(ask), cloud_distance(points, queries[ask]))


class _Setup:
    """What a score derives from the truth and the options, validated before any work."""

    def __init__(self, truth, *, tau, tau_fraction, n_truth_samples, n_test_samples,
                 coverage_points, precision, seed, edge_options):
        self.prepared = Truth.of(truth)
        self.mesh = self.prepared.mesh
        if seed is not None and (isinstance(seed, bool) or
                                 not isinstance(seed, int | np.integer) or seed < 0):
            raise InputError(f"seed must be a non-negative integer or None, got {seed!r}")
        self.seed = seed
        # The seed of the keys and further draws of a score to a precision (a fresh one when
        # the caller asks for fresh randomness).
        self.key_seed = (int(np.random.SeedSequence().generate_state(1)[0]) if seed is None
                         else int(seed))
        counts = (n_truth_samples, n_test_samples, coverage_points)
        if precision is not None and any(c is not None for c in counts):
            raise InputError("give a precision or sample counts (n_truth_samples, "
                             "n_test_samples, coverage_points), not both")
        self.precision = (None if any(c is not None for c in counts)
                          else check_precision(defaults.PRECISION if precision is None
                                               else precision))
        defaults_counts = (defaults.TRUTH_SAMPLES, defaults.TEST_MESH_SAMPLES,
                           defaults.COVERAGE_POINTS)
        n_truth_samples, n_test_samples, coverage_points = (
            d if c is None else c for c, d in zip(counts, defaults_counts, strict=True))
        self.n_truth_samples = _count(n_truth_samples, "n_truth_samples")
        self.n_test_samples = _count(n_test_samples, "n_test_samples")
        self.coverage_points = _count(coverage_points, "coverage_points")
        self.lattice_size = (self.coverage_points if self.precision is None
                             else lattice_size(self.precision))
        self.check_lattice()
        self.diagonal = self.prepared.diagonal
        self.tau = resolve_length(tau, tau_fraction, defaults.TAU_FRACTION, self.diagonal, "tau")
        self.edge_options = dict(edge_options or {})
        unknown = set(self.edge_options) - _EDGE_OPTIONS
        if unknown:
            raise InputError(f"edge_options has unknown key(s) {sorted(unknown)}; "
                                    f"allowed: {sorted(_EDGE_OPTIONS)}")

    @property
    def distance(self) -> MeshDistance:
        return self.prepared.distance

    def check_lattice(self) -> None:
        """Refuse, before any work, a coverage lattice whose memory
        (``defaults.LATTICE_BYTES_PER_POINT`` a point) exceeds ``defaults.COVERAGE_MAX_BYTES``,
        naming the argument that sized it (``precision`` or ``coverage_points``) and the value
        that fits."""
        levels = subdivision_levels(self.mesh, self.lattice_size,
                                    defaults.COVERAGE_MAX_SUBDIVISION)
        points = int(np.sum(levels**2))
        allowed = defaults.COVERAGE_MAX_BYTES // defaults.LATTICE_BYTES_PER_POINT
        if points <= allowed:
            return
        faces = self.mesh.n_faces
        # A request of s points gives at most (sqrt(s) + sqrt(faces))**2: each face's level is
        # below sqrt(its share of s) + 1 (``sampling.subdivision_levels``).
        fits = math.floor((math.sqrt(allowed) - math.sqrt(faces))**2) if faces < allowed else 0
        name = "coverage_points" if self.precision is None else "precision"
        if fits < lattice_size(0.5):   # not even the coarsest precision's lattice
            fix = f"the truth's {faces:,} faces need more than that at any {name}"
        elif self.precision is None:
            fix = f"give at most {fits:,}"
        else:   # lattice_size(p) = 4 / p**2, p rounded up to two digits
            digit = 10.0**(math.floor(math.log10(2 / math.sqrt(fits))) - 1)
            fix = f"give at least {math.ceil(2 / math.sqrt(fits) / digit) * digit:.2g}"
        value = f"{self.coverage_points:,}" if self.precision is None else f"{self.precision:g}"
        raise ParameterError(
            f"{name} {value} asks a coverage lattice of {points:,} points on the truth's "
            f"{faces:,} faces, about {points * defaults.LATTICE_BYTES_PER_POINT / 1e9:,.1f} GB "
            f"of memory, more than the {defaults.COVERAGE_MAX_BYTES / 1e9:.1f} GB allowed; "
            f"{fix}", argument=name)

    def check_frame(self, frame: str, name: str = "test") -> None:
        """Refuse two different known frames; when either is ``"unknown"`` (a file that
        records none), go on and say so (``FrameAssumedWarning``)."""
        truth = self.mesh.frame
        if frame == truth != UNKNOWN:
            return
        if frame == truth:
            note = f"neither {name} nor the truth records its frame; compared as given"
        elif frame == UNKNOWN:
            note = (f"{name} records no frame (unknown); compared as if in the truth's {truth} "
                    "frame")
        elif truth == UNKNOWN:
            note = (f"the truth records no frame (unknown); compared as if in the {frame} frame "
                    f"of {name}")
        else:
            raise InputError(f"{name} is in the {frame} frame but truth in the "
                                    f"{truth} frame: register both in one frame")
        warnings.warn(note, FrameAssumedWarning, stacklevel=3)

    def check_edges(self, n_points: int) -> None:
        k = self.edge_options.get("k", defaults.EDGE_K)
        if isinstance(k, int | np.integer) and k >= 4 and n_points < k:
            raise InputError(
                f"test has {n_points} points, fewer than the edge metric's k = {k} "
                "(pass edges=False or a smaller edge_options['k'])")
        check_options(n_points, self.diagonal, **self.edge_options)

    def check_scale(self, test_size: float) -> None:
        diagonal = self.diagonal
        if test_size > 0 and max(test_size / diagonal, diagonal / test_size) \
                > defaults.SCALE_MISMATCH_RATIO:
            warnings.warn(
                f"test and truth sizes differ by "
                f"{max(test_size / diagonal, diagonal / test_size):.0f}x (bounding-box "
                f"diagonals {test_size:.4g} and {diagonal:.4g}): probably km against m",
                ScaleMismatchWarning, stacklevel=3)

    @cached_property
    def truth_pool(self) -> _Pool:
        """The truth's samples (points, faces) of a score to a precision: the first of its
        ``TRUTH_SAMPLES`` draw, then further seeded draws."""
        return _Pool(self.prepared.samples(defaults.TRUTH_SAMPLES, _child_seed(self.seed)),
                     lambda n, at: sample_surface(self.mesh, n, seed=[self.key_seed, 1, at]))

    @cached_property
    def lattice(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``Truth.lattice`` of this score: ``coverage_points``, or the size its precision
        asks (``precision.lattice_size``)."""
        return self.prepared.lattice(self.lattice_size)

    @cached_property
    def truth_samples(self) -> tuple[np.ndarray, np.ndarray]:
        """``Truth.samples`` of this score, drawn once (fresh ones each call when unseeded)."""
        return self.prepared.samples(self.n_truth_samples, _child_seed(self.seed))

    @cached_property
    def _queries(self) -> tuple[np.ndarray, np.ndarray]:
        seed = _child_seed(self.seed)
        if seed is None:  # the samples this score reports
            return _in_morton_order(self.truth_samples[0],
                                    self.prepared.lattice(self.coverage_points)[1])
        return self.prepared.queries(self.n_truth_samples, seed, self.coverage_points)

    def queries(self) -> np.ndarray:
        """Truth samples and coverage lattice points, (n_truth_samples + l, 3), in Morton order
        (``Truth.queries``): completeness and coverage in one nearest-distance query."""
        return self._queries[0]

    def split(self, nearest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The nearest test distances of the points of ``queries()``, in their order, as those
        of the truth samples and those of the lattice points."""
        unordered = np.empty_like(nearest)
        unordered[self._queries[1]] = nearest
        return unordered[:self.n_truth_samples], unordered[self.n_truth_samples:]

    def report(self, accuracy: _Accuracy, acc: dict, nearest: tuple[np.ndarray, np.ndarray],
               edge, *, test_kind: str, population: int | None, arrays: dict) -> ScoreReport:
        """The report from the accuracy statistics and the nearest test distances of the first
        truth samples and of the lattice points (``nearest``); ``population`` the size of a
        test cloud, whose points were drawn without replacement (None for a mesh's samples)."""
        completeness, lattice_distance = nearest
        n_samples = len(completeness)
        if self.precision is None:
            truth_points, truth_faces = self.truth_samples
        else:
            truth_points, truth_faces = self.truth_pool.take(0, n_samples)
        levels, _, lattice_faces = self.lattice
        comp = _summary(completeness)
        precision = accuracy.within / accuracy.n
        recall = float(np.mean(completeness < self.tau))
        fscore = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
        covered = np.bincount(lattice_faces, weights=lattice_distance < self.tau,
                              minlength=self.mesh.n_faces)
        face_coverage = covered / levels**2
        areas = self.prepared.areas
        coverage = float(np.sum(areas * face_coverage) / areas.sum())
        normal_consistency = (None if accuracy.cos_sum is None
                              else float(accuracy.cos_sum / accuracy.n))
        # A cloud scored point by point (n == population) has no sampling error.
        acc_se = acc.get("se", 0.0)   # a stream of every point keeps no distances: 0 below
        if population is not None:
            acc_se *= np.sqrt(max(0.0, 1.0 - accuracy.n / population))
        precision_se = proportion_se(precision, accuracy.n, population)
        recall_se = proportion_se(recall, n_samples)
        return ScoreReport(
            n_points=accuracy.n, n_truth_samples=n_samples, tau_m=self.tau,
            truth_diagonal_m=self.diagonal,
            **{f"accuracy_{k}_m": acc[k] for k in _STATS},
            **{f"completeness_{k}_m": comp[k] for k in _STATS},
            chamfer_m=0.5 * (acc["mean"] + comp["mean"]),
            hausdorff_m=max(acc["max"], comp["max"]), accuracy_mean_se_m=float(acc_se),
            completeness_mean_se_m=comp["se"], chamfer_se_m=0.5 * float(np.hypot(acc_se,
                                                                                comp["se"])),
            precision=float(precision), recall=recall, fscore=float(fscore),
            coverage=coverage, precision_se=precision_se, recall_se=recall_se,
            fscore_se=fscore_se(precision, recall, precision_se, recall_se),
            coverage_se=proportion_se(coverage, len(lattice_faces)),
            target_precision=self.precision, normal_consistency=normal_consistency,
            edge_score=None if edge is None else edge.score, test_kind=test_kind,
            seed=self.seed, n_test_points=population, **arrays,
            completeness_distances=completeness,
            truth_points=truth_points, truth_point_faces=truth_faces,
            face_coverage=face_coverage, edge=edge)


class _Accuracy:
    """Running accuracy statistics (test points -> truth surface) over blocks of test points.

    Keeps the count, sum, sum of squares and maximum of the distances, the count within tau,
    the sum of |cos| between test normals and the nearest truth faces' normals, the running
    bounding box of the points, and (``keep``) every block's distances and faces; without
    ``keep``, the first-pass counts of ``_RankFinder``.
    """

    def __init__(self, setup: _Setup, *, keep: bool):
        self.setup = setup
        self.n = self.within = 0
        self.total = self.squares = 0.0
        self.top = -np.inf
        self.cos_sum = None
        self.low, self.high = np.full(3, np.inf), np.full(3, -np.inf)
        self.keep = keep
        self.distances, self.faces = [], []
        self.ranks = None if keep else _RankFinder()

    def add(self, points: np.ndarray, normals: np.ndarray | None) -> None:
        """Add a block: points (b, 3) float64 metres, normals (b, 3) unit or None."""
        if len(points) == 0:
            return
        if (normals is None) != (self.cos_sum is None) and self.n > 0:
            raise InputError("test blocks must all have normals or none")
        distance, faces, _ = self.setup.distance.query(points)
        self.n += len(distance)
        self.total += float(distance.sum())
        self.squares += float(np.sum(distance**2))
        self.top = max(self.top, float(distance.max()))
        self.within += int(np.count_nonzero(distance < self.setup.tau))
        if normals is not None:
            cos = np.einsum("ij,ij->i", normals, self.setup.distance.normals[faces])
            self.cos_sum = (self.cos_sum or 0.0) + float(np.sum(np.abs(cos)))
        low, high = bounds(points)
        self.low, self.high = np.minimum(self.low, low), np.maximum(self.high, high)
        if self.keep:
            self.distances.append(distance)
            self.faces.append(faces)
        else:
            self.ranks.first_pass(distance)

    def summary(self, again: Callable[[], Iterable[np.ndarray]]) -> dict[str, float]:
        """Mean, RMS, median, 95th percentile and max; the order statistics exact, by further
        passes over the distances (``again()`` yields them block by block) when needed."""
        p50, p95 = self.ranks.percentiles(self.n, [50, 95], again)
        return {"mean": self.total / self.n, "rms": float(np.sqrt(self.squares / self.n)),
                "median": p50, "p95": p95, "max": self.top}


class _RankFinder:
    """Exact order statistics of a stream of non-negative float64, in bounded memory.

    The bit patterns of non-negative floats, read as unsigned integers, sort as the floats do.
    The first pass counts the values by their top ``_BITS[0]`` bits (and keeps them while
    there are at most ``defaults.QUANTILE_KEEP``); each later pass, for every wanted rank whose
    bin is still too full to keep, counts that bin's values by their next bits, or keeps the
    bin's values to sort once it holds at most ``QUANTILE_KEEP``. A bin refined to all 64 bits
    holds a single value. Memory: the counts (2**20 int64) and the kept values.
    """

    _BITS = (20, 16, 16, 12)

    def __init__(self):
        self.counts = np.zeros(1 << self._BITS[0], dtype=np.int64)
        self.small: list[np.ndarray] | None = []   # every value, while there are few

    def first_pass(self, values: np.ndarray) -> None:
        keys = values.view(np.uint64)
        self.counts += np.bincount(keys >> np.uint64(64 - self._BITS[0]),
                                   minlength=len(self.counts))
        if self.small is not None:
            self.small.append(values)
            if sum(len(v) for v in self.small) > defaults.QUANTILE_KEEP:
                self.small = None

    def percentiles(self, n: int, q: list[float], again: Callable[[], Iterable[np.ndarray]]
                    ) -> list[float]:
        """``np.percentile(values, q)`` (linear interpolation) of the ``n`` values streamed."""
        if self.small is not None:
            return [float(v) for v in np.percentile(np.concatenate(self.small), q)]
        fractions = np.true_divide(q, 100)
        virtual = (n - 1) * fractions   # numpy's "linear" method, step by step
        previous = np.floor(virtual).astype(np.int64)
        following = np.minimum(previous + 1, n - 1)
        values = self._values(sorted(set(previous) | set(following)), again, n)
        out = []
        for v, i, j in zip(virtual, previous, following, strict=True):
            a, b, t = values[i], values[j], v - i
            diff = b - a
            out.append(float(b - diff * (1 - t) if t >= 0.5 else a + diff * t))
        return out

    def _values(self, ranks: list[int], again, n: int) -> dict[int, np.float64]:
        """The values of 0-based ascending ranks, by radix selection (class docstring)."""
        found = {}
        # per rank: (prefix of its bin, bits in the prefix, rank within the bin, keep the bin)
        state = {r: self._narrow(self.counts, 0, 0, r) for r in ranks}
        while state:
            tasks = sorted({(p, used, keep) for p, used, _, keep in state.values()})
            counts = {t: np.zeros(1 << self._next_bits(t[1]), np.int64) for t in tasks
                      if not t[2]}
            kept = {t: [] for t in tasks if t[2]}
            seen = 0
            for values in again():
                keys = values.view(np.uint64)
                seen += len(keys)
                for prefix, used, keep in tasks:
                    inside = keys[(keys >> np.uint64(64 - used)) == prefix]
                    if keep:
                        kept[prefix, used, keep].append(inside)
                    else:
                        bits = self._next_bits(used)
                        digit = (inside >> np.uint64(64 - used - bits)) & np.uint64((1 << bits) - 1)
                        counts[prefix, used, keep] += np.bincount(digit, minlength=1 << bits)
                interrupt.check()
            if seen != n:
                raise InputError(f"the test gave {seen} points on a second pass, "
                                        f"{n} on the first: it changed while it was scored")
            for r, (prefix, used, within, keep) in list(state.items()):
                if keep:
                    values = np.sort(np.concatenate(kept[prefix, used, keep]))
                    found[r] = values.view(np.float64)[within]
                    del state[r]
                else:
                    state[r] = self._narrow(counts[prefix, used, keep], prefix, used, within)
                    prefix, used, within, keep = state[r]
                    if used == 64:   # one bit pattern: one value
                        found[r] = np.array([prefix], np.uint64).view(np.float64)[0]
                        del state[r]
        return found

    def _next_bits(self, used: int) -> int:
        """Bits of the digit after a prefix of ``used`` bits."""
        return self._BITS[list(np.cumsum((0, *self._BITS))).index(used)]

    @staticmethod
    def _narrow(counts: np.ndarray, prefix: int, used: int, within: int):
        """The bin of ``counts`` (over the next bits after ``prefix``) holding rank ``within``:
        its longer prefix, the rank inside it, and whether it is small enough to keep."""
        cumulative = np.cumsum(counts)
        digit = int(np.searchsorted(cumulative, within, side="right"))
        before = int(cumulative[digit - 1]) if digit > 0 else 0
        bits = int(np.log2(len(counts)))
        return ((prefix << bits) | digit, used + bits, within - before,
                int(counts[digit]) <= defaults.QUANTILE_KEEP)


def _child_seed(seed: int | None):
    """Seed of the truth sampling, independent of the test-mesh sampling drawn from ``seed``.

    ``[seed, 1]`` is a distinct stream for ``np.random.default_rng`` (SeedSequence entropy).
    """
    return None if seed is None else [seed, 1]


__all__ = ["Cloud", "Mesh", "ScoreReport", "Truth", "score", "score_stream"]
