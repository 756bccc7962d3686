"""How a strike log is stored: units and frame on every dataset, chunks sized to the content,
the compression SPEC.md states."""

from __future__ import annotations

import h5py
import numpy as np

from formats import StrikeLog
from formats.strike_log.schema import COMPRESSIONS, DATASET_UNITS, DEFAULT_COMPRESSION
from tests.conftest import write_sphere_log


def _datasets(f: h5py.File) -> dict[str, h5py.Dataset]:
    found = {}
    f.visititems(lambda name, obj: found.update({name: obj})
                 if isinstance(obj, h5py.Dataset) else None)
    return found


def test_every_dataset_says_its_units_and_frame(tmp_path):
    write_sphere_log(tmp_path / "log.h5", reports_angles=True)
    with h5py.File(tmp_path / "log.h5") as f:
        datasets = _datasets(f)
        assert set(datasets) == set(DATASET_UNITS)  # the table covers every dataset written
        for name, ds in datasets.items():
            assert (ds.attrs["units"], ds.attrs["frame"]) == DATASET_UNITS[name], name
        assert (f["shots/sensor_position"].attrs["units"],
                f["shots/sensor_position"].attrs["frame"]) == ("m", "I")
        assert f["truth/point"].attrs["frame"] == "B"
        assert f["shots/sensor_attitude"].attrs["frame"] == "S->I"


def test_spec_states_the_dataset_attributes():
    from importlib.resources import files

    text = files("formats").joinpath("SPEC.md").read_text(encoding="utf-8")
    assert "**`units`**" in text and "**`frame`**" in text
    assert "lzf with the shuffle filter" in text


def test_small_simulated_log_is_sized_to_its_content(tmp_path):
    from recon import api

    log = api.simulate("asteroid-cross", tmp_path / "r1.h5", seed=0,
                       overrides=["time.rotations=1"])
    with h5py.File(log.path) as f:
        n_shots, n_strikes = int(f.attrs["n_shots"]), int(f.attrs["n_strikes"])
        assert f["shots/time"].chunks == (n_shots,)
        assert f["strikes/range"].chunks[0] <= n_strikes * 5  # at most the pulses fired
        assert f["strikes/range"].compression == DEFAULT_COMPRESSION == "lzf"
        assert f["strikes/range"].shuffle and f["strikes/range"].fletcher32
        payload = sum(ds.size * ds.dtype.itemsize for ds in _datasets(f).values())
    # measured before: 1,548 shots, 7,740 strikes in 6,966,084 bytes with fixed chunks
    assert (n_shots, n_strikes) == (1548, 7740)
    assert log.path.stat().st_size < 1.1 * payload


def test_chunks_split_the_expected_rows_evenly(tmp_path):
    from formats.strike_log.writer import _chunk_rows

    assert _chunk_rows(None, 65_536) == 65_536
    assert _chunk_rows(7_740, 65_536) == 7_740
    assert _chunk_rows(77_400, 65_536) == 38_700      # two full chunks, not 1.7
    assert _chunk_rows(0, 16_384) == 1
    assert COMPRESSIONS[DEFAULT_COMPRESSION] == {"compression": "lzf", "shuffle": True}


def test_appending_beyond_the_expected_rows_works(tmp_path):
    from formats import StrikeLogWriter

    write_sphere_log(tmp_path / "log.h5", with_truth=False)
    with StrikeLog(tmp_path / "log.h5") as log:
        shots, strikes = log.shots(), log.strikes()
    with StrikeLogWriter.append(tmp_path / "log.h5") as w:
        w.write_shots(shots.time + 1e4, shots.sensor_position, shots.sensor_attitude,
                      shots.target_attitude)
        w.write_strikes(strikes[0] + len(shots), strikes[1], strikes[2])
    with StrikeLog(tmp_path / "log.h5") as log:
        assert log.n_shots == 2 * len(shots)
        np.testing.assert_array_equal(log.strikes()[2][len(strikes[2]):], strikes[2])
