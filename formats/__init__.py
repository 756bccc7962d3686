"""The strike-log format (SPEC.md) and mesh and point-cloud IO.

The bottom layer of recon: it imports none of the other packages. The names below are loaded
on first use (``from formats import StrikeLog`` works as usual), so that importing a light
submodule (``formats.errors``, ``formats.paths``) does not import numpy and h5py.
"""

from __future__ import annotations

import importlib

# Public name -> the submodule that defines it.
_EXPORTS = {
    **dict.fromkeys(("ReconError", "InputError", "ParameterError", "SceneError", "MethodFailed",
                     "ResourceError"), "formats.errors"),
    "Cloud": "formats.geometry",
    "Mesh": "formats.geometry",
    **dict.fromkeys(("FORMAT_NAME", "FORMAT_VERSION", "SIGMA3_PER_SIGMA", "SensorErrors",
                     "SensorInfo", "Shots", "StrikeChunk", "StrikeLog", "StrikeLogWriter",
                     "TruthStrikes", "sigma_from_sigma3"), "formats.strike_log"),
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'formats' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})
