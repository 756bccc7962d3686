"""Reconstruct a surface from a prepared point cloud with one registered method.

The pipeline of ``recon reconstruct``:

1. read the input (a cloud, or a strike log registered on the fly; ``recon.inputs``);
2. prepare it (``recon.surfaces.prepare``): optional outlier removal and voxel downsampling,
   then oriented normals, spacing and noise scale: a ``MethodInput``;
3. run the method, in this process (``reconstruct``) or isolated in a child process with time
   and memory limits (``reconstruct(..., isolate=True)``, what the CLI does), and check the mesh.
"""

from __future__ import annotations

from typing import Any

from formats.geometry import Cloud, Mesh
from recon.surfaces.checks import check_surface
from recon.surfaces.isolation import DEFAULT_MEMORY_MB, DEFAULT_TIMEOUT_S, run_isolated
from recon.surfaces.methods import MethodFailed, MethodInput, Run, bind, closed, watertight


def estimate_of(surface: Mesh, cloud: Cloud, *, heldout=None, seed: int = 0,
                target_kind: str = "unknown", misses=None):
    """``recon.surfaces.estimate.estimate`` of a surface on the (prepared) cloud it was made from
    (and the missed beams of its strike log, if any): its truth-free predicted Chamfer distance
    and F-score band."""
    from recon.surfaces.estimate import estimate

    return estimate((surface.vertices, surface.faces), cloud, heldout=heldout, seed=seed,
                    target_kind=target_kind, misses=misses)


def prepare_estimate(cloud: Cloud, *, seed: int = 0, target_kind: str = "unknown",
                     misses=None) -> None:
    """What ``estimate_of`` needs of ``cloud`` whatever the surface, made now and kept
    (``recon.surfaces.estimate.prepare``): called while the surface is fitted elsewhere, the
    estimate that follows the fit finds it made."""
    from recon.surfaces.estimate import prepare

    prepare(cloud, seed=seed, target_kind=target_kind, misses=misses)


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

    @property
    def closure(self) -> str:
        """``"watertight"``; ``"closed"``: no border, but an edge of more than two faces (a
        minimum cut's surface touching itself) or faces of both orientations on one; or
        ``"open"``: it has a border."""
        if self.info.get("watertight", watertight(self.faces)):
            return "watertight"
        return "closed" if closed(self.faces) else "open"


def reconstruct(cloud: MethodInput, *, method: str | Run = "poisson", params: dict | None = None,
                isolate: bool = False, timeout_s: float = DEFAULT_TIMEOUT_S,
                memory_mb: int | None = DEFAULT_MEMORY_MB, on_wait=None,
                threads: int | None = None) -> Surface:
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
    threads : int, optional
        Threads of an isolated run's worker (``run_isolated``: workers are pooled per value;
        ``-m auto`` refits its choice with its fits' threads, on a warm worker of theirs).

    Returns
    -------
    Surface

    Raises
    ------
    ParameterError
        Bad method name or parameter.
    MethodFailed
        The method failed, crashed, timed out, or returned an empty or degenerate mesh.
    """
    run = bind(method, params)
    if isolate:
        result = run_isolated(run, cloud, timeout_s=timeout_s, memory_mb=memory_mb,
                              on_wait=on_wait, threads=threads)
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
