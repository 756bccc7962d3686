"""Every method on dense noise-free samplings of a sphere and a box; the registry; parameters.

Tolerance (documented here, checked against exact distances):
- Chamfer distance (mean of the test-to-truth and truth-to-test mean distances) at most
  ``CHAMFER_FRACTION`` = 0.2% of the truth's bounding-box diagonal (0.0069 for the unit sphere,
  0.0046 for the 2 x 1 x 0.5 box), for every method except ``planes`` on the sphere: a sphere is
  no union of planes, and 30 planar facets approximate it to ``PLANES_ON_SPHERE`` = 1% of the
  diagonal (measured 0.58%);
- at least 97% of the truth surface within 1% of the diagonal of the mesh (no large holes;
  ``plane`` rounds the box's edges over its neighbourhood radius: measured 97.6%);
  for ``planes`` on the sphere 80% (the facets' corners stand off the sphere; measured 88%).
- ``ellipsoid`` on the box: a box is no ellipsoid; its best 9-parameter fit is within
  ``ELLIPSOID_ON_BOX`` = 4% of the diagonal (measured 2.7%), 20% of the box within 1% of the
  diagonal (measured 29%).
Measured Chamfer at these sample counts (fraction of the diagonal): 0.003% (apss on the sphere)
to 0.1% (plane on the box).
"""

from __future__ import annotations

import numpy as np
import pytest

from formats.errors import InputError, MethodFailed, ParameterError
from metrics import Mesh, point_mesh_distance, sample_surface
from recon.surfaces import methods
from recon.surfaces.methods._contour import node_keys, surface_nets
from recon.surfaces.prepare import prepare, preprocess
from recon.surfaces.reconstruct import reconstruct
from tests.recon.conftest import (
    BOX_HALF,
    box_distance,
    box_mesh,
    box_points,
    sphere_distance,
    sphere_mesh,
    sphere_points,
)

CHAMFER_FRACTION = 0.002
PLANES_ON_SPHERE = 0.01
ELLIPSOID_ON_BOX, ELLIPSOID_RECALL = 0.04, 0.2
RECALL_FRACTION, MIN_RECALL, PLANES_RECALL = 0.01, 0.97, 0.8
N_POINTS = 6000


@pytest.fixture(scope="module")
def shapes():
    sphere, sphere_view, _ = sphere_points(N_POINTS)
    box, box_view, _ = box_points(N_POINTS)
    truth_sphere, _ = sample_surface(Mesh(*sphere_mesh(6)), 20000, seed=3)
    truth_box, _ = sample_surface(Mesh(*box_mesh()), 20000, seed=3)
    return {
        "sphere": (prepare(sphere, view_points=sphere_view), sphere_distance, truth_sphere,
                   2 * np.sqrt(3.0)),
        "box": (prepare(box, view_points=box_view), box_distance, truth_box,
                2 * np.linalg.norm(BOX_HALF)),
    }


@pytest.mark.parametrize("shape", ["sphere", "box"])
@pytest.mark.parametrize("name", methods.available())
def test_method_reconstructs_noise_free_shape(shapes, shape, name):
    cloud, distance, truth_samples, diagonal = shapes[shape]
    surface = reconstruct(cloud, method=name)
    samples, _ = sample_surface(Mesh(surface.vertices, surface.faces), 20000, seed=1)
    accuracy = distance(samples).mean()
    completeness = point_mesh_distance(truth_samples, (surface.vertices, surface.faces))[0]
    chamfer = 0.5 * (accuracy + completeness.mean())
    tolerance, min_recall = {("planes", "sphere"): (PLANES_ON_SPHERE, PLANES_RECALL),
                             ("ellipsoid", "box"): (ELLIPSOID_ON_BOX, ELLIPSOID_RECALL)}.get(
        (name, shape), (CHAMFER_FRACTION, MIN_RECALL))
    assert chamfer <= tolerance * diagonal, f"{name} on the {shape}: Chamfer {chamfer:.3g}"
    recall = np.mean(completeness < RECALL_FRACTION * diagonal)
    assert recall >= min_recall, f"{name}: recall {recall:.3f}"


def test_planes_closes_a_box_into_its_six_faces(shapes):
    cloud = shapes["box"][0]
    surface = reconstruct(cloud, method="planes")
    assert surface.info["watertight"]
    assert len(surface.faces) <= 40
    np.testing.assert_allclose(np.abs(surface.vertices).max(axis=0), BOX_HALF, atol=1e-3)
    opened = reconstruct(cloud, method="planes", params={"closure": "open"})
    assert not opened.info["watertight"]


