"""recon's public API: the whole pipeline in a handful of verbs.

>>> from recon import api
>>> log = api.simulate("asteroid-lrf", "run.h5", seed=0)        # sim/: write a strike log
>>> cloud = api.ingest(log)                                      # body-frame Cloud
>>> surface = api.reconstruct(cloud, method="auto")              # Surface (a Mesh)
>>> report = api.score(surface, truth=log)                       # metrics.ScoreReport
>>> api.save(surface, "surface.ply")                             # atomic; never over an input
>>> pictures = api.edges(cloud, truth=log, output="edges")        # EdgesResult: PLY + PNG
>>> table = api.compare(cloud, truth=log, output="cmp")          # CompareResult

Every verb takes recon's own types (``formats.geometry.Cloud`` and ``Mesh``, a strike log path),
the plain data they wrap, or Open3D and trimesh point clouds and meshes, and returns recon's
types or a result dataclass (``ReconstructResult``, ``CompareResult``, ``StabilityResult``...).
Files are read once per call and written atomically: a file appears only when complete, and a
verb refuses to write over one of its own inputs. The ``recon`` command calls these verbs and
nothing else of recon, so a script gets what ``recon`` prints: the policy (which truth a log
implies, what ``auto`` decides, what a comparison writes) lives here and in the modules these
verbs call. Bad input raises a ``formats.errors.ReconError`` subclass with a one-line message;
a message about one argument starts with the parameter's name as passed here (``resume: ...``,
``overrides 'orbit.radius': ...``), which the error also carries as ``argument`` (``recon``
prints the option instead: ``--resume``, ``--set``).

Importing this module is light (no numpy, h5py or Open3D): each verb imports what it needs.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from formats.errors import ParameterError

if TYPE_CHECKING:
    from formats.geometry import Cloud, Frame, Mesh
    from metrics import ScoreReport
    from recon.registration.refine import Refinement
    from recon.surfaces.reconstruct import Surface

__all__ = [
    "AltimetryExport",
    "AltimetryResult",
    "CompareResult",
    "DemoResult",
    "EdgesResult",
    "IngestResult",
    "ParameterError",
    "ReconstructResult",
    "SimulatedLog",
    "StabilityResult",
    "StudiesResult",
    "StudyResult",
    "TrajectoryResult",
    "check_scheduler",
    "check_seed",
    "compare",
    "default_truth",
    "demo",
    "edges",
    "export_altimetry",
    "follow",
    "ingest",
    "ingest_altimetry",
    "ingest_file",
    "is_altimetry",
    "is_kernel",
    "load",
    "method_cost",
    "method_listing",
    "presets",
    "reconstruct",
    "reconstruct_file",
    "refine",
    "report",
    "save",
    "scene_keys",
    "score",
    "simulate",
    "stability",
    "studies",
    "study",
    "study_all",
    "trajectory",
    "truth_of",
]

DEMO_SCENE = "asteroid-lrf-slew"   # the paper's slewing single-beam LRF at 85 deg, 50 rotations
DEMO_METHOD = "screened-poisson"   # the most accurate method on the noisy ellipsoid (compare)
DEMO_SEED = 0
# Rows of the demo's table: label and ScoreReport attribute.
DEMO_SCORE_ROWS = (("Chamfer [m]", "chamfer_m"), ("Hausdorff [m]", "hausdorff_m"),
                   ("F-score at tau", "fscore"), ("coverage", "coverage"),
                   ("edge score", "edge_score"))


def _jsonable(value):
    from recon.experiments.sweep import to_jsonable

    return to_jsonable(value)


# ------------------------------------------------------------------------------ results


@dataclass(frozen=True)
class SimulatedLog(os.PathLike):
    """A strike log the simulator wrote: usable wherever a log path is (``os.PathLike``).

    Attributes
    ----------
    path : Path
    summary : dict
        What ``sim.simulate`` reports: shots, strikes, pulses, duration_s, wall_time_s, ...
    """

    path: Path
    summary: dict = field(repr=False)

    def __fspath__(self) -> str:
        return str(self.path)


@dataclass(frozen=True)
class IngestResult:
    """A registered cloud written to a file (``ingest_file``, ``follow``).

    Attributes
    ----------
    n_points : int
    frame : {"body", "inertial"}
    output : Path
    refined : bool
        Registered with the poses a refinement corrected.
    """

    n_points: int
    frame: str
    output: Path
    refined: bool = False


@dataclass(frozen=True)
class AltimetryResult:
    """A mission's altimetry product read into a body-frame cloud file (``ingest_altimetry``).

    Attributes
    ----------
    n_points : int
    dropped : dict of str -> int
        Flagged rows dropped, by reason.
    product : str
        What the product is (e.g. OSIRIS-REx OLA Level 2).
    output : Path
    """

    n_points: int
    dropped: dict
    product: str
    output: Path


@dataclass(frozen=True)
class AltimetryExport:
    """A strike log written as a mission's altimetry product (``export_altimetry``).

    Attributes
    ----------
    n_returns, n_no_return : int
        Rows of strikes, and (OLA) of pulses that struck nothing.
    product : str
    written : tuple of Path
    """

    n_returns: int
    n_no_return: int
    product: str
    written: tuple


@dataclass(frozen=True)
class TrajectoryResult:
    """A log's recorded poses written as text or SPICE kernels (``trajectory``).

    Attributes
    ----------
    n_shots : int
    frame : {"body", "inertial"} or None
        Of a text trajectory (kernels hold both frames: None).
    epoch_et : float or None
        ET [s, TDB past J2000] of the log's time 0 in a kernel (None for text).
    written : tuple of Path
    """

    n_shots: int
    frame: str | None
    epoch_et: float | None
    written: tuple


@dataclass(frozen=True)
class ReconstructResult:
    """One reconstruction of a cloud, and the mesh file written (``reconstruct_file``).

    Attributes
    ----------
    surface : recon.surfaces.reconstruct.Surface
        The mesh with its method, resolved parameters and run ``info`` (``wall_time_s``,
        ``watertight``, ``peak_memory_mb`` when isolated, ``estimate``, and ``auto``).
    input : str or None
        The file read (None for data in memory).
    output : Path or None
        The mesh written.
    n_points : int
        Points after preparation.
    spacing_m, noise_m : float
        Their typical spacing and noise, metres.
    view_points : bool
        Whether the cloud had view points (sensor positions).
    label : str
        The run (method and parameters) in words.
    """

    surface: Surface
    input: str | None
    output: Path | None
    n_points: int
    spacing_m: float
    noise_m: float
    view_points: bool
    label: str

    @property
    def estimate(self) -> dict:
        """The truth-free predicted Chamfer distance and F-score with their band."""
        return self.surface.info["estimate"]

    @property
    def auto(self) -> dict | None:
        """``method="auto"``'s candidates, choice and reason, or None."""
        return self.surface.info.get("auto")

    def to_dict(self) -> dict:
        """A JSON-ready summary (what ``recon reconstruct --json`` prints)."""
        info = {k: v for k, v in self.surface.info.items() if k != "auto"}
        auto = {} if self.auto is None else {"auto": self.auto}
        return _jsonable({
            "input": self.input, **auto, "n_points": self.n_points,
            "spacing_m": self.spacing_m, "noise_m": self.noise_m,
            "view_points": self.view_points, "method": self.surface.method,
            "params": self.surface.params, "label": self.label,
            "output": None if self.output is None else str(self.output),
            "n_vertices": self.surface.n_vertices, "n_faces": self.surface.n_faces, **info})


