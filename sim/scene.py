"""Scenes: TOML files that state only what differs from the defaults (sim/defaults.py).

A scene is resolved from three layers, each overriding the one before: the defaults, the scene
file (a built-in preset or a path) and ``--set section.key=value`` overrides. Of a group of
alternative keys (``time.rotations`` / ``time.duration``; ``orbit.density`` / ``orbit.mu`` /
``orbit.period``) a layer gives at most one, and the last layer that gives one wins.

Schema (units: m, s, kg; angles in degrees as the ``_deg`` suffix says; see sim/defaults.py for
every default and where it comes from)::

    [target]  kind = "ellipsoid" | "rso-a" | "rso-b" | "mesh"
              semi_axes, subdivisions          (ellipsoid)
              path, scale, center              (mesh)
              spin_period, spin_axis (B), attitude (B->I quaternion x, y, z, w at t = 0)
    [orbit]   radius, inclination_deg, node_deg, phase_deg,
              density | mu | period, change_time, change_inclination_deg
    [time]    step, rotations | duration
    [slew]    amplitude_deg, period, axis (nominal sensor frame), phase_deg
    [sensor]  pattern = "single" | "cross" | "zigzag" | "grid", field_of_view_deg,
              beams (zigzag), resolution (grid), range_min, range_max
    [errors]  range_sigma3, azimuth_sigma3_deg, elevation_sigma3_deg, position_sigma3,
              dilation_alpha, dilation_half_angle_mrad, dilation_subrays

Every problem with a scene raises :class:`SceneError` with one line naming the key.
"""

from __future__ import annotations

import copy
import difflib
import json
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from formats.errors import MeshFormatError, ReconError
from formats.strike_log import SensorErrors
from sim import targets
from sim.defaults import (
    ALTERNATIVES,
    GRAVITATIONAL_CONSTANT,
    MAX_FIELD_OF_VIEW_DEG,
    MAX_SUBDIVISIONS,
    ONLY_WITH,
    PATTERNS,
    SCHEMA,
    TARGET_KINDS,
)


class SceneError(ReconError, ValueError):
    """A scene file, preset name or ``--set`` override is unknown, mistyped or impossible."""


# --------------------------------------------------------------------------- presets


def _preset_dir():
    return resources.files("sim") / "presets"


def _preset_names() -> list[str]:
    return sorted(p.name[:-5] for p in _preset_dir().iterdir() if p.name.endswith(".toml"))


def _description(text: str) -> str:
    """The first comment line of a scene file, without the ``#``."""
    for line in text.splitlines():
        if line.startswith("#"):
            return line.lstrip("#").strip()
        if line.strip():
            break
    return ""


def list_presets() -> list[tuple[str, str]]:
    """Built-in scenes as ``(name, one-line description)``, sorted by name."""
    return [(name, _description((_preset_dir() / f"{name}.toml").read_text(encoding="utf-8")))
            for name in _preset_names()]


# --------------------------------------------------------------------------- the scene


@dataclass(frozen=True, eq=False)
class Scene:
    """A resolved, validated scene, ready to simulate.

    Attributes
    ----------
    name : str
        Preset name or the scene file's path.
    values : dict of section -> dict of key -> value
        Every key the scene uses, defaults filled in, in scene units (degrees for ``_deg``).
    source : str
        Text of the preset or file as given.
    overrides : tuple of str
        The ``section.key=value`` overrides applied.
    vertices : (n, 3) float64, metres, body frame B
        Truth mesh of the target.
    faces : (m, 3) int64
    target : str
        Short target name for the log (``asteroid``, ``rso-a``, ``rso-b``, ``mesh:<file>``).
    mu : float
        Gravitational parameter used for the orbit [m^3/s^2].
    orbit_period : float
        Period of the chaser's orbit [s].
    duration : float
        Length of the campaign [s].
    n_shots : int
        Number of shots, at ``t = k * step`` for ``k = 0 .. n_shots - 1``.
    errors : SensorErrors
        The ``[errors]`` section converted once to what the log records: 3-sigma, SI units.
    """

    name: str
    values: dict
    source: str
    overrides: tuple[str, ...]
    vertices: np.ndarray = field(repr=False)
    faces: np.ndarray = field(repr=False)
    target: str
    mu: float
    orbit_period: float
    duration: float
    n_shots: int
    errors: SensorErrors

    def __getitem__(self, key: str):
        """``scene["orbit.radius"]``: the value of one key (KeyError when it is not used)."""
        section, _, name = key.partition(".")
        return self.values[section][name]

    def get(self, key: str, default=None):
        section, _, name = key.partition(".")
        return self.values.get(section, {}).get(name, default)

    def to_toml(self) -> str:
        """The resolved scene as TOML: every key used, defaults included (stored in logs)."""
        lines = [f"# Scene {self.name!r} as simulated by recon: every key, defaults included "
                 "(sim/defaults.py)."]
        if self.overrides:
            lines.append("# Overrides: " + " ".join(self.overrides))
        for section, keys in self.values.items():
            lines.append(f"\n[{section}]")
            lines += [f"{key} = {toml_value(value)}" for key, value in keys.items()]
        return "\n".join(lines) + "\n"


