"""The planner benchmark's byte check (benchmarks/bench_planner.py, ``--identical-to``): two logs
of the same run compare equal whatever their creation times; a changed value or attribute is
named. No timing is asserted."""

from __future__ import annotations

import shutil

import h5py

from benchmarks import bench_planner
from tests.conftest import write_sphere_log


def test_log_differences_ignore_the_creation_time_and_name_what_differs(tmp_path):
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    write_sphere_log(a)
    shutil.copy(a, b)
    with h5py.File(b, "r+") as f:
        f.attrs["created_utc"] = "1999-01-01T00:00:00Z"
    assert bench_planner.log_differences(a, b) == []
    with h5py.File(b, "r+") as f:
        f["strikes/range"][0] += 1e-9
        f.attrs["seed"] = 12345
    assert bench_planner.log_differences(a, b) == ["/ attribute seed",
                                                   "/strikes/range: values differ"]
