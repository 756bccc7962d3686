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

from formats.errors import MethodFailed, ParameterError
from metrics import Mesh, sample_surface, score
from recon.registration.uncertainty import COLUMNS
from recon.surfaces.methods import bind, visibility
from recon.surfaces.prepare import prepare
from tests.recon.conftest import FAST_SCORE

# Sensor directions: the 6 axes and the 8 diagonals, unit length.
_DIAGONALS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) / 3**0.5
SENSOR_DIRECTIONS = np.concatenate([np.eye(3), -np.eye(3), _DIAGONALS])


PLATE = (2.0, 2.0, 0.02)
# Two 1 m cubes with a 1 m gap between them along x: the convex hull fills the gap; the
# diagonal sensors see the facing sides through it.
GAP = 1.0


def shape(name: str) -> tuple[np.ndarray, np.ndarray]:
    """Truth mesh (vertices, faces) of a test shape, metres."""
    import trimesh

    if name == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    elif name == "box":
        mesh = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    elif name == "plate":
        mesh = trimesh.creation.box(extents=PLATE)
    else:  # "two boxes"
        shift = 0.5 + GAP / 2
        mesh = trimesh.util.concatenate([
            trimesh.creation.box(extents=(1.0, 1.0, 1.0)).apply_translation((x, 0.0, 0.0))
            for x in (-shift, shift)])
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
    facing &= ~occluded(truth, points, sensors)
    rng = np.random.default_rng(seed)
    pick = np.argmax(facing * rng.random(facing.shape), axis=1)   # a random facing sensor
    view = sensors[pick]
    ray = points - view
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    points = points + ray * rng.normal(0.0, noise, (n, 1))
    columns = {key: np.zeros(n) for key in COLUMNS} | {"sigma_along": np.full(n, noise)}
    return points, view, columns


def occluded(truth, points: np.ndarray, sensors: np.ndarray) -> np.ndarray:
    """(n, s) bool: the segment from each point to each sensor meets the truth on its way."""
    import trimesh

    mesh = trimesh.Trimesh(*truth, process=False)
    beam = (sensors[None, :, :] - points[:, None, :]).reshape(-1, 3)
    reach = np.linalg.norm(beam, axis=1)
    start = np.repeat(points, len(sensors), axis=0) + 1e-6 * beam / reach[:, None]
    hit, ray, _ = mesh.ray.intersects_location(start, beam / reach[:, None],
                                               multiple_hits=False)
    blocked = np.zeros(len(beam), dtype=bool)
    blocked[ray[np.linalg.norm(hit - start[ray], axis=1) < reach[ray]]] = True
    return blocked.reshape(len(points), len(sensors))


def reconstruct(truth, n: int, *, noise: float = 0.0, seed: int = 0, **params):
    points, view, columns = scan(truth, n, noise=noise, seed=seed)
    cloud = prepare(points, view_points=view, uncertainty=columns, seed=seed)
    run = bind("visibility", params)
    vertices, faces = run.method_spec().run(cloud, **run.params)
    return vertices, faces, cloud


