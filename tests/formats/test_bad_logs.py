"""Every kind of bad strike log gets one clear InputError naming the file and the problem."""

from __future__ import annotations

import shutil

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from formats import StrikeLog
from formats.errors import InputError
from tests.conftest import write_sphere_log


def _read_everything(path):
    with StrikeLog(path) as log:
        log.validate()
        if log.has_truth:
            log.truth_strikes()
            log.truth_shots()


def _mutated(path, edit):
    with h5py.File(path, "r+") as f:
        edit(f)
    return path


def _replace(name, values):
    def edit(f):
        attrs = dict(f[name].attrs)
        del f[name]
        f[name] = values
        f[name].attrs.update(attrs)
    return edit


def _set(name, index, value):
    def edit(f):
        data = f[name][()]
        data[index] = value
        f[name][...] = data
    return edit


CASES = {
    "missing dataset": (lambda f: f.__delitem__("strikes/range"),
                        r"missing dataset /strikes/range"),
    "misshaped dataset": (_replace("shots/sensor_position", np.zeros((40, 2))),
                          r"/shots/sensor_position has shape \(40, 2\), expected \(40, 3\)"),
    "short dataset": (_replace("shots/time", np.arange(39.0)),
                      r"/shots/time has shape \(39,\), expected \(40\)"),
    "wrong dtype": (_replace("strikes/shot", np.zeros(80)), r"/strikes/shot has dtype float64"),
    "other version": (lambda f: f.attrs.__setitem__("format_version", 2),
                      r"format version 2 is not supported"),
    "not a strike log": (lambda f: f.attrs.__setitem__("format", "something-else"),
                         r"not a strike log"),
    "incomplete": (lambda f: f.attrs.__delitem__("n_strikes"), r"incomplete log"),
    "nan position": (_set("shots/sensor_position", (5, 1), np.nan), r"sensor_position has NaN"),
    "inf time": (_set("shots/time", 7, np.inf), r"time has NaN or Inf"),
    "non-unit quaternion": (_set("shots/target_attitude", (3, 3), 0.5),
                            r"target_attitude row 3 is not a unit quaternion"),
    "time not increasing": (_set("shots/time", 10, 0.0), r"time does not increase at shot 10"),
    "shot out of range": (_set("strikes/shot", 79, 400), r"shot index 400 out of range"),
    "beam out of range": (_set("strikes/beam", 4, 7), r"beam index 7 out of range"),
    "unordered strikes": (_set("strikes/shot", 2, 30), r"not ordered by shot"),
    "negative range": (_set("strikes/range", 0, -3.0), r"strike 0 has range -3.0"),
    "missing attribute": (lambda f: f.attrs.__delitem__("producer"),
                          r"missing root attribute 'producer'"),
    "missing sensor": (lambda f: f.__delitem__("sensor"), r"missing group /sensor"),
    "bad truth faces": (_set("truth/mesh/faces", (0, 0), 10**6), r"faces index missing vertices"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_damaged_log_raises_one_line_error(case, sphere_log):
    edit, pattern = CASES[case]
    path = _mutated(sphere_log, edit)
    with pytest.raises(InputError, match=pattern) as info:
        _read_everything(path)
    message = str(info.value)
    assert message.startswith(str(path)) and "\n" not in message


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"nope\.h5: no such file"):
        StrikeLog(tmp_path / "nope.h5")


def test_not_hdf5(tmp_path):
    path = tmp_path / "text.h5"
    path.write_text("hello")
    with pytest.raises(InputError, match=r"text\.h5: not an HDF5 file"):
        StrikeLog(path)


def test_truncated_file(sphere_log):
    data = sphere_log.read_bytes()
    sphere_log.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=r"sphere\.h5: (damaged|not an HDF5)"):
        _read_everything(sphere_log)


def test_truth_requested_from_a_log_without_truth(tmp_path):
    path = tmp_path / "log.h5"
    write_sphere_log(path, with_truth=False)
    with StrikeLog(path) as log, pytest.raises(InputError, match="no /truth group"):
        log.truth_mesh()


@pytest.fixture(scope="module")
def valid_log_bytes(tmp_path_factory):
    path = tmp_path_factory.mktemp("fuzz") / "valid.h5"
    write_sphere_log(path, n_shots=20, reports_angles=True)
    return path.read_bytes()


