"""Simulate a chaser imaging a spinning target with an LRF or a scanning LIDAR.

The simulator writes a strike log (formats/SPEC.md); it imports only ``formats``.

>>> scene = load_scene("asteroid-lrf", ["time.duration=3600"])   # doctest: +SKIP
>>> simulate(scene, "run.h5", seed=0)                            # doctest: +SKIP

Modules: ``defaults`` (every default, its bounds and its source), ``scene`` (TOML scenes and
presets: resolving the layers), ``schema`` (checking values against the declared bounds),
``derive`` (mesh, orbit, time line and error models of a checked scene), ``errors``
(``SceneError``), ``targets`` (truth meshes), ``motion`` (orbit and attitudes), ``sensors``
(beam patterns), ``raycast`` (Embree plus exact float64 hits), ``noise`` (error models),
``pipeline`` (the streaming pipeline).
"""

from formats.errors import SceneError
from sim import targets
from sim.pipeline import simulate
from sim.scene import Scene, list_presets, load_scene

__all__ = ["Scene", "SceneError", "list_presets", "load_scene", "simulate", "targets"]
