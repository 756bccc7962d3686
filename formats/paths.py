"""What a path given as an input or an output is, checked before any work starts.

Inputs and outputs are regular files. A directory, a device (``/dev/zero``), a FIFO or a socket
is refused with one line saying what it is: a FIFO would block a reader forever, a device would
be read without end or, as an output, replaced by a regular file.
"""

from __future__ import annotations

import stat
from pathlib import Path


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def check_source(path, error: type[Exception] = OSError) -> Path:
    """Refuse an input that is missing or not a regular file, with one line naming ``path``.

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
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise error(f"{path}: no such file") from None
    except OSError as exc:
        raise error(f"{path}: cannot be read ({exc.strerror})") from None
    if not stat.S_ISREG(mode):
        raise error(f"{path}: is {_kind(mode)}, not a file")
    return path


def check_destination(path, error: type[Exception] = OSError) -> Path:
    """Refuse a destination a writer must not replace; call before any work starts.

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
    if not path.parent.is_dir():
        raise error(f"{path}: directory {path.parent} does not exist")
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return path
    except OSError as exc:
        raise error(f"{path}: cannot be written ({exc.strerror})") from None
    if not stat.S_ISREG(mode):
        raise error(f"{path}: is {_kind(mode)}; give the name of a file to write")
    return path


def output_directory(path, error: type[Exception] = OSError) -> Path:
    """The output directory ``-o path``, created if missing; refuses a path that is a file.

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
    if path.exists() and not path.is_dir():
        raise error(f"-o {path}: is a file, not a directory")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise error(f"-o {path}: cannot create the directory ({exc.strerror})") from None
    return path