@dataclass(frozen=True)
class CompareResult:
    """Every method on one cloud, scored against the truth (``compare``).

    Attributes
    ----------
    records : list of dict
        One per run, ranked by Chamfer (failures last, with their reasons); the columns of
        results.csv.
    table : str
        The ranking as text.
    pareto_chamfer, pareto_fscore : list of dict
        The runs on the time-against-accuracy Pareto fronts (``label``, ``wall_time_s``, ...).
    full_grid : dict
        The full parameter grid's remaining runs and their estimated time.
    csv, json, png : Path
        results.csv, results.json and speed_accuracy.png.
    auto : dict or None
        With ``auto=True``: ``choice`` and ``agreement`` (where the choice ranks on the truth).
    auto_text : str or None
        The candidates table and the agreement line.
    """

    records: list
    table: str
    pareto_chamfer: list
    pareto_fscore: list
    full_grid: dict
    csv: Path
    json: Path
    png: Path
    auto: dict | None = None
    auto_text: str | None = None

    @property
    def full_grid_text(self) -> str:
        """One line: how long the full grid would take."""
        from recon.experiments.compare import format_full_grid

        return format_full_grid(self.full_grid)

    def to_dict(self) -> dict:
        """A JSON-ready summary without the text (what ``recon compare --json`` prints)."""
        auto = {} if self.auto is None else {"auto": self.auto}
        return _jsonable({"records": self.records, "pareto_chamfer": self.pareto_chamfer,
                          "pareto_fscore": self.pareto_fscore, "csv": self.csv,
                          "json": self.json, "png": self.png, "full_grid": self.full_grid,
                          **auto})


@dataclass(frozen=True)
class StabilityResult:
    """Every method over noise x density x outliers (``stability``).

    Attributes
    ----------
    records : list of dict
        One per (method, cell).
    csv, json : Path
        stability.csv and stability.json.
    pngs : list of Path
        Per method, its failure map and accuracy heatmap.
    failure_rate : dict of str -> float
        Per method, the fraction of cells where it failed.
    """

    records: list
    csv: Path
    json: Path
    pngs: list
    failure_rate: dict

    def to_dict(self) -> dict:
        """A JSON-ready summary without the records (what ``recon stability --json`` prints)."""
        return {"csv": str(self.csv), "json": str(self.json),
                "pngs": [str(p) for p in self.pngs], "failure_rate": self.failure_rate}


@dataclass(frozen=True)
class EdgesResult:
    """The edge points of a cloud against the truth, written (``edges``).

    Attributes
    ----------
    report : metrics.EdgeReport
    counts : dict of str -> int
        Surface, true and false edge points; missed feature and gentle truth edges.
    files : dict of str -> Path
        ``ply``, ``png`` and ``json``.
    """

    report: Any
    counts: dict
    files: dict

    def to_dict(self) -> dict:
        """A JSON-ready summary (what ``recon edges --json`` prints)."""
        return {"edge": self.report.to_dict(), "counts": self.counts,
                "files": {k: str(v) for k, v in self.files.items()}}


@dataclass(frozen=True)
class StudyResult:
    """One study run (``study``).

    Attributes
    ----------
    title : str
    size : str
        ``full``, ``quick`` or ``tiny``.
    claims : list of dict
        Each checked claim of the paper: ``id``, ``figure``, ``claim``, ``paper``, ``ours``,
        ``verdict`` (``reproduced``, ``partly``, ``not reproduced`` or ``not tested``) and
        ``rule``.
    n_cases, n_failed : int
    failures : list of dict
        ``key`` and ``reason`` of every failed case.
    files : list of str
        What the study wrote into its directory.
    wall_time_s : float
    summary : dict
        Everything, as written to ``summary_path``.
    summary_path : Path
    """

    title: str
    size: str
    claims: list
    n_cases: int
    n_failed: int
    failures: list
    files: list
    wall_time_s: float
    summary: dict
    summary_path: Path

    def to_dict(self) -> dict:
        """The summary (what ``recon study NAME --json`` prints)."""
        return self.summary


@dataclass(frozen=True)
class StudiesResult:
    """Every study run (``study_all``).

    Attributes
    ----------
    index : dict
        ``size``, ``studies`` (per study: ``wall_time_s``, ``n_cases``, ``n_failed``,
        ``verdicts``), ``wall_time_s``: the content of ``index_path``.
    index_path : Path
    """

    index: dict
    index_path: Path


@dataclass(frozen=True)
class DemoResult:
    """The end-to-end demo's files and scores (``demo``).

    Attributes
    ----------
    files : dict of str -> Path
        ``log``, ``cloud``, ``truth``, ``surface``, ``scores``.
    simulation : dict
        The simulator's summary.
    scores : dict of str -> metrics.ScoreReport
        ``cloud`` and ``surface``.
    n_faces : int
    """

    files: dict
    simulation: dict
    scores: dict
    n_faces: int

    def table(self) -> str:
        """The scores as a table: one row per score, one column per scored geometry."""
        tau = next(iter(self.scores.values())).tau_m
        lines = [f"{'score (tau = ' + format(tau, '.3g') + ' m)':<24}"
                 + "".join(f"{name:>10}" for name in self.scores)]
        for label, key in DEMO_SCORE_ROWS:
            lines.append(f"{label:<24}" + "".join(f"{getattr(s, key):>10.4g}"
                                                  for s in self.scores.values()))
        return "\n".join(lines)


# ------------------------------------------------------------------------------ data in


def _from_library(value):
    """An Open3D or trimesh point cloud or mesh as a ``Cloud`` or ``Mesh`` (anything else is
    returned as it is). Told apart by their types' modules, so neither library is imported."""
    module = type(value).__module__ or ""
    if not module.startswith(("open3d", "trimesh")):
        return value
    import numpy as np

    from formats.geometry import Cloud, Mesh

    if module.startswith("open3d"):
        if hasattr(value, "triangles"):
            return Mesh(np.asarray(value.vertices), np.asarray(value.triangles))
        if hasattr(value, "points"):
            normals = np.asarray(value.normals) if value.has_normals() else None
            return Cloud(np.asarray(value.points), normals=normals)
    elif hasattr(value, "vertices"):
        if getattr(value, "faces", None) is not None and len(value.faces):
            return Mesh(np.asarray(value.vertices), np.asarray(value.faces))
        return Cloud(np.asarray(value.vertices))
    raise ParameterError(f"{type(value).__module__}.{type(value).__name__} is neither a point "
                         "cloud nor a triangle mesh")


def load(value, *, name: str = "input", points_only: bool = False) -> Cloud | Mesh:
    """A ``Cloud`` or ``Mesh`` from recon's types, plain arrays, Open3D or trimesh objects, or
    a file (cloud, mesh or log).

    A strike log is ingested into a body-frame cloud (``points_only``: without its per-point
    attributes).
    """
    from formats.geometry import Cloud, Mesh

    value = _from_library(value)
    if isinstance(value, Cloud | Mesh):
        return value
    if isinstance(value, str | os.PathLike):
        from recon.inputs import load_geometry

        return load_geometry(value, points_only=points_only)
    if isinstance(value, tuple | list) or hasattr(value, "faces"):
        return Mesh.of(value, name)
    return Cloud.of(value, name)


def truth_of(value, *, scale: float = 1.0, units: str | None = None) -> Mesh:
    """The truth mesh named by ``value``: a ``Mesh``, ``(vertices, faces)``, an Open3D or trimesh
    mesh, a mesh file (in ``units``, default the format's, then times ``scale``), or a strike
    log with its embedded truth mesh."""
    from formats.geometry import Mesh

    if isinstance(value, str | os.PathLike):
        from recon.inputs import load_truth

        return load_truth(value, scale=scale, units=units)
    return Mesh.of(_from_library(value), "truth")


def default_truth(test):
    """The truth a test input implies on its own: a strike log's embedded truth mesh.

    Raises
    ------
    ParameterError
        ``test`` is not a strike log, so the truth must be given.
    """
    from formats.paths import check_source
    from recon.inputs import is_strike_log

    check_source(test, ParameterError)
    if not is_strike_log(test):
        raise ParameterError(f"truth must be given: {test} is not a strike log with truth",
                             argument="truth")
    return test


def _inputs(*values) -> list:
    """The values that name files (for ``formats.paths.protecting``)."""
    return [v for v in values if isinstance(v, str | os.PathLike)]


