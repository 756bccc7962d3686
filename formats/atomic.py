"""One mechanism for every writer: write under a temporary name, rename into place on close.

An interrupted run (an exception, Ctrl-C, SIGTERM, a crash, a writer dropped without ``close``)
leaves no file that looks complete and never replaces an existing output:

- the destination is checked before any work starts (:func:`check_destination`): only a new
  name or an existing regular file may be replaced, never a directory, a device, a FIFO or a
  socket, and the directory must exist;
- the temporary file ``.NAME.partial-PID-XXXX`` lives beside the destination; it is removed on
  every exit Python sees (exceptions, signals turned into exceptions by ``formats.interrupt``,
  interpreter exit), and one left by a killed process (SIGKILL, power loss) is removed by the
  next writer of the same name once its process is gone;
- the finished file gets the permissions of a newly created file (``0o666`` minus the umask);
- a full disk is one line naming the destination (``ResourceError``), never a traceback or a crash.
"""

from __future__ import annotations

import atexit
import contextlib
import errno
import os
import re
import shutil
import tempfile
import weakref
from collections.abc import Iterator
from pathlib import Path

from formats import interrupt
from formats.errors import ReconError, ResourceError
from formats.paths import check_destination

# errno values that mean "the disk (or the user's quota, or the file-size limit) is full".
_FULL_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}
# How HDF5 reports them inside its messages (h5py does not always set OSError.errno).
_FULL_TEXT = re.compile(r"errno = (28|27|122)\b|No space left on device|File too large|"
                        r"Disk quota exceeded")
# Free space kept beyond an estimate before a run starts: the estimate is of the data alone.
SPACE_MARGIN = 1.05
# Bytes a writer may buffer before it flushes: HDF5 must meet a full disk inside a write call,
# with little data in its cache, or its close and exit crash (SIGSEGV, measured with HDF5 2.0
# on a full tmpfs). Flushing every call costs 12x on 1,000-row calls; every 16 MB, under 3%.
FLUSH_BYTES = 16 << 20

_OPEN: weakref.WeakSet = weakref.WeakSet()   # writers not yet closed, aborted at exit


def check_space(path, n_bytes: float, error: type[Exception] = ResourceError) -> None:
    """Refuse to start a write of about ``n_bytes`` that the destination's disk cannot hold."""
    path = Path(path)
    try:
        free = shutil.disk_usage(path.parent).free
    except OSError:
        return
    if n_bytes * SPACE_MARGIN > free:
        raise error(f"{path}: needs about {n_bytes / 1e6:,.1f} MB but {path.parent} has "
                    f"{free / 1e6:,.1f} MB free")


def is_disk_full(exc: BaseException) -> bool:
    """True when ``exc`` (an OSError, or h5py's RuntimeError) reports a full disk or quota."""
    if isinstance(exc, OSError) and exc.errno in _FULL_ERRNOS:
        return True
    return isinstance(exc, OSError | RuntimeError) and bool(_FULL_TEXT.search(str(exc)))


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def process_alive(pid: int) -> bool:
    """Whether a process with id ``pid`` exists (ours or another user's)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:   # someone else's process
        return True
    return True


def partial_pid(path) -> int | None:
    """The writer's process id in the name of a temporary file ``.NAME.partial-PID-XXXX``."""
    match = re.match(r"^\..+\.partial-(\d+)-", Path(path).name)
    return None if match is None else int(match.group(1))


# Suffix of a live writer's temporary file: a dead live writer's file holds committed rows that
# ``recon recover`` turns into a log, so it is never removed as stale.
LIVE_SUFFIX = ".live"


def remove_stale_partials(path) -> list[Path]:
    """Delete the temporary files of ``path`` left by writers whose process is gone (except a
    live writer's, ``LIVE_SUFFIX``: recoverable).

    Returns the files removed.
    """
    path = Path(path)
    pattern = re.compile(rf"^\.{re.escape(path.name)}\.partial-(\d+)-")
    removed = []
    with contextlib.suppress(OSError):
        for entry in os.scandir(path.parent):
            match = pattern.match(entry.name)
            pid = int(match.group(1)) if match else None
            if (pid is not None and pid != os.getpid() and not process_alive(pid)
                    and not entry.name.endswith(LIVE_SUFFIX)):
                with contextlib.suppress(OSError):
                    os.unlink(entry.path)
                    removed.append(Path(entry.path))
    return removed


