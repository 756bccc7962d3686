"""Reconstruct a surface from a prepared point cloud with one registered method.

The pipeline of ``recon reconstruct``:

1. read the input (a cloud, or a strike log registered on the fly; ``recon.inputs``);
2. prepare it (``recon.surfaces.prepare``): optional outlier removal and voxel downsampling,
   then oriented normals, spacing and noise scale: a ``MethodInput``;
3. run the method, in this process (``reconstruct``) or isolated in a child process with time
   and memory limits (``reconstruct(..., isolate=True)``, what the CLI does), and check the mesh.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from formats.geometry import Cloud, Mesh
from formats.paths import check_destination
from recon.surfaces.checks import check_surface
from recon.surfaces.isolation import DEFAULT_MEMORY_MB, DEFAULT_TIMEOUT_S, Limits, run_isolated
from recon.surfaces.methods import MethodFailed, MethodInput, Run, bind, watertight
from recon.surfaces.prepare import InputError, Preparation, load_prepared


def estimate_of(surface: Mesh, cloud: Cloud, *, heldout=None, seed: int = 0):
    """``recon.surfaces.judge.estimate`` of a surface on the (prepared) cloud it was made from:
    its truth-free predicted Chamfer distance and F-score band."""
    from recon.surfaces.judge import estimate

    return estimate((surface.vertices, surface.faces), cloud, heldout=heldout, seed=seed)


class Surface(Mesh):
    """A reconstructed triangle mesh and how it was made: a ``formats.geometry.Mesh``.

    Attributes
    ----------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64, counter-clockwise seen from outside
    method : str
    params : dict
        The resolved parameters.
    info : dict
        ``wall_time_s``, ``watertight``, for isolated runs ``peak_memory_mb``, ``estimate``
        when made from a cloud (``estimate_of``), and for ``method="auto"`` the choice
        (``auto``).
    """

    __slots__ = ("info", "method", "params")

    def __init__(self, vertices, faces, method: str, params: dict[str, Any],
                 info: dict[str, Any] | None = None):
        super().__init__(vertices, faces)
        self.method, self.params, self.info = method, params, dict(info or {})

    def __repr__(self) -> str:
        return f"Surface({self.method}, {self.n_vertices} vertices, {self.n_faces} faces)"


def reconstruct(cloud: MethodInput, *, method: str | Run = "poisson", params: dict | None = None,
                isolate: bool = False, timeout_s: float = DEFAULT_TIMEOUT_S,
                memory_mb: int | None = DEFAULT_MEMORY_MB, on_wait=None) -> Surface:
    """Run one registered method on a prepared cloud.

    Parameters
    ----------
    cloud : MethodInput
        From ``recon.surfaces.prepare.prepare``.
    method : str or Run
        A ``Run`` (``recon.surfaces.methods.bind``), or a name from
        ``recon.surfaces.methods.available()``, resolved here once with ``params``.
    params : dict, optional
        With a name only: overrides of the method's defaults.
    isolate : bool
        Run in a child process with ``timeout_s`` and ``memory_mb`` limits (crashes and hangs
        become ``MethodFailed``) instead of in this process.
    timeout_s, memory_mb
        Limits of the isolated run.
    on_wait : callable, optional
        For an isolated run, called with the child's stage while waiting (``run_isolated``).

    Returns
    -------
    Surface

    Raises
    ------
    UnknownMethod, ParameterError
        Bad method name or parameter.
    MethodFailed
        The method failed, crashed, timed out, or returned an empty or degenerate mesh.
    """
    run = bind(method, params)
    if isolate:
        result = run_isolated(run, cloud, timeout_s=timeout_s, memory_mb=memory_mb,
                              on_wait=on_wait)
        if result["status"] != "ok":
            raise MethodFailed(f"{run.method} failed ({result['failure']}): {result['reason']}")
        info = {k: result[k] for k in ("wall_time_s", "peak_memory_mb", "watertight")}
        return Surface(result["vertices"], result["faces"], run.method, run.params, info)
    import time

    start = time.perf_counter()
    vertices, faces = run.method_spec().run(cloud, **run.params)
    elapsed = time.perf_counter() - start
    vertices, faces = check_surface(vertices, faces, cloud.points, method=run.method)
    return Surface(vertices, faces, run.method, run.params,
                   {"wall_time_s": elapsed, "watertight": watertight(faces)})


def reconstruct_to_file(cloud: Cloud, prepared: MethodInput, output, *, run: Run,
                        limits: Limits | None = None, isolate: bool = True,
                        on_wait: Callable[[str], None] | None = None,
                        heldout=None, source=None) -> dict[str, Any]:
    """Reconstruct a prepared cloud with ``run``, write the mesh, and summarise.

    Parameters
    ----------
    cloud : Cloud
        The prepared points before normals (``Preparation.apply``): says whether there were
        view points.
    prepared : MethodInput
    output : str or Path
        Mesh to write (.ply).
    run : Run
    limits : Limits, optional
        Of the isolated run (default: ``Limits()``).
    isolate : bool
        Run in a child process (default) or in this one.
    on_wait : callable, optional
        Called with the isolated child's stage while waiting.
    heldout : recon.surfaces.judge.HeldOut, optional
        Held-out residuals of the same run (``-m auto``'s), for the estimate.

    Returns
    -------
    dict
        ``n_points``, ``spacing_m``, ``noise_m``, ``view_points``, ``method``, ``params``,
        ``label``, ``output``, ``n_vertices``, ``n_faces``, ``wall_time_s``, ``watertight``,
        ``estimate`` (``recon.surfaces.judge.Estimate.to_dict``: the truth-free predicted
        Chamfer distance and F-score) and, isolated, ``peak_memory_mb``.
    """
    from formats.mesh_io import write_mesh

    limits = limits or Limits()
    surface = reconstruct(prepared, method=run, isolate=isolate, on_wait=on_wait,
                          **limits.kwargs())
    surface.info["estimate"] = estimate_of(surface, cloud, heldout=heldout,
                                           seed=prepared.seed).to_dict()
    write_mesh(output, Mesh(surface.vertices, surface.faces, frame=cloud.frame),
               source=None if source is None else Path(source).name)
    return {"n_points": len(prepared.points), "spacing_m": prepared.spacing,
            "noise_m": prepared.noise, "view_points": cloud.view_points is not None,
            "method": run.method, "params": surface.params, "label": run.label,
            "output": str(output), "n_vertices": len(surface.vertices),
            "n_faces": len(surface.faces), **surface.info}


def reconstruct_input(input, output, *, method: str | Run = "poisson",
                      params: dict | None = None, preparation: Preparation | None = None,
                      limits: Limits | None = None, isolate: bool = True,
                      on_wait: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Read a cloud or a strike log, prepare it, reconstruct it with one method, write the mesh.

    What ``recon reconstruct -m METHOD`` does (``-m auto``:
    ``recon.surfaces.auto.choose_and_reconstruct``).

    Parameters
    ----------
    input : str or Path
        Point cloud (.ply, .las, .laz, .h5) or strike log (registered on the fly).
    output : str or Path
        Mesh to write (.ply).
    method : str or Run
        A ``Run``, or a registered name resolved once here with ``params``.
    params : dict, optional
    preparation : Preparation, optional
    limits : Limits, optional
    isolate : bool
    on_wait : callable, optional
        See ``reconstruct_to_file``.

    Returns
    -------
    dict
        ``input`` and ``reconstruct_to_file``'s summary.
    """
    run = bind(method, params)
    check_destination(output, InputError)   # before the work, not after it
    cloud, prepared = load_prepared(input, preparation)
    return {"input": str(input)} | reconstruct_to_file(cloud, prepared, Path(output), run=run,
                                                       limits=limits, isolate=isolate,
                                                       on_wait=on_wait, source=input)