def save(geometry, path, *, source=None, units: str | None = None) -> Path:
    """Write a mesh or a point cloud; the suffix of ``path`` picks the format.

    The file appears only when complete (``formats.atomic``), and a file that the running
    command reads is refused (``formats.paths.check_destination``).

    Parameters
    ----------
    geometry : Mesh, Surface, Cloud, (n, 3) array, (vertices, faces), Open3D or trimesh object
    path : str or Path
        A mesh as .ply, .tab (PDS vertex/plate table) or .bds/.dsk (SPICE DSK); a cloud as
        .ply, .las, .laz or .h5.
    source : str or Path, optional
        The file the geometry was made from, recorded in the file's header.
    units : {"km", "m"}, optional
        Of a .tab mesh (default km).

    Returns
    -------
    Path
    """
    from formats.cloud_io import write_cloud
    from formats.geometry import Cloud, Mesh
    from formats.mesh_io import write_mesh
    from formats.paths import check_destination

    geometry = load(geometry, name="geometry")
    check_destination(path, ParameterError)
    name = None if source is None else Path(source).name
    if isinstance(geometry, Mesh):
        return write_mesh(path, Mesh(geometry.vertices, geometry.faces, frame=geometry.frame),
                          source=name, units=units)
    if units is not None:
        raise ParameterError(f"{path}: units apply to .tab meshes, not to clouds")
    return write_cloud(path, Cloud.of(geometry), source=name)


# ------------------------------------------------------------------------------ simulate


def simulate(scene, output, *, seed: int = 0, overrides: Sequence[str] = (),
             progress: bool | None = None, live: bool = False,
             compression: str | None = None) -> SimulatedLog:
    """Simulate a campaign and write its strike log.

    Parameters
    ----------
    scene : str or Path
        A preset name (``presets()``) or a scene TOML file.
    output : str or Path
        The ``.h5`` strike log to write (atomically: it appears only when complete).
    seed : int, >= 0
        Seed of every error model; the same seed gives the same bytes.
    overrides : sequence of str
        ``section.key=value`` scene overrides, applied after the scene file.
    progress : bool or None
        Progress bar (None: on a terminal only).
    live : bool
        Write the log in HDF5 SWMR mode, so that ``follow`` (``recon ingest LOG --follow``)
        reads the strikes as they arrive.
    compression : str, optional
        Filter of the log's datasets: ``"gzip"`` or ``"gzip:LEVEL"`` (deflate with shuffle,
        LEVEL 0-9, readable by every HDF5 tool; the default), ``"lzf"`` (with shuffle, readable
        only where h5py's lzf filter is installed) or ``"none"``.

    Returns
    -------
    SimulatedLog
    """
    import sim
    from formats.strike_log import DEFAULT_COMPRESSION

    check_seed(seed)
    summary = sim.simulate(sim.load_scene(str(scene), list(overrides)), output, seed=seed,
                           progress=progress, live=live,
                           compression=compression or DEFAULT_COMPRESSION)
    return SimulatedLog(Path(summary["path"]), summary)


def check_seed(seed: int) -> int:
    """``seed`` as an int when every verb that takes one does (an integer from 0 to
    ``sim.defaults.MAX_SEED``, which a log stores), else ``ParameterError``; each verb checks
    its seed before any work."""
    from numbers import Integral

    from sim.defaults import MAX_SEED

    if isinstance(seed, bool) or not isinstance(seed, Integral) or not 0 <= seed <= MAX_SEED:
        raise ParameterError(f"seed must be an integer from 0 to {MAX_SEED}, got {seed!r}",
                             argument="seed")
    return int(seed)


def presets() -> list[tuple[str, str]]:
    """``(name, description)`` of every scene preset."""
    import sim

    return sim.list_presets()


def scene_keys() -> dict[str, list[tuple[str, str, str, str]]]:
    """The scene schema: per section, ``(key, default as TOML, unit, meaning)`` of every key."""
    from sim.defaults import SCHEMA
    from sim.scene import toml_value

    return {section: [(name, "(none)" if key.default is None else toml_value(key.default),
                       key.unit, key.help) for name, key in keys.items()]
            for section, keys in SCHEMA.items()}


# ------------------------------------------------------------------------------ registration


def ingest(log, *, frame: Frame = "body", output=None,
           progress: Callable[[int], None] | None = None) -> Cloud:
    """Register a strike log's strikes into the target body frame (or the inertial frame).

    Registration uses only the recorded poses; it never reads the log's truth group.

    Parameters
    ----------
    log : str, Path or SimulatedLog
    frame : {"body", "inertial"}
    output : str or Path, optional
        Also write the cloud there (.ply, .las, .laz or .h5), from the same single pass.
    progress : callable, optional
        Called with the number of strikes registered after each block.

    Returns
    -------
    Cloud
        (n, 3) metres in ``frame`` with ``time``, ``shot``, ``beam``, ``range`` and the view
        points (sensor positions) as attributes.
    """
    from formats.paths import check_destination, protecting
    from recon.registration.ingest import ingest as register_log

    with protecting(_inputs(log)):
        if output is not None:
            check_destination(output, ParameterError)
        return register_log(log, frame=frame, output=output, progress=progress)


def ingest_file(log, output, *, frame: Frame = "body", refinement: Refinement | None = None,
                progress: Callable[[int, int], None] | None = None) -> IngestResult:
    """Register a strike log into a cloud file in bounded memory (``recon ingest``).

    Parameters
    ----------
    log : str, Path or SimulatedLog
    output : str or Path
        .ply, .las, .laz or .h5; it appears only when every block was read, checked and written.
    frame : {"body", "inertial"}
    refinement : Refinement, optional
        Register with the poses it corrects (``refine``).
    progress : callable, optional
        Called as ``progress(strikes_in_block, total_strikes)`` after each block.
    """
    from formats.paths import check_destination, protecting
    from recon.registration.ingest import ingest_to_file

    correction = None if refinement is None else refinement.correction
    with protecting(_inputs(log)):
        check_destination(output, ParameterError)
        summary = ingest_to_file(log, output, frame=frame, progress=progress,
                                 correction=correction)
    return IngestResult(summary["n_points"], frame, Path(output), refined=correction is not None)


def follow(log, output, *, frame: Frame = "body", timeout_s: float = 60.0,
           progress: Callable[[int, int], None] | None = None) -> IngestResult:
    """Register a strike log while ``simulate(..., live=True)`` writes it; write the cloud once
    the log is complete (``recon ingest --follow``).

    Parameters
    ----------
    log : str or Path
        The log's final path.
    output : str or Path
        .ply, .las, .laz or .h5.
    frame : {"body", "inertial"}
    timeout_s : float, seconds
        Give up after this long without a writer or new strikes.
    progress : callable, optional
        Called as ``progress(strikes_in_block, strikes_committed_so_far)`` after each block.
    """
    from formats.paths import check_destination
    from recon.registration.ingest import ingest_following

    if not timeout_s > 0:
        raise ParameterError(f"timeout_s must be a positive number of seconds, got "
                             f"{timeout_s:g}", argument="timeout_s")
    check_destination(output, ParameterError)
    summary = ingest_following(log, output, frame=frame, progress=progress, timeout_s=timeout_s)
    return IngestResult(summary["n_points"], frame, Path(output))


def refine(log, *, interval: float | None = None, spin: bool = False, seed: int = 0,
           progress: Callable[[float, float], None] | None = None,
           announce: Callable[[str], None] | None = None) -> Refinement:
    """Estimate a log's pose-knowledge errors (boresight misalignment, position bias; with
    ``interval`` also slowly varying ones; with ``spin`` a spin-rate correction) from the
    agreement of its passes (``recon ingest --refine``).

    Parameters
    ----------
    log : str, Path or SimulatedLog
    interval : float, optional, seconds
        Knot spacing of slowly varying errors (None: constant errors only).
    spin : bool
    seed : int
    progress : callable, optional
        Called as ``progress(done, total)`` after every step of the fit, in the refinement's
        estimated seconds.
    announce : callable, optional
        Called, before the work, with one line saying how long the refinement is estimated to
        take when that is more than half a minute
        (``recon.registration.refine.ANNOUNCE_S``).

    Returns
    -------
    recon.registration.refine.Refinement
        The estimates with their uncertainties (``lines()``, ``to_dict()``); pass it to
        ``ingest_file(..., refinement=)``.

    Raises
    ------
    ParameterError
        ``interval`` makes more knots than the sampled strikes can estimate, or a refinement
        estimated to take more than a day (``recon.registration.refine.MAX_REFINE_S``); the
        message names the shortest interval that would do.
    """
    from recon.registration.refine import refine as estimate

    check_seed(seed)
    return estimate(log, interval=interval, spin=spin, seed=seed, progress=progress,
                    announce=announce)


