"""Self-calibration on a thin plate seen from both sides (``recon.registration.refine``)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

import sim
from recon.registration import refine as refine_module
from recon.registration.ingest import ingest
from recon.registration.refine import refine
from tests.conftest import registration_error

MISALIGNMENT_DEG = np.array([0.03, 0.04, 0.0])
BIAS_M = 1.5     # inertial, along x_I: wider than the fine fit's neighbourhoods on the plate
# A 6 x 6 m plate 5 cm thick in the body x-z plane, spinning about z: each face in turn faces the
# sensor. A 9 x 9 beam grid over 2 deg at 250 m covers it; 3 orbits of the plate's spin.
PLATE = ("target.kind=\"mesh\"", "target.spin_period=3000", "orbit.radius=250", "orbit.mu=1.99",
         "sensor.pattern=\"grid\"", "sensor.field_of_view_deg=[2.0, 2.0]",
         "sensor.resolution=[9, 9]", "time.step=30", "time.duration=9000",
         "errors.range_sigma3=0.3")
POINTS = 5000


def _plate_log(tmp_path, name, *overrides):
    mesh = tmp_path / "plate.ply"
    if not mesh.exists():
        trimesh.creation.box(extents=(6.0, 0.05, 6.0)).export(mesh)
    path = tmp_path / f"plate-{name}.h5"
    sim.simulate(sim.load_scene("rso-a-lrf", [*PLATE, f"target.path=\"{mesh}\"", *overrides]),
                 path, seed=0, progress=False)
    return path


@pytest.fixture(scope="module")
def plate_logs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("plate")
    return {"clean": _plate_log(tmp, "clean"),
            "misaligned": _plate_log(tmp, "misaligned",
                                     "errors.boresight_misalignment_deg=[{}, {}, {}]"
                                     .format(*MISALIGNMENT_DEG)),
            "biased": _plate_log(tmp, "biased",
                                 f"errors.position_bias_inertial=[{BIAS_M}, 0.0, 0.0]")}


def test_a_misaligned_thin_plate_seen_from_both_sides_is_corrected(plate_logs):
    """Held-out strikes confirm the correction; mean point error 0.24 -> 0.10 m. The
    cross-track part trades off against a position error along the orbit normal, so the
    along-track part is the one held to the truth."""
    posed = plate_logs["misaligned"]
    result = refine(posed, max_points=POINTS)
    assert result.check_z > 3.0
    along = np.degrees(result.correction.misalignment[0, 1])
    assert 0.5 * MISALIGNMENT_DEG[1] < along <= 1.25 * MISALIGNMENT_DEG[1]
    assert registration_error(posed, result.correction) < 0.5 * registration_error(posed)


def test_a_position_bias_wider_than_the_fine_neighbourhood_is_found_by_the_coarse_stage(
        plate_logs):
    """A 1.5 m inertial bias, about twice the fine fit's neighbourhood: the fine fit from the
    recorded poses stops a metre short; the coarse stage's start lands on it."""
    posed = plate_logs["biased"]
    problem = refine_module._problem(posed, None, False, POINTS, 0)
    points = refine_module._register(problem.fit, problem.fit.shots)[0]
    neighbourhood = np.median(cKDTree(points).query(points, k=[refine_module.NEIGHBOURS])[0])
    assert neighbourhood < 0.75 * BIAS_M
    fine_only, _, _ = refine_module._best(problem, refine_module._fine(problem, problem.zero,
                                                                      None)[0])
    assert abs(fine_only.position[0, 0] - BIAS_M) > 0.5
    start = refine_module._coarse_start(problem)
    assert np.linalg.norm(start.position[0, :2] - [BIAS_M, 0.0]) < 0.25
    result = refine(posed, max_points=POINTS)
    assert result.correction.position[0, 0] == pytest.approx(BIAS_M, abs=0.1)
    assert registration_error(posed, result.correction) < 0.2 * registration_error(posed)


def test_a_plate_without_pose_error_is_left_byte_identical(plate_logs):
    clean = plate_logs["clean"]
    result = refine(clean, max_points=POINTS)
    assert result.correction.is_zero()
    assert np.array_equal(ingest(clean, correction=result.correction).points,
                          ingest(clean).points)
