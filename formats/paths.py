"""What a path given as an input or an output is, checked before any work starts.

Inputs are regular files recon can read: a missing file, a directory, a device (``/dev/zero``), a
FIFO, a socket, a file of the kernel's ``/proc`` or ``/sys`` file systems (``/proc/self/mem``
reads fail, ``/proc/kmsg`` blocks) and a file that cannot be read (permissions, I/O errors) are
each refused with one line saying what they are. A FIFO would block a reader forever, a device
would be read without end.

Outputs are new names or regular files in a directory that exists and can be written; never a
directory, device, FIFO or socket (which a writer would replace by a regular file), and never one
of the run's own inputs: while :func:`protecting` is active (``recon`` keeps it active around
every command), a destination that is the same file as an input (same device and inode, so also
through a symbolic or hard link) is refused before anything is written.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from collections.abc import Iterable, Iterator
from pathlib import Path

from formats.errors import ParameterError, ReconError

# Files of the inputs the current run reads, by (device, inode): the destinations it must not
# replace (``protecting``).
_INPUTS: dict[tuple[int, int], Path] = {}
# Kernel file systems whose "regular" files are interfaces, not data.
_KERNEL_FILE_SYSTEMS = ("/proc", "/sys")


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def _reason(exc: OSError) -> str:
    """The OS's words for ``exc`` ("Permission denied", "File name too long")."""
    return exc.strerror or os.strerror(exc.errno or 0) or type(exc).__name__


def _kernel_file(st: os.stat_result) -> str | None:
    """The kernel file system (``/proc``, ``/sys``) that holds the file of ``st``, if any."""
    for root in _KERNEL_FILE_SYSTEMS:
        with contextlib.suppress(OSError):
            if os.stat(root).st_dev == st.st_dev:
                return root
    return None


def check_source(path, error: type[Exception] = OSError) -> Path:
    """Refuse an input that is missing, not a regular file or cannot be read, with one line
    naming ``path``.

    The file is opened and its first byte read (without blocking), so a reader that follows
    meets no permission or I/O error at its first read.

    Parameters
    ----------
    path : str or Path
    error : exception class
        Raised (a ReconError subclass in recon).

    Returns
    -------
    Path
    """
    path = Path(path)
    try:
        st = path.stat()
    except FileNotFoundError:
        raise error(f"{path}: no such file") from None
    except OSError as exc:
        raise error(f"{path}: cannot be read ({_reason(exc)})") from None
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{path}: is {_kind(st.st_mode)}, not a file")
    kernel = _kernel_file(st)
    if kernel is not None:
        raise error(f"{path}: is a file of the kernel's {kernel} file system, not a data file")
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
        try:
            os.read(fd, 1)
        finally:
            os.close(fd)
    except OSError as exc:
        raise error(f"{path}: cannot be read ({_reason(exc)})") from None
    return path


