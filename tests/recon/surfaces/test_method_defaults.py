"""Defaults that follow the cloud: ``plane``'s cell and ``ball-pivoting-meshlab``'s radius are one
(or 1.5) spacing on clean clouds and grow with the noise where it is comparable to the spacing
(``recon.surfaces.methods._backends.above_noise``); explicit values are multiples of the spacing.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from recon.surfaces.methods import MethodInput, bind, plane
from recon.surfaces.methods import ball_pivoting_meshlab as bpm
from recon.surfaces.methods._backends import above_noise
from recon.surfaces.prepare import prepare
from tests.recon.conftest import sphere_points


def _cloud(spacing: float, noise: float) -> MethodInput:
    points = np.zeros((4, 3))
    return MethodInput(points=points, normals=points, spacing=spacing, noise=noise)


@pytest.mark.parametrize("spacing, noise, expected", [
    (0.1, 0.001, 0.1),      # clean: one spacing
    (0.1, 0.04, 0.1),       # 2 x noise below the spacing: still one spacing
    (0.05, 0.035, 0.07),    # RSO-A's LRF cloud: 2 x noise
    (0.92, 0.73, 1.46),     # the asteroid LIDAR cloud
])
def test_plane_cell_is_a_spacing_or_twice_the_noise(spacing, noise, expected):
    cloud = _cloud(spacing, noise)
    assert plane.cell_size(cloud, None) == pytest.approx(expected)
    assert plane.cell_size(cloud, 0.5) == pytest.approx(0.5 * spacing)  # explicit: spacings
    assert bind("plane").params["cell"] is None


@pytest.mark.parametrize("spacing, noise, expected", [
    (0.1, 0.001, 0.15),     # clean: 1.5 spacings
    (0.05, 0.035, 0.28),    # RSO-A's LRF cloud: 8 x noise
    (0.92, 0.73, 5.84),     # the asteroid LIDAR cloud
])
def test_meshlab_ball_is_one_and_a_half_spacings_or_eight_noises(spacing, noise, expected):
    cloud = _cloud(spacing, noise)
    assert bpm.ball_radius(cloud, None) == pytest.approx(expected)
    assert bpm.ball_radius(cloud, 3.0) == pytest.approx(3.0 * spacing)
    assert above_noise(cloud, 1.5, 8.0) == pytest.approx(expected)


@pytest.fixture(scope="module")
def noisy_sphere():
    """A sphere whose noise is about the spacing, as on the paper's LRF and LIDAR clouds."""
    points, view, _ = sphere_points(3000, seed=4, noise=0.06)
    cloud = prepare(points, view_points=view)
    assert cloud.noise > 0.5 * cloud.spacing  # the regime the rule is for
    return cloud


def test_plane_default_meshes_at_the_noise_cell(noisy_sphere):
    default = plane.run(noisy_sphere, **bind("plane").params)
    cell = 2.0 * noisy_sphere.noise / noisy_sphere.spacing
    explicit = plane.run(noisy_sphere, **bind("plane", {"cell": cell}).params)
    fine = plane.run(noisy_sphere, **bind("plane", {"cell": 1.0}).params)
    assert np.array_equal(default[1], explicit[1])
    assert len(default[1]) < 0.7 * len(fine[1])  # fewer faces than one cell per spacing
    error = {name: np.median(np.abs(np.linalg.norm(mesh[0], axis=1) - 1.0))
             for name, mesh in (("default", default), ("fine", fine))}
    assert error["default"] <= 1.2 * error["fine"], error  # no less accurate


def test_meshlab_ball_pivoting_default_uses_the_noise_radius(noisy_sphere):
    default = bpm.run(noisy_sphere, **bind("ball-pivoting-meshlab").params)
    factor = 8.0 * noisy_sphere.noise / noisy_sphere.spacing
    explicit = bpm.run(noisy_sphere, **bind("ball-pivoting-meshlab", {"radius": factor}).params)
    assert np.array_equal(default[1], explicit[1])
    clean = dataclasses.replace(noisy_sphere, noise=0.0)
    assert bpm.ball_radius(clean, None) == pytest.approx(1.5 * noisy_sphere.spacing)


def test_every_listed_method_says_what_its_default_costs():
    from recon.surfaces import methods

    assert set(methods.DEFAULT_FIT_S) == set(methods.available())
    listing = methods.listing()
    for name, (lidar, lrf) in methods.DEFAULT_FIT_S.items():
        block = listing.split(f"\n{name} [")[1].split("\n")[1]
        assert block.strip() == f"default fit: {lidar:.2g} s (336k LIDAR), {lrf:.2g} s (77k LRF)"


def test_help_states_the_slowest_measured_default(capsys):
    from cli.main import main
    from recon.surfaces import methods

    with pytest.raises(SystemExit):
        main(["reconstruct", "--help"])
    # argparse wraps the description, and may break a line after a hyphen
    text = " ".join(capsys.readouterr().out.split()).replace("- ", "-")

    slowest = max(methods.DEFAULT_FIT_S, key=lambda name: methods.DEFAULT_FIT_S[name][0])
    lidar = math.ceil(methods.DEFAULT_FIT_S[slowest][0])
    assert f"at most {lidar} s each ({slowest};" in text
    lrf = math.ceil(max(lrf for _, lrf in methods.DEFAULT_FIT_S.values()))
    assert f"LRF cloud in at most {lrf} s" in text
    assert f"Poisson {methods.DEFAULT_FIT_S['poisson'][0]:.2g} s" in text