def is_altimetry(path) -> bool:
    """Whether ``path`` is a mission's altimetry product (an OLA Level-2 label or a Hayabusa2
    LIDAR Level-2 CSV) rather than a strike log."""
    from recon.registration.altimetry import is_altimetry as is_product

    return is_product(path)


def ingest_altimetry(product, output) -> AltimetryResult:
    """Read a mission's altimetry product into a body-frame cloud file (flagged returns are
    dropped and counted).

    Parameters
    ----------
    product : str or Path
        OSIRIS-REx OLA Level-2 label (.xml) or Hayabusa2 LIDAR Level-2 CSV (.csv).
    output : str or Path
        .ply, .las, .laz or .h5.
    """
    from formats.paths import check_destination, protecting
    from recon.registration.altimetry import ingest_altimetry as read_product

    with protecting(_inputs(product)):
        check_destination(output, ParameterError)
        summary = read_product(product, output)
    return AltimetryResult(summary["n_points"], summary["dropped"], summary["product"],
                           Path(summary["output"]))


def export_altimetry(log, output, *, epoch_et: float | None = None) -> AltimetryExport:
    """Write a strike log as a mission's altimetry product: OLA Level 2 (``.xml`` label with its
    ``.dat`` table) or Hayabusa2 LIDAR Level 2 (``.csv``).

    Parameters
    ----------
    log : str, Path or SimulatedLog
    output : str or Path
    epoch_et : float, optional
        ET [s, TDB past J2000] of the log's time 0 (default: the log's own, else 0).
    """
    from formats.paths import check_destination, protecting
    from recon.registration.altimetry import export_altimetry as write_product

    with protecting(_inputs(log)):
        check_destination(output, ParameterError)
        summary = write_product(log, output, epoch_et=epoch_et)
    return AltimetryExport(summary["n_returns"], summary["n_no_return"], summary["product"],
                           tuple(Path(p) for p in summary["written"]))


def is_kernel(path) -> bool:
    """Whether ``trajectory`` writes ``path`` as SPICE kernels (.bsp SPK, .bc CK)."""
    from recon.registration.trajectory import KERNEL_SUFFIXES

    return Path(path).suffix.lower() in KERNEL_SUFFIXES


def trajectory(log, output, *, frame: str | None = None, epoch_et: float | None = None
               ) -> TrajectoryResult:
    """Write a log's recorded sensor poses: one line per shot (.txt, .csv) or SPICE kernels
    (.bsp: an SPK, .bc: a CK, each with its frames kernel; a CK with its clock kernel).

    Parameters
    ----------
    log : str, Path or SimulatedLog
    output : str or Path
    frame : {"body", "inertial"}, optional
        Of a text trajectory (default body); kernels hold both frames.
    epoch_et : float, optional
        Kernels: ET [s, TDB past J2000] of the log's time 0 (default: the log's own, else 0).
    """
    from formats.paths import check_destination, protecting
    from recon.registration.trajectory import export_kernel, export_trajectory, kernel_files

    kernel = is_kernel(output)
    if kernel and frame is not None:
        raise ParameterError("frame is for text trajectories: an SPK is in J2000 (the log's "
                             "inertial frame) and a CK holds the body frame too")
    if not kernel and epoch_et is not None:
        raise ParameterError("epoch_et is for kernels (.bsp, .bc)")
    with protecting(_inputs(log)):
        for path in kernel_files(output) if kernel else [output]:
            check_destination(path, ParameterError)   # every file before the first is written
        if kernel:
            summary = export_kernel(log, output, epoch_et=epoch_et)
            return TrajectoryResult(summary["n_shots"], None, summary["epoch_et"],
                                    tuple(Path(p) for p in summary["written"]))
        summary = export_trajectory(log, output, frame=frame or "body")
    return TrajectoryResult(summary["n_shots"], summary["frame"], None,
                            (Path(summary["output"]),))


# ------------------------------------------------------------------------------ scoring


def score(test, *, truth, truth_scale: float = 1.0, truth_units: str | None = None,
          tau: float | None = None,
          tau_fraction: float | None = None, edges: bool = True, seed: int | None = 0,
          progress=None, **options) -> ScoreReport:
    """Score a cloud or a mesh against the truth mesh (``metrics.score``).

    Parameters
    ----------
    test : Cloud, Mesh, Surface, (n, 3) array, (vertices, faces), Open3D or trimesh object, or
        a file (cloud, mesh or log)
    truth : Mesh, (vertices, faces), Open3D or trimesh mesh, a mesh file or a strike log with
        truth
    truth_scale : float
        Factor on a truth mesh file's coordinates (e.g. 1000 for km).
    truth_units : {"km", "m"}, optional
        Units of a truth mesh file (default: the format's; km for PDS tables, ICQ and DSK).
    tau, tau_fraction, edges, seed, progress, **options
        As ``metrics.score``.

    Returns
    -------
    metrics.ScoreReport
    """
    from metrics.score import score as score_against

    if seed is not None:   # None: fresh randomness
        check_seed(seed)
    truth = truth_of(truth, scale=truth_scale, units=truth_units)
    options = {"tau": tau, "tau_fraction": tau_fraction, "edges": edges, "seed": seed,
               "progress": progress} | options
    if isinstance(test, str | os.PathLike):
        return _score_file(test, truth, options)
    return score_against(load(test, name="test"), truth, **options)


def _score_file(test, truth: Mesh, options: dict) -> ScoreReport:
    """Score a file block by block (``metrics.score.score_stream``): a strike log as it is
    registered and a binary PLY, HDF5 or LAS cloud as it is read, in memory flat in their size;
    another cloud file read whole, without per-point arrays beside it. Errors name the file."""
    from formats.cloud_io import stream_cloud
    from formats.geometry import Cloud
    from metrics import defaults
    from metrics.score import score as score_against
    from metrics.score import score_stream
    from recon.inputs import is_strike_log

    if is_strike_log(test):
        from recon.registration.ingest import iter_points

        return score_stream(lambda: iter_points(test), truth, name=f"test {test}", **options)
    streamed = stream_cloud(test, defaults.STREAM_BLOCK)
    if streamed is not None:
        frame, blocks = streamed
        return score_stream(blocks, truth, name=f"test {test}", frame=frame, **options)
    geometry = load(test, name="test", points_only=True)
    if isinstance(geometry, Cloud):
        points, normals = geometry.points, geometry.normals
        step = defaults.STREAM_BLOCK
        return score_stream(
            lambda: ((points[i:i + step], None if normals is None else normals[i:i + step])
                     for i in range(0, len(points), step)), truth, name=f"test {test}",
            frame=geometry.frame, **options)
    from metrics.inputs import as_test

    as_test(geometry, f"test {test}")
    return score_against(geometry, truth, **options)


def edges(test, *, truth, output, truth_scale: float = 1.0, truth_units: str | None = None,
          seed: int = 0, title: str | None = None, edge_options: dict | None = None,
          progress=None) -> EdgesResult:
    """The edge points of a cloud against the truth, written as a PLY and the paper's picture
    (``recon.edge_pictures``): ``recon edges``.

    Parameters
    ----------
    test : Cloud, (n, 3) array, Mesh, Open3D or trimesh object, or a file (cloud, mesh or log)
    truth : Mesh, (vertices, faces), a mesh file or a strike log with truth
    output : str or Path
        Directory for edges.ply, edges.png and edges.json.
    truth_scale, truth_units, seed, title, edge_options, progress
        As ``score`` and ``recon.edge_pictures.edge_pictures``.

    Returns
    -------
    EdgesResult
    """
    from recon.edge_pictures import edge_pictures

    check_seed(seed)
    truth_mesh = truth_of(truth, scale=truth_scale, units=truth_units)
    result = edge_pictures(load(test, name="test"), truth_mesh, output, seed=seed, title=title,
                           edge_options=edge_options, progress=progress)
    return EdgesResult(result["report"], result["counts"], result["files"])