def toml_value(value) -> str:
    """A scene value written as TOML."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)   # a JSON string is a valid TOML basic string
    return "[" + ", ".join(toml_value(v) for v in value) + "]"


# --------------------------------------------------------------------------- layers


def _kind_name(value) -> str:
    return {bool: "boolean", int: "integer", float: "number", str: "string", list: "array",
            dict: "table"}.get(type(value), type(value).__name__)


def _is_number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _typed(section: str, key: str, value):
    """Check the type of one value against the schema; return it normalised (floats, lists)."""
    spec = SCHEMA[section][key]
    name = f"{section}.{key}"
    kind = spec.kind
    got = f"got {_kind_name(value)} {value!r}"
    if kind == "number":
        if not _is_number(value):
            raise SceneError(f"{name} must be a number [{spec.unit}], {got}")
        return float(value)
    if kind == "int":
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if not isinstance(value, int) or isinstance(value, bool):
            raise SceneError(f"{name} must be an integer, {got}")
        return value
    if kind == "str":
        if not isinstance(value, str):
            raise SceneError(f"{name} must be a string, {got}")
        return value
    if kind == "bool":
        if not isinstance(value, bool):
            raise SceneError(f"{name} must be true or false, {got}")
        return value
    lengths = (2, 4) if kind == "fov" else (int(kind[-1]),)
    want = " or ".join(str(n) for n in lengths)
    integer = kind.startswith("ivec")
    what = "integers" if integer else "numbers"
    if not isinstance(value, list) or len(value) not in lengths:
        raise SceneError(f"{name} must be an array of {want} {what}, {got}")
    if integer:
        value = [int(v) if isinstance(v, float) and v.is_integer() else v for v in value]
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
            raise SceneError(f"{name} must be an array of {want} integers, {got}")
        return value
    if not all(_is_number(v) for v in value):
        raise SceneError(f"{name} must be an array of {want} numbers, {got}")
    return [float(v) for v in value]


def _check_layer(layer: dict, where: str) -> dict:
    """Check a layer's sections, keys and types; return a normalised copy."""
    out: dict[str, dict] = {}
    for section, keys in layer.items():
        if section not in SCHEMA:
            hint = difflib.get_close_matches(section, SCHEMA, n=1)
            raise SceneError(f"{where}: unknown scene section [{section}]"
                             + (f" (did you mean [{hint[0]}]?)" if hint else
                                f"; sections are {', '.join(SCHEMA)}"))
        if not isinstance(keys, dict):
            raise SceneError(f"{where}: {section} must be a table [{section}] of keys, got "
                             f"{_kind_name(keys)} {keys!r}")
        out[section] = {}
        for key, value in keys.items():
            if key not in SCHEMA[section]:
                hint = difflib.get_close_matches(key, SCHEMA[section], n=1)
                raise SceneError(
                    f"{where}: unknown scene key {section}.{key}"
                    + (f" (did you mean {section}.{hint[0]}?)" if hint else
                       f"; keys of [{section}] are {', '.join(SCHEMA[section])}"))
            out[section][key] = _typed(section, key, value)
        given = [k for k in ALTERNATIVES.get(section, ()) if k in out[section]]
        if len(given) > 1:
            raise SceneError(f"{where}: give only one of "
                             + ", ".join(f"{section}.{k}" for k in given))
    return out


def _parse_override(text: str) -> tuple[str, str, Any]:
    """``section.key=value`` -> (section, key, value); values are TOML, bare words strings."""
    name, sep, raw = text.partition("=")
    section, dot, key = name.strip().partition(".")
    if not sep or not dot or not section or not key:
        raise SceneError(f"--set {text!r}: expected section.key=value, e.g. time.duration=3600")
    raw = raw.strip()
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw   # a bare word such as cross or ../meshes/eros.obj
    return section, key.strip(), value


