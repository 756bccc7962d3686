"""Test-only reconstruction methods that misbehave on purpose (hidden from every listing).

Importing this module registers them; isolated children import it by name to find them, so it
must stay importable from ``tests/recon`` (pytest puts that directory on ``sys.path``).
"""

from __future__ import annotations

import os
import time

import numpy as np

from formats.errors import MethodFailed
from recon.surfaces.methods import Method, MethodInput, Param, register


def _abort(cloud: MethodInput) -> tuple[np.ndarray, np.ndarray]:
    os.abort()  # SIGABRT, as qhull or a C++ assertion would


def _hang(cloud: MethodInput, *, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    time.sleep(seconds)  # a ball pivoting that never ends
    raise AssertionError("the time limit should have stopped this")


def _hog(cloud: MethodInput, *, megabytes: int) -> tuple[np.ndarray, np.ndarray]:
    block = np.ones(megabytes * 131072)  # 8 bytes each: allocates ``megabytes`` MiB
    return block[:3].reshape(1, 3), np.zeros((1, 3), dtype=np.int64)


def _empty(cloud: MethodInput) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)


def _flat(cloud: MethodInput) -> tuple[np.ndarray, np.ndarray]:
    p = cloud.points[:3].copy()
    return np.stack([p[0], p[0], p[0]]), np.array([[0, 1, 2]])


def _refuse(cloud: MethodInput) -> tuple[np.ndarray, np.ndarray]:
    raise MethodFailed("test-refuse: refused on purpose")


def _modules(cloud: MethodInput) -> tuple[np.ndarray, np.ndarray]:
    import sys

    loaded = [name for name in ("open3d", "dash", "plotly") if name in sys.modules]
    raise MethodFailed(f"test-modules: loaded {','.join(loaded)}")


for name, run, params in [
    ("test-abort", _abort, {}),
    ("test-hang", _hang, {"seconds": Param(3600.0, float, "how long to hang", minimum=0.0,
                                           maximum=86_400.0)}),
    ("test-hog", _hog, {"megabytes": Param(4096, int, "how much to allocate", minimum=0,
                                           maximum=1 << 20)}),
    ("test-empty", _empty, {}),
    ("test-flat", _flat, {}),
    ("test-refuse", _refuse, {}),
    ("test-modules", _modules, {}),
]:
    register(Method(name=name, run=run, params=params, kind="test", hidden=True,
                    summary="test-only"))
