"""Score a reconstruction (a cloud or a mesh) against a truth mesh: ``score(test, truth)``.

Definitions (d(x, Y) is the distance from x to Y; "within tau" means d < tau, as in Tanks and
Temples, Knapitsch et al. 2017, and Open3D's ``compute_metrics``):

- accuracy: d(test point, truth surface), exact point-to-triangle in float64, for every test
  point (a test mesh is first sampled uniformly by area, ``n_test_samples`` points).
- completeness: d(truth sample, test), for ``n_truth_samples`` points sampled uniformly by area on
  the truth: to a test cloud by nearest neighbour (scipy cKDTree), to a test mesh exactly.
- mean, RMS, median, 95th percentile and max of each; Chamfer = (mean accuracy + mean
  completeness) / 2; Hausdorff = max(max accuracy, max completeness).
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
and its coverage lattice are then made once and reused, and every report is the same as with a
fresh truth.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, fields

import numpy as np

from metrics import defaults
from metrics.distance import MeshDistance
from metrics.edges import EdgeReport, check_options, edge_report, resolve_length
from metrics.errors import MetricsInputError, ScaleMismatchWarning
from metrics.inputs import (
    Cloud,
    Mesh,
    as_mesh,
    as_test,
    bbox_diagonal,
    face_areas,
    face_normals,
)
from metrics.sampling import coverage_lattice, sample_surface, subdivision_levels
from metrics.spatial import cloud_distance

_STATS = ("mean", "rms", "median", "p95", "max")
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
        Test points scored (the cloud's size, or the samples drawn on a test mesh).
    n_truth_samples : int
    tau_m : float
    truth_diagonal_m : float
        Bounding-box diagonal of the truth.
    accuracy_mean_m, accuracy_rms_m, accuracy_median_m, accuracy_p95_m, accuracy_max_m : float
    completeness_mean_m, completeness_rms_m, completeness_median_m, completeness_p95_m,
    completeness_max_m : float
    chamfer_m, hausdorff_m : float
    precision, recall, fscore : float, in [0, 1]
    coverage : float, in [0, 1]
    normal_consistency : float in [0, 1] or None
    edge_score : float in [0, 1] or None (None when not computed)
    test_kind : {"cloud", "mesh"}
    seed : int or None
    accuracy_distances : (n_points,) float64
    accuracy_faces : (n_points,) int64, truth face nearest each test point
    test_points : (n_points, 3) float64
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
    precision: float
    recall: float
    fscore: float
    coverage: float
    normal_consistency: float | None
    edge_score: float | None
    test_kind: str
    seed: int | None
    accuracy_distances: np.ndarray = field(repr=False)
    accuracy_faces: np.ndarray = field(repr=False)
    test_points: np.ndarray = field(repr=False)
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
            elif not isinstance(value, np.ndarray):
                out[f.name] = value
        return out

    def arrays(self) -> dict[str, np.ndarray]:
        """The per-point and per-face arrays, by field name."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if isinstance(getattr(self, f.name), np.ndarray)}


def _summary(distance: np.ndarray) -> dict[str, float]:
    p50, p95 = np.percentile(distance, [50, 95])
    return {"mean": float(distance.mean()), "rms": float(np.sqrt(np.mean(distance**2))),
            "median": float(p50), "p95": float(p95), "max": float(distance.max())}


