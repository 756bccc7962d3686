"""recon's public API: the whole pipeline in a handful of verbs.

>>> from recon import api
>>> log = api.simulate("asteroid-lrf", "run.h5", seed=0)        # sim/: write a strike log
>>> cloud = api.ingest(log)                                      # body-frame Cloud
>>> surface = api.reconstruct(cloud, method="auto")              # Surface (a Mesh)
>>> report = api.score(surface, truth=log)                       # metrics.ScoreReport
>>> pictures = api.edges(cloud, truth=log, output="edges")        # edge points: PLY + PNG
>>> table = api.compare(cloud, truth=log, output="cmp")          # every method, speed x accuracy

Every verb takes recon's own types (``formats.geometry.Cloud`` and ``Mesh``, a strike log path)
or the plain data they wrap, and returns recon's types. Files are read once per call. The policy
the command line applies (which truth a log implies, what ``auto`` decides, what a comparison
writes) lives here and in the modules these verbs call, so a script gets what ``recon`` prints.
Bad input raises a ``formats.errors.ReconError`` subclass with a one-line message.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from formats.errors import ReconError
from formats.geometry import Cloud, Frame, Mesh

__all__ = ["SimulatedLog", "compare", "edges", "ingest", "reconstruct", "score", "simulate"]


class ApiError(ReconError, ValueError):
    """A public API call got an argument it cannot use."""


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


def simulate(scene, output, *, seed: int = 0, overrides: Sequence[str] = (),
             progress: bool | None = None, live: bool = False,
             compression: str | None = None) -> SimulatedLog:
    """Simulate a campaign and write its strike log.

    Parameters
    ----------
    scene : str or Path
        A preset name (``recon simulate --list``) or a scene TOML file.
    output : str or Path
        The ``.h5`` strike log to write (atomically: it appears only when complete).
    seed : int, >= 0
        Seed of every error model; the same seed gives the same bytes.
    overrides : sequence of str
        ``section.key=value`` scene overrides, as ``recon simulate --set``.
    progress : bool or None
        Progress bar (None: on a terminal only).
    live : bool
        Write the log in HDF5 SWMR mode, so that ``recon ingest LOG --follow`` (and
        ``formats.strike_log.follow``) read the strikes as they arrive.
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

    summary = sim.simulate(sim.load_scene(str(scene), list(overrides)), output, seed=seed,
                           progress=progress, live=live,
                           compression=compression or DEFAULT_COMPRESSION)
    return SimulatedLog(Path(summary["path"]), summary)


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
    from recon.registration.ingest import ingest as register_log

    return register_log(log, frame=frame, output=output, progress=progress)


def load(value, *, name: str = "input", points_only: bool = False) -> Cloud | Mesh:
    """A ``Cloud`` or ``Mesh`` from recon's types, plain arrays or a file (cloud, mesh or log).

    A strike log is ingested into a body-frame cloud (``points_only``: without its per-point
    attributes).
    """
    if isinstance(value, Cloud | Mesh):
        return value
    if isinstance(value, str | os.PathLike):
        from recon.inputs import load_geometry

        return load_geometry(value, points_only=points_only)
    if isinstance(value, tuple | list) or hasattr(value, "faces"):
        return Mesh.of(value, name)
    return Cloud.of(value, name)


def truth_of(value, *, scale: float = 1.0, units: str | None = None) -> Mesh:
    """The truth mesh named by ``value``: a ``Mesh`` or ``(vertices, faces)``, a mesh file (in
    ``units``, default the format's, then times ``scale``), or a strike log with its embedded
    truth mesh."""
    if isinstance(value, str | os.PathLike):
        from recon.inputs import load_truth

        return load_truth(value, scale=scale, units=units)
    return Mesh.of(value, "truth")


def default_truth(test):
    """The truth a test input implies on its own: a strike log's embedded truth mesh.

    Raises
    ------
    ApiError
        ``test`` is not a strike log, so the truth must be given.
    """
    from formats.paths import check_source
    from recon.inputs import is_strike_log

    check_source(test, ApiError)
    if not is_strike_log(test):
        raise ApiError(f"{test}: is not a strike log with truth; give --truth")
    return test


