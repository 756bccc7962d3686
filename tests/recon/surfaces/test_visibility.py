"""The ``visibility`` method: Delaunay cells labelled by the sensor-to-strike rays.

Each shape is sampled uniformly by area and each sample is seen from one of 14 sensor
positions around it (the 6 axis and 8 diagonal directions) that faces it, so every strike
carries a real ray; range noise moves the strike along its ray, as a rangefinder's does, and is
recorded as the cloud's ``sigma_along`` column. Distances to the truth are measured by
``metrics.score`` against the exact mesh.
"""

from __future__ import annotations

import numpy as np
import pytest

from metrics import Mesh, sample_surface, score
from recon.surfaces.checks import watertight
from recon.surfaces.methods import MethodFailed, ParameterError, bind
from recon.surfaces.methods.visibility import NoViewPoints
from recon.surfaces.prepare import prepare
from recon.surfaces.uncertainty import COLUMNS
from tests.recon.conftest import FAST_SCORE

# Sensor directions: the 6 axes and the 8 diagonals, unit length.
_DIAGONALS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) / 3**0.5
SENSOR_DIRECTIONS = np.concatenate([np.eye(3), -np.eye(3), _DIAGONALS])


def shape(name: str) -> tuple[np.ndarray, np.ndarray]:
    """Truth mesh (vertices, faces) of a test shape, metres."""
    import trimesh

    if name == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    elif name == "box":
        mesh = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    else:  # the thin plate: 2 m x 2 m x 2 cm
        mesh = trimesh.creation.box(extents=(2.0, 2.0, 0.02))
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)


def scan(truth, n: int, *, noise: float = 0.0, seed: int = 0, distance: float = 5.0):
    """Strikes on ``truth`` seen from the sensors facing them, with range noise along the ray.

    Returns
    -------
    points, view_points : (n, 3) float64, metres
    columns : dict of str to (n,) float64
        The uncertainty columns ingest writes: ``sigma_along`` = ``noise``, the others zero.
    """
    vertices, faces = truth
    points, face = sample_surface(Mesh(vertices, faces), n, seed=seed)
    a, b, c = (vertices[faces[face, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    sensors = distance * SENSOR_DIRECTIONS
    beam = sensors[None, :, :] - points[:, None, :]                              # (n, 14, 3)
    facing = np.einsum("nsi,ni->ns", beam, normal) / np.linalg.norm(beam, axis=2) > 0.3
    rng = np.random.default_rng(seed)
    pick = np.argmax(facing * rng.random(facing.shape), axis=1)   # a random facing sensor
    view = sensors[pick]
    ray = points - view
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    points = points + ray * rng.normal(0.0, noise, (n, 1))
    columns = {key: np.zeros(n) for key in COLUMNS} | {"sigma_along": np.full(n, noise)}
    return points, view, columns


def reconstruct(truth, n: int, *, noise: float = 0.0, seed: int = 0, **params):
    points, view, columns = scan(truth, n, noise=noise, seed=seed)
    cloud = prepare(points, view_points=view, uncertainty=columns, seed=seed)
    run = bind("visibility", params)
    vertices, faces = run.method_spec().run(cloud, **run.params)
    return vertices, faces, cloud