def _count(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise MetricsInputError(f"{name} must be a positive integer, got {value!r}")
    return int(value)


class Truth:
    """A truth mesh made ready once for scoring many tests against it.

    Holds what ``score`` derives from the truth alone, built on first use and reused by every
    later call: the exact-distance structure (``MeshDistance``), the surface samples per
    ``(n_truth_samples, seed)``, the coverage lattice per ``coverage_points`` and the face areas.
    A report against a ``Truth`` is identical to one against the bare mesh.

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


def _frozen(arrays: tuple) -> tuple:
    """The arrays made read-only: kept by a ``Truth`` and shared by its reports."""
    for array in arrays:
        array.setflags(write=False)
    return arrays


def score(test, truth, *, tau: float | None = None, tau_fraction: float | None = None,
          n_truth_samples: int = defaults.TRUTH_SAMPLES,
          n_test_samples: int = defaults.TEST_MESH_SAMPLES,
          coverage_points: int = defaults.COVERAGE_POINTS,
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
    n_truth_samples : int
        Points sampled on the truth for completeness and recall (default 200,000).
    n_test_samples : int
        Points sampled on a test mesh for accuracy and precision (default 200,000); unused for a
        cloud.
    coverage_points : int
        Target size of the coverage quadrature lattice (default 400,000; at least one point per
        truth face).
    seed : int or None
        Seed of all sampling (``np.random.default_rng``); the same seed gives the same report.
    edges : bool
        Compute the edge metric (``edge_score`` in the report; ~3 s per million points).
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
    MetricsInputError
        Empty or malformed inputs, NaN/Inf coordinates, a truth with no faces, bad options.

    Warns
    -----
    ScaleMismatchWarning
        Test and truth bounding-box diagonals differ by more than ``SCALE_MISMATCH_RATIO`` (100).
    """
    prepared = Truth.of(truth)
    truth = prepared.mesh
    test = as_test(test, "test")
    if test.frame != truth.frame:
        raise MetricsInputError(f"test is in the {test.frame} frame but truth in the "
                                f"{truth.frame} frame: register both in one frame")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int | np.integer)
                             or seed < 0):
        raise MetricsInputError(f"seed must be a non-negative integer or None, got {seed!r}")
    n_truth_samples = _count(n_truth_samples, "n_truth_samples")
    n_test_samples = _count(n_test_samples, "n_test_samples")
    coverage_points = _count(coverage_points, "coverage_points")
    diagonal = prepared.diagonal
    tau = resolve_length(tau, tau_fraction, defaults.TAU_FRACTION, diagonal, "tau")
    edge_options = dict(edge_options or {})
    unknown = set(edge_options) - _EDGE_OPTIONS
    if unknown:
        raise MetricsInputError(f"edge_options has unknown key(s) {sorted(unknown)}; allowed: "
                                f"{sorted(_EDGE_OPTIONS)}")

    if isinstance(test, Mesh):
        test_points, test_faces = sample_surface(test, n_test_samples, seed=seed)
        test_normals = face_normals(test.vertices, test.faces)[test_faces]
        test_size = bbox_diagonal(test.vertices)
    else:
        test_points, test_normals = test.points, test.normals
        test_size = bbox_diagonal(test_points)
    if edges:  # fail now rather than after the distances
        k = edge_options.get("k", defaults.EDGE_K)
        if isinstance(k, int | np.integer) and k >= 4 and len(test_points) < k:
            raise MetricsInputError(
                f"test has {len(test_points)} points, fewer than the edge metric's k = {k} "
                "(pass edges=False or a smaller edge_options['k'])")
        check_options(len(test_points), diagonal, **edge_options)
    if test_size > 0 and max(test_size / diagonal, diagonal / test_size) \
            > defaults.SCALE_MISMATCH_RATIO:
        warnings.warn(
            f"test and truth sizes differ by {max(test_size / diagonal, diagonal / test_size):.0f}"
            f"x (bounding-box diagonals {test_size:.4g} and {diagonal:.4g}): probably km "
            "against m", ScaleMismatchWarning, stacklevel=2)

    report_stage = progress or (lambda stage: None)
    # Accuracy: test -> truth surface, exact.
    truth_distance = prepared.distance
    accuracy, accuracy_faces, _ = truth_distance.query(test_points)
    report_stage("accuracy")

    # Completeness: truth samples -> test; coverage lattice -> test (one query for both).
    truth_points, truth_faces = prepared.samples(n_truth_samples, _child_seed(seed))
    levels, lattice, lattice_faces = prepared.lattice(coverage_points)
    queries = np.concatenate([truth_points, lattice])
    if isinstance(test, Mesh):
        both = MeshDistance(test).query(queries)[0]
    else:
        both = cloud_distance(test_points, queries)
    completeness, lattice_distance = both[:n_truth_samples], both[n_truth_samples:]
    report_stage("completeness")

    acc, comp = _summary(accuracy), _summary(completeness)
    precision = float(np.mean(accuracy < tau))
    recall = float(np.mean(completeness < tau))
    fscore = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    per_face = levels**2
    covered = np.bincount(lattice_faces, weights=lattice_distance < tau,
                          minlength=truth.n_faces)
    face_coverage = covered / per_face
    areas = prepared.areas
    coverage = float(np.sum(areas * face_coverage) / areas.sum())
    normal_consistency = None
    if test_normals is not None:
        cos = np.einsum("ij,ij->i", test_normals, truth_distance.normals[accuracy_faces])
        normal_consistency = float(np.mean(np.abs(cos)))

    edge = None
    if edges:
        edge = edge_report(test_points, truth, **edge_options)
        report_stage("edges")

    return ScoreReport(
        n_points=len(test_points), n_truth_samples=n_truth_samples, tau_m=tau,
        truth_diagonal_m=diagonal,
        **{f"accuracy_{k}_m": acc[k] for k in _STATS},
        **{f"completeness_{k}_m": comp[k] for k in _STATS},
        chamfer_m=0.5 * (acc["mean"] + comp["mean"]),
        hausdorff_m=max(acc["max"], comp["max"]),
        precision=precision, recall=recall, fscore=float(fscore), coverage=coverage,
        normal_consistency=normal_consistency,
        edge_score=None if edge is None else edge.score,
        test_kind="mesh" if isinstance(test, Mesh) else "cloud", seed=seed,
        accuracy_distances=accuracy, accuracy_faces=accuracy_faces, test_points=test_points,
        completeness_distances=completeness, truth_points=truth_points,
        truth_point_faces=truth_faces, face_coverage=face_coverage, edge=edge)


def _child_seed(seed: int | None):
    """Seed of the truth sampling, independent of the test-mesh sampling drawn from ``seed``.

    ``[seed, 1]`` is a distinct stream for ``np.random.default_rng`` (SeedSequence entropy).
    """
    return None if seed is None else [seed, 1]


__all__ = ["Cloud", "Mesh", "ScoreReport", "Truth", "score"]
