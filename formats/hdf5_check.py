"""Check an untrusted HDF5 file's structure before recon reads it.

A strike log or cloud may come from anyone. HDF5 can make a file read other files (external
raw storage, external links, virtual datasets: ``/etc/passwd`` read as vertices), and a damaged
file can make the library loop forever or crash: a flipped bit in the size of a global-heap
object (where variable-length strings such as the root attributes live) hangs HDF5 2.0 in
``H5Aread`` (reproduced with single bit flips at the object-size fields of a log's global heap
collection). No read of such a file can be guarded from inside the process, so
:func:`check_hdf5` walks the whole structure in a forked child with a time limit:

- every link: external and user-defined links are refused;
- every object's attributes, read in full (the global heap);
- every dataset: external storage and virtual layouts are refused; the chunk index is walked
  and every chunk, or the contiguous block, must lie inside the file.

A child that does not finish in ``CHECK_TIMEOUT_S`` or dies (HDF5 crashing on the damage) means
a damaged file. The verdict is cached per file version (device, inode, size, mtime), so opening
the same log again costs nothing. The walk reads metadata only: about 0.07 s, fork included, for
a 2.3 M-strike log of 164 MB and for a 2,000-strike one alike (median of 3, loaded 2-core machine).
"""

from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys
import threading
from pathlib import Path

# Seconds the structural walk may take: a valid log's takes milliseconds (metadata only), so
# reaching this means HDF5 is looping on damage.
CHECK_TIMEOUT_S = 10.0
_VERDICTS: dict[tuple, str] = {}   # (dev, inode, size, mtime_ns) -> "" or the problem


def _walk(path: str) -> str:
    """The first structural problem of ``path``, or "" (runs in the child)."""
    import h5py

    size = os.path.getsize(path)
    problems: list[str] = []

    def outside(where: str, offset, nbytes) -> None:
        if offset is None or offset < 0 or offset + nbytes > size:
            problems.append(f"{where} points outside the file")

    with h5py.File(path, "r") as f:
        def link(name, info):
            if isinstance(info, h5py.ExternalLink):
                problems.append(f"/{name} is an external link to {info.filename}:{info.path} "
                                "(refused: a log must not read other files)")
            elif not isinstance(info, h5py.HardLink | h5py.SoftLink):
                problems.append(f"/{name} is a user-defined link (refused)")
            return problems[0] if problems else None

        def item(name, obj):
            for key in obj.attrs:
                obj.attrs[key]    # reads the value: global-heap damage shows here
            if isinstance(obj, h5py.Dataset):
                dcpl = obj.id.get_create_plist()
                layout = dcpl.get_layout()
                if dcpl.get_external_count():
                    problems.append(f"/{name} keeps its data in external files (refused: a log "
                                    "must not read other files)")
                elif layout == h5py.h5d.VIRTUAL:
                    problems.append(f"/{name} is a virtual dataset (refused: a log must not "
                                    "read other files)")
                elif layout == h5py.h5d.CHUNKED:
                    obj.id.chunk_iter(lambda c: outside(f"/{name} chunk {c.chunk_offset}",
                                                        c.byte_offset, c.size))
                elif layout == h5py.h5d.CONTIGUOUS and obj.id.get_storage_size():
                    outside(f"/{name}", obj.id.get_offset(), obj.id.get_storage_size())
            return problems[0] if problems else None

        for key in f.attrs:
            f.attrs[key]
        f.visititems_links(link)
        if not problems:
            f.visititems(item)
    return problems[0] if problems else ""


def _problem(path: str) -> str:
    """``_walk``'s verdict, an exception of h5py included (runs in the child)."""
    try:
        return _walk(path)
    except Exception as exc:  # h5py raises many types on damaged files; all mean "damaged"
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        return f"damaged or unreadable HDF5 ({text})"


def _child(path: str, conn) -> None:
    try:
        conn.send(_problem(path))
    finally:
        conn.close()


def _verdict_in_subprocess(path: Path, timeout: float) -> str:
    """The walk in a fresh interpreter (``python -m formats.hdf5_check PATH``): for daemonic
    processes (a Dask worker), which multiprocessing does not let have children."""
    env = os.environ | {"PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    try:
        done = subprocess.run([sys.executable, "-m", "formats.hdf5_check", str(path)],
                              capture_output=True, text=True, timeout=timeout + 5.0, env=env)
    except subprocess.TimeoutExpired:
        return (f"damaged HDF5 structure (reading it did not finish in {timeout:g} s; "
                "HDF5 loops on this damage)")
    if done.returncode != 0:
        return "damaged HDF5 structure (reading it crashed the HDF5 library)"
    return done.stdout.strip()


def _verdict(path: Path, timeout: float) -> str:
    if multiprocessing.current_process().daemon:
        return _verdict_in_subprocess(path, timeout)
    # Forking copies the held locks of other threads; with threads running, a fresh
    # interpreter (forkserver) walks the file instead.
    method = "fork" if threading.active_count() == 1 else "forkserver"
    ctx = multiprocessing.get_context(method)
    receive, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_child, args=(str(path), send), daemon=True)
    child.start()
    send.close()
    try:
        if not receive.poll(timeout):
            return (f"damaged HDF5 structure (reading it did not finish in {timeout:g} s; "
                    "HDF5 loops on this damage)")
        try:
            return receive.recv()
        except EOFError:
            return "damaged HDF5 structure (reading it crashed the HDF5 library)"
    finally:
        receive.close()
        if child.is_alive():
            child.kill()
        child.join()


def check_hdf5(path, error: type[Exception], *, timeout: float | None = None) -> None:
    """Raise ``error("PATH: problem")`` unless ``path``'s HDF5 structure is safe to read.

    Parameters
    ----------
    path : str or Path
        An existing HDF5 file.
    error : exception class
        A ReconError subclass (``StrikeLogError``, ``MeshFormatError``).
    timeout : float, seconds, optional
        Limit of the structural walk (default ``CHECK_TIMEOUT_S``).
    """
    path = Path(path)
    st = path.stat()
    key = (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)
    if key not in _VERDICTS:
        _VERDICTS[key] = _verdict(path, CHECK_TIMEOUT_S if timeout is None else timeout)
    if _VERDICTS[key]:
        raise error(f"{path}: {_VERDICTS[key]}")


if __name__ == "__main__":   # the walk of _verdict_in_subprocess: print the problem or nothing
    print(_problem(sys.argv[1]))