def closed(faces: np.ndarray) -> bool:
    """Every edge borders faces of both orientations equally often: a closed, consistently
    oriented surface (the boundary of a union of cells; an edge where two inside cells touch
    has four faces and stays balanced)."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    forward, count = np.unique(directed, axis=0, return_counts=True)
    lookup = dict(zip(map(tuple, forward), count, strict=True))
    return all(lookup.get((b, a), 0) == c for (a, b), c in zip(map(tuple, forward), count,
                                                                 strict=True))


def volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Enclosed volume of a closed, outward-oriented mesh (divergence theorem), m^3."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def winding(vertices: np.ndarray, faces: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Winding number of a closed mesh around each query point (q,): 1 inside, 0 outside
    (Van Oosterom and Strackee's solid angle of each triangle, summed)."""
    a, b, c = (vertices[faces[:, i]][None] - query[:, None] for i in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
    det = np.einsum("qfi,qfi->qf", a, np.cross(b, c))
    dot = (la * lb * lc + np.einsum("qfi,qfi->qf", a, b) * lc
           + np.einsum("qfi,qfi->qf", b, c) * la + np.einsum("qfi,qfi->qf", c, a) * lb)
    return 2.0 * np.arctan2(det, dot).sum(axis=1) / (4.0 * np.pi)


# Bounds: in spacings of the cloud (a Delaunay surface through the strikes cuts corners and
# chords by up to about one spacing) plus, with noise, a fraction of the noise for the mean
# (Chamfer) and three sigmas for the worst point (Hausdorff).
@pytest.mark.parametrize("name, n, noise", [
    ("sphere", 3000, 0.0), ("sphere", 3000, 0.02), ("box", 3000, 0.0), ("box", 3000, 0.01)])
def test_closed_shapes_are_recovered_closed_and_close(name, n, noise):
    truth = shape(name)
    vertices, faces, cloud = reconstruct(truth, n, noise=noise)
    assert closed(faces)
    report = score((vertices, faces), truth, **FAST_SCORE)
    assert report.chamfer_m < 0.1 * cloud.spacing + 0.3 * noise, report.chamfer_m
    assert report.hausdorff_m < 1.2 * cloud.spacing + 3.0 * noise, report.hausdorff_m
    assert volume(vertices, faces) == pytest.approx(volume(*truth), rel=0.03)


@pytest.mark.parametrize("noise", [0.0, 0.002])
def test_thin_plate_keeps_both_sides_apart(noise):
    """2 m x 2 m x 2 cm, seen from above and below (spacing ~3 cm, more than the thickness):
    closed (no hole), and its volume is the plate's (a merged sheet would enclose none)."""
    truth = shape("plate")
    vertices, faces, cloud = reconstruct(truth, 4000, noise=noise)
    assert cloud.spacing > PLATE[2]
    assert closed(faces)
    assert volume(vertices, faces) == pytest.approx(np.prod(PLATE), rel=0.15)
    grid = np.stack(np.meshgrid(np.linspace(-0.9, 0.9, 7), np.linspace(-0.9, 0.9, 7)),
                    axis=-1).reshape(-1, 2)
    mid, above = (np.column_stack([grid, np.full(len(grid), z)]) for z in (0.0, 0.03))
    assert np.all(np.abs(winding(vertices, faces, mid) - 1.0) < 1e-6)
    assert np.all(np.abs(winding(vertices, faces, above)) < 1e-6)
    report = score((vertices, faces), truth, **FAST_SCORE)
    assert report.hausdorff_m < cloud.spacing, report.hausdorff_m


def test_rays_carve_the_gap_the_convex_hull_fills():
    truth = shape("two boxes")
    vertices, faces, _ = reconstruct(truth, 6000)
    assert closed(faces)
    gap = np.array([[0.0, y, z] for y in (-0.3, 0.0, 0.3) for z in (-0.3, 0.0, 0.3)])
    assert np.all(np.abs(winding(vertices, faces, gap)) < 1e-6)       # outside: carved
    centres = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    assert np.all(np.abs(winding(vertices, faces, centres) - 1.0) < 1e-6)
    assert volume(vertices, faces) == pytest.approx(volume(*truth), rel=0.05)


def test_range_noise_along_the_rays_does_not_crumple_the_surface():
    """Noise of 2 cm along the rays: the surface lies well within the noise of the truth and
    its area is the sphere's; the same method without denoising, through the noisy strikes,
    is rougher and larger."""
    noise = 0.02
    truth = shape("sphere")
    areas = {}
    for denoise in (None, False):
        vertices, faces, _ = reconstruct(truth, 6000, noise=noise, denoise=denoise)
        a, b, c = (vertices[faces[:, i]] for i in range(3))
        areas[denoise] = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
        if denoise is None:
            report = score((vertices, faces), truth, **FAST_SCORE)
            assert report.accuracy_mean_m < 0.5 * noise, report.accuracy_mean_m
    assert areas[None] == pytest.approx(4.0 * np.pi, rel=0.05)
    assert areas[False] > areas[None] * 1.03       # through the raw strikes: crumpled


def test_noise_near_the_spacing_is_averaged_over_larger_planes():
    """The 2 cm plate with 4 cm range noise (0.7 spacings along the normals): each plane
    averages 60 strikes, not 30, and the surface lies nearer the truth (mean accuracy 6.9-7.2
    mm on seeds 0-2, against 8.8-9.2 mm with 30 a plane)."""
    noise = 0.04
    truth = shape("plate")
    vertices, faces, cloud = reconstruct(truth, 4000, noise=noise)
    assert visibility.denoise_neighbours(float(np.median(cloud.sigma)), cloud.spacing) == 60
    report = score((vertices, faces), truth, **FAST_SCORE)
    assert report.accuracy_mean_m < 0.2 * noise, report.accuracy_mean_m


def test_denoise_neighbours_bring_the_noise_to_a_fraction_of_the_spacing():
    spacing = 0.1
    low = visibility.DENOISE_RESIDUAL * spacing * np.sqrt(visibility.DENOISE_K)
    assert visibility.denoise_neighbours(0.5 * low, spacing) == visibility.DENOISE_K
    assert visibility.denoise_neighbours(10 * low, spacing) == visibility.DENOISE_K_MAX
    noise = 0.5 * spacing                       # (0.5 / 0.08)^2 = 39.06 strikes
    assert visibility.denoise_neighbours(noise, spacing) == 39
    counts = [visibility.denoise_neighbours(x, spacing) for x in np.linspace(0, 0.1, 11)]
    assert counts == sorted(counts)


def test_same_seed_same_bytes_and_the_seed_matters():
    truth = shape("box")
    first = reconstruct(truth, 1500, noise=0.01, seed=3)
    again = reconstruct(truth, 1500, noise=0.01, seed=3)
    assert first[0].tobytes() == again[0].tobytes()
    assert first[1].tobytes() == again[1].tobytes()
    other = reconstruct(truth, 1500, noise=0.01, seed=4)
    assert first[0].tobytes() != other[0].tobytes()


def test_a_cloud_without_view_points_is_refused():
    points, _, _ = scan(shape("sphere"), 500)
    cloud = prepare(points)
    run = bind("visibility")
    with pytest.raises(MethodFailed, match="visibility: the cloud has no view points"):
        run.method_spec().run(cloud, **run.params)


@pytest.mark.parametrize("params, message", [
    ({"max_steps": 0}, "max_steps must be from 1 to 4096"),
    ({"beta": -1.0}, "beta must be from 0 to 100"),
    ({"sigma": -0.5}, "sigma must be from 0 to 100"),
    ({"behind": "far"}, "behind must be a float"),
])
def test_bad_parameters_are_named_before_any_work(params, message):
    with pytest.raises(ParameterError, match=message):
        bind("visibility", params)


def test_view_points_reach_the_isolated_worker_through_the_api():
    """``recon.api.reconstruct`` on a Cloud with ``view_x/y/z``: preparation keeps them and the
    isolated worker receives them (else the method would refuse the cloud)."""
    from formats.geometry import Cloud
    from recon import api

    points, view, _ = scan(shape("sphere"), 1500)
    cloud = Cloud(points, {"view_x": view[:, 0], "view_y": view[:, 1], "view_z": view[:, 2]})
    surface = api.reconstruct(cloud, method="visibility")
    assert surface.method == "visibility"
    assert closed(surface.faces)
    assert volume(surface.vertices, surface.faces) == pytest.approx(4.0 / 3.0 * np.pi,
                                                                    rel=0.05)


def axis_scan(truth, n: int, *, noise: float = 0.0, seed: int = 0):
    """As ``scan``, from the 6 axis sensors only, keeping the strikes one of them sees (at
    incidences under 72 degrees): the facing sides of the two boxes are seen by none, and no
    sensor-to-strike ray crosses the gap between them."""
    vertices, faces = truth
    points, face = sample_surface(Mesh(vertices, faces), n, seed=seed)
    a, b, c = (vertices[faces[face, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    sensors = 5.0 * SENSOR_DIRECTIONS[:6]
    beam = sensors[None, :, :] - points[:, None, :]
    facing = np.einsum("nsi,ni->ns", beam, normal) / np.linalg.norm(beam, axis=2) > 0.3
    facing &= ~occluded(truth, points, sensors)
    rng = np.random.default_rng(seed)
    seen = facing.any(axis=1)
    view = sensors[np.argmax(facing * rng.random(facing.shape), axis=1)][seen]
    points = points[seen]
    ray = (points - view) / np.linalg.norm(points - view, axis=1, keepdims=True)
    points = points + ray * rng.normal(0.0, noise, (len(points), 1))
    columns = {key: np.zeros(len(points)) for key in COLUMNS}
    return prepare(points, view_points=view, seed=seed,
                   uncertainty=columns | {"sigma_along": np.full(len(points), noise)})


def gap_misses(m: int = 200, seed: int = 0):
    """Missed beams of a sensor at +5 m on y, falling along -y through the gap between the two
    boxes (|x| < 0.4, |z| < 0.4 m; free from 0.5 to 20 m)."""
    from recon.registration.misses import MissedBeams

    xz = np.random.default_rng(seed).uniform(-0.4, 0.4, (m, 2))
    origin = np.column_stack([xz[:, 0], np.full(m, 5.0), xz[:, 1]])
    return MissedBeams(origin, np.tile([0.0, -1.0, 0.0], (m, 1)), 0.5, 20.0, np.arange(m),
                       np.zeros(m, dtype=np.int64), m)


def fit(cloud, **params):
    run = bind("visibility", params)
    return run.method_spec().run(cloud, **run.params)


@pytest.mark.parametrize("noise, beta", [(0.0, 0.0), (0.01, 0.0), (0.0, 0.1)])
def test_missed_beams_open_a_closure_no_strike_ray_crossed(noise, beta):
    """Two boxes seen from the 6 axes only: no ray crosses the gap, and the cut closes it
    (volume 3 m^3 for the boxes' 2). The missed beams through the gap open it: the gap is
    outside, the boxes inside, the volume theirs."""
    import dataclasses

    truth = shape("two boxes")
    cloud = axis_scan(truth, 3000, noise=noise)
    gap = np.array([[0.0, y, z] for y in (-0.3, 0.0, 0.3) for z in (-0.3, 0.0, 0.3)])
    closed_over = fit(cloud, beta=beta)
    assert np.all(np.abs(winding(*closed_over, gap) - 1.0) < 1e-6)     # the closure
    vertices, faces = fit(dataclasses.replace(cloud, misses=gap_misses()), beta=beta)
    assert closed(faces)
    assert np.all(np.abs(winding(vertices, faces, gap)) < 1e-6)        # opened
    centres = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    assert np.all(np.abs(winding(vertices, faces, centres) - 1.0) < 1e-6)
    assert volume(vertices, faces) == pytest.approx(volume(*truth), rel=0.05)


def test_missed_beams_that_cross_no_cell_change_no_byte():
    """Misses beside the body, or whose free span ends before it, leave the cut as it is: the
    same bytes as without misses."""
    import dataclasses

    from recon.registration.misses import MissedBeams

    cloud = axis_scan(shape("two boxes"), 1500, noise=0.01)
    beside = gap_misses()
    beside = dataclasses.replace(beside, origin=beside.origin + np.array([0.0, 0.0, 3.0]))
    short = dataclasses.replace(gap_misses(), range_max=4.0)     # ends 0.5 m before the boxes
    empty = MissedBeams(np.zeros((0, 3)), np.zeros((0, 3)), 0.5, 20.0,
                        np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), 0)
    plain = fit(cloud)
    for misses in (beside, short, empty):
        vertices, faces = fit(dataclasses.replace(cloud, misses=misses))
        assert vertices.tobytes() == plain[0].tobytes()
        assert faces.tobytes() == plain[1].tobytes()


def test_missed_beams_grazing_a_sphere_leave_it_whole():
    """Missed beams along z passing 2-30 cm outside a unit sphere with 2 cm range noise (the
    strikes' hull reaches past the truth there): the surface keeps its volume and accuracy."""
    import dataclasses

    from recon.registration.misses import MissedBeams

    truth = shape("sphere")
    points, view, columns = scan(truth, 3000, noise=0.02)
    cloud = prepare(points, view_points=view, uncertainty=columns)
    rng = np.random.default_rng(1)
    m = 2000
    angle, radius = rng.uniform(0, 2 * np.pi, m), rng.uniform(1.02, 1.3, m)
    origin = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), np.full(m, 5.0)])
    misses = MissedBeams(origin, np.tile([0.0, 0.0, -1.0], (m, 1)), 0.5, 20.0, np.arange(m),
                         np.zeros(m, dtype=np.int64), m)
    plain = fit(cloud)
    vertices, faces = fit(dataclasses.replace(cloud, misses=misses))
    assert closed(faces)
    assert volume(vertices, faces) == pytest.approx(volume(*plain), rel=0.01)
    before = score(plain, truth, **FAST_SCORE).chamfer_m
    assert score((vertices, faces), truth, **FAST_SCORE).chamfer_m < 1.1 * before