# ------------------------------------------------------------------------------ surfaces


def method_listing() -> str:
    """The reconstruction methods, their parameters with defaults, grids and what each default
    costs, as text (``recon reconstruct --list-methods``)."""
    from recon.surfaces import methods

    return methods.listing()


def method_cost() -> str:
    """One sentence on what the methods cost at their defaults: the slowest default fit on the
    benchmark's two clouds, from the table the benchmark writes (for ``--help``; reads JSON
    only, no method is imported)."""
    from recon.surfaces.fit_times import cost_help

    return cost_help()


def _bind(method: str, params):
    """A method's ``Run``: ``params`` as a dict or as ``KEY=VALUE`` strings (``--param``)."""
    from recon.surfaces import methods

    if not params:
        return methods.bind(method)
    if not isinstance(params, Mapping):
        return methods.parse_run(method, list(params))
    return methods.bind(method, params)


def _preparation(remove_outliers: bool, voxel: float | None, normals_k: int | None,
                 orient: str, seed: int):
    from recon.surfaces.normals import DEFAULT_K
    from recon.surfaces.prepare import Preparation

    check_seed(seed)
    return Preparation.from_options(remove_outliers=remove_outliers, voxel=voxel,
                                    normals_k=DEFAULT_K if normals_k is None else normals_k,
                                    orient=orient, seed=seed)


def reconstruct(cloud, *, method: str = "poisson", params: Mapping[str, Any] | None = None,
                remove_outliers: bool = False, voxel: float | None = None,
                normals_k: int | None = None, orient: str = "centroid", seed: int = 0,
                isolate: bool = True,
                timeout: float | None = None, memory_limit: int | None = None,
                auto_methods: Sequence[str] | None = None, holdout: float | None = None,
                target_kind: str = "unknown", output=None) -> Surface:
    """Reconstruct a surface mesh from a point cloud with one method, or ``method="auto"``.

    Parameters
    ----------
    cloud : Cloud, (n, 3) array, Open3D or trimesh point cloud, or a cloud file or strike log
    method : str
        A registered method (``method_listing()``) or ``"auto"``: chosen without the truth, its
        choice and reason in ``surface.info["auto"]``.
    params : dict, optional
        Overrides of the method's defaults (not with ``"auto"``).
    remove_outliers, voxel, normals_k, orient, seed
        Preparation: statistical outlier removal, voxel downsampling [m], neighbours of the
        normals (default ``recon.surfaces.normals.DEFAULT_K``), their orientation without view
        points, the seed of every random choice.
    isolate : bool
        Run the method in its own process with ``timeout`` [s] and ``memory_limit`` [MiB].
    auto_methods, holdout
        Candidates and held-out fraction of ``method="auto"``.
    target_kind : {"unknown", "natural"}
        What is known of the target, for ``method="auto"``: ``"natural"`` (an asteroid, a
        comet) lets a smooth closed model stand for a far side the strikes leave unseen
        (``recon.surfaces.auto``, step 5).
    output : str or Path, optional
        Also write the mesh there (``save``: atomically, never over the input).

    Returns
    -------
    recon.surfaces.reconstruct.Surface
        A ``Mesh`` with ``method``, resolved ``params`` and run ``info``; ``info["estimate"]``
        is the truth-free predicted Chamfer distance and F-score with their band
        (``recon.surfaces.estimate.estimate``; for ``"auto"`` from the chosen candidate's held-out
        passes).
    """
    return _reconstruct(cloud, output, method=method, params=params,
                        preparation=(remove_outliers, voxel, normals_k, orient, seed),
                        timeout=timeout, memory_limit=memory_limit, isolate=isolate,
                        auto_methods=auto_methods, holdout=holdout,
                        target_kind=target_kind).surface


def reconstruct_file(input, output, *, method: str = "poisson",
                     params: Mapping[str, Any] | Sequence[str] | None = None,
                     remove_outliers: bool = False, voxel: float | None = None,
                     normals_k: int | None = None, orient: str = "centroid", seed: int = 0,
                     isolate: bool = True, timeout: float | None = None,
                     memory_limit: int | None = None, auto_methods: Sequence[str] | None = None,
                     holdout: float | None = None, target_kind: str = "unknown",
                     on_wait: Callable[[str], None] | None = None,
                     say: Callable[[str], None] | None = None,
                     own_process: bool = False) -> ReconstructResult:
    """``reconstruct`` from a cloud file or strike log to a mesh file (``recon reconstruct``).

    Parameters
    ----------
    input : str or Path (or anything ``reconstruct`` takes)
    output : str or Path
        Mesh to write (.ply, .tab, .bds/.dsk); checked before any work.
    params : dict, or sequence of ``KEY=VALUE`` str, optional
    on_wait : callable, optional
        Called with the isolated run's stage while waiting.
    say : callable, optional
        ``method="auto"``: called with the candidates table and the reason once chosen.
    own_process : bool
        The caller owns its process (a program, such as the ``recon`` command, not a library's
        caller) and calls this before numpy or Open3D is imported: the process is set up for
        the reconstruction (``_own_process``).
    method, remove_outliers, voxel, normals_k, orient, seed, isolate, timeout, memory_limit,
    auto_methods, holdout, target_kind
        As ``reconstruct``.

    Returns
    -------
    ReconstructResult
    """
    if own_process:
        _own_process(method)
    return _reconstruct(input, output, method=method, params=params,
                        preparation=(remove_outliers, voxel, normals_k, orient, seed),
                        timeout=timeout, memory_limit=memory_limit, isolate=isolate,
                        auto_methods=auto_methods, holdout=holdout, target_kind=target_kind,
                        on_wait=on_wait, say=say)


def _own_process(method: str) -> None:
    """Set up a process that reconstructs and does nothing else (``reconstruct_file``'s
    ``own_process``): Open3D's plotly drawing, which nothing in recon draws with, is left out
    of its imports (``recon.surfaces.isolation.leave_out_unused``: a third of Open3D's import);
    and for ``method="auto"``, whose fits run in worker processes with their own threads,
    numpy's BLAS in this process runs on one thread (``OPENBLAS_NUM_THREADS``, unless set; the
    library reads it as numpy is imported, so only before that): the choice's and the
    estimate's linear algebra is on matrices of a few columns, where a second BLAS thread
    waits for work beside the workers, spinning on a core they need (docs/decisions.md). The
    same numbers out: a thread count does not change them here (the choice, its figures and
    the written mesh compared on the tuning clouds)."""
    if method == "auto" and "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from recon.surfaces.isolation import leave_out_unused

    leave_out_unused()


