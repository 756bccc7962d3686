"""Round trips, atomic writes, appends and chunked reads of strike logs."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from formats import SensorInfo, StrikeLog, StrikeLogWriter
from formats.errors import InputError
from formats.strike_log import angles_to_directions, directions_to_angles
from tests.conftest import write_sphere_log


def _sensor(reports_angles=False):
    return SensorInfo("cross", angles_to_directions(np.array([0, .1, -.1, 0, 0]),
                                                    np.array([0, 0, 0, .1, -.1])),
                      range_min=1.0, range_max=5000.0, field_of_view=(-.1, .1, -.1, .1),
                      reports_angles=reports_angles)


def _random_rows(rng, n_shots, n_beams):
    t = np.cumsum(rng.uniform(1, 10, n_shots))
    pos = rng.normal(0, 500, (n_shots, 3))
    sq, tq = Rotation.random(n_shots, rng).as_quat(), Rotation.random(n_shots, rng).as_quat()
    pairs = np.sort(rng.choice(n_shots * n_beams, 3 * n_shots, replace=False))
    shot, beam = np.divmod(pairs, n_beams)
    return t, pos, sq, tq, shot, beam, rng.uniform(1, 1000, len(shot))


def test_round_trip_identical_arrays_and_attributes(tmp_path):
    rng = np.random.default_rng(1)
    t, pos, sq, tq, shot, beam, rho = _random_rows(rng, 500, 5)
    az, el = rng.normal(0, 1e-3, len(shot)), rng.normal(0, 1e-3, len(shot))
    path = tmp_path / "log.h5"
    sensor = _sensor(reports_angles=True)
    with StrikeLogWriter(path, sensor=sensor, target="asteroid", scene="[orbit]\nradius = 750",
                         seed=42) as w:
        for lo in range(0, 500, 128):  # several chunks
            w.write_shots(t[lo:lo + 128], pos[lo:lo + 128], sq[lo:lo + 128], tq[lo:lo + 128])
        w.write_strikes(shot, beam, rho, azimuth_offset=az, elevation_offset=el)
    with StrikeLog(path) as log:
        assert (log.n_shots, log.n_strikes) == (500, len(shot))
        assert log.attrs["scene"] == "[orbit]\nradius = 750"
        assert log.attrs["seed"] == 42 and log.attrs["target"] == "asteroid"
        assert log.sensor.pattern == "cross" and log.sensor.reports_angles
        np.testing.assert_array_equal(log.sensor.beam_directions, sensor.beam_directions)
        s = log.shots()
        for got, want in zip((s.time, s.sensor_position, s.sensor_attitude, s.target_attitude),
                             (t, pos, sq, tq), strict=True):
            np.testing.assert_array_equal(got, want)
        got_shot, got_beam, got_rho = log.strikes()
        np.testing.assert_array_equal(got_shot, shot)
        np.testing.assert_array_equal(got_beam, beam)
        np.testing.assert_array_equal(got_rho, rho)
        # The measured direction is the nominal beam rotated by the recorded offsets.
        n_az, n_el = directions_to_angles(sensor.beam_directions[beam])
        np.testing.assert_allclose(log.directions(beam, 0, len(shot)),
                                   angles_to_directions(n_az + az, n_el + el), atol=1e-15)
        assert not log.has_truth
        log.validate()


def test_iter_chunks_covers_every_strike_with_its_shot(tmp_path):
    rng = np.random.default_rng(2)
    t, pos, sq, tq, shot, beam, rho = _random_rows(rng, 300, 5)
    path = tmp_path / "log.h5"
    with StrikeLogWriter(path, sensor=_sensor(), target="t") as w:
        w.write_shots(t, pos, sq, tq)
        w.write_strikes(shot, beam, rho)
    with StrikeLog(path) as log:
        chunks = list(log.iter_chunks(chunk_rows=97))
    assert sum(len(c) for c in chunks) == len(shot)
    assert [c.start for c in chunks] == list(range(0, len(shot), 97))
    for c in chunks:
        np.testing.assert_array_equal(c.shots.time[c.shot - c.shot_offset], t[c.shot])


def test_truth_group_round_trip(tmp_path, sphere_log):
    with StrikeLog(sphere_log) as log:
        assert log.has_truth
        vertices, faces = log.truth_mesh()
        assert vertices.shape[1] == 3 and faces.dtype == np.int64
        truth = log.truth_strikes()
        np.testing.assert_allclose(np.linalg.norm(truth.point, axis=1), 50.0, rtol=1e-12)
        np.testing.assert_array_equal(log.truth_shots().time, log.shots().time)


def test_interrupted_write_leaves_no_file_and_keeps_existing(tmp_path):
    path = tmp_path / "log.h5"
    write_sphere_log(path)
    before = path.read_bytes()
    with pytest.raises(RuntimeError, match="crash"), \
            StrikeLogWriter(path, sensor=_sensor(), target="t") as w:
        w.write_shots([0.0], [[1.0, 0, 0]], [[0, 0, 0, 1.0]], [[0, 0, 0, 1.0]])
        raise RuntimeError("simulated crash")
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.h5"]


def test_append_extends_a_complete_log(tmp_path):
    path = tmp_path / "log.h5"
    q = [[0, 0, 0, 1.0]]
    with StrikeLogWriter(path, sensor=_sensor(), target="t") as w:
        w.write_shots([0.0], [[500.0, 0, 0]], q, q)
        w.write_strikes([0], [0], [400.0])
    with StrikeLogWriter.append(path) as w:
        w.write_shots([10.0], [[500.0, 0, 0]], q, q)
        w.write_strikes([1, 1], [0, 2], [400.0, 401.0])
        with pytest.raises(InputError, match="time does not increase"):
            w.write_shots([5.0], [[500.0, 0, 0]], q, q)
    with StrikeLog(path) as log:
        assert (log.n_shots, log.n_strikes) == (2, 3)
        np.testing.assert_array_equal(log.strikes()[2], [400.0, 400.0, 401.0])
        log.validate()


def test_writer_rejects_bad_rows(tmp_path):
    q = [[0, 0, 0, 1.0]]
    with StrikeLogWriter(tmp_path / "x.h5", sensor=_sensor(), target="t") as w:
        with pytest.raises(InputError, match="sensor_position must have shape"):
            w.write_shots([0.0], [[1.0, 0]], q, q)
        with pytest.raises(InputError, match="not a unit quaternion"):
            w.write_shots([0.0], [[1.0, 0, 0]], [[0, 0, 0, 2.0]], q)
        with pytest.raises(InputError, match="NaN or Inf"):
            w.write_shots([np.nan], [[1.0, 0, 0]], q, q)
        w.write_shots([0.0], [[1.0, 0, 0]], q, q)
        with pytest.raises(InputError, match="shot index 3 out of range"):
            w.write_strikes([3], [0], [1.0])
        with pytest.raises(InputError, match="beam index 9 out of range"):
            w.write_strikes([0], [9], [1.0])
        with pytest.raises(InputError, match="finite positive"):
            w.write_strikes([0], [0], [-1.0])
    with pytest.raises(InputError, match="pattern 'star' is not one of"):
        StrikeLogWriter(tmp_path / "y.h5", target="t",
                        sensor=SensorInfo("star", np.array([[0, 0, 1.0]]), 0, 1))
    with pytest.raises(InputError, match="range_min < range_max"):
        StrikeLogWriter(tmp_path / "y.h5", target="t",
                        sensor=SensorInfo("single", np.array([[0, 0, 1.0]]), 5, 1))
    assert not (tmp_path / "y.h5").exists()


def test_writer_names_the_first_bad_strike_in_a_block(tmp_path):
    """The strike checks decide a valid block from its range extremes and its shot steps; a bad
    block still names its first bad row, also across calls."""
    q = [[0, 0, 0, 1.0]] * 3
    sensor = SensorInfo("single", np.array([[0, 0, 1.0]]), 10.0, 1000.0)
    with StrikeLogWriter(tmp_path / "x.h5", sensor=sensor, target="t") as w:
        w.write_shots([0.0, 1.0, 2.0], [[500.0, 0, 0]] * 3, q, q)
        w.write_strikes([0, 1], [0, 0], [400.0, 401.0])
        for rng, message in [([400.0, np.nan, 5.0], r"strike 3 has range nan, expected"),
                             ([400.0, np.inf, 5.0], r"strike 3 has range inf, expected"),
                             ([400.0, 401.0, 5.0], r"strike 4 has range 5.0 m, below"),
                             ([400.0, 4000.0, 500.0], r"strike 3 has range 4000.0 m, beyond")]:
            with pytest.raises(InputError, match=message):
                w.write_strikes([1, 2, 2], [0, 0, 0], rng)
        with pytest.raises(InputError, match="not ordered by shot at strike 2"):
            w.write_strikes([0, 2], [0, 0], [400.0, 400.0])    # before the last call's shot 1
        with pytest.raises(InputError, match="not ordered by shot at strike 4"):
            w.write_strikes([1, 2, 1], [0, 0, 0], [400.0] * 3)
        w.write_strikes(np.array([1, 2], np.uint32), [0, 0], [10.0, 1000.0])   # the limits
    with StrikeLog(tmp_path / "x.h5") as log:
        assert log.n_strikes == 4


def test_closed_writer_refuses_writes(tmp_path):
    w = StrikeLogWriter(tmp_path / "x.h5", sensor=_sensor(), target="t")
    w.close()
    with pytest.raises(InputError, match="writer is closed"):
        w.write_shots([0.0], [[1.0, 0, 0]], [[0, 0, 0, 1.0]], [[0, 0, 0, 1.0]])


def test_chunked_storage_is_resizable_and_checksummed(sphere_log):
    with h5py.File(sphere_log) as f:
        for name in ("shots/time", "strikes/range", "truth/point"):
            assert f[name].maxshape[0] is None and f[name].chunks is not None
            assert f[name].fletcher32


@pytest.mark.parametrize("compression", ["lzf", "gzip", "gzip:9", "none"])
def test_compressed_logs_read_the_same(tmp_path, compression):
    rng = np.random.default_rng(4)
    t, pos, sq, tq, shot, beam, rho = _random_rows(rng, 100, 5)
    path = tmp_path / "c.h5"
    with StrikeLogWriter(path, sensor=_sensor(), target="t", compression=compression) as w:
        w.write_shots(t, pos, sq, tq)
        w.write_strikes(shot, beam, rho)
    with h5py.File(path) as f:
        assert f["strikes/shot"].compression == {"none": None}.get(compression,
                                                                  compression.split(":")[0])
    with StrikeLog(path) as log:
        log.validate()
        np.testing.assert_array_equal(log.strikes()[2], rho)
    with pytest.raises(InputError, match="compression must be one of none, lzf, gzip"):
        StrikeLogWriter(tmp_path / "d.h5", sensor=_sensor(), target="t", compression="zstd")


def test_missing_directory_and_dropped_writer(tmp_path):
    with pytest.raises(InputError, match=r"directory .*nowhere does not exist"):
        StrikeLogWriter(tmp_path / "nowhere" / "x.h5", sensor=_sensor(), target="t")
    w = StrikeLogWriter(tmp_path / "x.h5", sensor=_sensor(), target="t")
    w.write_shots([0.0], [[1.0, 0, 0]], [[0, 0, 0, 1.0]], [[0, 0, 0, 1.0]])
    del w  # dropped without close: an interrupted run
    assert list(tmp_path.iterdir()) == []


def test_sensor_errors_give_1_sigma_values_of_the_recorded_3_sigma():
    from formats import SensorErrors, sigma_from_sigma3

    errors = SensorErrors(range_sigma3=0.3, azimuth_sigma3=0.006, elevation_sigma3=0.003,
                          position_sigma3=2.0)
    assert (errors.range_sigma, errors.azimuth_sigma, errors.elevation_sigma,
            errors.position_sigma) == pytest.approx((0.1, 0.002, 0.001, 2.0 / 3.0), rel=1e-15)
    assert errors.angles and not errors.dilation
    assert sigma_from_sigma3(np.array([3.0, 6.0])) == pytest.approx([1.0, 2.0])