def test_planes_leaves_a_non_convex_target_open():
    # An L-shaped prism is not convex: "auto" must not close it into its convex hull.
    a, va, _ = box_points(4000, half=(1.0, 0.25, 0.25), seed=1)
    b, vb, _ = box_points(4000, half=(0.25, 1.0, 0.25), seed=2)
    a += [0.75, 0, 0]
    va += [0.75, 0, 0]
    b += [0, 0.75, 0]
    vb += [0, 0.75, 0]
    keep_a = ~((a[:, 0] < 0.25 + 1e-9) & (np.abs(a[:, 1]) < 0.25 - 1e-9))
    keep_b = ~((b[:, 1] < 0.25 + 1e-9) & (np.abs(b[:, 0]) < 0.25 - 1e-9))
    points = np.concatenate([a[keep_a], b[keep_b]])
    view = np.concatenate([va[keep_a], vb[keep_b]])
    surface = reconstruct(prepare(points, view_points=view), method="planes")
    assert not surface.info["watertight"]
    with pytest.raises(MethodFailed, match="do not bound a convex polyhedron"):
        reconstruct(prepare(points, view_points=view), method="planes",
                    params={"closure": "closed"})


def test_surface_nets_of_a_sphere_field_is_closed_and_on_the_sphere():
    cell, shape = 0.1, (30, 30, 30)
    index = np.stack(np.meshgrid(*[np.arange(1, 29)] * 3, indexing="ij"), -1).reshape(-1, 3)
    origin = np.full(3, -1.5)
    x = origin + cell * index
    values = np.linalg.norm(x, axis=1) - 1.0
    keys = node_keys(index, shape)
    order = np.argsort(keys)
    vertices, faces = surface_nets(keys[order], values[order], shape, origin, cell)
    from recon.surfaces.isolation import watertight

    assert watertight(faces)
    assert np.abs(np.linalg.norm(vertices, axis=1) - 1).max() < 0.02
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
    assert volume == pytest.approx(4 / 3 * np.pi, rel=0.02)  # positive: faces point outward


def test_every_method_is_deterministic(shapes):
    cloud = shapes["box"][0]
    for name in ("planes", "plane", "poisson"):
        one, two = reconstruct(cloud, method=name), reconstruct(cloud, method=name)
        assert one.vertices.tobytes() == two.vertices.tobytes()
        assert one.faces.tobytes() == two.faces.tobytes()


def test_registry_lists_methods_and_hides_test_ones():
    import recon_fake_methods  # noqa: F401  (registers the hidden test methods)

    listed = methods.available()
    assert {"plane", "planes", "poisson", "screened-poisson", "ball-pivoting",
            "ball-pivoting-meshlab", "alpha-shape", "rimls", "apss", "convex-hull", "ellipsoid",
            "delaunay-balls"} <= set(listed)
    assert not any(name.startswith("test-") for name in listed)
    assert "test-abort" in methods.available(include_hidden=True)
    with pytest.raises(ParameterError, match=r"unknown method 'marching' .*poisson"):
        methods.get("marching")


def test_parameters_parse_check_and_default():
    poisson = methods.get("poisson")
    assert poisson.parse(["depth=9", "linear_fit=true"]) == {"depth": 9, "linear_fit": True}
    assert methods.get("ball-pivoting").parse(["radii=1,2"]) == {"radii": (1.0, 2.0)}
    assert methods.get("alpha-shape").parse(["alpha=auto"]) == {"alpha": None}
    assert poisson.resolve({"depth": 6})["depth"] == 6
    assert poisson.variants()[0] == poisson.resolve()
    assert len({str(v) for v in poisson.variants()}) == len(poisson.variants())


@pytest.mark.parametrize("method, pairs, match", [
    ("poisson", ["depth"], "^params must be key=value"),
    ("poisson", ["colour=red"], "method 'poisson' has no parameter 'colour'"),
    ("poisson", ["depth=deep"], r"parameter depth='deep' is not an integer"),
    ("poisson", ["depth=0"], "depth must be from 1 to 14, got 0"),
    ("poisson", ["depth=100"], "depth must be from 1 to 14, got 100"),
    ("screened-poisson", ["depth=15"], "depth must be from 1 to 14, got 15"),
    ("ball-pivoting", ["radii=1,1e9"], r"radii must be from 0\.01 to 50, got 1000000000\.0"),
    ("ellipsoid", ["iterations=1000000"], "iterations must be from 0 to 1000"),
    ("poisson", ["scale=nan"], "scale must be from 1 to 4, got nan"),
    ("poisson", ["linear_fit=maybe"], "is not a bool"),
    ("planes", ["closure=ajar"], "closure must be one of"),
    ("ball-pivoting", ["radii=1,x"], "comma-separated list of numbers"),
])
def test_bad_parameters_are_named(method, pairs, match):
    with pytest.raises(ParameterError, match=match):
        methods.get(method).parse(pairs)


def test_every_number_parameter_declares_its_bounds():
    """A number parameter without bounds is refused when its method is made, and every
    registered method's numbers carry them (or choices)."""
    with pytest.raises(ValueError, match="parameter 'n' needs a minimum and a maximum"):
        methods.Method(name="unbounded", run=lambda cloud, n: None,
                       params={"n": methods.Param(1, int, "n", minimum=0)})
    for name in methods.available(include_hidden=True):
        for key, param in methods.get(name).params.items():
            assert param.bounded and (param.type not in (int, float) or param.allowed()), \
                (name, key)


