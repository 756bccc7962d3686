"""A log written with plain h5py from formats/SPEC.md alone is read and validated by recon."""

from __future__ import annotations

import h5py
import numpy as np

from formats import StrikeLog


def test_log_written_from_the_spec_with_plain_h5py(tmp_path):
    path = tmp_path / "foreign.h5"
    n_shots = 4
    # Sensor at +x, 100 m from the centre, boresight (+z of S) towards -x of I. The attitude
    # S->I is a rotation of -90 deg about y: it sends (0, 0, 1) to (-1, 0, 0).
    q_si = [0.0, -np.sin(np.pi / 4), 0.0, np.cos(np.pi / 4)]  # (x, y, z, w)
    with h5py.File(path, "w") as f:
        f.attrs.update({"format": "recon-strike-log", "format_version": 1,
                        "producer": "another-tool", "producer_version": "9.9",
                        "created_utc": "2026-01-01T00:00:00Z", "scene": "", "seed": -1,
                        "target": "plate", "n_shots": n_shots, "n_strikes": 3})
        s = f.create_group("sensor")
        s.attrs.update({"pattern": "single", "field_of_view": np.zeros(4), "range_min": 0.5,
                        "range_max": 2000.0, "reports_angles": False})
        s.create_dataset("beam_directions", data=[[0.0, 0.0, 1.0]])
        s.create_group("errors").attrs.update(
            {k: 0.0 for k in ("range_sigma3", "azimuth_sigma3", "elevation_sigma3",
                              "position_sigma3", "pulse_dilation_alpha",
                              "pulse_dilation_half_angle", "pulse_dilation_subrays")})
        g = f.create_group("shots")
        g["time"] = np.arange(n_shots, dtype=float)
        g["sensor_position"] = np.tile([100.0, 0, 0], (n_shots, 1))
        g["sensor_attitude"] = np.tile(q_si, (n_shots, 1))
        g["target_attitude"] = np.tile([0.0, 0, 0, 1], (n_shots, 1))
        k = f.create_group("strikes")
        k["shot"] = np.array([0, 1, 3], dtype=np.uint32)
        k["beam"] = np.zeros(3, dtype=np.uint32)
        k["range"] = np.array([90.0, 90.0, 95.0])
    with StrikeLog(path) as log:
        log.validate()
        assert log.attrs["producer"] == "another-tool"
        chunk = next(log.iter_chunks())
        # The documented placement: p_B = R_BI^T (r_I + R_SI (rho d_S)).
        from scipy.spatial.transform import Rotation

        i = chunk.shot - chunk.shot_offset
        p_i = chunk.shots.sensor_position[i] + Rotation.from_quat(
            chunk.shots.sensor_attitude[i]).apply(chunk.range[:, None] * chunk.direction)
        np.testing.assert_allclose(p_i, [[10.0, 0, 0], [10.0, 0, 0], [5.0, 0, 0]], atol=1e-12)