def _read_source(name_or_path) -> tuple[str, str, Path | None]:
    """(name, text, directory for relative paths or None) of a preset or a scene file."""
    text_name = str(name_or_path)
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise SceneError(f"scene file {text_name}: no such file")
        try:
            return text_name, path.read_text(encoding="utf-8"), path.resolve().parent
        except (OSError, UnicodeDecodeError) as exc:
            raise SceneError(f"scene file {text_name}: cannot read ({exc})") from None
    if text_name in _preset_names():
        return text_name, (_preset_dir() / f"{text_name}.toml").read_text(encoding="utf-8"), None
    hint = difflib.get_close_matches(text_name, _preset_names(), n=1)
    raise SceneError(f"scene {text_name!r} is neither a preset nor a .toml file"
                     + (f" (did you mean {hint[0]}?)" if hint else
                        "; `recon simulate --list` shows the presets"))


# --------------------------------------------------------------------------- loading


def load_scene(name_or_path, overrides=()) -> Scene:
    """Resolve and validate a scene: a preset name or a TOML path, then ``--set`` overrides.

    Parameters
    ----------
    name_or_path : str or Path
        A preset name (``recon simulate --list``) or the path of a scene TOML file.
    overrides : sequence of str
        ``section.key=value`` strings applied after the file; values are TOML
        (``3600``, ``[1.2, 1.2]``, ``true``) or bare words (``cross``).

    Returns
    -------
    Scene
        With the target's truth mesh built and the orbit, duration and shot count derived.

    Raises
    ------
    SceneError
        Unknown preset, section or key; wrong type; impossible value. The message is one line
        naming the key.
    """
    name, text, base = _read_source(name_or_path)
    try:
        file_layer = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"scene {name}: invalid TOML ({exc})") from None
    file_layer = _check_layer(file_layer, f"scene {name}")
    if base is not None and "path" in file_layer.get("target", {}):
        path = Path(file_layer["target"]["path"]).expanduser()
        file_layer["target"]["path"] = str(path if path.is_absolute() else base / path)

    override_layer: dict[str, dict] = {}
    for text_override in overrides:
        section, key, value = _parse_override(text_override)
        override_layer.setdefault(section, {})[key] = value
    override_layer = _check_layer(override_layer, "--set")

    values: dict[str, dict] = {s: {k: copy.deepcopy(spec.default) for k, spec in keys.items()
                                   if spec.default is not None}
                               for s, keys in SCHEMA.items()}
    user_keys: dict[tuple[str, str], int] = {}   # key -> layer that gave it (1 file, 2 --set)
    for number, layer in enumerate((file_layer, override_layer), start=1):
        for section, keys in layer.items():
            for key, value in keys.items():
                for other in ALTERNATIVES.get(section, ()):
                    if key in ALTERNATIVES[section] and other != key:
                        values[section].pop(other, None)
                values[section][key] = value
                user_keys[(section, key)] = number
    return _validate(name, text, tuple(overrides), values, user_keys)


def _fail(key: str, message: str):
    raise SceneError(f"{key} {message}")


def _positive(values: dict, key: str, *, allow_inf: bool = False) -> float:
    section, name = key.split(".")
    v = values[section][name]
    if math.isnan(v) or v <= 0 or (math.isinf(v) and not allow_inf):
        _fail(key, f"must be a positive {'number' if allow_inf else 'finite number'} "
                   f"[{SCHEMA[section][name].unit}], got {v!r}")
    return v


def _non_negative(values: dict, key: str) -> float:
    section, name = key.split(".")
    v = values[section][name]
    if not (math.isfinite(v) and v >= 0):
        _fail(key, f"must be a finite number >= 0 [{SCHEMA[section][name].unit}], got {v!r}")
    return v


def _finite(values: dict, key: str) -> None:
    section, name = key.split(".")
    v = values[section][name]
    if not all(math.isfinite(x) for x in (v if isinstance(v, list) else [v])):
        _fail(key, f"must be finite, got {v!r}")


def _nonzero_vector(values: dict, key: str) -> None:
    _finite(values, key)
    section, name = key.split(".")
    if not any(values[section][name]):
        _fail(key, f"must be a non-zero vector, got {values[section][name]!r}")


