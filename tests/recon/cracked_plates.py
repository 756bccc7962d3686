"""Plates with an opening, for the crack tests of the held-out statistic (``judge.check``'s
``crack``, ``benchmarks/judge_rules.py``'s openings). Importable from ``tests/recon`` (pytest
puts that directory on ``sys.path``)."""

from __future__ import annotations

import numpy as np


def plate(rectangles) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned rectangles (x0, x1, y0, y1) in the plane z = 0, two triangles each."""
    vertices, faces = [], []
    for n, (x0, x1, y0, y1) in enumerate(rectangles):
        vertices += [(x0, y0, 0.0), (x1, y0, 0.0), (x1, y1, 0.0), (x0, y1, 0.0)]
        faces += [(4 * n, 4 * n + 1, 4 * n + 2), (4 * n, 4 * n + 2, 4 * n + 3)]
    return np.array(vertices, dtype=float), np.array(faces, dtype=np.int64)


# A 4 x 4 m plate with a 0.1 m crack along x = 0; one with a 0.1 m cross of cracks (a junction
# of four cells); one with a 1.4 m square hole at the centre.
CRACKED = plate([(-2.0, -0.05, -2.0, 2.0), (0.05, 2.0, -2.0, 2.0)])
JUNCTION = plate([(-2.0, -0.05, -2.0, -0.05), (0.05, 2.0, -2.0, -0.05),
                  (-2.0, -0.05, 0.05, 2.0), (0.05, 2.0, 0.05, 2.0)])
HOLED = plate([(-2.0, -0.7, -2.0, 2.0), (0.7, 2.0, -2.0, 2.0),
               (-0.7, 0.7, -2.0, -0.7), (-0.7, 0.7, 0.7, 2.0)])
