"""Progress within the cases of a sweep, so a long case moves its bar while it runs.

A case (``run_sweep``'s task, in a thread, a local process or a Dask worker) reports how far it
got with ``step(done, total)``: a block of shots simulated, a time prefix scored, a stage of an
isolated fit reached (``isolated_stage``). ``run_sweep``'s bar then shows the finished cases
plus the fractions of the running ones, and redraws every ``REFRESH_S`` whether or not anything
reported, so its clock moves during a case that reports nothing.

The channel is a small file per case in a scratch directory the sweep owns (written by
replacing, read by the sweep's process): it serves threads, local processes and workers on the
same file system. A worker elsewhere writes nothing and its bar advances per finished case.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path

# Seconds between two redraws of a sweep's bar (and reads of its cases' reports).
REFRESH_S = 1.0
# The bar of a sweep: finished cases with one decimal (the running ones' fractions added).
BAR_FORMAT = "{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total_fmt} {unit} [{elapsed}<{remaining}]"
# Seconds between two reports written by one case (a report at the end always goes through).
MIN_INTERVAL_S = 0.5
# How far an isolated fit (``recon.surfaces.isolation``) is at each of its stages.
ISOLATED_STAGES = {"starting": 0.0, "loading": 0.1, "running": 0.2, "checking": 0.8,
                   "scoring": 0.85}

_LOCAL = threading.local()


def _file(channel: Path, key: str) -> Path:
    return channel / (hashlib.sha1(key.encode("utf-8")).hexdigest() + ".progress")


@contextlib.contextmanager
def reporting(channel, key: str) -> Iterator[None]:
    """Within this block, ``step`` in this thread reports case ``key`` into ``channel`` (a
    directory; None: reports go nowhere)."""
    previous = getattr(_LOCAL, "target", None)
    _LOCAL.target = None if channel is None else [_file(Path(channel), key), -MIN_INTERVAL_S]
    try:
        yield
    finally:
        _LOCAL.target = previous


def step(done: float, total: float) -> None:
    """Report that the running case has done ``done`` of ``total`` units of its work.

    Cheap when nothing listens (outside ``reporting``); at most one write per
    ``MIN_INTERVAL_S``; never raises (progress is not worth a failed case).
    """
    target = getattr(_LOCAL, "target", None)
    if target is None or not total > 0:
        return
    fraction = min(max(float(done) / float(total), 0.0), 1.0)
    now = time.monotonic()
    if now - target[1] < MIN_INTERVAL_S and fraction < 1.0:
        return
    target[1] = now
    path = target[0]
    tmp = path.with_name(f"{path.name}.{os.getpid()}.{threading.get_ident()}")
    try:
        tmp.write_text(f"{fraction:.4f}")
        tmp.replace(path)
    except OSError:
        pass


def within(start: float, end: float):
    """A ``step`` for one part of a case: reports ``done / total`` of the part as the case's
    fraction between ``start`` and ``end`` (e.g. the simulation as the first half)."""
    return lambda done, total: step(start + (end - start) * min(done / total, 1.0), 1.0) \
        if total > 0 else None


def isolated_stage(stage: str) -> None:
    """``on_wait`` of ``recon.surfaces.isolation.run_isolated``: the stage as a fraction."""
    step(ISOLATED_STAGES.get(stage, 0.0), 1.0)


class Watcher:
    """The sweep's side: a thread that sets ``bar`` to the finished cases plus the reported
    fractions of the running ones, and redraws it every ``REFRESH_S``.

    Parameters
    ----------
    bar : tqdm.tqdm
        Its ``total`` is the number of cases; its ``n`` is set here (a float).
    channel : Path
        The directory the cases report into.
    finished : int
        Cases already finished (resumed ones).
    """

    def __init__(self, bar, channel: Path, finished: int = 0):
        self.bar, self.channel, self.finished = bar, Path(channel), finished
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="recon-progress", daemon=True)

    def __enter__(self) -> Watcher:
        if not self.bar.disable:
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()

    def done(self, key: str) -> None:
        """Case ``key`` finished: count it whole, forget its reports."""
        with self._lock:
            with contextlib.suppress(OSError):
                _file(self.channel, key).unlink(missing_ok=True)
            self.finished += 1
            self._show(self._running())

    def _running(self) -> float:
        total = 0.0
        for path in self.channel.glob("*.progress"):
            with contextlib.suppress(OSError, ValueError):
                total += min(max(float(path.read_text() or 0.0), 0.0), 1.0)
        return total

    def _show(self, running: float) -> None:
        self.bar.n = min(self.finished + running, self.bar.total or 0)
        self.bar.refresh()

    def _loop(self) -> None:
        while not self._stop.wait(REFRESH_S):
            with self._lock:
                self._show(self._running())
