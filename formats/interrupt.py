"""Ctrl-C and SIGTERM that always stop a run, even when Python swallows the exception.

Python raises ``KeyboardInterrupt`` from a signal handler at whatever bytecode runs next. When
that is a weak-reference callback or a ``__del__`` (h5py and the standard library's
``WeakValueDictionary`` run many), the interpreter prints "Exception ignored in ..." and carries
on, and the run completes as if nothing happened. :func:`handled` therefore both raises and
records the signal; every writer checks the record (:func:`check`) on each write and before
it publishes its file, so a swallowed interrupt still stops the run at the next block and never
replaces an output.

Only the command line installs the handlers, with :func:`handled` (a library must not take over
its caller's signals); :func:`check` is a no-op outside that block.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
import weakref

# Exit status of a run stopped by a signal: 128 + the signal's number (shells' convention).
EXIT_STATUS = {signal.SIGINT: 128 + signal.SIGINT, signal.SIGTERM: 128 + signal.SIGTERM}

_received: list[int] = []


class Interrupted(KeyboardInterrupt):
    """Raised when SIGINT or SIGTERM arrived; ``signum`` says which."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _swallowing(frame) -> bool:
    """True when an exception raised in ``frame`` would be ignored: a finaliser or a
    weak-reference callback (the interpreter prints it and carries on)."""
    if frame is None:
        return False
    code = frame.f_code
    return code.co_name == "__del__" or code.co_filename == weakref.__file__


def _handler(signum, frame) -> None:
    _received.append(signum)
    # What libraries log while they are torn down (a Dask cluster interrupted while starting
    # logs each worker that never started, with its traceback) is noise after a Ctrl-C.
    logging.disable(logging.CRITICAL)
    if not _swallowing(frame):   # else the next check() raises it
        raise Interrupted(signum)


@contextlib.contextmanager
def handled():
    """Within the block, SIGINT and SIGTERM raise :class:`Interrupted` and are recorded for
    :func:`check`; the previous handlers come back after it.

    Only the main thread can set handlers; in another thread the block runs unchanged.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _received.clear()
    previous = {signum: signal.signal(signum, _handler) for signum in EXIT_STATUS}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if _received:
            logging.disable(logging.NOTSET)


def received() -> int | None:
    """The first signal received in the last :func:`handled` block, or None."""
    return _received[0] if _received else None


def check() -> None:
    """Raise :class:`Interrupted` if a signal arrived, even one whose exception was swallowed."""
    if _received:
        raise Interrupted(_received[0])
