"""A small noisy unit sphere of strikes, for the tests of auto's race and schedule. Importable
from ``tests/recon`` (pytest puts that directory on ``sys.path``)."""

from __future__ import annotations

import numpy as np

from formats.geometry import Cloud


def small_sphere() -> tuple[Cloud, np.ndarray]:
    """1,500 strikes on the unit sphere with 0.01 Gaussian noise, one shot each (shots in
    order: blocks of contiguous shots are passes), and their view points (5 units out along
    each strike's direction)."""
    rng = np.random.default_rng(0)
    points = rng.normal(size=(1500, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    points += rng.normal(0.0, 0.01, points.shape)
    return Cloud(points, {"shot": np.arange(1500), "beam": np.zeros(1500)}), 5.0 * points