def _reconstruct(source, output, *, method: str, params, preparation: tuple, timeout,
                 memory_limit, isolate: bool, auto_methods, holdout, target_kind="unknown",
                 on_wait=None, say=None) -> ReconstructResult:
    """The one reconstruction policy: check the options and the output before any work,
    prepare, choose (``auto``), fit, predict the accuracy, write. ``preparation``: the
    arguments of ``_preparation``."""
    from formats.paths import check_destination, protecting
    from recon.inputs import walk_early
    from recon.surfaces.auto import FIT_THREADS, choose_for, format_choice, start_workers
    from recon.surfaces.isolation import Limits
    from recon.surfaces.methods import watertight
    from recon.surfaces.prepare import load_cleaned
    from recon.surfaces.reconstruct import Surface, estimate_of, prepare_estimate
    from recon.surfaces.reconstruct import reconstruct as run_method

    holdout, run = _reconstruct_options(method, params, holdout, target_kind)
    auto = run is None
    preparation = _preparation(*preparation)
    limits = Limits.from_options(timeout, memory_limit)
    with protecting(_inputs(source)):
        if output is not None:
            check_destination(output, ParameterError)   # before the work, not after it
        if auto:  # the fit workers import while the input loads (walked before their threads)
            walk_early(*_inputs(source))
            start_workers()
        cloud = load_cleaned(_from_library(source), preparation)
        choice, prepared = None, _Later(preparation.prepare, cloud)
        if not auto:
            prepared.result()   # here and now: a refused cloud stops before anything else
        try:
            misses = _misses(source, cloud, preparation.seed)
            if auto:   # every strike prepared for the refit in the folds' thread, after them
                choice = choose_for(cloud, methods=auto_methods, preparation=preparation,
                                    limits=limits, holdout=holdout, target_kind=target_kind,
                                    misses=misses, then=prepared.run)
        except Exception:
            prepared.result()   # a cloud the preparation refuses: its error, as made first
            raise
        prepared = dataclasses.replace(prepared.result(), misses=misses)
        if choice is not None:
            run = choice.run
            if say is not None:
                say(format_choice(choice))
        # auto's choice refitted on a warm worker of its fits, with their threads: the fit
        # compare makes of the same run; while a worker fits, this process makes what the
        # estimate needs of the cloud whatever the surface (the truth's proxy)
        with _beside(prepare_estimate if isolate else None, cloud, seed=preparation.seed,
                     target_kind=target_kind, misses=misses):
            surface = run_method(prepared, method=run, isolate=isolate, on_wait=on_wait,
                                 threads=FIT_THREADS if auto else None, **limits.kwargs())
        if choice is not None and choice.carved:
            vertices, faces = choice.carve(surface.vertices, surface.faces, cloud.points)
            surface = Surface(vertices, faces, surface.method, surface.params,
                              surface.info | {"carved": True, "watertight": watertight(faces)})
        surface.frame = cloud.frame  # so that scoring against a truth in another frame is refused
        surface.info["estimate"] = estimate_of(
            surface, cloud, heldout=None if choice is None else choice.chosen.heldout,
            seed=preparation.seed, target_kind=target_kind, misses=misses).to_dict()
        if choice is not None:
            surface.info["auto"] = choice.to_dict()
        named = isinstance(source, str | os.PathLike)
        if output is not None:
            save(surface, output, source=source if named else None)
    return ReconstructResult(surface, str(source) if named else None,
                             None if output is None else Path(output), len(prepared.points),
                             prepared.spacing, prepared.noise, cloud.view_points is not None,
                             run.label if choice is None else choice.label)


class _Later:
    """``function(*args)``, run once: by ``run`` (in any thread), or by ``result`` when it
    was not run (or is not running) by then; ``result`` returns its value or raises its
    error, waiting for a run under way."""

    def __init__(self, function: Callable, *args):
        import threading

        self._call = (function, args)
        self._lock = threading.Lock()
        self._outcome: tuple | None = None

    def run(self) -> None:
        with self._lock:
            if self._outcome is None:
                function, args = self._call
                try:
                    self._outcome = (True, function(*args))
                except Exception as error:   # raised again by ``result``
                    self._outcome = (False, error)

    def result(self):
        self.run()
        ok, value = self._outcome
        if not ok:
            raise value
        return value


@contextlib.contextmanager
def _beside(function: Callable | None, *args, **kwargs):
    """Run ``function(*args, **kwargs)`` in a thread while the body runs (None: nothing), and
    wait for it after the body. Made ahead of the code that needs its result, which calls it
    again: an exception it raised is dropped here and raised there, in its place; after a
    body that raised it is not waited for."""
    if function is None:
        yield
        return
    from concurrent.futures import ThreadPoolExecutor

    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="recon-beside")
    future = pool.submit(function, *args, **kwargs)
    try:
        yield
        future.exception()   # waits; the caller meets any exception where it needs the result
    finally:
        pool.shutdown(wait=False)


def _reconstruct_options(method: str, params, holdout: float | None, target_kind: str):
    """``_reconstruct``'s options checked before any work: the hold-out share (the default for
    None) and the bound run (None for ``"auto"``).

    Raises
    ------
    ParameterError
        A hold-out share outside (0, 0.5] or an unknown target kind (checked even when unused:
        a bad value is a mistake), or parameters given with ``"auto"``.
    """
    from recon.surfaces.auto import HOLDOUT_FRACTION, TARGET_KINDS

    holdout = HOLDOUT_FRACTION if holdout is None else holdout
    if not 0 < holdout <= 0.5:
        raise ParameterError(f"holdout must be in (0, 0.5], got {holdout}", argument="holdout")
    if target_kind not in TARGET_KINDS:
        raise ParameterError(f"target_kind must be one of {', '.join(TARGET_KINDS)}, "
                             f"got {target_kind!r}", argument="target_kind")
    if method == "auto":
        if params:
            raise ParameterError("params cannot be combined with method='auto'",
                                 argument="params")
        return holdout, None
    return holdout, _bind(method, params)


def _misses(source, cloud, seed: int):
    """The missed beams near ``cloud``'s strikes when ``source`` is a strike log
    (``recon.surfaces.auto.misses_near``), else None (a cloud file records no misses)."""
    from recon.inputs import is_strike_log
    from recon.surfaces.auto import misses_near

    if not isinstance(source, str | os.PathLike) or not is_strike_log(source):
        return None
    return misses_near(source, cloud.points, seed=seed)


# ------------------------------------------------------------------------------ experiments


def check_scheduler(scheduler: str | None, *, probe: bool = True) -> str | None:
    """A scheduler value for ``compare``, ``stability`` and ``study``: None, ``"threads"``,
    ``"serial"`` or a Dask address (``tcp://host:port``) where, with ``probe``, a Dask
    scheduler answers. Returned as it is; otherwise ``recon.experiments.sweep.ParameterError``."""
    from recon.experiments.sweep import check_scheduler as check_value
    from recon.experiments.sweep import probe_scheduler

    if check_value(scheduler) not in (None, "threads", "serial") and probe:
        probe_scheduler(scheduler)
    return scheduler


def _name(source, *, full: bool = True) -> str:
    """A file's path (or, not ``full``, its name) for fingerprints and titles; in-memory data is
    named by its type."""
    if not isinstance(source, str | os.PathLike):
        return type(source).__name__
    return str(source) if full else Path(source).name


