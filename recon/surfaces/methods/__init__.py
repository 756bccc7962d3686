"""Surface reconstruction methods, one module each, registered here by name.

A method is a function ``run(cloud, **params) -> (vertices, faces)`` taking a ``MethodInput``
(points with oriented normals, spacing and noise scale, all in the body frame) and returning a
triangle mesh: ``(v, 3) float64`` metres and ``(f, 3) int64`` indices, counter-clockwise seen
from outside. Its module wraps it in a ``Method`` (parameters with defaults, a small grid for
``recon compare``, a kind) and calls ``register``. Adding a method touches one file: its module
plus its name in ``BUILTIN_MODULES``.

Methods marked ``hidden`` (test-only ones) run when asked for by name but never appear in
``available()``, ``recon compare``'s default list or ``--help``.

A method name and its parameters are resolved once, where they enter (``bind(name, params)`` or
``Method.bind``), into a ``Run``: a small picklable value that travels unchanged through sweeps,
worker processes and the isolated child (``recon.surfaces.isolation``), which imports
``Run.module`` and looks the method up by name once to call it.
"""

from __future__ import annotations

import importlib
import json
import math
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from formats.errors import MethodFailed, ParameterError
from recon.surfaces import fit_times

if TYPE_CHECKING:
    from recon.registration.misses import MissedBeams

Kind = Literal["primitive", "planar", "smooth", "interpolating", "baseline", "test"]
KINDS = ("primitive", "planar", "smooth", "interpolating", "baseline", "test")

# Built-in method modules, imported (cheaply: heavy libraries load inside each ``run``) the first
# time the registry is used.
BUILTIN_MODULES = (
    "recon.surfaces.methods.convex_hull",
    "recon.surfaces.methods.ellipsoid",
    "recon.surfaces.methods.planes",
    "recon.surfaces.methods.plane",
    "recon.surfaces.methods.poisson",
    "recon.surfaces.methods.completed_poisson",
    "recon.surfaces.methods.screened_poisson",
    "recon.surfaces.methods.ball_pivoting",
    "recon.surfaces.methods.ball_pivoting_meshlab",
    "recon.surfaces.methods.alpha_shape",
    "recon.surfaces.methods.rimls",
    "recon.surfaces.methods.apss",
    "recon.surfaces.methods.delaunay_balls",
    "recon.surfaces.methods.visibility",
)

# What a default costs: each listed method's fit time [s] at its defaults, isolated as ``recon
# reconstruct`` runs it, on (the LIDAR cloud, the LRF cloud) of benchmarks/bench_methods.py:
# the table ``recon.surfaces.fit_times`` reads from the benchmark's results. ``listing`` prints
# them; a new method needs its line (tests/recon/surfaces).
DEFAULT_FIT_S: dict[str, tuple[float, float]] = fit_times.fit_s()
COST_SOURCE = fit_times.source()
# Points of the two clouds ``DEFAULT_FIT_S`` was measured on.
COST_POINTS = fit_times.cost_points()

# How a parameter's type reads in an error message: (one value, several values).
_TYPE_NAMES = {int: ("an integer", "integers"), float: ("a number", "numbers"),
               bool: ("a boolean", "booleans"), str: ("a string", "strings")}

@dataclass(frozen=True)
class MethodInput:
    """What every method receives.

    Attributes
    ----------
    points : (n, 3) float64, metres, body frame
    normals : (n, 3) float64
        Unit normals oriented out of the surface (``recon.surfaces.normals.estimate_normals``).
    spacing : float, metres
        Median ``sqrt(area per point)`` (``recon.surfaces.normals.point_spacing``); radii, cells and
        thresholds scale with it.
    noise : float, metres
        Robust out-of-surface scatter (``recon.surfaces.normals.noise_scale``).
    seed : int
        Seed of every random choice a method makes.
    neighbours : (n,) int64, optional
        Size of each point's normal neighbourhood (``recon.surfaces.normals.local_planes``: grown
        until it spans a plane, e.g. across LRF tracks); methods fitting local planes start there.
    sigma : (n,) float64, metres, optional
        1-sigma uncertainty of each point along its surface normal, from the sensor error model
        recorded in the strike log (``recon.surfaces.uncertainty``): anisotropic, the beam's
        range error and its lateral (angle, pose) error projected on the normal. None when the
        cloud carries no error model; methods that can weight points (``weighted``) use
        ``1 / sigma^2``.
    view_points : (n, 3) float64, metres, body frame, optional
        Sensor position each point was seen from (the cloud's ``view_x/y/z``): the segment from
        it to the point crossed empty space (the ``visibility`` method uses these rays). None
        for a cloud without view points.
    misses : recon.registration.misses.MissedBeams, optional
        The strike log's missed beams near the points, in the body frame: origins, unit
        directions and the free span ``range_min``..``range_max`` of each (beams that crossed
        free space and struck nothing; the ``visibility`` method votes the cells they cross
        outside, other methods ignore them). None for a cloud file, which records no misses.
    """

    points: np.ndarray
    normals: np.ndarray
    spacing: float
    noise: float
    seed: int = 0
    neighbours: np.ndarray | None = None
    sigma: np.ndarray | None = None
    view_points: np.ndarray | None = None
    misses: MissedBeams | None = None


