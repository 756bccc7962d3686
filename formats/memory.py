"""Memory a job needs, checked before it starts.

A file can declare far more data than it holds: an HDF5 dataset declared with 2**36 rows and
nothing written costs a few bytes on disk, and a compressed log of a few MB can declare 1e8
strikes. Reading such data whole, or building a problem sized from it, is checked here first
and refused with one line naming what is too large, instead of failing half-way with a
traceback (or taking the machine's memory from everyone else).
"""

from __future__ import annotations

import os
import resource


def proc_bytes(path: str, field: str) -> int | None:
    """The ``FIELD: N kB`` line of a /proc file (``/proc/meminfo``, ``/proc/PID/status``) in
    bytes; None when unreadable (the process is gone, or not Linux)."""
    try:
        with open(path) as lines:
            for line in lines:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def total_bytes() -> int | None:
    """The machine's memory (``MemTotal``) in bytes; None when unknown."""
    return _meminfo_bytes("MemTotal", "SC_PHYS_PAGES")


def _meminfo_bytes(field: str, pages: str) -> int | None:
    """``field`` of /proc/meminfo in bytes, else the ``pages`` sysconf count times the page
    size; None when neither is known."""
    value = proc_bytes("/proc/meminfo", field)
    if value is None and hasattr(os, "sysconf"):
        try:
            value = os.sysconf(pages) * os.sysconf("SC_PAGE_SIZE")
        except (OSError, ValueError):
            value = None
    return value


def available_bytes() -> int | None:
    """Bytes this process can still allocate: the memory the system has available
    (``MemAvailable``), and no more than the address space its limit leaves (``RLIMIT_AS``,
    ``ulimit -v``, beyond its current size); None when neither is known.

    Returns
    -------
    int or None, bytes
    """
    available = _meminfo_bytes("MemAvailable", "SC_AVPHYS_PAGES")
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    size = proc_bytes("/proc/self/status", "VmSize")
    if soft != resource.RLIM_INFINITY and size is not None:
        left = max(0, soft - size)
        available = left if available is None else min(available, left)
    return available


def size_text(n_bytes: float) -> str:
    """``n_bytes`` for a message: ``"384.0 GB"``, ``"12.5 MB"`` (decimal units)."""
    return f"{n_bytes / 1e9:,.1f} GB" if n_bytes >= 1e9 else f"{n_bytes / 1e6:,.1f} MB"


def check_memory(what: str, n_bytes: float, error: type[Exception], advice: str = "") -> None:
    """Refuse work that needs about ``n_bytes`` of memory when less is available.

    Parameters
    ----------
    what : str
        The start of the message, naming the file, key or argument, up to the subject of
        "needs" (``"LOG.h5: /sensor/beam_directions declares shape (17179869184, 3); reading
        it"``).
    n_bytes : float, bytes
        Memory the work needs.
    error : exception class
        Raised (a ReconError subclass) with one line: ``what``, the memory needed and
        available, then ``advice`` when given.
    advice : str
        What the user can do instead (``"recon ingest streams the log to a file"``).
    """
    available = available_bytes()
    if available is None or n_bytes <= available:
        return
    raise error(f"{what} needs about {size_text(n_bytes)} of memory but only "
                f"{size_text(available)} is available" + (f"; {advice}" if advice else ""))