def compare(cloud, *, truth, output, methods: Sequence[str] | None = None,
            grid: str = "defaults", truth_scale: float = 1.0, remove_outliers: bool = False,
            voxel: float | None = None, normals_k: int | None = None, orient: str = "centroid",
            seed: int = 0, timeout: float | None = None, memory_limit: int | None = None,
            samples: int | None = None, auto: bool = False, target_kind: str = "unknown",
            scheduler: str | None = None, n_workers: int | None = None, resume: bool = False,
            keep_meshes: bool = True, say: Callable[[str], None] | None = None
            ) -> CompareResult:
    """Run every method on one cloud (at its defaults; ``grid="full"`` adds the parameter
    grids), each isolated, and score each surface against the truth: the speed against
    accuracy comparison of ``recon compare``.

    Parameters
    ----------
    cloud : Cloud, (n, 3) array, Open3D or trimesh point cloud, or a cloud file or strike log
    truth : Mesh, (vertices, faces), Open3D or trimesh mesh, a mesh file or a strike log with
        truth
    output : str or Path
        Directory for results.csv, results.json, speed_accuracy.png, the meshes (unless
        ``keep_meshes=False``) and, with ``auto``, auto.json.
    methods : sequence of str, optional
        Methods to run (default: all).
    grid : {"defaults", "full"}
    truth_scale : float
        Factor on a truth mesh file's coordinates (e.g. 1000 for km).
    remove_outliers, voxel, normals_k, orient, seed
        Preparation, as ``reconstruct``.
    timeout, memory_limit : float [s], int [MiB], optional
        Of every isolated run.
    samples : int, optional
        Surface samples per side when scoring (default: as many as metrics' stated precision
        needs, ``metrics.precision``).
    auto : bool
        Also run ``method="auto"``'s choice (its ladder restricted to ``methods``) and record
        where it ranks on the truth.
    target_kind : {"unknown", "natural"}
        What ``auto`` is told of the target, as ``reconstruct``.
    scheduler : str, optional
        ``check_scheduler``'s values (default: a local pool of threads).
    n_workers : int, optional
        Runs at once on this machine, each in its own worker process (default: one per core);
        not used by ``"serial"`` (one at a time) or on a cluster given by address (its own
        workers run them).
    resume : bool
        Keep the runs ``output`` already holds.
    say : callable, optional
        Called with a one-line description of the inputs before the runs start.

    Returns
    -------
    CompareResult

    Raises
    ------
    MethodFailed
        Every run failed (after results.csv and results.json record how).
    """
    import json

    from formats.atomic import write_text_atomically
    from formats.geometry import Mesh
    from formats.paths import writing_into
    from recon.experiments import compare as comparison
    from recon.experiments.cases import SWEEP_THREADS, score_options, variants
    from recon.experiments.sweep import check_scheduler as check_value
    from recon.experiments.sweep import default_workers
    from recon.inputs import load_truth, walk_early
    from recon.surfaces.isolation import Limits, start_workers, warm_truth
    from recon.surfaces.methods import MethodFailed
    from recon.surfaces.prepare import load_prepared

    preparation = _preparation(remove_outliers, voxel, normals_k, orient, seed)
    limits = Limits.from_options(timeout, memory_limit)
    runs = variants(methods, grid=grid)
    options = score_options(samples, memory_mb=limits.memory_mb)
    check_value(scheduler)
    _check_workers(n_workers)
    # before any work (a read-only parent); removed again if a refused input leaves it empty
    with writing_into(output, ParameterError) as output:
        local = scheduler in (None, "threads")
        if local:  # local workers import Open3D while the input loads
            walk_early(*_inputs(cloud, truth))  # before the pool's launcher thread starts
            start_workers(min(len(runs), n_workers or default_workers()), SWEEP_THREADS)
        truth_mesh = (load_truth(truth, scale=truth_scale) if isinstance(truth, str | os.PathLike)
                      else Mesh.of(_from_library(truth), "truth"))
        if local:  # ... and make the truth ready for scoring while the cloud is prepared
            warm_truth(tuple(truth_mesh), options, SWEEP_THREADS)
        points, prepared = load_prepared(_from_library(cloud), preparation)
        misses = _misses(cloud, points, preparation.seed)
        prepared = dataclasses.replace(prepared, misses=misses)
        if say is not None:
            say(f"compare: {len(prepared.points)} points (spacing {prepared.spacing:.3g} m, noise "
                f"{prepared.noise:.3g} m), truth {len(truth_mesh[1])} faces -> {output}")
        report = comparison.compare(
            prepared, truth_mesh, output, runs=runs, scheduler=scheduler, n_workers=n_workers,
            resume=resume, keep_meshes=keep_meshes, title=_name(cloud, full=False),
            score_options=options,
            fingerprint={"input": _name(cloud), "truth": _name(truth), "voxel": preparation.voxel,
                         "remove_outliers": preparation.remove_outliers,
                         "normals_k": preparation.k},
            strikes=points, misses=misses, **limits.kwargs())
        agreement = None
        if auto:
            agreement = _auto_agreement(points, report["records"], methods, preparation, limits,
                                        target_kind, misses=misses,
                                        prepared=prepared, truth=truth_mesh, score_options=options)
            write_text_atomically(output / "auto.json",
                                  json.dumps(_jsonable(agreement[0]), indent=2) + "\n",
                                  error=ParameterError)
        if not any(r.get("status") == "ok" for r in report["records"]):
            kinds = sorted({str(r.get("failure")) for r in report["records"]})
            raise MethodFailed(f"every run failed ({len(report['records'])} runs: "
                               f"{', '.join(kinds)}); the failures are in {report['csv']}")
        return CompareResult(report["records"], report["table"], report["pareto_chamfer"],
                             report["pareto_fscore"], report["full_grid"], report["csv"],
                             report["json"], report["png"],
                             *(agreement if agreement is not None else (None, None)))


def _auto_agreement(cloud: Cloud, records: list, methods, preparation, limits,
                    target_kind: str, *, misses, prepared, truth, score_options
                    ) -> tuple[dict, str]:
    """``method="auto"``'s choice on the prepared cloud and where it ranks among the compared
    runs: (``{"choice", "agreement"}``, the candidates table and the agreement line). A choice
    carved by the log's missed beams is a surface no compared run made: it is fitted on every
    strike, carved as ``recon reconstruct -m auto`` carves it, scored against ``truth`` like the
    runs (``score_options``) and ranked among them."""
    from recon.experiments.compare import CHAMFER, agreement, format_agreement
    from recon.surfaces.auto import choose_for, format_choice
    from recon.surfaces.reconstruct import reconstruct as run_method

    choice = choose_for(cloud, methods=methods, preparation=preparation, limits=limits,
                        target_kind=target_kind, misses=misses)
    if choice.carved:
        surface = run_method(prepared, method=choice.run, **limits.kwargs())
        carved = choice.carve(surface.vertices, surface.faces, cloud.points)
        scores = score(carved, truth=truth, **(score_options or {}))
        records = [*records, {"status": "ok", "key": choice.chosen.key, "label": choice.label,
                              "method": choice.run.method, CHAMFER: scores.chamfer_m,
                              "fscore": scores.fscore}]
    verdict = agreement(records, choice.chosen.key)
    return ({"choice": choice.to_dict(), "agreement": verdict},
            format_choice(choice) + "\n" + format_agreement(verdict))


def stability(source, *, output, truth=None, truth_scale: float = 1.0,
              overrides: Sequence[str] = (), methods: Sequence[str] | None = None,
              noise: Sequence[float] | None = None, density: Sequence[float] | None = None,
              outliers: Sequence[float] | None = None, seed: int = 0,
              timeout: float | None = None, memory_limit: int | None = None,
              samples: int | None = None, scheduler: str | None = None,
              n_workers: int | None = None, resume: bool = False) -> StabilityResult:
    """Where each method fails, over range noise x point density x outlier fraction
    (``recon stability``).

    A scene (a preset name or a ``.toml`` file) is simulated once per noise level with that
    range error, and its truth is the scene's target. A cloud or a log is degraded per cell;
    its truth is ``truth``, else a log's own truth mesh (a plain cloud needs ``truth``).

    Parameters
    ----------
    source : str or Path
        Scene preset name, scene ``.toml``, point cloud or strike log.
    output : str or Path
        Directory for stability.csv, stability.json and the charts.
    truth : str or Path, optional
        Truth mesh file or strike log with truth; overrides the source's own.
    truth_scale : float
        Factor on a truth mesh file's coordinates.
    overrides : sequence of str
        ``KEY=VALUE`` scene overrides (scenes only).
    methods : sequence of str, optional
        Methods, each at its defaults (default: all listed).
    noise, density, outliers : sequence of float, optional
        Grid levels: range noise (3 sigma, metres), fractions of the points kept, outlier
        fractions, 0 to 1 (default: ``recon.experiments.stability``'s). A grid of more than
        200,000 runs (cells x methods), or whose runs would take more than a week at the least,
        is refused before any work (``recon.experiments.stability.check_grid``).
    seed : int
    timeout, memory_limit : float [s], int [MiB], optional
    samples : int, optional
        Surface samples per side when scoring (default ``STABILITY_SAMPLES``: the count a
        cell's Chamfer needs for its stated precision).
    scheduler, n_workers, resume
        As ``compare``; ``n_workers`` is also the runs at once the grid's estimate counts (on a
        Dask cluster given by address, give its size; ``"serial"`` counts one).

    Returns
    -------
    StabilityResult
    """
    from formats.paths import writing_into
    from recon.experiments import stability as sweep
    from recon.experiments.cases import SWEEP_THREADS, score_options, variants
    from recon.experiments.sweep import check_scheduler as check_value
    from recon.experiments.sweep import default_workers
    from recon.inputs import walk_early
    from recon.surfaces.isolation import Limits, start_workers, warm_truth

    runs = variants(methods, grid=False)  # unknown names fail before anything is read
    check_seed(seed)
    limits = Limits.from_options(timeout, memory_limit)
    samples = samples or sweep.STABILITY_SAMPLES   # a cell's stated precision
    options = score_options(samples, memory_mb=limits.memory_mb)
    check_value(scheduler)
    _check_workers(n_workers)
    # the grid's levels and cost, before anything is simulated, read or written
    noise, density, outliers = sweep.check_grid(
        sweep.DEFAULT_NOISE if noise is None else noise,
        sweep.DEFAULT_DENSITY if density is None else density,
        sweep.DEFAULT_OUTLIERS if outliers is None else outliers, len(runs), samples=samples,
        workers=1 if scheduler == "serial" else n_workers or default_workers())
    # removed again if a refused input leaves it empty
    with writing_into(output, sweep.ParameterError) as output:
        local = scheduler in (None, "threads")
        if local:  # local workers import Open3D while the input loads
            walk_early(*_inputs(source, truth))  # before the pool's launcher thread starts
            start_workers(n_workers or default_workers(), SWEEP_THREADS)
        clouds, truth_mesh = _stability_clouds(source, output, truth, truth_scale, overrides,
                                               noise, seed)
        if local:  # the workers make the truth ready for scoring while the first cell is prepared
            warm_truth(tuple(truth_mesh), options, SWEEP_THREADS)
        report = sweep.stability(output, clouds=clouds, truth=truth_mesh, names=methods, seed=seed,
                                 scheduler=scheduler, n_workers=n_workers, resume=resume,
                                 score_options=options,
                                 fingerprint={"source": str(source), "overrides": list(overrides),
                                              "truth": str(truth)},
                                 noise=noise, density=density, outliers=outliers,
                                 **limits.kwargs())
        return StabilityResult(report["records"], report["csv"], report["json"], report["pngs"],
                               report["failure_rate"])


