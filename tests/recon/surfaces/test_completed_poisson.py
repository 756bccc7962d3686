"""``completed-poisson``: the Poisson surface of the strikes where they are, their ellipsoid where
none is."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from formats.errors import MethodFailed
from recon.surfaces.methods.completed_poisson import unseen_points
from recon.surfaces.methods.ellipsoid import fit_quadric
from recon.surfaces.prepare import prepare
from recon.surfaces.reconstruct import reconstruct
from tests.recon.surfaces.test_auto_prior import AXES, bumpy_body


def ellipsoid_error(vertices: np.ndarray) -> np.ndarray:
    """How far each vertex is off the bumpy body's ellipsoid, as a fraction of its radius."""
    return np.abs(np.linalg.norm(vertices / AXES, axis=1) - 1.0)


@pytest.fixture(scope="module")
def belts():
    """A bumpy ellipsoid seen along two perpendicular belts (a third of it), prepared."""
    points, view = bumpy_body(3000, width=0.12)
    return points, prepare(points, view_points=view)


def test_the_unseen_part_follows_the_ellipsoid_where_poisson_guesses_a_blob(belts):
    # Measured: the vertices farther than 0.3 of the mean semi-axis from every strike (the
    # method's reach) lie 0.1 % of the radius off the body's ellipsoid on average, Poisson's
    # own blob 1.3 %.
    points, cloud = belts
    tree = cKDTree(points)
    off = {}
    for name, params in (("completed-poisson", {}), ("poisson", {"depth": 6, "trim": np.inf})):
        surface = reconstruct(cloud, method=name, params=params)
        far = tree.query(surface.vertices)[0] > 0.3 * AXES.mean()
        assert far.sum() > 100, name
        off[name] = ellipsoid_error(surface.vertices[far]).mean()
    assert off["completed-poisson"] < 0.003
    assert off["poisson"] > 3 * off["completed-poisson"]


def test_where_the_strikes_are_the_surface_follows_them(belts):
    points, cloud = belts
    surface = reconstruct(cloud, method="completed-poisson")
    from metrics import point_mesh_distance

    distance = point_mesh_distance(points, (surface.vertices, surface.faces))[0]
    assert np.median(distance) < 0.01   # the noise is 0.004, the bumps 0.01 of the radius


def test_unseen_points_lie_beyond_the_reach_with_outward_unit_normals(belts):
    points, _ = belts
    centre, axes, rotation = fit_quadric(points, iterations=20)
    vertices, normals = unseen_points(points, centre, axes, rotation, reach=0.4,
                                      subdivisions=4)
    assert len(vertices) > 0
    # the strikes lie near the ellipsoid here: their projections onto it are near them
    assert np.all(cKDTree(points).query(vertices)[0] > 0.3 * axes.mean())
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)
    assert np.all(np.sum(normals * (vertices - centre), axis=1) > 0)
    # A reach beyond the body leaves nothing to complete.
    assert len(unseen_points(points, centre, axes, rotation, reach=10.0, subdivisions=4)[0]) == 0


def test_the_same_strikes_give_the_same_bytes(belts):
    _, cloud = belts
    one = reconstruct(cloud, method="completed-poisson")
    two = reconstruct(cloud, method="completed-poisson")
    assert one.vertices.tobytes() == two.vertices.tobytes()
    assert one.faces.tobytes() == two.faces.tobytes()


def test_strikes_that_enclose_no_convex_body_fail_by_name():
    rng = np.random.default_rng(0)
    xy = rng.uniform(-1, 1, (500, 2))
    patch = np.column_stack([xy, 0.2 * xy[:, 0] * xy[:, 1] + rng.normal(0, 1e-3, 500)])
    cloud = prepare(patch, view_points=patch + np.array([0.0, 0.0, 5.0]))
    with pytest.raises(MethodFailed, match="completed-poisson: no ellipsoid to complete with"):
        reconstruct(cloud, method="completed-poisson")
