"""Generated targets: closed and outward, the same bytes per seed, sizes in range, and seen by a
short simulation."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from formats.errors import SceneError
from formats.strike_log import StrikeLog
from sim import procedural, targets
from tests.sim.conftest import distance_to_mesh, registered_points, run_scene

# The asteroid at 4 subdivisions (5,120 faces) keeps these tests small; the craters still span
# several vertices at the sizes they are drawn at.
BUILDERS = {
    "satellite": procedural.satellite,
    "polyhedron": procedural.polyhedron,
    "cratered-asteroid": lambda seed: procedural.cratered_asteroid(seed, subdivisions=4),
}
SEEDS = (0, 1, 2, 7)


def _parts(vertices, faces):
    return trimesh.Trimesh(vertices, faces, process=False).split(only_watertight=False)


@pytest.mark.parametrize("kind", BUILDERS)
@pytest.mark.parametrize("seed", SEEDS)
def test_every_part_is_closed_and_outward(kind, seed):
    v, f = BUILDERS[kind](seed)
    assert v.dtype == np.float64 and f.dtype == np.int64
    assert targets.is_closed(f)
    parts = _parts(v, f)
    for part in parts:
        assert part.is_watertight and part.is_winding_consistent
        assert targets.signed_volume(part.vertices, part.faces) > 0
    # Single bodies are one part; a satellite is a bus, arms, panels, mast, dish, boom, box.
    assert len(parts) == 1 if kind != "satellite" else len(parts) >= 8


@pytest.mark.parametrize("kind", BUILDERS)
def test_same_seed_same_bytes_other_seeds_differ(kind):
    a, b, c = BUILDERS[kind](3), BUILDERS[kind](3), BUILDERS[kind](4)
    assert a.vertices.tobytes() == b.vertices.tobytes()
    assert a.faces.tobytes() == b.faces.tobytes()
    assert a.vertices.shape != c.vertices.shape or not np.allclose(a.vertices, c.vertices)


@pytest.mark.parametrize("seed", range(12))
def test_satellite_dimensions_are_in_range_and_built_as_designed(seed):
    d = procedural.satellite_design(seed)
    assert all(1.0 <= e <= 3.0 for e in d.bus)
    assert 2 <= len(d.panels) <= 4
    for p in d.panels:
        assert 0.02 <= p.thickness <= 0.06 and 1.0 <= p.width <= 2.5
        assert abs(p.x0) >= d.bus[0] / 2 and abs(p.x1) > abs(p.x0)
    for side in (1, -1):
        wing = [p for p in d.panels if np.sign(p.x1) == side]
        span = max(abs(p.x1) for p in wing) - min(abs(p.x0) for p in wing)
        assert 4.0 - 1e-9 <= span <= 8.0 + 1e-9            # panels several metres long
    assert d.dish_face != d.boom_face and abs(d.dish_face[0]) == abs(d.boom_face[0]) == 0
    assert 0.5 <= d.dish_radius <= 1.5 and 0.03 <= d.dish_thickness <= 0.05
    assert 0.1 * d.dish_radius <= d.dish_depth <= 0.25 * d.dish_radius
    assert 2.0 <= d.boom_length <= 5.0 and all(0.3 <= e <= 0.8 for e in d.end_box)
    # The mesh spans the wings along x, exactly.
    v, _ = procedural.satellite(seed)
    assert v[:, 0].max() == pytest.approx(max(p.x1 for p in d.panels))
    assert v[:, 0].min() == pytest.approx(min(p.x1 for p in d.panels))
    # The boom's end box is the farthest part along the boom's face normal.
    axis = np.asarray(d.boom_face)
    reach = np.dot(d.boom_mount, axis) + d.boom_length + np.dot(d.end_box, np.abs(axis))
    assert (v @ axis).max() == pytest.approx(reach)


def test_dish_is_a_thin_closed_cap_opening_upwards():
    v, f = procedural.dish(1.0, 0.2, 0.04, rings=6, segments=24)
    mesh = trimesh.Trimesh(v, f, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    # Volume of a paraboloid shell of uniform vertical thickness: pi r^2 t (less the chords).
    assert mesh.volume == pytest.approx(np.pi * 0.04, rel=0.03)
    assert v[:, 2].min() == 0.0 and v[:, 2].max() == pytest.approx(0.24)


@pytest.mark.parametrize("seed", SEEDS)
def test_polyhedron_is_convex_with_20_to_28_facets_at_its_size(seed):
    v, f = procedural.polyhedron(seed, size=5.7)
    assert 20 <= len(f) <= 28 and len(f) == 2 * len(v) - 4
    assert trimesh.Trimesh(v, f, process=False).is_convex
    assert np.ptp(v, axis=0).max() == pytest.approx(5.7)
    # Scaling keeps the body: x3.5 is the same polyhedron.
    big, _ = procedural.polyhedron(seed, size=5.7 * 3.5)
    assert np.allclose(big, v * 3.5)


@pytest.mark.parametrize("seed", SEEDS)
def test_cratered_asteroid_is_not_convex_and_has_its_size(seed):
    v, f = BUILDERS["cratered-asteroid"](seed)
    mesh = trimesh.Trimesh(v, f, process=False)
    assert np.ptp(v, axis=0).max() == pytest.approx(500.0)
    # Craters and the large concavity: the hull holds more than the body, and the concavity
    # leaves surface more than 20 m (4 % of the size) inside the hull (positive: inside).
    assert mesh.convex_hull.volume > 1.005 * mesh.volume
    assert trimesh.proximity.signed_distance(mesh.convex_hull, v).max() > 20.0


@pytest.mark.parametrize(("call", "match"), [
    (lambda: procedural.satellite(-1), r"seed must be a non-negative integer, got -1"),
    (lambda: procedural.polyhedron(0, size=0.0), r"size must be a positive length"),
    (lambda: procedural.cratered_asteroid(1.5), r"seed must be a non-negative integer"),
])
def test_bad_arguments_are_named(call, match):
    with pytest.raises(ValueError, match=match):
        call()


SCENES = [
    ("rso-a-cross", ["target.kind=satellite", "target.seed=5"], "satellite:seed=5"),
    ("rso-a-cross", ["target.kind=polyhedron", "target.seed=2", "target.size=20"],
     "polyhedron:seed=2,size=20"),
    ("asteroid-cross", ["target.kind=cratered-asteroid", "target.seed=1"],
     "cratered-asteroid:seed=1"),
]


@pytest.mark.parametrize(("preset", "overrides", "label"), SCENES, ids=[s[2] for s in SCENES])
def test_a_short_simulation_strikes_the_generated_target(tmp_path, preset, overrides, label):
    summary, path = run_scene(tmp_path, preset, *overrides, "time.duration=4000")
    points = registered_points(path)
    with StrikeLog(path) as log:
        vertices, faces = log.truth_mesh()
        assert log.attrs["target"] == label
    assert summary["strikes"] == len(points) > 50
    sample = np.random.default_rng(0).choice(len(points), min(500, len(points)), replace=False)
    size = np.ptp(vertices, axis=0).max()
    assert distance_to_mesh(points[sample], vertices, faces).max() <= 1e-6 * size


def test_scene_keys_of_generated_targets_are_checked(tmp_path):
    with pytest.raises(SceneError, match=r'target\.size is only used when target\.kind is '
                                         r'"polyhedron" or "cratered-asteroid", not "satellite"'):
        run_scene(tmp_path, "rso-a-cross", "target.kind=satellite", "target.size=3")
    with pytest.raises(SceneError, match=r"target\.seed must be at least 0"):
        run_scene(tmp_path, "rso-a-cross", "target.kind=polyhedron", "target.seed=-2")
    with pytest.raises(SceneError, match=r'target\.seed is only used when target\.kind is '):
        run_scene(tmp_path, "rso-a-cross", "target.seed=2")


def test_the_size_key_states_the_generators_defaults():
    from sim.defaults import SCHEMA

    text = SCHEMA["target"]["size"].help
    assert f"none: {procedural.DEFAULT_POLYHEDRON_SIZE_M:g})" in text
    assert f"none: {procedural.DEFAULT_ASTEROID_SIZE_M:g})" in text