def test_hull_entries_against_the_box_they_enter():
    """Rays into the hull of a cube's corners and inner points enter at its face, in a cell
    holding the entry point; rays beside it, or whose span starts inside, are left out."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(0)
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5)
                        for z in (-0.5, 0.5)])
    tri = visibility.Cells.of(Delaunay(np.concatenate([corners, rng.uniform(-0.4, 0.4,
                                                                            (200, 3))])))
    xy = rng.uniform(-0.45, 0.45, (50, 2))
    origin = np.concatenate([np.column_stack([xy, np.full(50, 3.0)]),
                             [[2.0, 0.0, 3.0]]])                          # the last: beside
    direction = np.tile([0.0, 0.0, -1.0], (51, 1))
    ray, cell, t = visibility.hull_entries(tri, origin, direction, 0.0, 10.0)
    np.testing.assert_array_equal(ray, np.arange(50))
    np.testing.assert_allclose(t, 2.5, atol=1e-9)
    at = origin[ray] + t[:, None] * direction[ray]
    bary = np.einsum("rij,rj->ri", tri.inverse[cell], at - tri.offset[cell])
    bary = np.column_stack([bary, 1.0 - bary.sum(axis=1)])
    assert np.all(bary > -1e-9)
    inside, _, _ = visibility.hull_entries(tri, origin, direction, 2.7, 10.0)
    assert len(inside) == 0                       # each span begins 0.2 m inside the cube
