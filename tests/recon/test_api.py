"""recon.api: the verbs take recon's types, plain arrays and paths, and name a bad argument."""

from __future__ import annotations

import numpy as np
import pytest

from formats.errors import InputError, ReconError
from formats.geometry import Cloud, Mesh
from recon import api
from tests.recon.conftest import SPHERE_RADIUS, sphere_mesh, sphere_points


def _sphere_cloud(n=2000):
    points, view, _ = sphere_points(n)
    return Cloud(points, {"view_x": view[:, 0], "view_y": view[:, 1], "view_z": view[:, 2]})


def test_reconstruct_and_score_take_arrays_and_pairs():
    points, _, _ = sphere_points(2000)
    surface = api.reconstruct(points, method="convex-hull", isolate=False)
    assert isinstance(surface, Mesh) and surface.method == "convex-hull"
    report = api.score(surface, truth=tuple(sphere_mesh(4)), edges=False,
                       n_truth_samples=5000, coverage_points=5000)
    assert report.chamfer_m < 0.05 * SPHERE_RADIUS   # a hull of 2,000 points on the sphere
    # Every surface comes with its truth-free predicted Chamfer band, which holds the truth's.
    estimate = surface.info["estimate"]
    assert estimate["source"] == "in-sample"
    assert estimate["chamfer_low_m"] <= report.chamfer_m <= estimate["chamfer_high_m"]


def test_auto_records_its_choice():
    surface = api.reconstruct(_sphere_cloud(), method="auto", auto_methods=["convex-hull"])
    assert surface.method == "convex-hull"
    assert surface.info["auto"]["method"] == "convex-hull"
    assert surface.info["estimate"]["source"] == "held-out"
    assert surface.info["auto"]["candidates"][0]["chosen"]


def test_auto_refuses_params():
    with pytest.raises(ReconError, match="params cannot be combined with method='auto'"):
        api.reconstruct(_sphere_cloud(), method="auto", params={"depth": 6})


@pytest.mark.parametrize(("value", "match"), [
    ("not geometry", r"cloud must be a Cloud or an \(n, 3\) array of points, got str"),
    (np.zeros((4, 2)), r"cloud must be a Cloud or an \(n, 3\) array"),
])
def test_cloud_of_names_the_argument(value, match):
    with pytest.raises(InputError, match=match):
        Cloud.of(value, "cloud")


def test_mesh_of_names_the_argument():
    with pytest.raises(InputError, match="truth must be a Mesh, a \\(vertices, faces\\) pair"):
        Mesh.of(42, "truth")
    with pytest.raises(InputError, match="truth: mesh faces must be integers"):
        Mesh.of((np.zeros((3, 3)), np.zeros((1, 3))), "truth")
