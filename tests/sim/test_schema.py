"""The scene schema: every declared bound is enforced, with a message naming the key."""

from __future__ import annotations

import math

import pytest

import sim
from formats.errors import SceneError
from sim.defaults import ALTERNATIVES, SCHEMA, Key
from sim.schema import only_with, requirement


def _context(section: str, key: str) -> list[str]:
    """Overrides under which ``section.key`` means something."""
    if (section, key) in only_with():
        by_section, by_key, allowed = only_with()[(section, key)]
        return [f"{by_section}.{by_key}={allowed[0]}"]
    return []


def _as_value(spec: Key, x: float) -> str:
    if spec.kind.startswith(("vec", "ivec")):
        return "[" + ", ".join([repr(x)] * int(spec.kind[-1])) + "]"
    return repr(x)


def _out_of_bounds():
    """One value past each declared bound of each key."""
    for section, keys in SCHEMA.items():
        for key, spec in keys.items():
            step = 1 if spec.kind in ("int", "ivec2") else 0.5
            if spec.minimum is not None:
                x = spec.minimum if spec.exclusive_minimum else spec.minimum - step
                yield pytest.param(section, key, _as_value(spec, x), id=f"{section}.{key}<")
            if spec.maximum is not None:
                x = spec.maximum if spec.exclusive_maximum else spec.maximum + step
                if spec.kind == "int":
                    x = math.ceil(x)
                yield pytest.param(section, key, _as_value(spec, x), id=f"{section}.{key}>")


@pytest.mark.parametrize(("section", "key", "value"), list(_out_of_bounds()))
def test_every_declared_bound_is_enforced(section, key, value):
    spec = SCHEMA[section][key]
    overrides = [*_context(section, key), f"{section}.{key}={value}"]
    with pytest.raises(SceneError, match=rf"^{section}\.{key} must be ") as info:
        sim.load_scene("asteroid-lrf", overrides)
    assert requirement(spec) in str(info.value)


@pytest.mark.parametrize(("section", "key"), [
    (s, k) for s, keys in SCHEMA.items() for k, spec in keys.items() if spec.kind == "number"])
def test_no_number_key_accepts_nan(section, key):
    with pytest.raises(SceneError, match=rf"^{section}\.{key} must be "):
        sim.load_scene("asteroid-lrf", [*_context(section, key), f"{section}.{key}=nan"])


def test_choices_are_declared_and_enforced():
    for section, key in {(s, k) for s, k, _ in only_with().values()}:
        spec = SCHEMA[section][key]
        assert spec.choices and spec.default in spec.choices
        with pytest.raises(SceneError, match=rf"^{section}\.{key} must be one of "):
            sim.load_scene("asteroid-lrf", [f"{section}.{key}=nothing"])


def test_defaults_satisfy_their_own_bounds():
    scene = sim.load_scene("asteroid-lrf")
    assert scene.values["time"] == {"step": 10.0, "rotations": 50.0}
    for section, alternatives in ALTERNATIVES.items():
        assert sum(k in scene.values[section] for k in alternatives) == 1


def test_inf_only_where_declared():
    assert math.isinf(sim.load_scene("asteroid-lrf", ["target.spin_period=inf",
                                                      "time.duration=100"])["target.spin_period"])
    with pytest.raises(SceneError, match=r"^orbit\.radius must be a positive finite number"):
        sim.load_scene("asteroid-lrf", ["orbit.radius=inf"])
