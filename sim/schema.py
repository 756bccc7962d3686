"""Checking scene values against the schema of sim/defaults.py.

Every key declares its type, unit and accepted values beside its default (``Key``); this module
only reads those declarations. Checking is in two steps:

- :func:`check_layer`, per layer (scene file, overrides): sections and keys exist,
  values have the declared type (normalised to floats and lists), at most one key of each group
  of alternatives;
- :func:`check_values`, once the layers are merged: keys that mean nothing for the chosen target
  or pattern, then one loop over the schema checking each value against its declared bounds,
  then the few cross-key rules declared in sim/defaults.py.

What needs the mesh (an orbit outside the target, a mass from the density) is checked where it
is derived, in sim/derive.py. Every problem raises :class:`SceneError` with one line naming the
key.
"""

from __future__ import annotations

import datetime
import difflib
import math
from collections.abc import Callable

from formats.errors import SceneError
from sim.defaults import (
    ALTERNATIVES,
    MAX_FIELD_OF_VIEW_DEG,
    MAX_MAGNITUDE,
    MAX_PATHS,
    MAX_STRING_CHARS,
    MIN_MAGNITUDE,
    NEEDED_WHEN,
    ONLY_WITH,
    ORDERED,
    SCHEMA,
    TOGETHER,
    Key,
)
from sim.sensors import PATTERNS, patterns_using

# --------------------------------------------------------------------------- types, per layer


def _kind_name(value) -> str:
    return {bool: "boolean", int: "integer", float: "number", str: "string", list: "array",
            dict: "table"}.get(type(value), type(value).__name__)


# Characters of a value quoted in a message: a hostile 5 MB value is cut, not echoed.
SHOWN_CHARS = 80


def brief(value) -> str:
    """``repr(value)``, cut to SHOWN_CHARS characters."""
    text = repr(value)
    return text if len(text) <= SHOWN_CHARS else text[:SHOWN_CHARS - 3] + "..."


def _is_number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _iso_utc(value) -> str:
    """A TOML date or date-time as ISO 8601 text, in UTC when it has an offset."""
    if isinstance(value, datetime.datetime) and value.tzinfo is not None:
        value = value.astimezone(datetime.UTC).replace(tzinfo=None)
    return value.isoformat()


def _typed_string(name: str, value: str) -> None:
    if len(value) > MAX_STRING_CHARS or any(ord(c) < 32 for c in value):
        raise SceneError(f"{name} must be a string of at most {MAX_STRING_CHARS} printable "
                         f"characters, got {len(value):,} characters {brief(value)}")


def _as_number(name: str, spec: Key, value, got: str) -> float:
    if not _is_number(value):
        raise SceneError(f"{name} must be a number [{spec.unit}], {got}")
    return float(value)


def _as_int(name: str, spec: Key, value, got: str) -> int:
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if not isinstance(value, int) or isinstance(value, bool):
        raise SceneError(f"{name} must be an integer, {got}")
    return value


def _as_str(name: str, spec: Key, value, got: str) -> str:
    if isinstance(value, datetime.datetime | datetime.date):
        value = _iso_utc(value)   # a bare TOML date-time (orbit.start_utc)
    if not isinstance(value, str):
        raise SceneError(f"{name} must be a string, {got}")
    _typed_string(name, value)
    return value


def _as_paths(name: str, spec: Key, value, got: str) -> list[str]:
    if not isinstance(value, list) or not value or len(value) > MAX_PATHS or \
            not all(isinstance(v, str) and v for v in value):
        raise SceneError(f"{name} must be an array of 1 to {MAX_PATHS} file names, {got}")
    for item in value:
        _typed_string(name, item)
    return list(value)


def _as_bool(name: str, spec: Key, value, got: str) -> bool:
    if not isinstance(value, bool):
        raise SceneError(f"{name} must be true or false, {got}")
    return value


def _as_array(name: str, spec: Key, value, got: str) -> list:
    """``vec<N>``, ``ivec<N>`` and ``fov`` (2 or 4 numbers) values."""
    lengths = (2, 4) if spec.kind == "fov" else (int(spec.kind[-1]),)
    want = " or ".join(str(n) for n in lengths)
    integer = spec.kind.startswith("ivec")
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


