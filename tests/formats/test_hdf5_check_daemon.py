"""The structural check of an HDF5 file also runs where multiprocessing may not fork (a Dask
worker is a daemonic process: "daemonic processes are not allowed to have children")."""

from __future__ import annotations

import multiprocessing

import h5py
import numpy as np

from formats.hdf5_check import _verdict


def _verdict_as_daemon(path, result) -> None:
    result.put(_verdict(path, 10))


def _run_in_daemon(path) -> str:
    ctx = multiprocessing.get_context("spawn")
    result = ctx.Queue()
    process = ctx.Process(target=_verdict_as_daemon, args=(str(path), result), daemon=True)
    process.start()
    verdict = result.get(timeout=120)
    process.join()
    return verdict


def test_a_daemonic_process_checks_a_file(tmp_path):
    good, linked = tmp_path / "good.h5", tmp_path / "linked.h5"
    with h5py.File(good, "w") as f:
        f["x"] = np.arange(3.0)
    with h5py.File(linked, "w") as f:
        f["x"] = h5py.ExternalLink(str(good), "/x")
    assert _run_in_daemon(good) == ""
    assert "external link" in _run_in_daemon(linked)
