"""``recon trajectory LOG -o X.bsp | X.bc``: the recorded poses as SPICE kernels, read back with
NAIF's toolkit (spiceypy's spkezr, ckgp, pxform) at every shot time."""

from __future__ import annotations

import numpy as np
import pytest
import spiceypy
from scipy.spatial.transform import Rotation

from cli.main import main
from formats import StrikeLog, spice
from formats.errors import InputError, ParameterError
from recon import api
from recon.registration.trajectory import export_kernel

# Tolerances of the round trip (the kernels must return the log's poses).
MM = 1e-3
MICRORADIAN = 1e-6


@pytest.fixture(scope="module")
def noisy_log(tmp_path_factory):
    """A slewing LRF whose recorded poses carry a random walk and a drift (not a smooth law)."""
    path = tmp_path_factory.mktemp("kernels") / "log.h5"
    return api.simulate("asteroid-lrf-slew", path, seed=3, overrides=[
        "time.duration=2000", "time.step=20", "errors.attitude_walk_arcsec=30",
        "errors.position_drift=2", "errors.spin_period_error=5"]).path


def _recorded(log):
    with StrikeLog(log) as strike_log:
        return strike_log.shots()


def _angle(matrices, quaternions) -> np.ndarray:
    return (Rotation.from_matrix(matrices) * Rotation.from_quat(quaternions).inv()).magnitude()