@dataclass(frozen=True)
class Param:
    """One method parameter: its default, type, a one-line meaning and its allowed values.

    Every number is bounded: an ``int`` or ``float`` parameter gives ``choices`` or both
    ``minimum`` and ``maximum`` (``Method`` refuses one without), so that a value that would
    run out of memory or time (a Poisson depth of 100) is refused before any work, in the
    process or isolated. ``math.inf`` is a bound only where infinity means something (a trim
    that keeps everything).
    """

    default: Any
    type: type
    doc: str
    choices: tuple | None = None
    minimum: float | None = None
    maximum: float | None = None
    sequence: bool = False  # a comma-separated list of ``type`` (e.g. ball radii)

    @property
    def bounded(self) -> bool:
        """Whether the allowed values are declared (numbers need bounds or choices)."""
        if self.type not in (int, float) or self.choices is not None:
            return True
        return self.minimum is not None and self.maximum is not None

    def allowed(self) -> str:
        """The allowed values in words, e.g. ``1 to 12`` (empty when any value goes)."""
        if self.choices is not None:
            return "one of " + ", ".join(str(c) for c in self.choices)
        if self.minimum is not None and self.maximum is not None:
            return f"{self.minimum:g} to {self.maximum:g}"
        return ""

    def parse(self, text: str, *, name: str, method: str) -> Any:
        """Convert ``text`` from the command line (``--param name=text``) and check it.

        ``auto`` or ``none`` give None for parameters whose default is None (automatic).
        """
        if self.default is None and text.strip().lower() in ("auto", "none"):
            return None
        items = text.split(",") if self.sequence else [text]
        try:
            values = tuple(_convert(item.strip(), self.type) for item in items)
        except ValueError:
            single, plural = _TYPE_NAMES.get(self.type, (self.type.__name__,) * 2)
            kind = f"a comma-separated list of {plural}" if self.sequence else single
            raise ParameterError(f"method {method!r}: parameter {name}={text!r} is not "
                                 f"{kind}") from None
        return self.check(values if self.sequence else values[0], name=name, method=method)

    def check(self, value: Any, *, name: str, method: str) -> Any:
        """Return ``value`` coerced to this parameter's type, or raise ``ParameterError``."""
        if value is None and self.default is None:
            return None
        values = tuple(value) if self.sequence and not isinstance(value, str) else (value,)
        if self.sequence and not values:
            raise ParameterError(f"method {method!r}: parameter {name} needs at least one value")
        coerced = []
        for item in values:
            if self.type is bool and not isinstance(item, (bool, np.bool_)):
                raise ParameterError(f"method {method!r}: parameter {name} must be true or "
                                     f"false, got {item!r}")
            try:
                item = self.type(item)
            except (TypeError, ValueError):
                raise ParameterError(f"method {method!r}: parameter {name} must be a "
                                     f"{self.type.__name__}, got {item!r}") from None
            if self.choices is not None and item not in self.choices:
                raise ParameterError(f"method {method!r}: parameter {name} must be one of "
                                     f"{self.choices}, got {item!r}")
            if ((self.minimum is not None and not item >= self.minimum)
                    or (self.maximum is not None and not item <= self.maximum)):
                raise ParameterError(f"method {method!r}: parameter {name} must be from "
                                     f"{self.allowed()}, got {item!r}")
            coerced.append(item)
        return tuple(coerced) if self.sequence else coerced[0]