# The type check of each scalar kind; every other kind is an array (``_as_array``).
_AS_KIND: dict[str, Callable] = {"number": _as_number, "int": _as_int, "str": _as_str,
                                 "paths": _as_paths, "bool": _as_bool}


def _typed(section: str, key: str, value):
    """Check the type of one value against the schema; return it normalised (floats, lists)."""
    spec = SCHEMA[section][key]
    check = _AS_KIND.get(spec.kind, _as_array)
    return check(f"{section}.{key}", spec, value, f"got {_kind_name(value)} {brief(value)}")


def check_layer(layer: dict, where: str, *, argument: str | None = None) -> dict:
    """Check one layer's sections, keys and types; return a normalised copy.

    Parameters
    ----------
    layer : dict of section -> dict of key -> value
        As parsed from TOML or from overrides.
    where : str
        What the layer is, for messages (``scene <name>``, ``overrides``).
    argument : str, optional
        The API argument that gave the layer (``where`` then starts with its name): the
        errors' ``argument``.

    Returns
    -------
    dict of section -> dict of key -> value, numbers as float (int for ``int`` keys), arrays as
    lists.

    Raises
    ------
    SceneError
        Unknown section or key (with the nearest valid one), wrong type, or two alternatives.
    """
    out: dict[str, dict] = {}
    for section, keys in layer.items():
        if section not in SCHEMA:
            hint = difflib.get_close_matches(section[:SHOWN_CHARS], SCHEMA, n=1)
            raise SceneError(f"{where}: unknown scene section [{brief(section)[1:-1]}]"
                             + (f" (did you mean [{hint[0]}]?)" if hint else
                                f"; sections are {', '.join(SCHEMA)}"), argument=argument)
        if not isinstance(keys, dict):
            raise SceneError(f"{where}: {section} must be a table [{section}] of keys, got "
                             f"{_kind_name(keys)} {brief(keys)}", argument=argument)
        out[section] = {}
        for key, value in keys.items():
            if key not in SCHEMA[section]:
                hint = difflib.get_close_matches(key[:SHOWN_CHARS], SCHEMA[section], n=1)
                raise SceneError(
                    f"{where}: unknown scene key {section}.{brief(key)[1:-1]}"
                    + (f" (did you mean {section}.{hint[0]}?)" if hint else
                       f"; keys of [{section}] are {', '.join(SCHEMA[section])}"),
                    argument=argument)
            out[section][key] = _typed(section, key, value)
        given = [k for k in ALTERNATIVES.get(section, ()) if k in out[section]]
        if len(given) > 1:
            raise SceneError(f"{where}: give only one of "
                             + ", ".join(f"{section}.{k}" for k in given), argument=argument)
    return out


# --------------------------------------------------------------------------- declared bounds


def _shown(value) -> str:
    return f"{value:g}" if isinstance(value, float | int) else repr(value)


def _unit(spec: Key, bracket: bool) -> str:
    if not spec.unit:
        return ""
    return f" [{spec.unit}]" if bracket else f" {spec.unit}"


def _lower_bound_only(spec: Key) -> str:
    """``requirement`` of a key bounded below only."""
    lo = spec.minimum
    if spec.kind == "int":
        return f"at least {lo:g}"
    if lo == 0 and spec.exclusive_minimum:
        return f"a positive {'finite ' if spec.finite else ''}number{_unit(spec, True)}"
    return (f"a finite number {'>' if spec.exclusive_minimum else '>='} {lo:g}"
            f"{_unit(spec, True)}")


def _range(spec: Key) -> str:
    """``requirement`` of a number bounded above, and maybe below."""
    lo, hi = spec.minimum, spec.maximum
    above = f"{'below' if spec.exclusive_maximum else 'at most'} {hi:g}{_unit(spec, False)}"
    if lo is None:
        return above
    if not (spec.exclusive_minimum or spec.exclusive_maximum):
        return f"between {lo:g} and {hi:g}{_unit(spec, False)}"
    return f"{'above' if spec.exclusive_minimum else 'at least'} {lo:g} and {above}"


