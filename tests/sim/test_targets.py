"""Truth meshes: sizes from the paper, closed and outward, user meshes scaled."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from formats.errors import InputError
from sim import targets
from tests.conftest import SHARED_MESHES
from tests.sim.conftest import write_obj


def _outward_and_closed(vertices, faces):
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert targets.is_closed(faces)
    assert targets.signed_volume(vertices, faces) > 0


@pytest.mark.parametrize("n", [0, 1, 3, 5])
def test_ellipsoid_vertices_on_surface_and_face_count(n):
    axes = np.array([143.75, 86.25, 287.5])
    v, f = targets.ellipsoid(axes, n)
    assert len(f) == 20 * 4 ** n
    assert np.allclose(((v / axes) ** 2).sum(axis=1), 1.0, atol=1e-12)
    _outward_and_closed(v, f)


def test_ellipsoid_default_is_the_papers_asteroid():
    v, f = targets.ellipsoid()
    assert np.allclose(v.max(axis=0), [143.75, 86.25, 287.5])
    assert np.allclose(v.min(axis=0), [-143.75, -86.25, -287.5])
    exact = 4.0 / 3.0 * np.pi * 143.75 * 86.25 * 287.5
    assert targets.signed_volume(v, f) == pytest.approx(exact, rel=2e-3)
    # Every face normal points away from the centre (convex, centred).
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    assert np.all(np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c) > 0)


def test_rso_a_matches_the_paper():
    v, f = targets.rso_a()
    _outward_and_closed(v, f)
    assert v[:, 0].min() == pytest.approx(-10.0) and v[:, 0].max() == pytest.approx(10.0)
    # The 5 m bus: the eight corners of [-2.5, 2.5]^3 are vertices.
    corners = np.array([[x, y, z] for x in (-2.5, 2.5) for y in (-2.5, 2.5) for z in (-2.5, 2.5)])
    assert all(np.any(np.all(np.isclose(v, c), axis=1)) for c in corners)
    # Sphere and dish protrude from +y only; the panels make it "oblate along x".
    assert v[:, 1].max() > 3.5 and v[:, 1].min() == pytest.approx(-2.5)
    extent = np.ptp(v, axis=0)
    assert extent[0] > 3 * max(extent[1], extent[2])
    assert len(trimesh.Trimesh(v, f, process=False).split(only_watertight=True)) == 8


def test_rso_b_matches_the_paper():
    v, f = targets.rso_b()
    _outward_and_closed(v, f)
    assert v[:, 0].min() == pytest.approx(-10.0) and v[:, 0].max() == pytest.approx(10.0)
    parts = trimesh.Trimesh(v, f, process=False).split(only_watertight=True)
    assert len(parts) == 8   # 2 cubes, 2 cylinders, pole, disk, boom, panel
    # Less oblate than RSO-A: a larger share of its extent off the x axis.
    a = np.ptp(targets.rso_a()[0], axis=0)
    b = np.ptp(v, axis=0)
    assert b[1:].max() / b[0] > a[1:].max() / a[0]


def test_primitives_are_closed_and_outward():
    for v, f in (targets.box([0, 0, 0], [1, 2, 3]), targets.sphere([1, 2, 3], 2.0),
                 targets.cylinder([0, 0, 0], [1, 1, 0], 0.5, 4.0)):
        _outward_and_closed(v, f)
    v, f = targets.cylinder([0, 0, 0], [0, 0, 1], 1.0, 2.0, segments=256)
    assert targets.signed_volume(v, f) == pytest.approx(2 * np.pi, rel=1e-3)
    v, f = targets.sphere([0, 0, 0], 1.0, segments=256)
    assert targets.signed_volume(v, f) == pytest.approx(4 / 3 * np.pi, rel=1e-3)


def test_load_mesh_scales_and_centres(tmp_path):
    v, f = targets.box([1, 1, 1], [2, 3, 4])   # centroid (1.5, 2, 2.5)
    path = write_obj(tmp_path / "b.obj", v, f)
    scaled, faces = targets.load_mesh(path, 1000.0)
    assert np.allclose(scaled, v * 1000.0) and np.array_equal(faces, f)
    centred, _ = targets.load_mesh(path, 2.0, center=True)
    assert np.allclose(centred.min(axis=0), [-1, -2, -3]) and np.allclose(centred.max(axis=0),
                                                                          [1, 2, 3])


def test_load_mesh_missing_file(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        targets.load_mesh(tmp_path / "nothing.obj")


@pytest.mark.skipif(not (SHARED_MESHES / "bennu_radar_2.7k.obj").exists(),
                    reason="shared meshes not present")
def test_load_shared_km_model_to_metres():
    v, f = targets.load_mesh(SHARED_MESHES / "bennu_radar_2.7k.obj", 1000.0)
    assert len(f) == 2692
    assert np.ptp(v, axis=0) == pytest.approx([566.5, 535.9, 508.8], rel=1e-3)


def test_is_closed_detects_open_and_flipped_meshes():
    _, f = targets.box([0, 0, 0], [1, 1, 1])
    assert targets.is_closed(f)
    assert not targets.is_closed(f[:-1])
    flipped = f.copy()
    flipped[0] = flipped[0, ::-1]
    assert not targets.is_closed(flipped)
