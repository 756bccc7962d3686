"""``recon trajectory``: the recorded sensor poses as text, in the frame of the ingested cloud."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cli.main import main
from formats.errors import ParameterError
from recon import api
from recon.registration.trajectory import COLUMNS, export_trajectory


@pytest.fixture
def spinning_log(tmp_path):
    """300 shots of the cross LRF around the spinning asteroid (the target turns 70 deg)."""
    return api.simulate("asteroid-cross", tmp_path / "log.h5", seed=0,
                        overrides=["time.duration=3000"]).path


def test_body_frame_trajectory_matches_the_ingested_view_points(spinning_log, tmp_path):
    summary = export_trajectory(spinning_log, tmp_path / "traj.txt", chunk_rows=7)
    assert summary["n_shots"] == 300
    header = [ln for ln in (tmp_path / "traj.txt").read_text().splitlines() if ln[0] == "#"]
    assert "# frame: body" in header and header[-1] == "# " + " ".join(COLUMNS)
    table = np.loadtxt(tmp_path / "traj.txt")
    cloud = api.ingest(spinning_log)
    shot = cloud.attributes["shot"].astype(int)
    np.testing.assert_allclose(table[shot, 1:4], cloud.view_points, atol=1e-9)
    np.testing.assert_array_equal(table[shot, 0], cloud.attributes["time"])
    # beam 0 of the cross fires along +z of S: the quaternion turns it toward the point seen
    beam0 = cloud.attributes["beam"] == 0
    assert beam0.sum() > 100
    rotation = Rotation.from_quat(table[shot[beam0], 7:11])
    toward = cloud.points[beam0] - cloud.view_points[beam0]
    toward /= np.linalg.norm(toward, axis=1, keepdims=True)
    np.testing.assert_allclose(rotation.apply([0.0, 0.0, 1.0]), toward, atol=1e-9)
    # roll, pitch, yaw state the same rotation
    ypr = Rotation.from_euler("ZYX", table[:, [6, 5, 4]])
    assert np.allclose((ypr.inv() * Rotation.from_quat(table[:, 7:11])).magnitude(), 0,
                       atol=1e-9)


def test_inertial_csv_is_as_recorded(spinning_log, tmp_path):
    from formats import StrikeLog

    assert main(["trajectory", str(spinning_log), "-o", str(tmp_path / "t.csv"),
                 "--frame", "inertial"]) == 0
    lines = (tmp_path / "t.csv").read_text().splitlines()
    assert lines[0] == ",".join(COLUMNS)
    table = np.loadtxt(tmp_path / "t.csv", delimiter=",", skiprows=1)
    with StrikeLog(spinning_log) as log:
        shots = log.shots()
    np.testing.assert_allclose(table[:, 1:4], shots.sensor_position)
    same = Rotation.from_quat(table[:, 7:11]).inv() * Rotation.from_quat(shots.sensor_attitude)
    assert np.allclose(same.magnitude(), 0, atol=1e-9)


def test_bad_trajectory_requests(spinning_log, tmp_path, capsys):
    with pytest.raises(ParameterError, match=r"t\.las: a trajectory is written as \.txt or"):
        export_trajectory(spinning_log, tmp_path / "t.las")
    assert main(["trajectory", str(tmp_path / "missing.h5"), "-o", str(tmp_path / "t.txt")]) == 1
    assert capsys.readouterr().err.count("\n") == 1
    assert not (tmp_path / "t.txt").exists()