@settings(max_examples=150, deadline=None, derandomize=True,  # seeded: the same 150 cases each run
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_truncated_or_flipped_bytes_raise_only_our_error(data, valid_log_bytes, tmp_path):
    """Property: whatever damage, reading raises InputError or nothing, never anything else."""
    blob = bytearray(valid_log_bytes)
    if data.draw(st.booleans(), label="truncate"):
        blob = blob[: data.draw(st.integers(0, len(blob) - 1), label="length")]
    else:
        for _ in range(data.draw(st.integers(1, 16), label="flips")):
            i = data.draw(st.integers(0, len(blob) - 1), label="offset")
            blob[i] ^= 1 << data.draw(st.integers(0, 7), label="bit")
    path = tmp_path / "damaged.h5"
    path.write_bytes(bytes(blob))
    try:
        _read_everything(path)
    except InputError as exc:
        assert "\n" not in str(exc)


def test_copy_is_independent(sphere_log, tmp_path):
    """Sanity check of the harness: an unmodified copy reads cleanly."""
    copy = tmp_path / "copy.h5"
    shutil.copyfile(sphere_log, copy)
    _read_everything(copy)


def test_duplicate_shot_beam_pair(sphere_log):
    path = _mutated(sphere_log, _set("strikes/beam", 1, 0))  # shot 0 has beams 0 and 0
    with pytest.raises(InputError, match=r"\(shot, beam\) pair appears twice"):
        _read_everything(path)


@pytest.mark.parametrize(("edit", "pattern"), [
    (_set("shots/time", 8, 0.0), r"time does not increase at shot 8"),    # first row of block 2
    (_set("strikes/shot", 8, 0), r"not ordered by shot at strike 8"),      # first row of block 2
])
def test_validate_checks_across_block_boundaries(sphere_log, edit, pattern):
    path = _mutated(sphere_log, edit)
    with StrikeLog(path) as log, pytest.raises(InputError, match=pattern):
        log.validate(chunk_rows=8)


def test_validate_checks_each_block_once(sphere_log, monkeypatch):
    """validate() reads and checks every shot and strike row exactly once."""
    import formats.strike_log.reader as strike_log  # where validate looks its checks up

    rows = {"shots": 0, "strikes": 0}
    check_shots, check_strikes = strike_log._check_shot_rows, strike_log._check_strike_rows

    def count_shots(shots, *args):
        rows["shots"] += len(shots)
        check_shots(shots, *args)

    def count_strikes(shot, *args, **kwargs):
        rows["strikes"] += len(shot)
        check_strikes(shot, *args, **kwargs)

    monkeypatch.setattr(strike_log, "_check_shot_rows", count_shots)
    monkeypatch.setattr(strike_log, "_check_strike_rows", count_strikes)
    with StrikeLog(sphere_log) as log:
        log.validate(chunk_rows=16)
        assert rows == {"shots": log.n_shots, "strikes": log.n_strikes}


def test_validate_rejects_empty_blocks(sphere_log):
    with StrikeLog(sphere_log) as log, pytest.raises(InputError,
                                                     match="chunk_rows must be positive"):
        log.validate(chunk_rows=0)


def _retyped(name, dtype):
    """Store dataset ``name`` as ``dtype`` (the same values, converted)."""
    def edit(f):
        values = f[name][()]
        _replace(name, values.astype(dtype))(f)
    return edit


def test_float32_range_is_refused_on_open(sphere_log):
    """The spec's float64 range, stored as float32: refused by the reader as by validate (a
    float32 carries 24 bits: at 1 km its steps are 61 micrometres, at 100 km 7.8 mm)."""
    path = _mutated(sphere_log, _retyped("strikes/range", np.float32))
    with pytest.raises(InputError, match=rf"^{path}: /strikes/range has dtype float32, "
                                         r"expected float64$"):
        StrikeLog(path)


def test_every_dataset_of_another_dtype_is_named(sphere_log):
    """One message names each dataset whose dtype is not the spec's, whichever group."""
    for name, dtype in [("shots/time", np.float32), ("strikes/range", np.float32),
                        ("strikes/beam", np.int64), ("sensor/beam_directions", np.float16),
                        ("truth/facet", np.uint64), ("truth/mesh/vertices", np.float32)]:
        _mutated(sphere_log, _retyped(name, dtype))
    with pytest.raises(InputError) as info:
        _read_everything(sphere_log)
    message = str(info.value)
    assert message == (
        f"{sphere_log}: /sensor/beam_directions has dtype float16, expected float64; "
        "/shots/time has dtype float32, expected float64; "
        "/strikes/beam has dtype int64, expected uint32; "
        "/strikes/range has dtype float32, expected float64; "
        "/truth/facet has dtype uint64, expected uint32; "
        "/truth/mesh/vertices has dtype float32, expected float64")


def test_either_byte_order_is_read(sphere_log):
    """Byte order is HDF5's to convert, exactly: a big-endian float64 range is the spec's."""
    with StrikeLog(sphere_log) as log:
        want = log.strikes()[2]
    path = _mutated(sphere_log, _retyped("strikes/range", ">f8"))
    with StrikeLog(path) as log:
        log.validate()
        np.testing.assert_array_equal(log.strikes()[2], want)