def test_resolve_rejects_unknown_names():
    with pytest.raises(ParameterError, match="has no parameter 'depht'"):
        methods.get("poisson").resolve({"depht": 8})


def test_preprocess_removes_outliers_and_downsamples():
    from formats.geometry import Cloud

    points, view, _ = sphere_points(5000)
    rng = np.random.default_rng(4)
    far = rng.uniform(-3, 3, (50, 3))
    far = far[np.linalg.norm(far, axis=1) > 1.5]
    cloud = Cloud(np.concatenate([points, far]),
                       {"view_x": np.r_[view[:, 0], far[:, 0]],
                        "view_y": np.r_[view[:, 1], far[:, 1]],
                        "view_z": np.r_[view[:, 2], far[:, 2]]})
    cleaned = preprocess(cloud, remove_outliers=True)
    assert np.all(np.abs(np.linalg.norm(cleaned.points, axis=1) - 1) < 0.3)
    assert len(cleaned) > 4800
    coarse = preprocess(cloud, voxel=0.2)
    assert len(coarse) < 1500
    assert coarse.view_points is not None and coarse.view_points.shape == coarse.points.shape


@pytest.mark.parametrize("points, match", [
    (np.zeros((10, 3)), "need at least 16 points"),
    (np.zeros((40, 2)), r"points must be \(n, 3\)"),
    (np.zeros((40, 3)), "all points coincide"),
])
def test_prepare_rejects_unusable_clouds(points, match):
    with pytest.raises(InputError, match=match):
        prepare(points)


def test_voxel_must_be_positive():
    from formats.geometry import Cloud

    with pytest.raises(InputError, match="voxel must be a positive size"):
        preprocess(Cloud(np.zeros((20, 3))), voxel=0.0)


class _FakeMeshSet:
    """The two calls ``meshlab_arrays`` makes of a pymeshlab MeshSet."""

    def __init__(self, vertices, faces):
        self.vertices, self.faces = np.asarray(vertices, float), np.asarray(faces)

    def current_mesh(self):
        return self

    def face_number(self):
        return len(self.faces)

    def vertex_matrix(self):
        return self.vertices

    def face_matrix(self):
        return self.faces


def test_nan_vertices_of_mls_meshes_are_dropped_with_their_faces():
    from recon.surfaces.methods._backends import meshlab_arrays

    vertices = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan, 0, 0], [1, 1, 0]]
    faces = [[0, 1, 2], [1, 4, 2], [0, 3, 1]]
    v, f = meshlab_arrays(_FakeMeshSet(vertices, faces), method="rimls", drop_nan=True)
    assert f.tolist() == [[0, 1, 2], [1, 4, 2]] and np.all(np.isfinite(v))
    with pytest.raises(MethodFailed, match="rimls: 60% of the vertices are NaN"):
        meshlab_arrays(_FakeMeshSet([[np.nan] * 3] * 3 + [[0, 0, 0], [1, 0, 0]],
                                    [[0, 1, 2], [2, 3, 4]]), method="rimls", drop_nan=True)


def test_a_run_is_resolved_once_and_travels_as_a_value():
    import pickle

    run = methods.bind("poisson", {"depth": 6})
    assert run.params == methods.get("poisson").resolve({"depth": 6})
    assert run.label == "poisson depth=6" and run.kind == "smooth"
    assert run.module == "recon.surfaces.methods.poisson"
    assert pickle.loads(pickle.dumps(run)) == run
    assert methods.bind(run) is run
    assert run.key == methods.run_key("poisson", run.params)
    with pytest.raises(ParameterError, match="already bound"):
        methods.bind(run, {"depth": 7})
    with pytest.raises(ParameterError, match="has no parameter 'depht'"):
        methods.bind("poisson", {"depht": 6})


def test_a_thread_asking_for_a_method_while_another_loads_them_waits_for_the_whole_registry(
        monkeypatch):
    import threading
    import time

    from recon.surfaces.methods import Method

    # A fresh registry whose one built-in module takes a while to import: the second thread
    # arrives while the first is importing it.
    monkeypatch.setattr(methods, "_REGISTRY", {})
    monkeypatch.setattr(methods, "_LOADED", False)
    monkeypatch.setattr(methods, "BUILTIN_MODULES", ("slow_builtin",))
    started = threading.Event()

    def slow_import(name):
        started.set()
        time.sleep(0.3)
        methods.register(Method(name="slow", run=lambda cloud: None, params={}))

    monkeypatch.setattr(methods.importlib, "import_module", slow_import)
    seen = {}
    first = threading.Thread(target=lambda: seen.setdefault("first", methods.available()))
    first.start()
    started.wait(5)
    seen["second"] = methods.available()
    first.join(5)
    assert seen["second"] == ["slow"] and seen["first"] == ["slow"]
