"""The ``ellipsoid`` primitive, the Voronoi-based ``delaunay-balls``, parameter counts, and
noise-aware weights from the recorded error model."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from formats.errors import MethodFailed
from formats.strike_log import SensorErrors
from recon.registration.uncertainty import strike_columns
from recon.surfaces import methods, uncertainty
from recon.surfaces.methods import watertight
from recon.surfaces.methods.delaunay_balls import min_cut_labels
from recon.surfaces.methods.ellipsoid import fit_quadric
from recon.surfaces.methods.plane import project_to_planes
from recon.surfaces.prepare import prepare
from recon.surfaces.reconstruct import reconstruct
from tests.recon.conftest import (
    BOX_HALF,
    box_distance,
    box_mesh,
    box_points,
    ellipsoid_points,
    sphere_distance,
    sphere_points,
)


def _rotated_ellipsoid(n, *, noise, outliers=0.0, seed=0):
    axes = np.array([1.0, 2.0, 3.5])
    points, view, _ = ellipsoid_points(n, seed=seed, noise=noise, axes=axes)
    rotation = Rotation.from_euler("xyz", [20, -35, 50], degrees=True)
    centre = np.array([5.0, -2.0, 1.0])
    points, view = rotation.apply(points) + centre, rotation.apply(view) + centre
    rng = np.random.default_rng(seed + 1)
    extra = round(outliers * n)
    if extra:
        points = np.concatenate([points, rng.uniform(centre - 4, centre + 4, (extra, 3))])
        view = np.concatenate([view, view[:extra]])
    return points, view, axes, rotation, centre


def test_ellipsoid_recovers_axes_centre_and_orientation_through_outliers():
    points, _, axes, rotation, centre = _rotated_ellipsoid(4000, noise=0.01, outliers=0.05)
    fitted_centre, fitted_axes, frame = fit_quadric(points)
    np.testing.assert_allclose(fitted_axes, axes, rtol=5e-3)
    np.testing.assert_allclose(fitted_centre, centre, atol=5e-3)
    truth_frame = rotation.as_matrix()          # columns: the x, y, z semi-axis directions
    cosines = np.abs(np.einsum("ij,ij->j", frame, truth_frame))
    assert np.all(cosines > 0.9999)
    # Without the robust rounds the 5% uniform outliers bias the axes by several percent.
    _, biased, _ = fit_quadric(points, iterations=0)
    assert np.abs(biased / axes - 1).max() > 0.02


def test_ellipsoid_method_is_nine_parameters_and_closed():
    points, view, *_ = _rotated_ellipsoid(3000, noise=0.005)
    surface = reconstruct(prepare(points, view_points=view), method="ellipsoid",
                          params={"subdivisions": 3})
    assert surface.info["watertight"] and len(surface.faces) == 20 * 4**3
    spec = methods.get("ellipsoid")
    assert spec.kind == "primitive"
    assert spec.parameter_count(surface.vertices, surface.faces) == 9


def test_ellipsoid_refuses_a_saddle():
    rng = np.random.default_rng(0)
    xy = rng.uniform(-1, 1, (500, 2))
    saddle = np.column_stack([xy, xy[:, 0] ** 2 - xy[:, 1] ** 2])
    with pytest.raises(MethodFailed, match="not an ellipsoid"):
        fit_quadric(saddle)


def test_parameter_counts_of_planes_and_free_meshes():
    planes = methods.get("planes")
    cube_v, cube_f = box_mesh()                       # 12 triangles on 6 planes, closed
    assert planes.parameter_count(cube_v, cube_f) == 6 * 3
    square_v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    square_f = np.array([[0, 1, 2], [0, 2, 3]])       # one open polygon: plane + 4 corners
    assert planes.parameter_count(square_v, square_f) == 3 + 2 * 4
    points, view, _ = box_points(4000)
    cloud = prepare(points, view_points=view)
    hull = reconstruct(cloud, method="convex-hull")
    assert methods.get("convex-hull").parameter_count(hull.vertices, hull.faces) == \
        3 * len(hull.vertices)


@pytest.mark.parametrize("shape", ["sphere", "box"])
@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_delaunay_balls_is_watertight_and_close_on_sphere_and_box(shape, noise):
    make, distance, diagonal = {"sphere": (sphere_points, sphere_distance, 2 * np.sqrt(3)),
                                "box": (box_points, box_distance,
                                        2 * np.linalg.norm(BOX_HALF))}[shape]
    points, view, _ = make(6000, noise=noise)
    surface = reconstruct(prepare(points, view_points=view), method="delaunay-balls")
    assert watertight(surface.faces)
    # Vertices are (denoised) samples: within 3 noise sigmas (and 0.1% of the diagonal).
    assert np.median(distance(surface.vertices)) <= 1e-3 * diagonal + noise
    a, b, c = (surface.vertices[surface.faces[:, i]] for i in range(3))
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
    exact = 4 / 3 * np.pi if shape == "sphere" else 8 * np.prod(BOX_HALF)
    # Measured: -0.3% to -0.9% (the interpolating surface cuts chords inside a curve).
    assert volume == pytest.approx(exact, rel=0.03)  # positive: faces point outward


def test_delaunay_balls_needs_inner_balls():
    points, view, _ = sphere_points(500)
    with pytest.raises(MethodFailed, match="no inner Delaunay ball"):
        reconstruct(prepare(points, view_points=view), method="delaunay-balls",
                    params={"kappa": 100.0})


def _brute_force_cut(n, pairs, capacity, seeds_in, seeds_out, boundary, boundary_capacity):
    """The cheapest labelling by enumeration (seeds fixed), as a list of bools."""
    import itertools

    free = [i for i in range(n) if not seeds_in[i] and not seeds_out[i]]
    best = None
    for bits in itertools.product([False, True], repeat=len(free)):
        label = seeds_in.copy()
        label[free] = bits
        cost = sum(c for (a, b), c in zip(pairs, capacity, strict=True) if label[a] != label[b])
        cost += sum(c for cell, c in zip(boundary, boundary_capacity, strict=True) if label[cell])
        if best is None or cost < best[0]:
            best = (cost, label.tolist())
    return best[1]


@pytest.mark.parametrize("seed", range(5))
def test_min_cut_labels_against_brute_force(seed):
    rng = np.random.default_rng(seed)
    n = 9
    pairs = np.array([(a, b) for a in range(n) for b in range(a + 1, n) if rng.random() < 0.4])
    capacity = rng.integers(1, 20, len(pairs))
    seeds_in = np.zeros(n, dtype=bool)
    seeds_out = np.zeros(n, dtype=bool)
    seeds_in[[0, 1]] = True
    seeds_out[[7, 8]] = True
    boundary = np.array([3, 5])
    boundary_capacity = rng.integers(1, 20, 2)
    label = min_cut_labels(n, pairs, capacity, seeds_in, seeds_out, boundary, boundary_capacity)
    expected = _brute_force_cut(n, pairs, capacity, seeds_in, seeds_out, boundary,
                                boundary_capacity)

    def cost(lab):
        return sum(c for (a, b), c in zip(pairs, capacity, strict=True) if lab[a] != lab[b]) \
            + sum(c for cell, c in zip(boundary, boundary_capacity, strict=True) if lab[cell])

    assert cost(label.tolist()) == cost(expected)     # ties may pick another minimum
    assert label[seeds_in].all() and not label[seeds_out].any()


def test_normal_sigma_is_anisotropic_along_the_beam():
    errors = SensorErrors(range_sigma3=0.3, azimuth_sigma3=np.radians(0.6),
                          elevation_sigma3=np.radians(0.6))
    ranges = np.array([100.0, 100.0])
    columns = strike_columns(errors, ranges, reports_angles=True)
    np.testing.assert_allclose(columns["sigma_along"], 0.1)
    np.testing.assert_allclose(columns["sigma_across"], 100 * np.radians(0.2))
    points = np.zeros((2, 3))
    view = np.array([[0, 0, 100.0], [100.0, 0, 0]])
    normals = np.array([[0, 0, 1.0], [0.5, 0, np.sqrt(0.75)]])  # head-on; 60 deg off the beam
    sigma = uncertainty.normal_sigma(normals, view, points, columns)
    assert sigma[0] == pytest.approx(0.1)
    lateral = 100 * np.radians(0.2)
    assert sigma[1] == pytest.approx(np.sqrt(0.1**2 * 0.25 + lateral**2 * 0.75))
    assert uncertainty.normal_sigma(normals, view, points, strike_columns(
        SensorErrors(), ranges, reports_angles=False)) is None


def test_weighted_plane_fit_trusts_the_precise_strikes():
    # Half the strikes of a unit sphere are 10x noisier, and their recorded sigma says so.
    rng = np.random.default_rng(3)
    points, _, normal = sphere_points(6000)
    sigma = np.where(np.arange(6000) % 2 == 0, 0.002, 0.02)
    noisy = points + normal * rng.normal(0.0, sigma)[:, None]
    w = uncertainty.weights(sigma, len(points))
    errors = []
    for weights in (None, w):
        moved, _ = project_to_planes(noisy, normal, k=30, iterations=2, order=2,
                                     weights=weights)
        errors.append(np.sqrt(np.mean(sphere_distance(moved) ** 2)))
    unweighted, weighted = errors
    assert weighted < 0.6 * unweighted, errors


def test_ingest_records_each_strikes_uncertainty(tmp_path):
    import sim
    from recon.registration.ingest import ingest

    path = tmp_path / "lidar.h5"
    sim.simulate(sim.load_scene("asteroid-lidar-noise", ["time.duration=200",
                                                         "sensor.resolution=[4,4]"]),
                 path, seed=0, progress=False)
    cloud = ingest(path)
    ranges = cloud.attributes["range"]
    along = np.hypot(1.0 / 3, 2.0 / 3)          # the Jenoptik 1 m range, 2 m pose (3-sigma)
    np.testing.assert_allclose(cloud.attributes["sigma_along"], along, rtol=1e-6)
    np.testing.assert_allclose(cloud.attributes["sigma_across"],
                               np.hypot(ranges * np.radians(0.2) / 3, 2.0 / 3), rtol=1e-5)
    prepared = prepare(cloud.points, view_points=cloud.view_points,
                       uncertainty=cloud.attributes)
    assert prepared.sigma is not None and np.all(prepared.sigma >= along * 0.999 - 1e-9)