def requirement(spec: Key) -> str:
    """What a key's declared bounds require, as the end of a sentence ``key must be ...``."""
    lo, hi = spec.minimum, spec.maximum
    if spec.choices:
        return "one of " + ", ".join(spec.choices)
    if spec.kind.startswith("ivec") and lo is not None and hi is None:
        return "at least " + " x ".join([f"{lo:g}"] * int(spec.kind[-1]))
    if spec.kind.startswith("vec") and lo == 0 and spec.exclusive_minimum and hi is None:
        return f"{spec.kind[-1]} positive numbers{_unit(spec, True)}"
    if lo is None and hi is None:
        return "finite"
    return _lower_bound_only(spec) if hi is None else _range(spec)


def _within(spec: Key, x: float) -> bool:
    """One number against the declared bounds (NaN never, infinity only where declared)."""
    if math.isnan(x) or (spec.finite and math.isinf(x)):
        return False
    lo, hi = spec.minimum, spec.maximum
    if lo is not None and (x <= lo if spec.exclusive_minimum else x < lo):
        return False
    return not (hi is not None and (x >= hi if spec.exclusive_maximum else x > hi))


def _check_value(name: str, spec: Key, value) -> None:
    """One value (already of the declared type) against its declared bounds."""
    if spec.kind == "str":
        if spec.choices and value not in spec.choices:
            raise SceneError(f"{name} must be {requirement(spec)}, got {brief(value)}")
        return
    if spec.kind in ("bool", "paths"):
        return
    items = value if isinstance(value, list) else [value]
    if isinstance(value, list) and spec.finite and not all(math.isfinite(x) for x in items):
        raise SceneError(f"{name} must be finite, got {value!r}")
    if not all(_within(spec, x) for x in items):
        raise SceneError(f"{name} must be {requirement(spec)}, got {_shown(value)}")
    if any(math.isfinite(x) and x != 0 and not MIN_MAGNITUDE <= abs(x) <= MAX_MAGNITUDE
           for x in items):
        raise SceneError(f"{name} must lie within {MIN_MAGNITUDE:g} to {MAX_MAGNITUDE:g}"
                         f"{_unit(spec, False)} in magnitude, got {_shown(value)}")
    if spec.nonzero and not any(items):
        raise SceneError(f"{name} must be a non-zero vector, got {value!r}")


def _check_field_of_view(name: str, fov: list[float]) -> None:
    """``[az, el]`` extents or ``[az_min, az_max, el_min, el_max]`` limits [deg]."""
    if len(fov) == 2:
        for axis, extent in zip(("azimuth", "elevation"), fov, strict=True):
            if extent < 0:
                raise SceneError(f"{name} {axis} extent must be >= 0 deg, got {extent:g}")
            if extent >= MAX_FIELD_OF_VIEW_DEG:
                raise SceneError(f"{name} {axis} extent of {extent:g} deg is impossible (must "
                                 f"be below {MAX_FIELD_OF_VIEW_DEG:g} deg)")
        return
    for axis, lo, hi in (("azimuth", fov[0], fov[1]), ("elevation", fov[2], fov[3])):
        if lo > hi:
            raise SceneError(f"{name} {axis} minimum {lo:g} deg exceeds its maximum {hi:g} deg")
        if hi - lo >= MAX_FIELD_OF_VIEW_DEG:
            raise SceneError(f"{name} {axis} extent of {hi - lo:g} deg is impossible (must be "
                             f"below {MAX_FIELD_OF_VIEW_DEG:g} deg)")
        if max(abs(lo), abs(hi)) >= MAX_FIELD_OF_VIEW_DEG / 2:
            raise SceneError(f"{name} {axis} limits must lie within 90 deg of the boresight, "
                             f"got [{lo:g}, {hi:g}]")


