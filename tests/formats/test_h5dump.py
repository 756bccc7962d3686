"""A default strike log is readable by the HDF5 command-line tools, not only by h5py.

h5dump (Debian package hdf5-tools, installed by .ci/setup) stands for every HDF5 tool that has
only the filters HDF5 itself ships (HDFView, MATLAB, IDL, C programs): with h5py's lzf filter it
prints "unable to print data" or an empty ``DATA {}`` for a compressed dataset.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess

import h5py
import pytest

from recon import api

H5DUMP = shutil.which("h5dump")
# CI must run this test: a missing h5dump there is a setup failure, not a reason to skip.
IN_CI = os.environ.get("CI", "").lower() == "true"


@pytest.fixture(scope="module")
def h5dump() -> str:
    if H5DUMP is None:
        if IN_CI:
            pytest.fail("h5dump is not installed; .ci/setup installs it (Debian package "
                        "hdf5-tools)")
        pytest.skip("h5dump not installed (Debian/Ubuntu: apt-get install hdf5-tools)")
    return H5DUMP


def _datasets(path) -> dict[str, tuple[int, ...]]:
    found = {}
    with h5py.File(path) as f:
        f.visititems(lambda name, obj: found.update({name: obj.shape})
                     if isinstance(obj, h5py.Dataset) else None)
    return found


def _dump(h5dump: str, path, dataset: str) -> str:
    run = subprocess.run([h5dump, "-d", dataset, str(path)], capture_output=True, text=True,
                         timeout=120, check=False)
    assert run.returncode == 0, f"h5dump -d {dataset}: {run.stderr.strip()}"
    assert "unable to print data" not in run.stdout + run.stderr, dataset
    return run.stdout


def _first_values(text: str) -> str:
    """What h5dump prints inside ``DATA { ... }`` before the first attribute (stripped)."""
    match = re.search(r"DATA \{(.*?)\n\s*\}", text, re.S)
    assert match, "no DATA block"
    return match.group(1).strip()


@pytest.mark.parametrize("compression", [None, "gzip:9"])
def test_h5dump_prints_every_dataset_of_a_simulated_log(tmp_path, h5dump, compression):
    # A LIDAR grid with angle errors writes every dataset SPEC.md defines (angle offsets too).
    log = api.simulate("asteroid-lidar-noise", tmp_path / "log.h5", seed=0, compression=compression,
                       overrides=["time.duration=60", "sensor.resolution=[4,4]"]).path
    datasets = _datasets(log)
    assert {"shots/time", "shots/sensor_position", "strikes/azimuth_offset",
            "truth/point", "truth/mesh/faces"} <= set(datasets)
    for name, shape in datasets.items():
        assert shape and shape[0] > 0, name   # a log with data in every dataset
        values = _first_values(_dump(h5dump, log, "/" + name))
        assert values.startswith("(0"), f"{name}: h5dump printed no values ({values[:80]!r})"