def same_file(a, b) -> bool:
    """Whether ``a`` and ``b`` name one existing file (same device and inode: symbolic and hard
    links to a file are that file)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


@contextlib.contextmanager
def protecting(inputs: Iterable) -> Iterator[None]:
    """While active, :func:`check_destination` refuses any destination that is one of
    ``inputs`` (same device and inode). Names that are not existing files are ignored.

    Parameters
    ----------
    inputs : iterable of str or Path
        The files the run reads.
    """
    added = {}
    for item in inputs:
        try:
            st = os.stat(item)
        except (OSError, ValueError, TypeError):
            continue
        if stat.S_ISREG(st.st_mode) and (st.st_dev, st.st_ino) not in _INPUTS:
            added[st.st_dev, st.st_ino] = Path(item)
    _INPUTS.update(added)
    try:
        yield
    finally:
        for key in added:
            _INPUTS.pop(key, None)


def check_destination(path, error: type[Exception] = OSError) -> Path:
    """Refuse a destination a writer must not replace; call before any work starts.

    Refused: a name too long for the file system, a directory that does not exist or cannot be
    written, a destination that is a directory, device, FIFO or socket, one of the inputs
    :func:`protecting` holds, and a symbolic link (the atomic rename would replace the link, not
    write where it points).

    Parameters
    ----------
    path : str or Path
    error : exception class
        Raised (a ReconError subclass in recon) with one line naming ``path``.

    Returns
    -------
    Path
    """
    path = Path(path)
    try:
        st = path.stat()
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise error(f"{path}: cannot be written ({_reason(exc)})") from None
    parent = path.parent
    try:
        parent_mode = parent.stat().st_mode
    except FileNotFoundError:
        raise error(f"{path}: directory {parent} does not exist") from None
    except OSError as exc:
        raise error(f"{path}: cannot be written ({_reason(exc)})") from None
    if not stat.S_ISDIR(parent_mode):
        raise error(f"{path}: {parent} is not a directory")
    if st is not None:
        if not stat.S_ISREG(st.st_mode):
            raise error(f"{path}: is {_kind(st.st_mode)}; give the name of a file to write")
        source = _INPUTS.get((st.st_dev, st.st_ino))
        if source is not None:
            same = "" if source == path else f" ({source})"
            raise error(f"{path}: is an input of this run{same}; writing it would destroy the "
                        "input, give another output name")
    if path.is_symlink():
        raise error(f"{path}: is a symbolic link; give the name of a regular file to write "
                    f"(or {path.resolve()} itself)")
    reason = _unwritable(parent)
    if reason is not None:
        raise error(f"{path}: cannot write in {parent} ({reason})")
    return path


def _unwritable(directory: Path) -> str | None:
    """Why no new file can be created in ``directory`` (read-only, no permission), or None when
    one can: the writer's temporary file goes there. Tried, not guessed from mode bits, which a
    privileged user or a read-only mount contradict."""
    try:
        fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
        os.close(fd)
        probe = os.open(directory, os.O_WRONLY | os.O_TMPFILE, 0o600)
        os.close(probe)
    except AttributeError:   # no O_TMPFILE on this system: the writer meets the error itself
        return None
    except OSError as exc:
        if exc.errno in (errno.EOPNOTSUPP, errno.EISDIR, errno.EINVAL):
            return None   # a file system without O_TMPFILE
        return _reason(exc)
    return None


def output_directory(path, error: type[ReconError] = ParameterError) -> Path:
    """The output directory ``path`` (the argument ``output``), created if missing; refuses a
    path that is a file or a directory that cannot be written.

    Parameters
    ----------
    path : str or Path
    error : ReconError subclass
        Raised with one line starting with ``output`` and naming ``path``
        (``argument="output"``).

    Returns
    -------
    Path
    """
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        mode = None
    except OSError as exc:
        raise error(f"output {path}: cannot be written ({_reason(exc)})",
                    argument="output") from None
    if mode is not None and not stat.S_ISDIR(mode):
        raise error(f"output {path}: is a file, not a directory", argument="output")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise error(f"output {path}: cannot create the directory ({_reason(exc)})",
                    argument="output") from None
    reason = _unwritable(path)
    if reason is not None:
        raise error(f"output {path}: cannot write in the directory ({reason})",
                    argument="output")
    return path


@contextlib.contextmanager
def writing_into(path, error: type[ReconError] = ParameterError) -> Iterator[Path]:
    """:func:`output_directory` for the block that writes into it: when the block raises, the
    directories this call created (``path`` and its missing parents) are removed again while
    they are empty, so a refused or failed run leaves no empty output directory behind.

    Parameters
    ----------
    path : str or Path
    error : ReconError subclass
        As :func:`output_directory`.

    Yields
    ------
    Path
    """
    path = Path(path)
    created = [directory for directory in (path, *path.parents) if not directory.exists()]
    output_directory(path, error)
    try:
        yield path
    except BaseException:
        for directory in created:   # the innermost first
            try:
                directory.rmdir()
            except OSError:   # not empty (or gone): it and its parents stay
                break
        raise
