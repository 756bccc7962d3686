"""Scenes: TOML files that state only what differs from the defaults (sim/defaults.py).

A scene is resolved from three layers, each overriding the one before: the defaults, the scene
file (a built-in preset or a path) and ``section.key=value`` overrides. Of a group of
alternative keys (``time.rotations`` / ``time.duration``; ``orbit.density`` / ``orbit.mu`` /
``orbit.period``) a layer gives at most one, and the last layer that gives one wins.

Schema (units: m, s, kg; angles in degrees as the ``_deg`` suffix says; see sim/defaults.py for
every default and where it comes from)::

    [target]  kind = "ellipsoid" | "rso-a" | "rso-b" | "mesh" | "satellite" | "polyhedron"
                     | "cratered-asteroid"
              semi_axes, subdivisions          (ellipsoid)
              path, scale, center              (mesh)
              seed                             (satellite, polyhedron, cratered-asteroid)
              size                             (polyhedron, cratered-asteroid)
              spin_period, spin_axis (B), attitude (B->I quaternion x, y, z, w at t = 0)
    [orbit]   kind = "kepler" | "spice"
              radius, inclination_deg, node_deg, phase_deg,
              density | mu | period, change_time, change_inclination_deg      (kepler)
              kernels, observer, target, inertial_frame, target_frame, sensor_frame,
              start_utc | start_et                                             (spice)
    [time]    step, rotations | duration
    [slew]    amplitude_deg, period, axis (nominal sensor frame), phase_deg   (mode fixed)
    [attitude] mode = "fixed" | "gaps", max_rate_deg_s, max_offset_deg, replan_s (gaps)
    [sensor]  pattern = "single" | "cross" | "zigzag" | "grid", field_of_view_deg,
              beams (zigzag), resolution (grid), range_min, range_max
    [errors]  range_sigma3, azimuth_sigma3_deg, elevation_sigma3_deg, position_sigma3,
              dilation_alpha, dilation_half_angle_mrad, dilation_subrays,
              boresight_misalignment_deg, attitude_bias_arcsec, attitude_walk_arcsec,
              position_bias, position_bias_inertial, position_drift, position_drift_time,
              spin_axis_error_deg, spin_period_error, time_tag_offset
              (pose knowledge, sim/pose_errors.py)

Loading is three steps, one module each: this module resolves the layers; sim/schema.py checks
the values against the bounds each key declares in sim/defaults.py (plus the few cross-key
rules); sim/derive.py builds the mesh and derives mu, the orbit period, the duration, the shot
count and the error models. Every problem with a scene raises :class:`SceneError` with one line
naming the key.
"""

from __future__ import annotations

import copy
import difflib
import json
import math
import os
import tomllib
from dataclasses import dataclass, fields
from importlib import resources
from pathlib import Path
from typing import Any

from formats.errors import SceneError
from formats.paths import check_source
from sim.defaults import ALTERNATIVES, MAX_SCENE_BYTES, SCHEMA
from sim.derive import Derived, derive
from sim.schema import brief, check_layer, check_values

__all__ = ["Scene", "SceneError", "list_presets", "load_scene", "toml_value"]


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
class Scene(Derived):
    """A resolved, validated scene, ready to simulate: its values and what they imply.

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
        Short target name for the log (``asteroid``, ``rso-a``, ``rso-b``, ``mesh:<file>``,
        ``satellite:seed=<n>``, ``polyhedron:seed=<n>[,size=<m>]``, ...).
    mu : float or None
        Gravitational parameter used for the orbit [m^3/s^2] (None: SPICE-driven).
    orbit_period : float or None
        Period of the chaser's orbit [s] (None: SPICE-driven).
    duration : float
        Length of the campaign [s].
    n_shots : int
        Number of shots, at ``t = k * step`` for ``k = 0 .. n_shots - 1``.
    epoch_et : float or None
        ET [s, TDB past J2000] of the first shot of a SPICE-driven scene (None otherwise).
    errors : SensorErrors
        The ``[errors]`` section converted once (sim/derive.py) to what the log records:
        3-sigma values in SI units (radians); its properties give the 1-sigma values.
    """

    name: str
    values: dict
    source: str
    overrides: tuple[str, ...]

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
        if self.overrides:   # one line: _parse_override refuses control characters
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


def _parse_override(text: str) -> tuple[str, str, Any]:
    """``section.key=value`` -> (section, key, value); values are TOML, bare words strings."""
    name, sep, raw = text.partition("=")
    section, dot, key = name.strip().partition(".")
    if not sep or not dot or not section or not key:
        raise SceneError(f"overrides {brief(text)}: expected section.key=value, e.g. "
                         "time.duration=3600", argument="overrides")
    if any(ord(c) < 32 for c in text):   # a newline would start a new TOML line
        raise SceneError(f"overrides {brief(text)}: control characters (newlines, tabs) are "
                         "not allowed in a value", argument="overrides")
    raw = raw.strip()
    value = _parse_toml(f"v = {raw}", f"overrides {brief(text)}", bare=raw)["v"]
    return section, key.strip(), value


