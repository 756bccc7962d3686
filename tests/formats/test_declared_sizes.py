"""Datasets declared far larger than any memory: a shape costs nothing to declare (chunks never
written read as fill values), so every dataset read whole is checked against the memory
available first and refused with one line naming the file and the key."""

from __future__ import annotations

import resource
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from formats import StrikeLog, memory
from formats.cloud_io import read_cloud, write_cloud
from formats.errors import InputError
from formats.geometry import Cloud

REPO = Path(__file__).resolve().parents[2]
HUGE = 2**36   # rows: (HUGE, 3) float64 is 1.6 TB


def _declare(f: h5py.File, key: str, rows: int, dtype) -> None:
    """Replace dataset ``key`` by one of ``rows`` rows (and its old row shape), none written."""
    tail = f[key].shape[1:]
    del f[key]
    f.create_dataset(key, shape=(rows, *tail), dtype=dtype, chunks=(1024, *tail))


def test_huge_beam_directions_are_refused_on_open(sphere_log):
    with h5py.File(sphere_log, "r+") as f:
        _declare(f, "sensor/beam_directions", 2**34, "<f8")
    with pytest.raises(InputError, match=rf"^{sphere_log}: /sensor/beam_directions declares "
                                         r"shape \(17179869184, 3\); reading it whole needs "
                                         r"about 412\.3 GB of memory but only"):
        StrikeLog(sphere_log)


def test_huge_truth_mesh_is_refused_before_it_is_read(sphere_log):
    with h5py.File(sphere_log, "r+") as f:
        _declare(f, "truth/mesh/vertices", HUGE, "<f8")
        _declare(f, "truth/mesh/faces", HUGE, "<u4")
        del f["truth/mesh"].attrs["sha256"]
    with StrikeLog(sphere_log) as log:
        for read in (log.truth_mesh, log.validate):
            with pytest.raises(InputError, match=r"/truth/mesh/vertices declares shape "
                                                 r"\(68719476736, 3\); reading it whole \(with "
                                                 r"1 other dataset\) needs about"):
                read()


@pytest.mark.parametrize("key", ["points", "attributes/time"])
def test_huge_hdf5_cloud_is_refused_before_it_is_read(key, tmp_path):
    path = tmp_path / "c.h5"
    write_cloud(path, Cloud(np.zeros((10, 3)), {"time": np.arange(10.0)}))
    with h5py.File(path, "r+") as f:
        _declare(f, key, HUGE, "<f8")
    with pytest.raises(InputError, match=rf"^{path}: /{key} declares shape \(68719476736"):
        read_cloud(path)


def test_what_fits_is_read(sphere_log, monkeypatch):
    """The check compares with what is available: a log's small datasets read as before, and
    the same read is refused when less memory is left than they need."""
    with StrikeLog(sphere_log) as log:
        assert len(log.truth_mesh().faces) == 320
        monkeypatch.setattr(memory, "available_bytes", lambda: 1000)
        with pytest.raises(InputError, match=r"needs about 0\.0 MB of memory but only 0\.0 MB"):
            log.truth_mesh()


def test_available_memory_stays_within_the_address_space_limit():
    """Under ``ulimit -v`` the memory available is what the limit leaves, not the system's."""
    limit = 2 << 30
    script = ("import resource, sys; from formats.memory import available_bytes; "
              f"resource.setrlimit(resource.RLIMIT_AS, ({limit}, "
              "resource.getrlimit(resource.RLIMIT_AS)[1])); print(available_bytes())")
    hard = resource.getrlimit(resource.RLIMIT_AS)[1]
    if hard != resource.RLIM_INFINITY and hard < limit:
        pytest.skip("the hard address-space limit is below the test's")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, cwd=REPO).stdout
    assert 0 < int(out) < limit
