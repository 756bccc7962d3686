"""A scene whose geometry comes from SPICE kernels (``[orbit] kind = "spice"``): simulating from
the kernels recon writes of a log reproduces that log's strikes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from formats import StrikeLog, spice
from formats.errors import SceneError
from recon import api
from recon.registration.trajectory import export_kernel
from sim import load_scene

START = "2019-02-13T01:00:00"
# A cross LRF sweeping the spinning asteroid with a slew: 120 shots, 600 pulses.
ORIGINAL = ["time.duration=1200", "time.step=10", "slew.amplitude_deg=4", "slew.period=90"]
KERNELS = ["traj.bsp", "traj.tf", "att.bc", "att.tsc"]


@pytest.fixture(scope="module")
def original(tmp_path_factory):
    """An error-free log and the kernels of its poses (recorded = true)."""
    folder = tmp_path_factory.mktemp("spice-scene")
    log = api.simulate("asteroid-cross", folder / "original.h5", seed=1, overrides=ORIGINAL).path
    epoch = spice.utc_to_et(START)
    export_kernel(log, folder / "traj.bsp", epoch_et=epoch)
    export_kernel(log, folder / "att.bc", epoch_et=epoch)
    return folder, log, epoch


def _spice_overrides(folder, *, sensor_frame: bool = True) -> list[str]:
    kernels = ", ".join(f'"{folder / name}"' for name in KERNELS)
    overrides = ["time.duration=1200", "time.step=10", "orbit.kind=spice",
                 f"orbit.kernels=[{kernels}]", "orbit.observer=RECON_SENSOR",
                 "orbit.target=RECON_TARGET", "orbit.target_frame=RECON_TARGET_FIXED",
                 f"orbit.start_utc={START}"]
    return overrides + (["orbit.sensor_frame=RECON_SENSOR_FRAME"] if sensor_frame else [])


def _strikes(log):
    with StrikeLog(log) as strike_log:
        shot, beam, rng = strike_log.strikes()
        return shot, beam, rng, strike_log.shots(), strike_log.epoch_et


def test_kernels_written_by_recon_reproduce_the_strikes(original, tmp_path):
    folder, log, epoch = original
    again = api.simulate("asteroid-cross", tmp_path / "again.h5", seed=1,
                         overrides=_spice_overrides(folder)).path
    shot0, beam0, range0, shots0, epoch0 = _strikes(log)
    shot1, beam1, range1, shots1, epoch1 = _strikes(again)
    assert epoch0 is None and epoch1 == pytest.approx(epoch, abs=1e-6)
    assert len(shot0) > 300   # the cross strikes the asteroid most of the time
    np.testing.assert_array_equal(shot1, shot0)
    np.testing.assert_array_equal(beam1, beam0)
    assert np.abs(range1 - range0).max() < 1e-3
    np.testing.assert_allclose(shots1.sensor_position, shots0.sensor_position, atol=1e-6)
    turn = Rotation.from_quat(shots1.target_attitude) * Rotation.from_quat(
        shots0.target_attitude).inv()
    assert turn.magnitude().max() < 1e-9
    # the kernels are unloaded once the run is over
    with spice.LOCK:
        import spiceypy

        assert spiceypy.ktotal("ALL") == 1   # the leapseconds kernel alone


def test_without_a_sensor_frame_the_boresight_points_at_the_target(original, tmp_path):
    folder, _, _ = original
    log = api.simulate("asteroid-cross", tmp_path / "nadir.h5", seed=1, overrides=[
        *_spice_overrides(folder, sensor_frame=False), "slew.amplitude_deg=0"]).path
    _, _, _, shots, _ = _strikes(log)
    boresight = Rotation.from_quat(shots.sensor_attitude).apply([0.0, 0.0, 1.0])
    toward = -shots.sensor_position / np.linalg.norm(shots.sensor_position, axis=1,
                                                      keepdims=True)
    np.testing.assert_allclose(boresight, toward, atol=1e-12)


def test_scene_errors_name_the_key(original):
    folder, _, _ = original
    base = _spice_overrides(folder)
    with pytest.raises(SceneError, match=r"orbit.start_utc, orbit.start_et"):
        load_scene("asteroid-cross", [o for o in base if "start_utc" not in o])
    with pytest.raises(SceneError, match=r"orbit.radius is only used when orbit.kind is "
                                         r"\"kepler\""):
        load_scene("asteroid-cross", [*base, "orbit.radius=900"])
    with pytest.raises(SceneError, match=r"orbit\.target_frame is needed"):
        load_scene("asteroid-cross", [o for o in base if "target_frame" not in o])
    with pytest.raises(SceneError, match=r"orbit\.start_utc 'yesterday'"):
        load_scene("asteroid-cross", [*base[:-2], "orbit.start_utc=yesterday"])
    with pytest.raises(SceneError, match=r"time\.rotations needs the spin model"):
        load_scene("asteroid-cross", [o for o in base if "duration" not in o])
    with pytest.raises(SceneError, match=r"errors\.spin_period_error needs the spin model"):
        load_scene("asteroid-cross", [*base, "errors.spin_period_error=2"])
    with pytest.raises(SceneError, match="array of 1 to"):
        load_scene("asteroid-cross", [*base, "orbit.kernels=[]"])
    missing = [o if "kernels" not in o else f'orbit.kernels=["{folder}/none.bsp"]' for o in base]
    with pytest.raises(SceneError, match=r"orbit\.kernels .*none\.bsp: no such file"):
        api.simulate("asteroid-cross", folder / "x.h5", overrides=missing)
    wrong = [o if "observer" not in o else "orbit.observer=NOBODY" for o in base]
    with pytest.raises(SceneError, match="NOBODY"):
        api.simulate("asteroid-cross", folder / "x.h5", overrides=wrong)
    late = [o if "start_utc" not in o else "orbit.start_utc=2019-02-14T01:00:00" for o in base]
    with pytest.raises(SceneError, match=r"SPKINSUFFDATA|CKINSUFFDATA|insufficient"):
        api.simulate("asteroid-cross", folder / "x.h5", overrides=late)
    assert not (folder / "x.h5").exists()


def test_a_scene_file_names_kernels_beside_it_and_takes_a_toml_date(original):
    folder, _, epoch = original
    scene_file = folder / "scene.toml"
    scene_file.write_text("""# The cross LRF flown on recon's own kernels.
[sensor]
pattern = "cross"
[time]
step = 10
duration = 1200
[orbit]
kind = "spice"
kernels = ["traj.bsp", "traj.tf", "att.bc", "att.tsc"]
observer = "RECON_SENSOR"
target = "-998"
target_frame = "RECON_TARGET_FIXED"
sensor_frame = "RECON_SENSOR_FRAME"
start_utc = 2019-02-13T01:00:00Z
""")
    scene = load_scene(scene_file)
    assert scene["orbit.kernels"] == [str(folder / k) for k in KERNELS]
    assert scene.epoch_et == pytest.approx(epoch, abs=1e-6)
    assert scene.mu is None and scene.orbit_period is None
    assert "spin_period" not in scene.values["target"]
    # the resolved scene (stored in logs) reads back as the same scene
    again = folder / "again.toml"
    again.write_text(scene.to_toml())
    assert load_scene(again).values == scene.values