def _parse_toml(text: str, where: str, *, bare: str | None = None) -> dict:
    """``tomllib.loads`` with its failures as SceneErrors; ``bare`` is the value of an override
    whose text is not TOML (a bare word such as cross or ../meshes/eros.obj)."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        if bare is not None:
            return {"v": bare}
        raise SceneError(f"{where}: invalid TOML ({exc})") from None
    except RecursionError:   # tomllib recurses once per nesting level
        raise SceneError(f"{where}: arrays or tables nested too deeply") from None


def _read_source(name_or_path) -> tuple[str, str, Path | None]:
    """(name, text, directory for relative paths or None) of a preset or a scene file."""
    text_name = str(name_or_path)
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        try:
            check_source(path, SceneError)
        except SceneError as exc:
            raise SceneError(f"scene file {exc}") from None
        if path.stat().st_size > MAX_SCENE_BYTES:
            raise SceneError(f"scene file {text_name}: {path.stat().st_size:,} bytes, larger "
                             f"than any scene ({MAX_SCENE_BYTES:,} bytes at most)")
        try:
            return text_name, path.read_text(encoding="utf-8"), path.resolve().parent
        except (OSError, UnicodeDecodeError) as exc:
            raise SceneError(f"scene file {text_name}: cannot read ({exc})") from None
    if text_name in _preset_names():
        return text_name, (_preset_dir() / f"{text_name}.toml").read_text(encoding="utf-8"), None
    hint = difflib.get_close_matches(text_name, _preset_names(), n=1)
    raise SceneError(f"scene {text_name!r} is neither a preset nor a .toml file"
                     + (f" (did you mean {hint[0]}?)" if hint else
                        f"; presets: {', '.join(_preset_names())}"))


# --------------------------------------------------------------------------- loading

# Directories (os.pathsep-separated) where a preset's relative mesh path is looked up after the
# current directory: presets name published shape models by file name, not by a path on one
# machine (bennu-ola names bennu_radar_2.7k.obj).
MESH_PATH_VARIABLE = "RECON_MESH_PATH"


def _resolve_paths(layer: dict, base: Path | None) -> None:
    """Make a layer's file paths absolute: relative to the scene file's directory ``base``; for
    a preset (``base`` None), a mesh path is looked up in the current directory, then in the
    directories of ``RECON_MESH_PATH``."""
    target, orbit = layer.get("target", {}), layer.get("orbit", {})
    if "path" in target:
        path = Path(target["path"]).expanduser()
        if base is not None and not path.is_absolute():
            path = base / path
        elif base is None and not path.is_absolute() and not path.exists():
            for directory in os.environ.get(MESH_PATH_VARIABLE, "").split(os.pathsep):
                if directory and (Path(directory) / path).is_file():
                    path = Path(directory) / path
                    break
        target["path"] = str(path)
    if "kernels" in orbit and base is not None:
        orbit["kernels"] = [str(p if p.is_absolute() else base / p)
                            for p in (Path(k).expanduser() for k in orbit["kernels"])]


def load_scene(name_or_path, overrides=()) -> Scene:
    """Resolve and validate a scene: a preset name or a TOML path, then overrides.

    Parameters
    ----------
    name_or_path : str or Path
        A preset name (``list_presets()``) or the path of a scene TOML file.
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
    file_layer = _parse_toml(text, f"scene {name}")
    file_layer = check_layer(file_layer, f"scene {name}")
    _resolve_paths(file_layer, base)

    override_layer: dict[str, dict] = {}
    for text_override in overrides:
        section, key, value = _parse_override(text_override)
        override_layer.setdefault(section, {})[key] = value
    override_layer = check_layer(override_layer, "overrides", argument="overrides")

    values: dict[str, dict] = {s: {k: copy.deepcopy(spec.default) for k, spec in keys.items()
                                   if spec.default is not None}
                               for s, keys in SCHEMA.items()}
    user_keys: dict[tuple[str, str], int] = {}   # key -> layer that gave it (1 file, 2 overrides)
    for number, layer in enumerate((file_layer, override_layer), start=1):
        for section, keys in layer.items():
            for key, value in keys.items():
                for other in ALTERNATIVES.get(section, ()):
                    if key in ALTERNATIVES[section] and other != key:
                        values[section].pop(other, None)
                values[section][key] = value
                user_keys[(section, key)] = number
    values = check_values(values, user_keys)
    derived = derive(values)
    return Scene(name=name, values=values, source=text, overrides=tuple(overrides),
                 **{f.name: getattr(derived, f.name) for f in fields(Derived)})
