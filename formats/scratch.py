"""Scratch directories that no run leaves behind, interrupted or killed.

A run keeps temporary files (a study case's strike log, a worker's jobs) in directories named
``PREFIX<pid>-XXXX`` in the system's temporary directory, ``pid`` being the process that made
it. They go:

- when the block that made them ends (:func:`directory`), or their owner removes them;
- on an interrupt, when the command line ends its work at once (it skips the interpreter's
  clean-up): :func:`remove_owned` removes this process's directories and those of the
  children it killed (a Dask worker simulating a case);
- after a crash or SIGKILL: the next :func:`make` of the same prefix removes the directories
  whose process is gone.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from formats.atomic import process_alive

# Directories this process made and has not removed yet.
_MINE: set[Path] = set()
# A scratch directory's name: a recon prefix, its owner's process id, mkdtemp's random tail.
_NAME = re.compile(r"^(recon-[a-z]+(?:-[a-z]+)*-)(\d+)-[A-Za-z0-9_]+$")


def _owned(pids: Iterable[int], prefix: str | None = None) -> Iterator[Path]:
    """Scratch directories of ``pids`` in the temporary directory (of ``prefix`` only)."""
    wanted = {int(pid) for pid in pids}
    with contextlib.suppress(OSError):
        for entry in os.scandir(tempfile.gettempdir()):
            match = _NAME.match(entry.name)
            if (match and int(match.group(2)) in wanted and entry.is_dir(follow_symlinks=False)
                    and (prefix is None or match.group(1) == prefix)):
                yield Path(entry.path)


def remove(path) -> None:
    """Delete the scratch directory ``path`` and everything in it (no error if gone)."""
    path = Path(path)
    shutil.rmtree(path, ignore_errors=True)
    _MINE.discard(path)


def remove_stale(prefix: str) -> list[Path]:
    """Delete the directories of ``prefix`` whose process is gone; return them."""
    stale = []
    with contextlib.suppress(OSError):
        for entry in os.scandir(tempfile.gettempdir()):
            match = _NAME.match(entry.name)
            if (match and match.group(1) == prefix and entry.is_dir(follow_symlinks=False)
                    and not process_alive(int(match.group(2)))):
                stale.append(Path(entry.path))
    for path in stale:
        remove(path)
    return stale


def make(prefix: str) -> Path:
    """A new scratch directory ``PREFIX<pid>-XXXX`` (``prefix`` like ``recon-study-``); the
    caller removes it with :func:`remove`."""
    if not _NAME.match(f"{prefix}0-x"):
        raise ValueError(f"prefix must look like 'recon-name-', got {prefix!r}")
    remove_stale(prefix)
    path = Path(tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}-"))
    _MINE.add(path)
    return path


@contextlib.contextmanager
def directory(prefix: str) -> Iterator[Path]:
    """A scratch directory for the block (as ``tempfile.TemporaryDirectory``)."""
    path = make(prefix)
    try:
        yield path
    finally:
        remove(path)


def remove_owned(pids: Iterable[int] = ()) -> None:
    """Delete this process's scratch directories and those of the (killed) processes
    ``pids``: what an interrupted command line does before it exits at once."""
    for path in list(_MINE):
        remove(path)
    for path in list(_owned(pids)):
        remove(path)