def _validate(name: str, text: str, overrides: tuple[str, ...], values: dict,
              user_keys: dict[tuple[str, str], int]) -> Scene:
    target, orbit, time, slew, sensor, errors = (values[s] for s in SCHEMA)

    # Choices and keys that mean nothing for the chosen target or pattern.
    if target["kind"] not in TARGET_KINDS:
        _fail("target.kind", f"must be one of {', '.join(TARGET_KINDS)}, got {target['kind']!r}")
    if sensor["pattern"] not in PATTERNS:
        _fail("sensor.pattern", f"must be one of {', '.join(PATTERNS)}, got "
                                f"{sensor['pattern']!r}")
    # A key that means nothing for the chosen target or pattern is an error when given in the
    # layer that chose it, or later; an earlier layer's (a preset's grid resolution, when --set
    # picks a cross) is dropped.
    for (section, key), (by_section, by_key, allowed) in ONLY_WITH.items():
        if values[by_section][by_key] not in allowed:
            if user_keys.get((section, key), -1) >= user_keys.get((by_section, by_key), 0):
                _fail(f"{section}.{key}", f"is only used when {by_section}.{by_key} is "
                      + " or ".join(f'"{a}"' for a in allowed)
                      + f', not "{values[by_section][by_key]}"')
            values[section].pop(key, None)
    if (orbit.get("change_time") is None) != (orbit.get("change_inclination_deg") is None):
        given, missing = (("orbit.change_time", "orbit.change_inclination_deg")
                          if "change_time" in orbit else
                          ("orbit.change_inclination_deg", "orbit.change_time"))
        _fail(missing, f"is needed with {given}")

    # The target.
    kind = target["kind"]
    if kind == "ellipsoid":
        if not all(math.isfinite(a) and a > 0 for a in target["semi_axes"]):
            _fail("target.semi_axes", f"must be 3 positive lengths [m], got "
                                      f"{target['semi_axes']!r}")
        if not 0 <= target["subdivisions"] <= MAX_SUBDIVISIONS:
            _fail("target.subdivisions", f"must be between 0 and {MAX_SUBDIVISIONS}, got "
                                         f"{target['subdivisions']}")
        vertices, faces = targets.ellipsoid(target["semi_axes"], target["subdivisions"])
        label = "asteroid"
    elif kind == "rso-a":
        vertices, faces = targets.rso_a()
        label = "rso-a"
    elif kind == "rso-b":
        vertices, faces = targets.rso_b()
        label = "rso-b"
    else:
        if "path" not in target:
            _fail("target.path", 'is needed when target.kind is "mesh"')
        _positive(values, "target.scale")
        try:
            vertices, faces = targets.load_mesh(target["path"], target["scale"],
                                                center=target["center"])
        except MeshFormatError as exc:
            raise SceneError(f"target.path: {exc}") from None
        label = f"mesh:{Path(target['path']).name}"
    _positive(values, "target.spin_period", allow_inf=True)
    _nonzero_vector(values, "target.spin_axis")
    _nonzero_vector(values, "target.attitude")
    q = np.asarray(target["attitude"])
    target["attitude"] = (q / np.linalg.norm(q)).tolist()

    # The orbit: outside the target, with a period.
    radius = _positive(values, "orbit.radius")
    reach = targets.bounding_radius(vertices)
    if radius <= reach:
        _fail("orbit.radius", f"= {radius:g} m puts the orbit inside the target (its farthest "
                              f"point is {reach:.4g} m from the centre)")
    for key in ("inclination_deg", "change_inclination_deg"):
        if key in orbit:
            _finite(values, f"orbit.{key}")
            if not 0 <= orbit[key] <= 180:
                _fail(f"orbit.{key}", f"must be between 0 and 180 deg, got {orbit[key]:g}")
    _finite(values, "orbit.node_deg")
    _finite(values, "orbit.phase_deg")
    if "change_time" in orbit:
        _non_negative(values, "orbit.change_time")
    if "period" in orbit:
        period = _positive(values, "orbit.period")
        mu = 4.0 * math.pi ** 2 * radius ** 3 / period ** 2
    else:
        if "mu" in orbit:
            mu = _positive(values, "orbit.mu")
        else:
            density = _positive(values, "orbit.density")
            volume = targets.signed_volume(vertices, faces)
            if not targets.is_closed(faces) or volume <= 0:
                _fail("orbit.density", "cannot give a mass: the target mesh is not closed; give "
                                       "orbit.mu or orbit.period instead")
            mu = GRAVITATIONAL_CONSTANT * density * volume
        period = 2.0 * math.pi * math.sqrt(radius ** 3 / mu)

    # Time.
    step = _positive(values, "time.step")
    if "duration" in time:
        duration = _positive(values, "time.duration")
    else:
        rotations = _positive(values, "time.rotations")
        if math.isinf(target["spin_period"]):
            _fail("time.rotations", "needs a spinning target (target.spin_period is inf); give "
                                    "time.duration instead")
        duration = rotations * target["spin_period"]
    n_shots = math.floor(duration / step + 1e-9)
    if n_shots < 1:
        _fail("time.duration" if "duration" in time else "time.rotations",
              f"gives {duration:g} s, shorter than one time.step ({step:g} s)")

    # Slew.
    amplitude = slew["amplitude_deg"]
    if not (math.isfinite(amplitude) and 0 <= amplitude < 90):
        _fail("slew.amplitude_deg", f"must be at least 0 and below 90 deg, got {amplitude!r}")
    _positive(values, "slew.period")
    _nonzero_vector(values, "slew.axis")
    _finite(values, "slew.phase_deg")

    # Sensor.
    if "field_of_view_deg" in sensor:
        _check_field_of_view(sensor["field_of_view_deg"])
    if "beams" in sensor and sensor["beams"] < 2:
        _fail("sensor.beams", f"must be at least 2 for a zigzag, got {sensor['beams']}")
    if "resolution" in sensor and min(sensor["resolution"]) < 1:
        _fail("sensor.resolution", f"must be at least 1 x 1, got {sensor['resolution']}")
    range_min = _non_negative(values, "sensor.range_min")
    range_max = _positive(values, "sensor.range_max")
    if range_max <= range_min:
        _fail("sensor.range_max", f"= {range_max:g} m must exceed sensor.range_min = "
                                  f"{range_min:g} m")

    # Errors.
    for key in ("range_sigma3", "azimuth_sigma3_deg", "elevation_sigma3_deg", "position_sigma3",
                "dilation_alpha", "dilation_half_angle_mrad"):
        _non_negative(values, f"errors.{key}")
    if errors["dilation_half_angle_mrad"] >= 1000.0 * math.pi / 2:
        _fail("errors.dilation_half_angle_mrad", f"must be below 90 deg (1570.8 mrad), got "
                                                 f"{errors['dilation_half_angle_mrad']:g}")
    if errors["dilation_subrays"] < 1:
        _fail("errors.dilation_subrays", f"must be at least 1, got {errors['dilation_subrays']}")

    ordered = {s: {k: values[s][k] for k in SCHEMA[s] if k in values[s]} for s in SCHEMA}
    return Scene(name=name, values=ordered, source=text, overrides=overrides, vertices=vertices,
                 faces=faces, target=label, mu=mu, orbit_period=period, duration=duration,
                 n_shots=n_shots, errors=sensor_errors(ordered["errors"]))


