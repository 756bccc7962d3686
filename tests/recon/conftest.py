"""Fixtures of the reconstruction tests: sampled shapes with known surfaces, simulated logs."""

from __future__ import annotations

import numpy as np
import pytest

SPHERE_RADIUS = 1.0
BOX_HALF = np.array([1.0, 0.5, 0.25])
# Semi-axes of a small copy of the paper's ellipsoid (143.75, 86.25, 287.5 m divided by 100).
ELLIPSOID_AXES = np.array([1.4375, 0.8625, 2.875])


def sphere_points(n: int, *, seed: int = 0, noise: float = 0.0):
    """Uniform samples of the unit sphere, view points 3 radii out along each normal."""
    rng = np.random.default_rng(seed)
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    points = normal * (SPHERE_RADIUS + rng.normal(0.0, noise, (n, 1)))
    return points, normal * 3 * SPHERE_RADIUS, normal


def box_points(n: int, *, seed: int = 0, noise: float = 0.0, half=BOX_HALF):
    """Uniform-by-area samples of an axis-aligned box, view points 2 m out along each normal."""
    rng = np.random.default_rng(seed)
    half = np.asarray(half, dtype=float)
    areas = np.array([half[1] * half[2], half[0] * half[2], half[0] * half[1]]).repeat(2)
    face = rng.choice(6, size=n, p=areas / areas.sum())
    axis, sign = face // 2, np.where(face % 2 == 0, 1.0, -1.0)
    points = rng.uniform(-half, half, (n, 3))
    points[np.arange(n), axis] = sign * half[axis]
    normal = np.zeros((n, 3))
    normal[np.arange(n), axis] = sign
    points += normal * rng.normal(0.0, noise, (n, 1))
    return points, points + 2.0 * normal, normal


def ellipsoid_points(n: int, *, seed: int = 0, noise: float = 0.0, axes=ELLIPSOID_AXES):
    """Samples of an ellipsoid (uniform in direction), view points 10 units out along normals."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    surface = u * axes
    normal = surface / axes**2
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    points = surface + normal * rng.normal(0.0, noise, (n, 1))
    return points, surface + 10.0 * normal, normal


def sphere_distance(x: np.ndarray) -> np.ndarray:
    """Exact distance of points (m, 3) to the unit sphere."""
    return np.abs(np.linalg.norm(x, axis=1) - SPHERE_RADIUS)


def box_distance(x: np.ndarray, half=BOX_HALF) -> np.ndarray:
    """Exact distance of points (m, 3) to the surface of the box of half-extents ``half``."""
    q = np.abs(x) - half
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    inside = np.minimum(q.max(axis=1), 0.0)
    return np.abs(outside + inside)


def box_mesh(half=BOX_HALF):
    import trimesh

    mesh = trimesh.creation.box(extents=2 * np.asarray(half))
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)


def sphere_mesh(subdivisions: int = 5):
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=SPHERE_RADIUS)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)


# Few samples per side keep a score under a second; the tests compare methods whose Chamfer
# distances differ by far more than the ~1% sampling error this leaves.
FAST_SCORE = {"n_truth_samples": 5000, "n_test_samples": 5000, "coverage_points": 10000,
              "edges": False}


@pytest.fixture(scope="session")
def asteroid_log(tmp_path_factory):
    """Noise-free single-beam LRF log of the paper's ellipsoid (asteroid-lrf, 77,400 shots)."""
    import sim

    path = tmp_path_factory.mktemp("logs") / "asteroid-lrf.h5"
    sim.simulate(sim.load_scene("asteroid-lrf"), path, seed=0, progress=False)
    return path


@pytest.fixture(scope="session")
def rso_log(tmp_path_factory):
    """Noise-free 5-beam cross LRF log of RSO-A over 5 rotations (about 38,000 strikes)."""
    import sim

    path = tmp_path_factory.mktemp("logs") / "rso-a-cross.h5"
    sim.simulate(sim.load_scene("rso-a-cross", ["time.rotations=5"]), path, seed=0,
                 progress=False)
    return path


# A single-beam LRF circling a 10 m sphere with the paper's 0.3 m 3-sigma range noise: a shot
# every 0.25 s moves the strike ~5 mm along its track, twenty times below the 0.1 m noise (the
# situation of a dense track, where a random hold-out leaves every held-out strike a training
# neighbour with nearly the same noise). 12,000 strikes on a few passes.
TRACK_SPHERE = ["target.semi_axes=[10,10,10]", "target.subdivisions=4", "orbit.radius=50",
                "orbit.period=3000", "target.spin_period=20000", "time.step=0.25",
                "time.rotations=0.15", "errors.range_sigma3=0.3"]


@pytest.fixture(scope="session")
def track_sphere(tmp_path_factory):
    """(cloud, (truth vertices, truth faces)) of the ``TRACK_SPHERE`` log, ingested."""
    import sim
    from formats import StrikeLog
    from recon.registration.ingest import ingest

    path = tmp_path_factory.mktemp("logs") / "track-sphere.h5"
    sim.simulate(sim.load_scene("asteroid-lrf", TRACK_SPHERE), path, seed=0, progress=False)
    with StrikeLog(path) as log:
        truth = log.truth_mesh()
    return ingest(path), (np.asarray(truth[0]), np.asarray(truth[1]))