def _stability_clouds(source, output: Path, truth, truth_scale: float, overrides, noise,
                      seed: int):
    """The clouds a stability sweep degrades and their truth mesh: a cloud or log file as it
    is, or a scene simulated once per noise level (a log's with its missed beams)."""
    from recon.experiments import stability as sweep
    from recon.inputs import is_strike_log, load_cloud, load_truth

    path = Path(source)
    if path.is_file() and path.suffix.lower() != ".toml":
        if overrides:
            raise sweep.ParameterError(f"overrides: a cloud or a log ({path}) takes none, only "
                                       "a scene does", argument="overrides")
        cloud = load_cloud(path)
        if truth is not None:
            truth_mesh = load_truth(truth, scale=truth_scale)
        elif is_strike_log(path):
            truth_mesh = load_truth(path)
        else:
            raise sweep.ParameterError(f"truth must be given: {path} is a cloud, not a strike "
                                       "log with truth", argument="truth")
        return {"base": sweep.StabilityCloud(cloud.points, cloud.view_points, False,
                                             _misses(path, cloud, seed))}, truth_mesh
    clouds, truth_mesh = sweep.simulate_levels(str(source), noise, output, overrides=overrides,
                                               seed=seed)
    if truth is not None:
        truth_mesh = load_truth(truth, scale=truth_scale)
    return clouds, truth_mesh


def studies() -> list[tuple[str, str]]:
    """``(name, title)`` of every study of the paper, in its order."""
    from recon.experiments import studies as registry

    return registry.describe()


def study(name: str, output, *, size: str = "full", scheduler: str | None = None,
          resume: bool = False, n_workers: int | None = None) -> StudyResult:
    """Run one of the paper's studies into ``output`` (``recon study NAME``).

    Parameters
    ----------
    name : str
        One of ``studies()``.
    output : str or Path
        Directory (created) for results.csv, summary.json and the charts.
    size : {"full", "quick", "tiny"}
        As in the paper, reduced for CI, or tiny for tests.
    scheduler, n_workers, resume
        As ``compare``, but by default on a local Dask cluster of ``n_workers`` worker
        processes (``"threads"``: ``n_workers`` threads of this process).

    Returns
    -------
    StudyResult
        The claims checked (each with the paper's claim, ours and a verdict), the cases and
        failures, the files; ``summary`` as written to ``output/summary.json``.
    """
    from recon.experiments import studies as registry
    from recon.experiments.studies.runner import SUMMARY_JSON

    _check_workers(n_workers)
    summary = registry.run(name, output, size=size, scheduler=scheduler, resume=resume,
                           n_workers=n_workers)
    return StudyResult(summary["title"], summary["size"], summary["claims"], summary["n_cases"],
                       summary["n_failed"], summary["failures"], summary["files"],
                       summary["wall_time_s"], summary, Path(output) / SUMMARY_JSON)


def study_all(output, *, size: str = "full", scheduler: str | None = None,
              resume: bool = False, n_workers: int | None = None) -> StudiesResult:
    """Run every study into ``output/NAME/`` and write ``output/index.json``
    (``recon study all``); arguments as ``study``."""
    from recon.experiments import studies as registry

    _check_workers(n_workers)
    index = registry.run_all(output, size=size, scheduler=scheduler, resume=resume,
                             n_workers=n_workers)
    return StudiesResult(index, Path(output) / registry.INDEX_JSON)


def _check_workers(n_workers: int | None) -> None:
    if n_workers is not None and n_workers < 1:
        raise ParameterError(f"n_workers must be >= 1, got {n_workers}", argument="n_workers")


def report(directory, output) -> Path:
    """Write one self-contained HTML page of a ``study`` (one or all) or ``compare`` directory
    (``recon report``); return its path."""
    from recon.experiments.report import write_report

    return write_report(directory, output)


def demo(output, *, scene: str = DEMO_SCENE, method: str = DEMO_METHOD,
         overrides: Sequence[str] = (), seed: int = DEMO_SEED,
         say: Callable[[str], None] = lambda text: None) -> DemoResult:
    """The whole pipeline on a built-in scene (``recon demo``), the first thing a new user runs:
    simulate (a preset) -> validate -> ingest (body-frame cloud, written and kept from one pass)
    -> reconstruct -> score the cloud and the surface against the log's truth mesh, every file
    in ``output``.

    Parameters
    ----------
    output : str or Path
        Directory (created) for strikes.h5, cloud.ply, truth.ply, surface.ply, scores.json.
    scene : str
        Preset name or scene file.
    method : str
        Reconstruction method, run isolated.
    overrides : sequence of str
        ``section.key=value`` scene overrides.
    seed : int
        Seed of the simulation, the normals and the scoring samples.
    say : callable
        Called with one line per step as the demo goes (the CLI passes ``print``).
    """
    from formats import StrikeLog
    from formats.atomic import write_text_atomically
    from formats.mesh_io import write_mesh

    out = Path(output)
    out.mkdir(parents=True, exist_ok=True)
    files = {"log": out / "strikes.h5", "cloud": out / "cloud.ply", "truth": out / "truth.ply",
             "surface": out / "surface.ply", "scores": out / "scores.json"}

    start = _demo_step(say, f"simulate {scene} (seed {seed})")
    log = simulate(scene, files["log"], seed=seed, overrides=overrides)
    summary = log.summary
    say(f"  {summary['shots']:,} shots, {summary['strikes']:,} strikes, "
        f"{summary['duration_s'] / 3600:.1f} h of flight, in {time.perf_counter() - start:.1f} s")

    _demo_step(say, "validate the strike log")
    with StrikeLog(log) as reader:
        reader.validate()
        truth = reader.truth_mesh()
    write_mesh(files["truth"], truth, source=files["log"].name)

    start = _demo_step(say, "ingest: register strikes into the target body frame")
    cloud = ingest(log, output=files["cloud"])
    say(f"  {len(cloud):,} points in {time.perf_counter() - start:.1f} s")

    start = _demo_step(say, f"reconstruct with {method}")
    surface = reconstruct(cloud, method=method, seed=seed, isolate=True)
    write_mesh(files["surface"], surface, source=files["cloud"].name)
    say(f"  {surface.n_faces:,} faces in {time.perf_counter() - start:.1f} s")

    start = _demo_step(say, "score cloud and surface against the truth mesh")
    scores = {"cloud": score(cloud, truth=truth, seed=seed),
              "surface": score(surface, truth=truth, seed=seed)}
    say(f"  in {time.perf_counter() - start:.1f} s")
    write_text_atomically(files["scores"], json.dumps(
        {"scene": scene, "simulation": summary,
         "scores": {k: s.to_dict() for k, s in scores.items()}}, indent=2, default=str))
    return DemoResult(files, summary, scores, surface.n_faces)


def _demo_step(say: Callable[[str], None], text: str) -> float:
    say(f"- {text}")
    return time.perf_counter()