@pytest.mark.parametrize("segment_states", [spice.SEGMENT_STATES, 7])
def test_spk_and_ck_return_the_recorded_poses_at_every_shot(noisy_log, tmp_path, monkeypatch,
                                                             segment_states):
    monkeypatch.setattr(spice, "SEGMENT_STATES", segment_states)
    epoch = spice.utc_to_et("2019-02-13T01:00:00")
    spk = export_kernel(noisy_log, tmp_path / "traj.bsp", epoch_et=epoch)
    ck = export_kernel(noisy_log, tmp_path / "att.bc", epoch_et=epoch)
    assert sorted(spk["written"]) == sorted(str(tmp_path / n) for n in ("traj.bsp", "traj.tf"))
    assert {n for n in ck["written"]} == {str(tmp_path / n) for n in
                                          ("att.bc", "att.tf", "att.tsc")}
    shots = _recorded(noisy_log)
    et = epoch + shots.time
    kernels = [tmp_path / n for n in ("traj.bsp", "att.bc", "att.tf", "att.tsc")]
    with spice.loaded(kernels):
        states = np.array([spiceypy.spkezr("RECON_SENSOR", e, "J2000", "NONE",
                                           "RECON_TARGET")[0] for e in et])
        position_error = np.linalg.norm(states[:, :3] * 1000 - shots.sensor_position, axis=1)
        assert position_error.max() < MM
        sensor = np.array([spiceypy.pxform("RECON_SENSOR_FRAME", "J2000", e) for e in et])
        target = np.array([spiceypy.pxform("RECON_TARGET_FIXED", "J2000", e) for e in et])
        assert _angle(sensor, shots.sensor_attitude).max() < MICRORADIAN
        assert _angle(target, shots.target_attitude).max() < MICRORADIAN
        # ckgp on the CK's own clock: the C-matrix sends J2000 vectors to the sensor frame
        for row in (0, len(et) // 2, len(et) - 1):
            ticks = spiceypy.sce2c(spice.CLOCK_ID, et[row])
            cmat, _ = spiceypy.ckgp(spice.SENSOR_CK_ID, ticks, 0, "J2000")
            assert _angle(cmat.T[None], shots.sensor_attitude[row:row + 1])[0] < MICRORADIAN
        # the CK's angular rates: the target spins about its z axis at the recorded period
        # (the true 15,480 s plus the 5 s knowledge error)
        middle = et[len(et) // 2]
        state = spiceypy.sxform("RECON_TARGET_FIXED", "J2000", middle)
        rotation, derivative = state[:3, :3], state[3:, :3]
        skew = derivative @ rotation.T
        omega = np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
        np.testing.assert_allclose(omega, rotation[:, 2] * 2 * np.pi / 15485.0, rtol=1e-3,
                                   atol=1e-9)
        # between shots the SPK interpolates: a point halfway lies between its neighbours
        half = 0.5 * (et[:-1] + et[1:])
        between = spice.positions("RECON_SENSOR", "RECON_TARGET", "J2000", half)
        chord = 0.5 * (shots.sensor_position[:-1] + shots.sensor_position[1:])
        assert np.abs(between - chord).max() < 5.0


def test_a_log_epoch_must_be_finite(noisy_log, tmp_path):
    import shutil

    import h5py


    bad = tmp_path / "bad.h5"
    shutil.copyfile(noisy_log, bad)
    with h5py.File(bad, "r+") as f:
        f.attrs["epoch_et"] = np.float64(np.inf)
    with pytest.raises(InputError, match="'epoch_et' must be finite"):
        StrikeLog(bad)


def test_log_epoch_is_the_default_and_kernels_match_the_text_trajectory(noisy_log, tmp_path):
    summary = export_kernel(noisy_log, tmp_path / "traj.bsp")
    assert summary["epoch_et"] == 0.0   # no SPICE-driven scene: the J2000 epoch
    shots = _recorded(noisy_log)
    with spice.loaded([tmp_path / "traj.bsp", tmp_path / "traj.tf"]):
        p = spice.positions("RECON_SENSOR", "RECON_TARGET", "J2000", shots.time)
    assert np.abs(p - shots.sensor_position).max() < MM


def test_cli_writes_kernels_and_refuses_what_does_not_fit(noisy_log, tmp_path, capsys):
    out = tmp_path / "att.bc"
    assert main(["trajectory", str(noisy_log), "-o", str(out),
                 "--epoch-utc", "2020-10-20T21:50:00"]) == 0
    assert "att.tsc" in capsys.readouterr().out and out.is_file()
    assert main(["trajectory", str(noisy_log), "-o", str(tmp_path / "t.bsp"),
                 "--frame", "body"]) == 1
    assert "--frame is for text trajectories" in capsys.readouterr().err
    assert main(["trajectory", str(noisy_log), "-o", str(tmp_path / "t.bsp"),
                 "--epoch-utc", "not a date"]) == 1
    err = capsys.readouterr().err
    assert "--epoch-utc 'not a date'" in err and len(err.strip().splitlines()) == 1
    assert main(["trajectory", str(noisy_log), "-o", str(tmp_path / "t.txt"),
                 "--epoch-et", "0"]) == 1
    assert "are for kernels" in capsys.readouterr().err
    with pytest.raises(ParameterError, match=r"written as \.bsp or \.bc"):
        export_kernel(noisy_log, tmp_path / "t.spk")
    with pytest.raises(ParameterError, match="finite ET"):
        export_kernel(noisy_log, tmp_path / "t.bsp", epoch_et=float("nan"))
    assert not (tmp_path / "t.bsp").exists()


@pytest.mark.parametrize("blocker", ["directory", "input"])
def test_a_refused_companion_file_leaves_every_old_file(noisy_log, tmp_path, blocker):
    """The frames and clock kernels beside a CK are checked before anything is written: a clock
    kernel path that is a directory, or the log itself, leaves the old kernel and frames."""
    import os

    output = tmp_path / "k.bc"
    output.write_text("old kernel")
    (tmp_path / "k.tf").write_text("old frames")
    clock = tmp_path / "k.tsc"
    if blocker == "directory":
        clock.mkdir()
    else:
        os.link(noisy_log, clock)
    with pytest.raises(ParameterError, match=r"k\.tsc: is "):
        api.trajectory(noisy_log, output)
    assert output.read_text() == "old kernel"
    assert (tmp_path / "k.tf").read_text() == "old frames"
