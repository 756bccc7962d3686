"""Crafted and damaged logs (issue 13): a log never reads other files, never hangs the reader,
and validate reads everything it describes, /truth included."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from formats import StrikeLog, hdf5_check
from formats.errors import InputError
from formats.strike_log.schema import mesh_checksum
from tests.conftest import write_sphere_log


def _validate(path):
    with StrikeLog(path) as log:
        log.validate()


def _secret(tmp_path):
    """A file outside the log whose bytes a crafted log would pass off as vertices."""
    path = tmp_path / "secret.bin"
    path.write_bytes(np.arange(36, dtype=np.float64).tobytes())
    return path


def test_external_raw_storage_is_refused(sphere_log, tmp_path):
    secret = _secret(tmp_path)
    with h5py.File(sphere_log, "r+") as f:
        del f["truth/mesh/vertices"]
        f["truth/mesh"].create_dataset("vertices", shape=(12, 3), dtype="<f8",
                                       external=[(str(secret), 0, 12 * 3 * 8)])
    with pytest.raises(InputError, match=r"/truth/mesh/vertices keeps its data in external "
                                             r"files \(refused"):
        StrikeLog(sphere_log)


def test_external_link_is_refused(sphere_log, tmp_path):
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["r"] = np.full(80, 5.0)
    with h5py.File(sphere_log, "r+") as f:
        del f["strikes/range"]
        f["strikes/range"] = h5py.ExternalLink(str(other), "/r")
    with pytest.raises(InputError, match=r"/strikes/range is an external link to .*other\.h5"):
        StrikeLog(sphere_log)


def test_virtual_dataset_is_refused(sphere_log, tmp_path):
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["r"] = np.full(80, 5.0)
    layout = h5py.VirtualLayout(shape=(80,), dtype="<f8")
    layout[:] = h5py.VirtualSource(str(other), "r", shape=(80,))
    with h5py.File(sphere_log, "r+") as f:
        del f["strikes/range"]
        f["strikes"].create_virtual_dataset("range", layout)
    with pytest.raises(InputError, match=r"/strikes/range is a virtual dataset \(refused"):
        StrikeLog(sphere_log)


def test_dataset_pointing_outside_the_file_is_refused(sphere_log):
    with h5py.File(sphere_log, "r") as f:
        offset = f["truth/mesh/vertices"].id.get_offset()
    data = bytearray(sphere_log.read_bytes())
    # The contiguous block's address, as stored in the dataset's layout message.
    at = data.find(int(offset).to_bytes(8, "little"))
    data[at:at + 8] = (len(data) + 4096).to_bytes(8, "little")
    sphere_log.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"(points outside the file|damaged)"):
        _validate(sphere_log)


def test_global_heap_damage_that_hangs_hdf5_is_an_error(sphere_log, monkeypatch):
    """A flipped bit in the size of the first global-heap object (the root attribute 'format')
    makes HDF5 2.0 loop forever in H5Aread; the structural check in a child stops it when the
    child has used its CPU time."""
    monkeypatch.setattr(hdf5_check, "CHECK_CPU_S", 3)
    data = bytearray(sphere_log.read_bytes())
    heap = data.find(b"GCOL")
    assert heap > 0
    data[heap + 25] ^= 0x04   # GCOL header 16 bytes, object header: 2+2+4, then the size
    sphere_log.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"damaged HDF5 structure \(reading it used 3 s "
                                             r"of CPU time without finishing"):
        StrikeLog(sphere_log)


def test_valid_log_is_checked_once_per_version(sphere_log):
    _validate(sphere_log)
    key = next(k for k in hdf5_check._VERDICTS if k[1] == sphere_log.stat().st_ino)
    assert hdf5_check._VERDICTS[key] == ""


@pytest.mark.parametrize("name, row", [("truth/sensor_position", (3, 0)),
                                       ("truth/target_attitude", (5, 1)),
                                       ("truth/point", (7, 2)),
                                       ("truth/range", 9)])
def test_validate_reads_the_truth_datasets(sphere_log, name, row):
    with h5py.File(sphere_log, "r+") as f:
        data = f[name][()]
        data[row] = np.nan
        f[name][...] = data
    with pytest.raises(InputError, match=r"truth (sensor_position|target_attitude|point|"
                                             r"range)"):
        _validate(sphere_log)


def test_truth_facet_out_of_range(sphere_log):
    with h5py.File(sphere_log, "r+") as f:
        f["truth/facet"][4] = 10**6
    with pytest.raises(InputError, match=r"truth facet out of range"):
        _validate(sphere_log)


def test_truth_mesh_has_a_checksum_and_a_flipped_bit_is_caught(sphere_log):
    with h5py.File(sphere_log, "r") as f:
        vertices, faces = f["truth/mesh/vertices"][()], f["truth/mesh/faces"][()]
        assert f["truth/mesh"].attrs["sha256"] == mesh_checksum(vertices, faces)
    with h5py.File(sphere_log, "r+") as f:
        v = f["truth/mesh/vertices"][()]
        v[3, 1] = np.nextafter(v[3, 1], np.inf)   # one ulp: a single flipped bit
        f["truth/mesh/vertices"][...] = v
    with pytest.raises(InputError, match=r"truth mesh does not match its sha256"):
        _validate(sphere_log)


def test_range_beyond_range_max_is_refused(sphere_log):
    with h5py.File(sphere_log, "r+") as f:
        f["strikes/range"][6] = 1e300
    with pytest.raises(InputError, match=r"strike 6 has range 1e\+300 m, beyond the sensor's "
                                             r"range_max of 1000 m"):
        _validate(sphere_log)


def test_streaming_readers_refuse_duplicate_pairs(sphere_log):
    """iter_chunks (ingest, score) makes validate's duplicate check, across blocks too."""
    with h5py.File(sphere_log, "r+") as f:
        f["strikes/beam"][1] = 0          # shot 0: beams 0 and 0
    with StrikeLog(sphere_log) as log, pytest.raises(InputError, match=r"pair appears twice"):
        for _ in log.iter_chunks(chunk_rows=1):
            pass


def test_streaming_readers_check_time_across_blocks(tmp_path):
    path = tmp_path / "log.h5"
    write_sphere_log(path)
    with h5py.File(path, "r+") as f:
        f["shots/time"][20] = f["shots/time"][19] - 1.0
    with StrikeLog(path) as log, pytest.raises(InputError, match=r"time does not increase"):
        for _ in log.iter_chunks(chunk_rows=40):   # shot 19 ends a block, 20 starts the next
            pass


@pytest.mark.parametrize("make, what", [(lambda p: p.mkdir(), "a directory"),
                                        (lambda p: __import__("os").mkfifo(p), "a FIFO")])
def test_inputs_that_are_not_files_are_named(tmp_path, make, what):
    path = tmp_path / "input.h5"
    make(path)
    with pytest.raises(InputError, match=rf"input\.h5: is {what}, not a file"):
        StrikeLog(path)


def test_character_device_is_named():
    with pytest.raises(InputError, match=r"/dev/zero: is a character device, not a file"):
        StrikeLog("/dev/zero")
