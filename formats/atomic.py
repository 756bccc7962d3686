"""One mechanism for every writer: write under a temporary name, rename into place on close.

An interrupted run (an exception, a crash, a writer dropped without ``close``) leaves no file that
looks complete and never replaces an existing output.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path


class AtomicWriter:
    """Base of writers that publish ``path`` only when they close cleanly.

    Subclasses open their handle on ``self.temporary`` (an empty file created beside ``path``)
    and implement ``_finish`` (complete and close the handle, raising if the content is
    incomplete) and ``_release`` (close the handle after a failure). ``missing_dir_error`` is the
    ReconError subclass raised when the destination's directory does not exist.

    Parameters
    ----------
    path : str or Path
        Destination.
    suffix : str
        Suffix of the temporary name (some libraries pick the format from it).
    """

    missing_dir_error: type[Exception] = OSError

    def __init__(self, path, *, suffix: str = ""):
        self.path = Path(path)
        if not self.path.parent.is_dir():
            raise self.missing_dir_error(
                f"{self.path}: directory {self.path.parent} does not exist")
        fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.partial-", dir=self.path.parent,
                                   suffix=suffix)
        os.close(fd)
        self.temporary = Path(tmp)
        self.closed = False

    def _finish(self) -> None:
        raise NotImplementedError

    def _release(self) -> None:
        raise NotImplementedError

    def close(self) -> None:
        """Complete the file and move it into place (a no-op when already closed)."""
        if self.closed:
            return
        try:
            self._finish()
            os.replace(self.temporary, self.path)
        except BaseException:
            self.abort()
            raise
        self.closed = True

    def abort(self) -> None:
        """Drop the temporary file; the destination is left as it was."""
        self.closed = True
        with contextlib.suppress(Exception):
            self._release()
        self.temporary.unlink(missing_ok=True)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def __del__(self):  # a writer dropped without close() is an interrupted run
        if not getattr(self, "closed", True):
            self.abort()
