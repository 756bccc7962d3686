"""How a strike log is stored: units and frame on every dataset, chunks sized to the content,
the compression SPEC.md states."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from formats import StrikeLog
from formats.errors import InputError
from formats.strike_log.schema import (
    DATASET_UNITS,
    DEFAULT_COMPRESSION,
    GZIP_LEVEL,
    compression_filters,
)
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
    assert "deflate (gzip) with the shuffle filter" in text


def test_small_simulated_log_is_sized_to_its_content(tmp_path):
    from recon import api

    log = api.simulate("asteroid-cross", tmp_path / "r1.h5", seed=0,
                       overrides=["time.rotations=1"])
    with h5py.File(log.path) as f:
        n_shots, n_strikes = int(f.attrs["n_shots"]), int(f.attrs["n_strikes"])
        assert f["shots/time"].chunks == (n_shots,)
        assert f["strikes/range"].chunks[0] <= n_strikes * 5  # at most the pulses fired
        assert f["strikes/shot"].compression == "gzip"
        assert f["strikes/shot"].compression_opts == GZIP_LEVEL
        assert DEFAULT_COMPRESSION == f"gzip:{GZIP_LEVEL}"
        assert f["strikes/shot"].shuffle and f["strikes/shot"].fletcher32
        # The noisy float64 columns and the truth's facets: checksummed, not compressed
        # (schema.UNFILTERED_COLUMNS).
        for name in ("strikes/range", "truth/point", "truth/range", "truth/facet"):
            assert f[name].compression is None and f[name].fletcher32, name
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


@pytest.mark.parametrize(("spec", "expected"), [
    ("none", {}),
    ("lzf", {"compression": "lzf", "shuffle": True}),
    ("gzip", {"compression": "gzip", "compression_opts": GZIP_LEVEL, "shuffle": True}),
    ("gzip:9", {"compression": "gzip", "compression_opts": 9, "shuffle": True}),
    ("gzip:0", {"compression": "gzip", "compression_opts": 0, "shuffle": True}),
])
def test_compression_names(spec, expected):
    assert compression_filters(spec) == expected


@pytest.mark.parametrize("spec", ["zstd", "gzip:10", "gzip:", "gzip:-1", "lzf:3", "none:1", ""])
def test_bad_compression_names_are_refused(spec):
    with pytest.raises(InputError, match=r"compression must be one of none, lzf, gzip or "
                                             r"gzip:LEVEL \(LEVEL 0-9\), got"):
        compression_filters(spec)


def test_simulate_refuses_a_bad_compression_before_writing(tmp_path, capsys):
    from cli.main import main

    assert main(["simulate", "asteroid-cross", "-o", str(tmp_path / "x.h5"),
                 "--compression", "gzip:12"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "gzip:LEVEL (LEVEL 0-9), got 'gzip:12'" in err
    assert list(tmp_path.iterdir()) == []


def test_simulate_writes_the_compression_asked(tmp_path):
    from cli.main import main

    assert main(["simulate", "asteroid-cross", "-o", str(tmp_path / "x.h5"),
                 "--compression", "lzf", "--set", "time.duration=600"]) == 0
    with h5py.File(tmp_path / "x.h5") as f:
        assert f["shots/time"].compression == "lzf"
        assert f["strikes/range"].compression is None
    with StrikeLog(tmp_path / "x.h5") as log:
        log.validate()


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


@pytest.mark.parametrize("compression", ["lzf", "gzip"])
@pytest.mark.parametrize("angle_error", [0.0, 1e-3])
def test_filters_skip_the_angle_offsets_only_when_they_hold_noise(tmp_path, angle_error,
                                                                  compression):
    from formats import StrikeLogWriter
    from formats.strike_log import SensorErrors, SensorInfo

    sensor = SensorInfo("custom", np.array([[0.0, 0.0, 1.0]]), range_min=1.0, range_max=1e3,
                        field_of_view=(0.0, 0.0, 0.0, 0.0), reports_angles=True,
                        errors=SensorErrors(azimuth_sigma3=angle_error))
    with StrikeLogWriter(tmp_path / "log.h5", sensor=sensor, target="t",
                         compression=compression) as log:
        log.write_shots([0.0], [[1e3, 0.0, 0.0]], [[0.0, 0.0, 0.0, 1.0]], [[0.0, 0.0, 0.0, 1.0]])
        log.write_strikes([0], [0], [900.0], azimuth_offset=[0.0], elevation_offset=[0.0])
    with h5py.File(tmp_path / "log.h5") as f:
        expected = None if angle_error else compression
        assert f["strikes/azimuth_offset"].compression == expected
        assert f["strikes/elevation_offset"].compression == expected
        assert f["strikes/beam"].compression == compression
        assert f["strikes/range"].compression is None
        assert all(f[name].fletcher32 for name in ("strikes/azimuth_offset", "strikes/range"))


def test_noisy_columns_are_checksummed_only_under_every_compression():
    from formats.strike_log.writer import _filters

    for compression in ("none", "lzf", "gzip", "gzip:9"):
        assert _filters(compression, "strikes/range", True) == {"fletcher32": True}
    assert _filters("gzip:6", "strikes/shot", False)["compression_opts"] == 6
    assert _filters("none", "strikes/shot", False) == {"fletcher32": True}


@pytest.fixture(scope="module")
def simulated_log(tmp_path_factory):
    from recon import api

    return api.simulate("asteroid-cross", tmp_path_factory.mktemp("sim") / "log.h5", seed=0,
                        overrides=["time.duration=600"]).path


def _rewrite(path, name: str, **filters) -> None:
    """Store dataset ``name`` of the log at ``path`` again with other h5py ``filters``, keeping
    its values, chunks and attributes."""
    with h5py.File(path, "r+") as f:
        old = f[name]
        values, chunks, attrs = old[()], old.chunks, dict(old.attrs)
        del f[name]
        new = f.create_dataset(name, data=values, chunks=chunks,
                               maxshape=(None, *values.shape[1:]), **filters)
        new.attrs.update(attrs)


def test_logs_with_deflated_truth_facets_read_the_same(tmp_path, simulated_log):
    """Logs written before the truth's facets were stored with Fletcher-32 only (deflate and
    shuffle on them too) read and validate exactly as the logs written now."""
    (tmp_path / "now.h5").write_bytes(simulated_log.read_bytes())
    (tmp_path / "before.h5").write_bytes(simulated_log.read_bytes())
    _rewrite(tmp_path / "before.h5", "truth/facet", fletcher32=True,
             **compression_filters(DEFAULT_COMPRESSION))
    with h5py.File(tmp_path / "before.h5") as f:
        assert f["truth/facet"].compression == "gzip" and f["truth/facet"].fletcher32
    with StrikeLog(tmp_path / "now.h5") as now, StrikeLog(tmp_path / "before.h5") as before:
        before.validate()
        for key in ("point", "facet", "range"):
            np.testing.assert_array_equal(getattr(now.truth_strikes(), key),
                                          getattr(before.truth_strikes(), key))
        for a, b in zip(now.strikes(), before.strikes(), strict=True):
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("name", ["truth/facet", "strikes/shot", "truth/point"])
def test_a_flipped_byte_in_a_stored_chunk_is_caught(tmp_path, simulated_log, name):
    """Every chunked dataset carries Fletcher-32, compressed or not: one changed byte in a
    chunk as stored is a one-line InputError on read, never a silently wrong value."""
    (tmp_path / "log.h5").write_bytes(simulated_log.read_bytes())
    with h5py.File(tmp_path / "log.h5") as f:
        info = f[name].id.get_chunk_info(0)
    data = bytearray((tmp_path / "log.h5").read_bytes())
    data[info.byte_offset + info.size // 2] ^= 0x10
    (tmp_path / "log.h5").write_bytes(bytes(data))
    with StrikeLog(tmp_path / "log.h5") as log, pytest.raises(InputError, match="damaged"):
        log.validate()


def test_same_seed_stores_the_same_chunk_bytes(tmp_path, simulated_log):
    """Run again with the same seed, every chunk of every chunked dataset is stored with the
    same bytes (filters and checksums included), not only the same values."""
    from recon import api

    again = api.simulate("asteroid-cross", tmp_path / "again.h5", seed=0,
                         overrides=["time.duration=600"]).path
    with h5py.File(simulated_log) as a, h5py.File(again) as b:
        chunked = {name: ds for name, ds in _datasets(a).items() if ds.chunks}
        assert set(chunked) >= {"strikes/shot", "truth/facet", "truth/point"}
        for name, ds in chunked.items():
            n = ds.id.get_num_chunks()
            assert n == b[name].id.get_num_chunks(), name
            for i in range(n):
                offset = ds.id.get_chunk_info(i).chunk_offset
                assert ds.id.read_direct_chunk(offset) == b[name].id.read_direct_chunk(
                    offset), (name, i)