def _convert(text: str, kind: type) -> Any:
    if kind is bool:
        lowered = text.lower()
        if lowered in ("1", "true", "yes", "on"):
            return True
        if lowered in ("0", "false", "no", "off"):
            return False
        raise ValueError(text)
    return kind(text)


@dataclass(frozen=True)
class Method:
    """A registered reconstruction method.

    Attributes
    ----------
    name : str
        Registry name (``recon reconstruct -m NAME``).
    run : callable
        ``run(cloud: MethodInput, **params) -> (vertices, faces)``; raises ``MethodFailed``.
    params : dict of str to Param
    grid : tuple of dict
        Parameter overrides ``recon compare`` runs besides the defaults.
    kind : {"primitive", "planar", "smooth", "interpolating", "baseline", "test"}
        ``primitive``: a few numbers (an ellipsoid); ``planar``: a few planar polygons;
        ``smooth``: an implicit surface fitted to the points;
        ``interpolating``: triangles through the points themselves; ``baseline``: a floor.
    summary : str
        One line for listings.
    preload : tuple of str
        Modules imported before the clock starts, so timings exclude import cost.
    hidden : bool
        Test-only: runnable by name, never listed.
    parameters : callable, optional
        ``parameters(vertices, faces) -> int``: the model's free parameters (``parameter_count``);
        None: a free mesh, 3 per vertex.
    """

    name: str
    run: Callable[..., tuple[np.ndarray, np.ndarray]]
    params: Mapping[str, Param]
    grid: tuple[Mapping[str, Any], ...] = ()
    kind: Kind = "smooth"
    summary: str = ""
    preload: tuple[str, ...] = ()
    hidden: bool = False
    parameters: Callable[[np.ndarray, np.ndarray], int] | None = None
    defaults: Mapping[str, Any] = field(init=False, repr=False)

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {self.kind!r}")
        unbounded = [k for k, p in self.params.items() if not p.bounded]
        if unbounded:
            raise ValueError(f"method {self.name!r}: parameter {unbounded[0]!r} needs a minimum "
                             "and a maximum (or choices)")
        object.__setattr__(self, "defaults", {k: p.default for k, p in self.params.items()})

    @property
    def module(self) -> str:
        """Module that registers this method (an isolated child imports it to find the method)."""
        return self.run.__module__

    def parameter_count(self, vertices: np.ndarray, faces: np.ndarray) -> int:
        """Free parameters of the model this method made: 9 for an ellipsoid, 3 per plane for a
        polyhedron, 3 per vertex for a free mesh (the default), reported beside faces."""
        if self.parameters is not None:
            return int(self.parameters(vertices, faces))
        return 3 * len(vertices)

    def resolve(self, params: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """The full parameter set: defaults overridden by ``params``, each checked.

        Raises
        ------
        ParameterError
            An unknown name or a bad value.
        """
        params = dict(params or {})
        unknown = sorted(set(params) - set(self.params))
        if unknown:
            known = ", ".join(self.params) or "none"
            raise ParameterError(f"method {self.name!r} has no parameter {unknown[0]!r} "
                                 f"(its parameters: {known})")
        resolved = dict(self.defaults)
        for name, value in params.items():
            resolved[name] = self.params[name].check(value, name=name, method=self.name)
        return resolved

    def bind(self, params: Mapping[str, Any] | None = None) -> Run:
        """This method with ``params`` resolved over its defaults (``resolve``), as a ``Run``."""
        resolved = self.resolve(params)
        changed = [f"{k}={_fmt(v)}" for k, v in resolved.items() if self.defaults.get(k) != v]
        return Run(method=self.name, params=resolved, module=self.module, kind=self.kind,
                   label=" ".join([self.name, *changed]))

    def parse(self, pairs: list[str] | tuple[str, ...]) -> dict[str, Any]:
        """Parse ``key=value`` strings from the command line into checked overrides."""
        overrides: dict[str, Any] = {}
        for pair in pairs:
            key, sep, text = pair.partition("=")
            key = key.strip()
            if not sep or not key:
                raise ParameterError(f"params must be key=value, got {pair!r}",
                                     argument="params")
            if key not in self.params:
                known = ", ".join(self.params) or "none"
                raise ParameterError(f"method {self.name!r} has no parameter {key!r} "
                                     f"(its parameters: {known})")
            overrides[key] = self.params[key].parse(text, name=key, method=self.name)
        return overrides

    def variants(self) -> list[dict[str, Any]]:
        """Resolved parameter sets ``recon compare`` runs: the defaults, then the grid, unique."""
        out: list[dict[str, Any]] = []
        for overrides in ({}, *self.grid):
            resolved = self.resolve(overrides)
            if resolved not in out:
                out.append(resolved)
        return out


@dataclass(frozen=True)
class Run:
    """One method with its resolved parameters: what every isolated run, sweep case and auto
    candidate carries. Make it with ``bind`` (or ``Method.bind``), which checks the parameters.

    Attributes
    ----------
    method : str
        Registry name.
    params : dict
        The full, checked parameter set (defaults included). Do not mutate.
    module : str
        Module that registers the method: a fresh process imports it to find the method.
    kind : {"primitive", "planar", "smooth", "interpolating", "baseline", "test"}
    label : str
        The method and the parameters that differ from its defaults, e.g. ``poisson depth=6``.
    """

    method: str
    params: dict[str, Any]
    module: str
    kind: Kind
    label: str

    @property
    def key(self) -> str:
        """Stable unique key: the method and its parameters as sorted JSON."""
        return run_key(self.method, self.params)

    def method_spec(self) -> Method:
        """The registered ``Method`` (imports ``module`` first, so test-only methods resolve)."""
        importlib.import_module(self.module)
        return get(self.method)


def run_key(method: str, params: Mapping[str, Any]) -> str:
    """Stable unique key of a (method, parameters) pair: ``Run.key``."""
    return f"{method} {json.dumps(_plain(params), sort_keys=True)}"


def _plain(value: Any) -> Any:
    """``value`` with tuples as lists, numpy scalars as Python's, non-finite floats as None."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return _plain(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _fmt(value: Any) -> str:
    if isinstance(value, (tuple, list)):
        return ",".join(_fmt(v) for v in value)
    return f"{value:g}" if isinstance(value, float) else str(value)


_REGISTRY: dict[str, Method] = {}
_LOADED = False
# Held while the built-in modules are imported: a second thread asking for a method waits for
# the registry to be whole instead of reading it half filled.
_LOADING = threading.RLock()


def register(method: Method) -> Method:
    """Add ``method`` to the registry (replacing one of the same name) and return it."""
    _REGISTRY[method.name] = method
    return method


def _load_builtins() -> None:
    global _LOADED
    if _LOADED:
        return
    with _LOADING:
        if not _LOADED:
            for name in BUILTIN_MODULES:
                importlib.import_module(name)
            _LOADED = True


def available(*, include_hidden: bool = False) -> list[str]:
    """Names of the registered methods, in ``BUILTIN_MODULES`` order (hidden ones excluded)."""
    _load_builtins()
    return [name for name, m in _REGISTRY.items() if include_hidden or not m.hidden]


def get(name: str) -> Method:
    """The registered method called ``name``.

    Raises
    ------
    ParameterError
        No such method; the message lists the available ones.
    """
    _load_builtins()
    if name not in _REGISTRY:
        raise ParameterError(f"unknown method {name!r} (available: {', '.join(available())})")
    return _REGISTRY[name]


def listing() -> str:
    """The listed methods, their kinds, summaries, what their defaults cost (``DEFAULT_FIT_S``),
    parameters with defaults, and grids."""
    lines = ["Default fit: seconds at the defaults on a 336k-point asteroid LIDAR cloud and a "
             "77k-point RSO-A LRF cloud", f"({COST_SOURCE}).", ""]
    for name in available():
        spec = get(name)
        lines.append(f"{name} [{spec.kind}]: {spec.summary}")
        if name in DEFAULT_FIT_S:
            lidar, lrf = DEFAULT_FIT_S[name]
            lines.append(f"    default fit: {lidar:.2g} s (336k LIDAR), {lrf:.2g} s (77k LRF)")
        for key, param in spec.params.items():
            default = "auto" if param.default is None else param.default
            allowed = f"; {param.allowed()}" if param.allowed() else ""
            lines.append(f"    {key} = {default}  ({param.doc}{allowed})")
        for overrides in spec.grid:
            lines.append(f"    grid: {' '.join(f'{k}={v}' for k, v in overrides.items())}")
    return "\n".join(lines)


def predicted_fit_s(run: Run, n_points: int) -> float | None:
    """What ``run`` is expected to take on ``n_points`` points, seconds, from ``DEFAULT_FIT_S``.

    A power law ``t = t_m (n / n_m)^p`` from the larger measured cloud ``m`` not above ``n``
    (the smaller one below it), the exponent ``p`` from the two measured times (at least 1: no
    method is sublinear). Known only for a listed method at its defaults; None otherwise.

    Parameters
    ----------
    run : Run
    n_points : int
    """
    if run.method not in DEFAULT_FIT_S or run.params != get(run.method).defaults:
        return None
    (t_big, t_small), (n_big, n_small) = DEFAULT_FIT_S[run.method], COST_POINTS
    exponent = max(1.0, math.log(t_big / t_small) / math.log(n_big / n_small))
    t_m, n_m = (t_big, n_big) if n_points >= n_big else (t_small, n_small)
    return t_m * (max(int(n_points), 1) / n_m) ** exponent


def bind(method: str | Run, params: Mapping[str, Any] | None = None) -> Run:
    """Resolve a method name and parameter overrides once into a ``Run``.

    Parameters
    ----------
    method : str or Run
        A registered name (hidden test methods included), or a ``Run`` (returned as it is).
    params : dict, optional
        Overrides of the method's defaults; only with a name.

    Raises
    ------
    ParameterError
    """
    if isinstance(method, Run):
        if params:
            raise ParameterError(f"run {method.label!r} is already bound; pass no params")
        return method
    return get(method).bind(params)


def parse_run(method: str, pairs: Sequence[str] = ()) -> Run:
    """A ``Run`` from a method name and command-line ``key=value`` strings (``--param``)."""
    spec = get(method)
    return spec.bind(spec.parse(pairs))


def closed(faces: np.ndarray) -> bool:
    """True when no edge borders a single face: the surface encloses a volume. Unlike
    ``watertight``, an edge may have more than two faces (a minimum cut's surface touching
    itself at an edge) and faces need not agree on their orientation.

    Parameters
    ----------
    faces : (f, 3) int64, non-negative
    """
    if len(faces) == 0:
        return False
    a, b, n = _directed_edges(faces)
    # sorted undirected keys: an edge of a single face differs from both neighbours
    key = np.sort(np.minimum(a, b) * n + np.maximum(a, b))
    change = key[1:] != key[:-1]
    once = np.concatenate([[True], change]) & np.concatenate([change, [True]])
    return not np.any(once)


def _directed_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Every face's edges a -> b as two (3f,) int64 arrays, and ``n`` (the vertex count the
    faces use) so that ``a * n + b`` is one integer key an edge."""
    faces = np.asarray(faces, dtype=np.int64)
    return faces.ravel(), faces[:, [1, 2, 0]].ravel(), int(faces.max()) + 1


def watertight(faces: np.ndarray) -> bool:
    """True when every edge has exactly two faces that traverse it in opposite directions.

    Each edge is one int64 key (``a * n + b`` for the edge from vertex a to b, n vertices), so
    the test is two 1-D sorts rather than row-wise uniques of the (3f, 2) edge array.

    Parameters
    ----------
    faces : (f, 3) int64, non-negative
    """
    if len(faces) == 0:
        return False
    a, b, n = _directed_edges(faces)
    directed = np.sort(a * n + b)
    if len(directed) % 2 or np.any(directed[1:] == directed[:-1]):
        return False  # an odd edge count, or an edge traversed twice the same way
    undirected = np.sort(np.minimum(a, b) * n + np.maximum(a, b))
    # Sorted, every key exactly twice: equal within each pair, different across pairs.
    return bool(np.all(undirected[0::2] == undirected[1::2])
                and np.all(undirected[1:-1:2] != undirected[2::2]))


def check_mesh_arrays(vertices, faces, *, method: str) -> tuple[np.ndarray, np.ndarray]:
    """Coerce a method's output to ``(float64 (v, 3), int64 (f, 3))`` and drop unused vertices.

    Raises
    ------
    MethodFailed
        Wrong shapes, non-finite vertices or out-of-range indices.
    """
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if not np.all(np.isfinite(vertices)):
        raise MethodFailed(f"{method}: mesh has non-finite vertices")
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise MethodFailed(f"{method}: faces index vertices that do not exist")
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    remap = np.cumsum(used) - 1
    return vertices[used], remap[faces].astype(np.int64)