class AtomicWriter:
    """Base of writers that publish ``path`` only when they close cleanly.

    Subclasses open their handle on ``self.temporary`` (an empty file created beside ``path``)
    and implement ``_finish`` (complete and close the handle, raising if the content is
    incomplete) and ``_release`` (close the handle after a failure); their write methods call
    ``self._check()`` first. ``missing_dir_error`` is the ReconError subclass raised for a
    destination that cannot be written (no such directory, a directory, a device...).

    Parameters
    ----------
    path : str or Path
        Destination.
    suffix : str
        Suffix of the temporary name (some libraries pick the format from it).
    """

    missing_dir_error: type[Exception] = OSError

    def __init__(self, path, *, suffix: str = ""):
        self.closed = True
        self.path = check_destination(path, self.missing_dir_error)
        remove_stale_partials(self.path)
        try:
            fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.partial-{os.getpid()}-",
                                       dir=self.path.parent, suffix=suffix)
        except OSError as exc:
            raise self._error(exc) from None
        os.close(fd)
        self.temporary = Path(tmp)
        self.closed = False
        _OPEN.add(self)

    def _finish(self) -> None:
        raise NotImplementedError

    def _release(self) -> None:
        raise NotImplementedError

    def _flush(self) -> None:
        """Push buffered data to the file (subclasses that buffer override it)."""

    def _published(self) -> None:
        """Called once the file is in place (subclasses may record it)."""

    def _check(self) -> None:
        """Call at the start of every write: refuse a closed writer, stop on a signal."""
        if self.closed:
            raise self.missing_dir_error(f"{self.path}: the writer is closed")
        interrupt.check()

    def _wrote(self, n_bytes: int) -> None:
        """Call after every write of ``n_bytes``: flushes every ``FLUSH_BYTES``."""
        self._unflushed = getattr(self, "_unflushed", 0) + n_bytes
        if self._unflushed >= FLUSH_BYTES:
            self._unflushed = 0
            self._flush()

    def _error(self, exc: BaseException) -> Exception:
        """The one-line error of an OS failure while writing ``path``."""
        if is_disk_full(exc):
            return ResourceError(f"{self.path}: no space left on device (or quota exceeded) in "
                            f"{self.path.parent}")
        reason = getattr(exc, "strerror", None) or str(exc).splitlines()[0]
        return self.missing_dir_error(f"{self.path}: cannot write ({reason})")

    def close(self) -> None:
        """Complete the file and move it into place (a no-op when already closed)."""
        if self.closed:
            return
        try:
            interrupt.check()
            self._finish()
            os.chmod(self.temporary, 0o666 & ~_umask())
            interrupt.check()
            os.replace(self.temporary, self.path)
            self._published()
        except (OSError, RuntimeError) as exc:
            self.abort(disk_full=is_disk_full(exc))
            if isinstance(exc, ReconError):
                raise
            raise self._error(exc) from None
        except BaseException:
            self.abort()
            raise
        self.closed = True

    def abort(self, *, disk_full: bool = False) -> None:
        """Drop the temporary file; the destination is left as it was.

        The name goes first, so no partial file is left even if closing the handle fails.
        After a full disk the file is emptied before its handle closes: HDF5 flushes on close,
        and a flush that fails again leaves it in a state that crashes the process (SIGSEGV,
        measured with HDF5 2.0); emptied, the flush has room.
        """
        if getattr(self, "closed", True):
            return
        self.closed = True
        if disk_full:
            with contextlib.suppress(OSError):
                os.truncate(self.temporary, 0)
        with contextlib.suppress(OSError):
            self.temporary.unlink()
        with contextlib.suppress(Exception):
            self._release()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
            return
        full = not isinstance(exc, ReconError) and is_disk_full(exc)
        self.abort(disk_full=full)
        if full:
            raise self._error(exc) from None

    def __del__(self):  # a writer dropped without close() is an interrupted run
        self.abort()


@atexit.register
def _abort_open_writers() -> None:
    for writer in list(_OPEN):
        writer.abort()


class _WholeFile(AtomicWriter):
    """A file written at once by a callback (a JSON summary, a chart): nothing to finish."""

    def __init__(self, path, *, suffix: str, error: type[Exception]):
        self.missing_dir_error = error
        super().__init__(path, suffix=suffix)

    def _finish(self) -> None:
        pass

    def _release(self) -> None:
        pass


def write_atomically(path, write, *, error: type[Exception] = OSError) -> Path:
    """Call ``write(temporary)`` on a temporary file beside ``path``, then rename it to ``path``.

    The same guarantees as every :class:`AtomicWriter`: the destination is checked first, an
    interrupted or failed ``write`` leaves the old file and no partial, a full disk is one line.

    Parameters
    ----------
    path : str or Path
        Destination.
    write : callable
        Called with the temporary path (its suffix is ``path``'s: libraries such as matplotlib
        pick the format from it); it writes the whole file.
    error : exception class
        Raised, with one line naming ``path``, for a destination that cannot be written.

    Returns
    -------
    Path
    """
    with _WholeFile(path, suffix=Path(path).suffix, error=error) as writer:
        write(writer.temporary)
    return writer.path


@contextlib.contextmanager
def written_together(paths, *, error: type[Exception] = OSError) -> Iterator[list[Path]]:
    """Write several files as one set: the block fills a temporary file beside each
    destination, and only when it ends cleanly are they all renamed into place, one after the
    other.

    Every destination is checked (as :func:`write_atomically` checks its one) before the block
    runs, so the work inside it starts only when all of them can be written; an exception or an
    interrupt inside it leaves every old file as it was and no partial file.

    Parameters
    ----------
    paths : iterable of str or Path
        Destinations.
    error : exception class
        Raised, with one line naming the destination, for one that cannot be written.

    Yields
    ------
    list of Path
        The temporary files, in the order of ``paths``, each with its destination's suffix
        (libraries such as matplotlib pick the format from it).
    """
    with contextlib.ExitStack() as writers:
        yield [writers.enter_context(_WholeFile(path, suffix=Path(path).suffix,
                                                error=error)).temporary for path in paths]


def write_text_atomically(path, text: str, *, error: type[Exception] = OSError) -> Path:
    """Write ``text`` (UTF-8) to ``path`` with :func:`write_atomically`."""
    return write_atomically(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"),
                            error=error)
