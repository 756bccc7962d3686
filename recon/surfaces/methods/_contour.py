"""Zero-level-set extraction on a sparse grid by naive surface nets (Gibson 1998).

Only the nodes near the data carry a value, so the field is given as sorted integer node keys
and their values; nodes without a value are simply absent. Every grid edge whose two end nodes
carry values of opposite sign crosses the surface; each grid cell touched by a crossing edge
gets one vertex, the mean of its edges' crossing points; each crossing edge yields the quad of
the four cells around it. Where the values stop (the data's boundary) the surface stops: open
surfaces stay open. Unlike marching cubes no case table is needed and the result is the same
for every orientation of the grid.
"""

from __future__ import annotations

import numpy as np


def node_keys(index: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    """Linear keys of integer node coordinates ``index`` (m, 3) on a grid of ``shape``."""
    return (index[:, 0] * shape[1] + index[:, 1]) * shape[2] + index[:, 2]


def key_index(keys: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    """Integer node coordinates (m, 3) of linear ``keys`` (inverse of ``node_keys``)."""
    k = keys % shape[2]
    j = (keys // shape[2]) % shape[1]
    i = keys // (shape[1] * shape[2])
    return np.stack([i, j, k], axis=1)


def surface_nets(keys: np.ndarray, values: np.ndarray, shape: tuple[int, int, int],
                 origin: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate the zero set of a sparse grid field.

    Parameters
    ----------
    keys : (m,) int64, sorted, unique
        ``node_keys`` of the nodes carrying a value; every node must have coordinates in
        ``1 .. shape - 2`` so that neighbours and cells stay on the grid.
    values : (m,) float64
        Field at those nodes: negative inside, positive outside; NaN means no value.
    shape : (3,) int
        Grid nodes per axis.
    origin : (3,) float64, metres
        Position of node (0, 0, 0).
    cell : float, metres
        Node spacing.

    Returns
    -------
    vertices : (v, 3) float64, metres
    faces : (f, 3) int64
        Counter-clockwise seen from the positive (outside) side.
    """
    strides = np.array([shape[1] * shape[2], shape[2], 1], dtype=np.int64)
    node_xyz = origin + cell * key_index(keys, shape)
    cell_keys, points, quads, outward = [], [], [], []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        neighbour = keys + strides[a]
        pos = np.searchsorted(keys, neighbour)
        pos = np.minimum(pos, len(keys) - 1)
        found = keys[pos] == neighbour
        f0 = values
        f1 = np.where(found, values[pos], np.nan)
        crossing = found & np.isfinite(f0) & np.isfinite(f1) & ((f0 < 0) != (f1 < 0))
        n0 = keys[crossing]
        t = f0[crossing] / (f0[crossing] - f1[crossing])
        point = node_xyz[crossing].copy()
        point[:, a] += t * cell
        # The four cells around the edge, counter-clockwise about +a in the (b, c) plane:
        # min corners n0 + (-1, -1), (0, -1), (0, 0), (-1, 0) in (b, c).
        around = np.stack([n0 - strides[b] - strides[c], n0 - strides[c], n0,
                           n0 - strides[b]], axis=1)
        cell_keys.append(around.ravel())
        points.append(np.repeat(point, 4, axis=0))
        quads.append(around)
        outward.append(f0[crossing] < 0)  # inside -> outside along +a: normal along +a
    all_cells = np.concatenate(cell_keys)
    if len(all_cells) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    unique, inverse = np.unique(all_cells, return_inverse=True)
    sums = np.stack([np.bincount(inverse, weights=np.concatenate(points)[:, i],
                                 minlength=len(unique)) for i in range(3)], axis=1)
    counts = np.bincount(inverse, minlength=len(unique))
    vertices = sums / counts[:, None]
    quad = np.searchsorted(unique, np.concatenate(quads))
    forward = np.concatenate(outward)
    quad[~forward] = quad[~forward][:, ::-1]
    faces = np.concatenate([quad[:, [0, 1, 2]], quad[:, [0, 2, 3]]]).astype(np.int64)
    return vertices, faces