# Checks beyond declared bounds, for the one key whose meaning depends on its length.
EXTRA_CHECKS: dict[tuple[str, str], Callable[[str, list], None]] = {
    ("sensor", "field_of_view_deg"): _check_field_of_view,
}


# --------------------------------------------------------------------------- merged values


def only_with() -> dict[tuple[str, str], tuple[str, str, tuple[str, ...]]]:
    """ONLY_WITH of sim/defaults.py and the ``[sensor]`` keys each registered beam pattern
    reads (sim/sensors.py): (section, key) -> (section, key, allowed values)."""
    read = {key for pattern in PATTERNS.values() for key in pattern.keys}
    return {**ONLY_WITH, **{("sensor", key): ("sensor", "pattern", patterns_using(key))
                            for key in sorted(read)}}


def _drop_unused(values: dict, user_keys: dict[tuple[str, str], int]) -> None:
    """Apply ``only_with()``: a key that means nothing for the chosen target or pattern.

    Given in the layer that made the choice, or later, it is an error; given only by an earlier
    layer (a preset's grid resolution, when an override picks a cross) it is dropped.
    """
    for (section, key), (by_section, by_key, allowed) in only_with().items():
        chosen = values[by_section][by_key]
        if chosen in allowed:
            continue
        if user_keys.get((section, key), -1) >= user_keys.get((by_section, by_key), 0):
            raise SceneError(f"{section}.{key} is only used when {by_section}.{by_key} is "
                             + " or ".join(f'"{a}"' for a in allowed) + f', not "{chosen}"')
        values[section].pop(key, None)


def _check_rules(values: dict) -> None:
    """The cross-key rules of sim/defaults.py: NEEDED_WHEN, TOGETHER, ORDERED."""
    for (section, key), (by_section, by_key, allowed) in NEEDED_WHEN.items():
        if values[by_section][by_key] in allowed and key not in values[section]:
            raise SceneError(f"{section}.{key} is needed when {by_section}.{by_key} is "
                             + " or ".join(f'"{a}"' for a in allowed))
    for pair in TOGETHER:
        given = [(s, k) for s, k in pair if k in values[s]]
        if len(given) == 1:
            (missing,) = (f"{s}.{k}" for s, k in pair if (s, k) not in given)
            raise SceneError(f"{missing} is needed with {given[0][0]}.{given[0][1]}")
    for (lo_section, lo_key), (hi_section, hi_key) in ORDERED:
        lo, hi = values[lo_section][lo_key], values[hi_section][hi_key]
        if hi <= lo:
            unit = SCHEMA[hi_section][hi_key].unit
            raise SceneError(f"{hi_section}.{hi_key} = {hi:g} {unit} must exceed "
                             f"{lo_section}.{lo_key} = {lo:g} {unit}")


def check_values(values: dict, user_keys: dict[tuple[str, str], int]) -> dict:
    """Check merged scene values; return them in schema order, unused keys dropped.

    Parameters
    ----------
    values : dict of section -> dict of key -> value
        Defaults, scene file and overrides merged, each value of its declared type
        (:func:`check_layer`).
    user_keys : dict of (section, key) -> int
        The layer that gave each key: 1 the scene file, 2 the overrides; absent: a default.

    Returns
    -------
    dict of section -> dict of key -> value, every section and key in SCHEMA order.

    Raises
    ------
    SceneError
        A value outside its declared bounds, a key that means nothing here, or a broken
        cross-key rule; one line naming the key.
    """
    for section, key in {(s, k) for s, k, _ in only_with().values()}:   # the choices first
        _check_value(f"{section}.{key}", SCHEMA[section][key], values[section][key])
    _drop_unused(values, user_keys)
    for section, keys in SCHEMA.items():
        for key, spec in keys.items():
            if key in values[section]:
                name = f"{section}.{key}"
                _check_value(name, spec, values[section][key])
                extra = EXTRA_CHECKS.get((section, key))
                if extra is not None:
                    extra(name, values[section][key])
    _check_rules(values)
    return {s: {k: values[s][k] for k in SCHEMA[s] if k in values[s]} for s in SCHEMA}
