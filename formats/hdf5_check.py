"""Check an untrusted HDF5 file's structure before recon reads it.

A strike log or cloud may come from anyone. HDF5 can make a file read other files (external
raw storage, external links, virtual datasets: ``/etc/passwd`` read as vertices), and a damaged
file can make the library loop forever or crash: a flipped bit in the size of a global-heap
object (where variable-length strings such as the root attributes live) hangs HDF5 2.0 in
``H5Aread`` (reproduced with single bit flips at the object-size fields of a log's global heap
collection). No read of such a file can be guarded from inside the process, so
:func:`check_hdf5` walks the whole structure in a child process whose CPU time is limited:

- every link: external and user-defined links are refused;
- every object's attributes, read in full (the global heap);
- every dataset: external storage and virtual layouts are refused; the chunk index is walked
  and every chunk, or the contiguous block, must lie inside the file.

A child that uses ``CHECK_CPU_S`` seconds of CPU (the kernel stops it: ``RLIMIT_CPU``) or dies
(HDF5 crashing on the damage) means a damaged file. No wall-clock limit decides: on a busy
machine a valid file's walk waits for the processor (docs/decisions.md gives a measured case) but
its CPU time stays what it is on an idle one. The verdict is
cached per file version (device, inode, size, mtime), so opening the same log again costs
nothing, and a log recon itself wrote is trusted (``trust``). The walk reads metadata only: a
2.3 M-strike log of 164 MB takes about 0.1 s in a forked child, 0.9 s in a fresh interpreter
(the path of multi-threaded processes), interpreter start included.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

from formats.memory import check_memory

# Bytes a value of a dataset read whole takes in memory: recon holds them as float64 or int64.
HELD_VALUE_BYTES = 8
# CPU seconds the structural walk may use, interpreter start included: a valid log's takes
# milliseconds of walking (metadata only) after about 1 s of start-up in a fresh interpreter,
# so reaching this means HDF5 is looping on damage.
CHECK_CPU_S = 10
_VERDICTS: dict[tuple, str] = {}   # (dev, inode, size, mtime_ns) -> "" or the problem


def _walk(path: str, live: bool = False) -> str:
    """The first structural problem of ``path``, or "" (runs in the child); ``live``: the
    temporary file of a live (SWMR) writer, opened as an SWMR reader (a writer that died left
    its file marked open for writing, which an ordinary open refuses)."""
    import h5py

    size = os.path.getsize(path)
    problems: list[str] = []

    def outside(where: str, offset, nbytes) -> None:
        if offset is None or offset < 0 or offset + nbytes > size:
            problems.append(f"{where} points outside the file")

    with h5py.File(path, "r", **({"swmr": True, "locking": False} if live else {})) as f:
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


def _limit_cpu(seconds: int) -> None:
    """In the child: let the kernel stop it after ``seconds`` of CPU time (SIGXCPU, then
    SIGKILL a second later), with no core file."""
    import resource

    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    resource.setrlimit(resource.RLIMIT_CPU, (seconds, seconds + 1))


def _report(path: str, live: bool = False) -> bytes:
    """The walk's verdict as the child sends it: ``b"="`` then the problem (empty when none)."""
    try:
        return b"=" + _walk(path, live).encode()
    except Exception as exc:  # h5py raises many types on damaged files; all mean "damaged"
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        return b"=" + f"damaged or unreadable HDF5 ({text})".encode()


def _forked(path: Path, cpu_s: int, live: bool = False) -> tuple[bytes, int]:
    """Walk in a forked child; its report and the signal that ended it (0: none)."""
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:   # the child: report and leave without running the parent's clean-up
        try:
            os.close(read)
            _limit_cpu(cpu_s)
            os.write(write, _report(str(path), live))
        finally:
            os._exit(0)
    os.close(write)
    chunks = []
    status = None
    try:
        while chunk := os.read(read, 65536):
            chunks.append(chunk)
        _, status = os.waitpid(pid, 0)
    finally:
        os.close(read)
        if status is None:   # interrupted: never leave the child behind
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
    return b"".join(chunks), os.WTERMSIG(status) if os.WIFSIGNALED(status) else 0