def score(test, *, truth, truth_scale: float = 1.0, truth_units: str | None = None,
          tau: float | None = None,
          tau_fraction: float | None = None, edges: bool = True, seed: int | None = 0,
          progress=None, **options):
    """Score a cloud or a mesh against the truth mesh (``metrics.score``).

    Parameters
    ----------
    test : Cloud, Mesh, Surface, (n, 3) array, (vertices, faces), or a file (cloud, mesh or log)
    truth : Mesh, (vertices, faces), a mesh file or a strike log with truth
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

    truth = truth_of(truth, scale=truth_scale, units=truth_units)
    options = {"tau": tau, "tau_fraction": tau_fraction, "edges": edges, "seed": seed,
               "progress": progress} | options
    if isinstance(test, str | os.PathLike):
        # A file is scored block by block (metrics.score.score_stream): a strike log as it is
        # registered and a binary PLY, HDF5 or LAS cloud as it is read, in memory flat in
        # their size; another cloud file read whole, without per-point arrays beside it.
        # Errors name the file.
        from formats.cloud_io import stream_cloud
        from metrics import defaults
        from metrics.score import score_stream
        from recon.inputs import is_strike_log

        if is_strike_log(test):
            from recon.registration.ingest import iter_points

            return score_stream(lambda: iter_points(test), truth, name=f"test {test}",
                                **options)
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
    return score_against(load(test, name="test"), truth, **options)


def edges(test, *, truth, output, truth_scale: float = 1.0, truth_units: str | None = None,
          seed: int = 0, title: str | None = None, edge_options: dict | None = None,
          progress=None) -> dict:
    """The edge points of a cloud against the truth, written as a PLY and the paper's picture
    (``recon.edge_pictures``): ``recon edges``.

    Parameters
    ----------
    test : Cloud, (n, 3) array, Mesh, or a file (cloud, mesh or log)
    truth : Mesh, (vertices, faces), a mesh file or a strike log with truth
    output : str or Path
        Directory for edges.ply, edges.png and edges.json.
    truth_scale, truth_units, seed, title, edge_options, progress
        As ``api.score`` and ``recon.edge_pictures.edge_pictures``.

    Returns
    -------
    dict
        ``report`` (``metrics.EdgeReport``), ``files``, ``counts``.
    """
    from recon.edge_pictures import edge_pictures

    truth_mesh = truth_of(truth, scale=truth_scale, units=truth_units)
    return edge_pictures(load(test, name="test"), truth_mesh, output, seed=seed, title=title,
                         edge_options=edge_options, progress=progress)


def reconstruct(cloud, *, method: str = "poisson", params: dict[str, Any] | None = None,
                remove_outliers: bool = False, voxel: float | None = None,
                normals_k: int | None = None, orient: str = "centroid", seed: int = 0,
                isolate: bool = True,
                timeout: float | None = None, memory_limit: int | None = None,
                auto_methods: Sequence[str] | None = None, holdout: float | None = None):
    """Reconstruct a surface mesh from a point cloud with one method, or ``method="auto"``.

    Parameters
    ----------
    cloud : Cloud, (n, 3) array, or a cloud file or strike log
    method : str
        A registered method (``recon reconstruct --list-methods``) or ``"auto"``: chosen without
        the truth, its choice and reason in ``surface.info["auto"]``.
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

    Returns
    -------
    recon.surfaces.reconstruct.Surface
        A ``Mesh`` with ``method``, resolved ``params`` and run ``info``; ``info["estimate"]``
        is the truth-free predicted Chamfer distance and F-score with their band
        (``recon.surfaces.judge.estimate``; for ``"auto"`` from the chosen candidate's held-out
        passes).
    """
    from recon.surfaces.auto import HOLDOUT_FRACTION, choose_for
    from recon.surfaces.isolation import Limits
    from recon.surfaces.methods import bind
    from recon.surfaces.prepare import Preparation, load_prepared
    from recon.surfaces.reconstruct import estimate_of
    from recon.surfaces.reconstruct import reconstruct as run_method

    preparation = Preparation(remove_outliers=remove_outliers, voxel=voxel, fallback=orient,
                              seed=seed, **({} if normals_k is None else {"k": normals_k}))
    limits = Limits.from_options(timeout, memory_limit)
    choice = None
    if method == "auto":
        if params:
            raise ApiError("params cannot be combined with method='auto'")
        run = None
    else:
        run = bind(method, params)
    cloud, prepared = load_prepared(cloud, preparation)
    if run is None:
        choice = choose_for(cloud, methods=auto_methods, preparation=preparation, limits=limits,
                            holdout=HOLDOUT_FRACTION if holdout is None else holdout)
        run = choice.run
    surface = run_method(prepared, method=run, isolate=isolate, **limits.kwargs())
    surface.frame = cloud.frame  # so that scoring against a truth in another frame is refused
    surface.info["estimate"] = estimate_of(
        surface, cloud, heldout=None if choice is None else choice.chosen.heldout,
        seed=seed).to_dict()
    if choice is not None:
        surface.info["auto"] = choice.to_dict()
    return surface


def compare(cloud, *, truth, output, methods: Sequence[str] | None = None, **options) -> dict:
    """Run every method on one cloud (at its defaults; ``grid="full"`` adds the parameter
    grids), each isolated, and score each surface against the truth: the speed against
    accuracy comparison of ``recon compare``.

    Parameters
    ----------
    cloud : Cloud, (n, 3) array, or a cloud file or strike log
    truth : Mesh, (vertices, faces), a mesh file or a strike log with truth
    output : str or Path
        Directory for results.csv, results.json, speed_accuracy.png and the meshes.
    methods : sequence of str, optional
        Methods to run (default: all).
    **options
        As ``recon.experiments.compare.compare_input``: ``grid``, ``auto``, ``preparation``,
        ``limits``, ``samples``, ``scheduler``, ``n_workers``, ``resume``, ``keep_meshes``.

    Returns
    -------
    dict
        ``records`` (ranked), ``table``, the Pareto fronts and the paths written.
    """
    from recon.experiments.compare import compare_input

    return compare_input(cloud, truth, output, names=methods, **options)
