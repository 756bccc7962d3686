"""The writer holds rows back until they fill a chunk (writer.py, ``_extend``): whatever the
sizes of the write calls, the log holds the same rows."""

from __future__ import annotations

import itertools
from dataclasses import astuple

import h5py
import numpy as np
import pytest

from formats import SensorInfo, Shots, StrikeLogWriter, TruthStrikes

BEAMS = np.array([[0.0, 0.0, 1.0], [0.0, np.sin(0.01), np.cos(0.01)]])
SENSOR = SensorInfo("custom", BEAMS, range_min=1.0, range_max=1e4,
                    field_of_view=(0.0, 0.0, 0.0, 0.01), reports_angles=True)
MESH = (np.eye(3), np.array([[0, 1, 2]]))


def _rows(n_shots: int, seed: int = 3):
    """Shots and two strikes per shot, with distinct values in every column."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n_shots, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    shots = Shots(np.arange(n_shots) * 10.0, rng.normal(0, 1e3, (n_shots, 3)), q, q[::-1].copy())
    n = 2 * n_shots
    strikes = {"shot": np.repeat(np.arange(n_shots), 2), "beam": np.tile([0, 1], n_shots),
               "range": rng.uniform(500, 900, n), "azimuth_offset": rng.normal(0, 1e-3, n),
               "elevation_offset": rng.normal(0, 1e-3, n)}
    truth = TruthStrikes(rng.normal(0, 100, (n, 3)), rng.integers(0, 1, n),
                         rng.uniform(500, 900, n))
    return shots, strikes, truth


def _write(writer, shots, strikes, truth, shot_cuts):
    """Write shots ``shot_cuts[i] .. shot_cuts[i + 1] - 1`` and their strikes per call."""
    for a, b in itertools.pairwise(shot_cuts):
        part = Shots(*(v[a:b] for v in astuple(shots)))
        writer.write_shots(*astuple(part), truth=part)
        s = slice(2 * a, 2 * b)
        writer.write_strikes(**{k: v[s] for k, v in strikes.items()},
                             truth=TruthStrikes(*(v[s] for v in astuple(truth))))


def _contents(path) -> dict:
    with h5py.File(path) as f:
        found = {}
        f.visititems(lambda name, obj: found.update({name: obj[()]})
                     if isinstance(obj, h5py.Dataset) and obj.chunks else None)
        return found | {"n": (int(f.attrs["n_shots"]), int(f.attrs["n_strikes"]))}


# Chunks of 6 shot rows and 10 strike rows, so that 37 shots cross many chunk boundaries.
SMALL_CHUNKS = {"sensor": SENSOR, "target": "t", "truth_mesh": MESH, "expected_shots": 6,
                "expected_strikes": 10}


def _same_contents(a, b) -> tuple[dict, dict]:
    """The contents of two logs, asserted equal dataset by dataset."""
    one, other = _contents(a), _contents(b)
    assert one.keys() == other.keys()
    for name in one:
        np.testing.assert_array_equal(other[name], one[name], err_msg=name)
    return one, other


@pytest.mark.parametrize("cuts", [[0, 1, 4, 5, 12, 12, 20, 31, 37], [0, 37], [0, 6, 8, 37]])
def test_any_call_sizes_give_the_same_rows(tmp_path, cuts):
    """Chunks of 6 shot and 10 strike rows, calls that end inside, on and across them."""
    shots, strikes, truth = _rows(37)
    with StrikeLogWriter(tmp_path / "one.h5", **SMALL_CHUNKS) as w:
        _write(w, shots, strikes, truth, [0, 37])
    with StrikeLogWriter(tmp_path / "cut.h5", **SMALL_CHUNKS) as w:
        for a, b in itertools.pairwise(cuts):
            _write(w, shots, strikes, truth, [a, b])
            # only whole chunks reach the file before the close
            assert w._file["strikes/range"].shape[0] == 2 * b // 10 * 10
            assert w._file["truth/point"].shape[0] == 2 * b // 10 * 10
            assert w._file["shots/time"].shape[0] == b // 6 * 6
    one, cut = _same_contents(tmp_path / "one.h5", tmp_path / "cut.h5")
    assert one["n"] == cut["n"] == (37, 74)
    np.testing.assert_array_equal(one["strikes/range"], strikes["range"])
    np.testing.assert_array_equal(one["truth/point"], truth.point)


def test_appending_to_a_log_whose_last_chunk_is_partial(tmp_path):
    shots, strikes, truth = _rows(37)
    with StrikeLogWriter(tmp_path / "one.h5", **SMALL_CHUNKS) as w:
        _write(w, shots, strikes, truth, [0, 37])
    with StrikeLogWriter(tmp_path / "cut.h5", **SMALL_CHUNKS) as w:
        _write(w, shots, strikes, truth, [0, 3, 13])     # 13 shots: 26 strikes, chunks of 10
    for cuts in ([13, 14, 22], [22, 37]):
        with StrikeLogWriter.append(tmp_path / "cut.h5") as w:
            _write(w, shots, strikes, truth, cuts)
    _same_contents(tmp_path / "one.h5", tmp_path / "cut.h5")


def test_an_aborted_writer_leaves_no_file(tmp_path):
    shots, strikes, truth = _rows(7)
    with pytest.raises(RuntimeError, match="stop"), StrikeLogWriter(
            tmp_path / "log.h5", sensor=SENSOR, target="t", truth_mesh=MESH) as w:
        _write(w, shots, strikes, truth, [0, 7])
        raise RuntimeError("stop")
    assert list(tmp_path.iterdir()) == []


def test_rows_of_zeros_are_not_stored_and_read_back_as_zeros(tmp_path):
    """A noise-free sensor's angle offsets are zeros: no chunk is stored for them (SPEC.md,
    Storage); a column that is zeros only in part reads back exactly."""
    from formats import StrikeLog

    shots, strikes, truth = _rows(37)
    strikes["azimuth_offset"][:] = 0.0
    strikes["elevation_offset"][:30] = 0.0   # chunks of 10 rows: 3 of zeros, then values
    with StrikeLogWriter(tmp_path / "log.h5", sensor=SENSOR, target="t", truth_mesh=MESH,
                         expected_shots=6, expected_strikes=10) as w:
        _write(w, shots, strikes, truth, [0, 4, 9, 20, 37])
    with h5py.File(tmp_path / "log.h5") as f:
        assert f["strikes/azimuth_offset"].id.get_num_chunks() == 0
        assert f["strikes/elevation_offset"].id.get_num_chunks() < 8   # 74 rows, 8 chunks
    with StrikeLog(tmp_path / "log.h5") as log:
        chunk = next(log.iter_chunks())
    assert chunk.range.tolist() == strikes["range"].tolist()
    with h5py.File(tmp_path / "log.h5") as f:
        np.testing.assert_array_equal(f["strikes/azimuth_offset"][()], 0.0)
        np.testing.assert_array_equal(f["strikes/elevation_offset"][()],
                                      strikes["elevation_offset"])