def _spawned(path: Path, cpu_s: int, live: bool = False) -> tuple[bytes, int]:
    """Walk in a fresh interpreter; its report and the signal that ended it (0: none)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    # OSError: the interpreter cannot be started (check_hdf5 says so in one line).
    done = subprocess.run([sys.executable, "-c", "import sys; from formats.hdf5_check import "
                           "_limit_cpu, _report; _limit_cpu(int(sys.argv[2])); "
                           "sys.stdout.buffer.write(_report(sys.argv[1], sys.argv[3] == 'live'))",
                           str(path), str(cpu_s), "live" if live else ""], capture_output=True,
                          env=env)
    return done.stdout, max(0, -done.returncode)


def _verdict(path: Path, cpu_s: int, live: bool = False) -> str:
    # fork() copies only the calling thread, and locks other threads hold stay held in the
    # child: with threads running (a Dask worker), a fresh interpreter walks the file instead.
    # (multiprocessing would refuse inside a Dask worker: daemonic processes have no children.)
    single = threading.active_count() == 1 and hasattr(os, "fork")
    report, signum = (_forked if single else _spawned)(path, cpu_s, live)
    if signum in (signal.SIGXCPU, signal.SIGKILL) and not report.startswith(b"="):
        return (f"damaged HDF5 structure (reading it used {cpu_s} s of CPU time without "
                "finishing; HDF5 loops on this damage)")
    if not report.startswith(b"="):
        return "damaged HDF5 structure (reading it crashed the HDF5 library)"
    return report[1:].decode(errors="replace")


def is_hdf5(path, error: type[Exception]) -> bool:
    """Whether ``path`` starts as an HDF5 file; ``error("PATH: cannot be read (why)")`` when
    it cannot be opened (no permission), where h5py raises an OSError with HDF5's message."""
    import h5py

    try:
        return bool(h5py.is_hdf5(path))
    except OSError as exc:
        reason = os.strerror(exc.errno) if exc.errno else str(exc).splitlines()[0]
        raise error(f"{path}: cannot be read ({reason})") from None


def _key(path: Path, live: bool = False) -> tuple:
    st = path.stat()
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, live)


def trust(path) -> None:
    """Record ``path`` as safe without a walk: for files recon itself just wrote (a sweep's
    worker reads back the log it simulated, and a walk from a threaded worker costs a fresh
    interpreter, ~1 s)."""
    _VERDICTS[_key(Path(path))] = ""


def check_hdf5(path, error: type[Exception], *, cpu_s: int | None = None,
               live: bool = False) -> None:
    """Raise ``error("PATH: problem")`` unless ``path``'s HDF5 structure is safe to read.

    Parameters
    ----------
    path : str or Path
        An existing HDF5 file.
    error : exception class
        A ReconError subclass (``InputError``).
    cpu_s : int, seconds, optional
        CPU time the structural walk may use (default ``CHECK_CPU_S``).
    live : bool
        ``path`` is a live (SWMR) writer's temporary file: walk it as an SWMR reader.
    """
    path = Path(path)
    key = _key(path, live)
    if key not in _VERDICTS:
        try:
            _VERDICTS[key] = _verdict(path, CHECK_CPU_S if cpu_s is None else int(cpu_s), live)
        except OSError as exc:   # no verdict on the file: not cached
            raise error(f"{path}: cannot check its HDF5 structure (cannot start "
                        f"{sys.executable}: {exc.strerror or exc})") from None
    if _VERDICTS[key]:
        raise error(f"{path}: {_VERDICTS[key]}")


def check_whole(path, datasets, error: type[Exception]) -> None:
    """Raise ``error("PATH: /KEY declares shape ...")`` unless ``datasets`` fit in memory
    read whole; call before reading them.

    A dataset's declared shape costs nothing to write (chunks never written read as fill
    values), so an untrusted file can ask for any amount of memory; what its datasets declare,
    at ``HELD_VALUE_BYTES`` a value (or their own size, if larger), is compared with the
    memory available (``formats.memory``).

    Parameters
    ----------
    path : str or Path
        The file, named in the message.
    datasets : sequence of h5py.Dataset
        Datasets of ``path`` about to be read whole; the largest is named.
    error : exception class
        A ReconError subclass (``InputError``).
    """
    largest = max(datasets, key=lambda ds: ds.size)
    n_bytes = sum(ds.size * max(ds.dtype.itemsize, HELD_VALUE_BYTES) for ds in datasets)
    others = len(datasets) - 1
    check_memory(f"{path}: {largest.name} declares shape {largest.shape}; reading it whole"
                 + (f" (with {others} other dataset{'s' * (others > 1)})" if others else ""),
                 n_bytes, error)