def sensor_errors(errors: dict) -> SensorErrors:
    """A scene's ``[errors]`` section as the log records it: 3-sigma, SI units.

    The one conversion from scene units (degrees, milliradians); the pulse-dilation cone is
    recorded only when dilation is on.
    """
    on = errors["dilation_alpha"] > 0
    return SensorErrors(
        range_sigma3=errors["range_sigma3"],
        azimuth_sigma3=math.radians(errors["azimuth_sigma3_deg"]),
        elevation_sigma3=math.radians(errors["elevation_sigma3_deg"]),
        position_sigma3=errors["position_sigma3"],
        pulse_dilation_alpha=errors["dilation_alpha"],
        pulse_dilation_half_angle=errors["dilation_half_angle_mrad"] * 1e-3 if on else 0.0,
        pulse_dilation_subrays=float(errors["dilation_subrays"]) if on else 0.0)


def _check_field_of_view(fov: list[float]) -> None:
    key = "sensor.field_of_view_deg"
    if not all(math.isfinite(a) for a in fov):
        _fail(key, f"must be finite, got {fov!r}")
    if len(fov) == 2:
        for axis, extent in zip(("azimuth", "elevation"), fov, strict=True):
            if extent < 0:
                _fail(key, f"{axis} extent must be >= 0 deg, got {extent:g}")
            if extent >= MAX_FIELD_OF_VIEW_DEG:
                _fail(key, f"{axis} extent of {extent:g} deg is impossible (must be below "
                           f"{MAX_FIELD_OF_VIEW_DEG:g} deg)")
        return
    for axis, lo, hi in (("azimuth", fov[0], fov[1]), ("elevation", fov[2], fov[3])):
        if lo > hi:
            _fail(key, f"{axis} minimum {lo:g} deg exceeds its maximum {hi:g} deg")
        if hi - lo >= MAX_FIELD_OF_VIEW_DEG:
            _fail(key, f"{axis} extent of {hi - lo:g} deg is impossible (must be below "
                       f"{MAX_FIELD_OF_VIEW_DEG:g} deg)")
        if max(abs(lo), abs(hi)) >= MAX_FIELD_OF_VIEW_DEG / 2:
            _fail(key, f"{axis} limits must lie within 90 deg of the boresight, got "
                       f"[{lo:g}, {hi:g}]")
