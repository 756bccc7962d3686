"""``watertight`` and ``closed`` against references written a different way (row-wise uniques
of the edge array, what they replaced) on closed, opened, flipped, duplicated and non-manifold
meshes."""

from __future__ import annotations

import numpy as np
import pytest

from recon.surfaces.methods import closed, watertight
from tests.recon.conftest import box_mesh, sphere_mesh


def reference(faces: np.ndarray) -> bool:
    """Every undirected edge twice and every directed edge once, by ``np.unique(axis=0)``."""
    if len(faces) == 0:
        return False
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    _, count = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    return bool(np.all(count == 2)) and len(np.unique(directed, axis=0)) == len(directed)


def variants():
    sphere = sphere_mesh(3)[1]
    box = box_mesh()[1]
    rng = np.random.default_rng(0)
    yield "sphere", sphere, True
    yield "box", box, True
    yield "two spheres", np.concatenate([sphere, sphere + sphere.max() + 1]), True
    yield "opened", sphere[1:], False
    yield "one face flipped", np.concatenate([sphere[:1, ::-1], sphere[1:]]), False
    yield "a face twice", np.concatenate([sphere, sphere[:1]]), False
    yield "a face and its flip", np.concatenate([sphere, sphere[:1], sphere[:1, ::-1]]), False
    # A fin: a third face on an edge (non-manifold), closed by its own flip.
    fin = np.array([[box[0, 0], box[0, 1], box.max() + 1]])
    yield "fin", np.concatenate([box, fin, fin[:, ::-1]]), False
    yield "empty", np.zeros((0, 3), dtype=np.int64), False
    yield "one triangle", np.array([[0, 1, 2]]), False
    yield "a triangle both ways", np.array([[0, 1, 2], [0, 2, 1]]), True
    yield "repeated vertex", np.array([[0, 0, 1], [0, 1, 0]]), False
    for i in range(20):
        keep = rng.random(len(sphere)) < 0.995
        shuffled = rng.permutation(sphere[keep])
        yield f"random {i}", shuffled, bool(keep.all())


@pytest.mark.parametrize("name, faces, closed", list(variants()))
def test_watertight_agrees_with_the_row_wise_reference(name, faces, closed):
    faces = np.asarray(faces, dtype=np.int64)
    assert watertight(faces) == reference(faces) == closed, name


def closed_reference(faces: np.ndarray) -> bool:
    """No undirected edge of a single face, by ``np.unique(axis=0)``."""
    if len(faces) == 0:
        return False
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    _, count = np.unique(np.sort(edges, axis=1), axis=0, return_counts=True)
    return not np.any(count == 1)


# Closed, though not watertight: every edge has two faces or more, whatever their orientation.
CLOSED_NOT_WATERTIGHT = {"one face flipped", "a face twice", "a face and its flip", "fin",
                         "repeated vertex"}


@pytest.mark.parametrize("name, faces, watertight_", list(variants()))
def test_closed_agrees_with_the_row_wise_reference(name, faces, watertight_):
    faces = np.asarray(faces, dtype=np.int64)
    expected = watertight_ or name in CLOSED_NOT_WATERTIGHT
    assert closed(faces) == closed_reference(faces) == expected, name
