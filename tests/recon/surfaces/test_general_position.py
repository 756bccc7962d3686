"""Degenerate clouds (noise-free lattices: coplanar and cocircular) before qhull's Delaunay.

qhull merges facets for minutes on such input; ``general_position`` perturbs it by a seeded
offset far below the spacing. Checked here: the offset is seeded and bounded, it removes the
flat tetrahedra qhull otherwise returns, and both Delaunay methods reconstruct a noise-free
lattice box closely.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import Delaunay

from metrics import Mesh, point_mesh_distance, sample_surface
from recon.surfaces.methods._backends import JITTER_SPACINGS, general_position
from recon.surfaces.prepare import prepare
from recon.surfaces.reconstruct import reconstruct
from tests.recon.conftest import box_mesh

STEP = 0.05  # lattice step, metres
HALF = np.array([1.0, 0.5, 0.25])  # the conftest box's half sides


def lattice_box() -> tuple[np.ndarray, np.ndarray]:
    """Points of a STEP lattice on the 2 x 1 x 0.5 box's faces (exactly coplanar, cocircular
    in every lattice square) and view points 10 m out along each point's face normal."""
    axes = [np.linspace(-h, h, round(2 * h / STEP) + 1) for h in HALF]
    points, normals = [], []
    for k in range(3):
        i, j = [a for a in range(3) if a != k]
        u, v = np.meshgrid(axes[i], axes[j], indexing="ij")
        for sign in (-1.0, 1.0):
            face = np.zeros((u.size, 3))
            face[:, i], face[:, j], face[:, k] = u.ravel(), v.ravel(), sign * HALF[k]
            points.append(face)
            normals.append(np.tile(np.eye(3)[k] * sign, (u.size, 1)))
    points, normals = np.concatenate(points), np.concatenate(normals)
    _, first = np.unique(np.round(points / STEP * 8), axis=0, return_index=True)
    first = np.sort(first)  # edges and corners belong to several faces: keep one copy
    return points[first], points[first] + 10.0 * normals[first]


def flat_tetrahedra(points: np.ndarray) -> int:
    """Tetrahedra of qhull's Delaunay whose volume is below 1e-14 of STEP^3 (qhull merged
    coplanar facets and split them again into flat tetrahedra; the perturbed lattice's thinnest
    slivers are about 1e-11 of STEP^3)."""
    tri = Delaunay(points)
    corners = points[tri.simplices]
    volume = np.abs(np.linalg.det(corners[:, 1:] - corners[:, :1])) / 6.0
    return int(np.count_nonzero(volume < 1e-14 * STEP**3))


def test_offset_is_seeded_and_bounded():
    points, _ = lattice_box()
    moved = general_position(points, STEP, seed=3)
    assert np.array_equal(moved, general_position(points, STEP, seed=3))
    assert not np.array_equal(moved, general_position(points, STEP, seed=4))
    offset = np.abs(moved - points)
    assert offset.max() <= JITTER_SPACINGS * STEP
    assert offset.max() > 0.5 * JITTER_SPACINGS * STEP


def test_offset_removes_the_flat_tetrahedra_of_a_lattice():
    points, _ = lattice_box()
    assert flat_tetrahedra(points) > 0  # what qhull makes of the raw lattice
    assert flat_tetrahedra(general_position(points, STEP, seed=0)) == 0


@pytest.mark.parametrize("name", ["alpha-shape", "delaunay-balls"])
def test_delaunay_methods_reconstruct_a_noise_free_lattice(name):
    points, view = lattice_box()
    cloud = prepare(points, view_points=view)
    surface = reconstruct(cloud, method=name)
    truth = Mesh(*box_mesh())
    assert point_mesh_distance(points, truth)[0].max() < 1e-12  # the lattice lies on the box
    # The surface lies on the box (delaunay-balls denoises this coarse lattice first: its
    # corners read as noise) and covers it.
    assert np.median(point_mesh_distance(surface.vertices, truth)[0]) < 0.01 * STEP
    samples, _ = sample_surface(truth, 5000, seed=0)
    assert np.quantile(point_mesh_distance(samples, surface)[0], 0.95) < STEP
    assert surface.info["wall_time_s"] < 60.0  # seconds idle; minutes if qhull merges
