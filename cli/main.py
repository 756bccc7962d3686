"""Entry point of the ``recon`` command.

Each subcommand lives in its own module under ``cli/`` exposing ``register(subparsers)``, which
adds its parser and sets ``func`` to the callable that runs it. Heavy packages are imported inside
those callables, so ``recon --help`` starts instantly.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import shutil
import signal
import sys
from typing import TYPE_CHECKING

from cli import options

if TYPE_CHECKING:
    from formats.errors import ReconError

# Subcommand modules, in the order `recon --help` lists them: the pipeline's order.
COMMAND_MODULES = (
    "cli.demo",
    "cli.simulate",
    "cli.logs",
    "cli.recover",
    "cli.ingest",
    "cli.score",
    "cli.edges",
    "cli.reconstruct",
    "cli.study",
)


class _Version(argparse.Action):
    """``--version``: prints recon's installed version (looked up only when asked: reading the
    package metadata is a fair share of ``recon --help``'s start)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help="show recon's version and exit"):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from formats.version import __version__

        print(f"recon {__version__}")
        parser.exit()


class _Parser(argparse.ArgumentParser):
    """argparse that says a usage error in one line (it names the argument; ``--help`` shows
    the usage) and exits with status 1 (not 2), like every other user error."""

    def error(self, message: str):
        self.exit(1, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="recon",
        description="Simulate LRF and LIDAR imaging of space objects, register the strikes into "
                    "the target body frame, reconstruct surfaces and score them against truth.")
    parser.add_argument("--version", action=_Version)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def size_progress_bars() -> None:
    """Give the progress bars a size when the terminal reports none.

    Some pseudo-terminals (CI runners, ``script``) report 0 rows or 0 columns; tqdm then draws
    nothing at all (0 rows) or a bar of no width. The sizes ``shutil`` falls back to (the
    ``LINES``/``COLUMNS`` variables, else 24 x 80) go to tqdm's ``TQDM_NROWS``/``TQDM_NCOLS``
    defaults, which every bar of this process and its workers reads; sizes a user set win.
    tqdm reads them when it is imported: call this first (``main`` does, before any command
    module is imported).
    """
    try:
        size = os.get_terminal_size(sys.stderr.fileno())
    except (OSError, ValueError, AttributeError):
        return  # not a terminal: the bars stay off
    fallback = shutil.get_terminal_size()
    if size.lines == 0:
        os.environ.setdefault("TQDM_NROWS", str(fallback.lines or 24))
    if size.columns == 0:
        os.environ.setdefault("TQDM_NCOLS", str(fallback.columns or 80))


def main(argv: list[str] | None = None) -> int:
    """Run ``recon`` with ``argv`` (default: ``sys.argv[1:]``); return the exit status."""
    size_progress_bars()
    parser = build_parser()
    args = parser.parse_args(argv)   # --help and usage errors end here, before any import below
    args.own_process = argv is None   # the recon command itself, not a caller of main(argv)
    if args.command is None:
        parser.print_help()
        return 1
    from formats import interrupt, paths
    from formats.errors import ReconError, ResourceError

    try:
        with interrupt.handled(), paths.protecting(options.inputs_of(args)):
            _check_outputs(args)
            status = int(args.func(args) or 0)
            interrupt.check()   # a signal whose exception a library swallowed
        return status
    except ResourceError as exc:
        # HDF5 cannot shut down after a failed write (its exit-time flush crashes with SIGSEGV,
        # measured with HDF5 2.0): the temporary file is gone, so leave without finalisers.
        print(f"recon {args.command}: error: {_one_line(exc)}", file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(1)
    except ReconError as exc:
        print(f"recon {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        return _interrupted(args, getattr(exc, "signum", signal.SIGINT), argv)
    except BrokenPipeError:
        # The reader of the output went away (recon ... | head): stop quietly, with the status
        # of a process ended by SIGPIPE, as other Unix tools do. Outputs not yet closed were
        # dropped as the error unwound; stdout goes to /dev/null so the interpreter's last
        # flush does not raise again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + signal.SIGPIPE
    except Exception:
        # A signal that lands in a lazy import of a C extension (open3d) surfaces as that
        # import's ImportError ("initialization failed"), not as the interrupt.
        if interrupt.received() is None:
            raise
        return _interrupted(args, interrupt.received(), argv)


def _check_outputs(args) -> None:
    """Refuse, before any work, two outputs that name one file (the second would write over
    the first), and an output that is an existing file the command reads (the writers refuse
    it again, with the files of output directories, as they open)."""
    from formats import paths

    outputs = options.outputs_of(args)
    named: dict[str, str] = {}
    for dest, output in outputs.items():
        first = named.setdefault(os.path.realpath(output), dest)
        if first != dest:
            raise options.UsageError(f"{output}: named by both {options.flag(first)} and "
                                     f"{options.flag(dest)}; give each output its own file")
        if os.path.isfile(output):
            paths.check_destination(output, options.UsageError)


def _interrupted(args, signum: int, argv) -> int:
    from formats import interrupt

    print(f"recon {args.command}: interrupted ({signal.Signals(signum).name}); outputs "
          "left as they were", file=sys.stderr)
    return _leave_now(interrupt.EXIT_STATUS.get(signum, 130), at_once=argv is None)


def _leave_now(status: int, *, at_once: bool = False) -> int:
    """After an interrupt: when work is still running (a Dask cluster's workers, an isolated
    method run, a thread in a long library call), or ``at_once`` (the ``recon`` command itself,
    not a caller of ``main(argv)``), end it and exit at once.

    The interpreter's own shutdown after a run that loaded Open3D, h5py and a few hundred MB
    of arrays can take longer than the 2 s bound (docs/decisions.md, "Measurements behind the
    defaults").

    Every writer has already dropped its temporary file while the interrupt unwound the stack,
    so nothing is left to finish; waiting would only let a cluster that was still starting
    fail its shutdown with a traceback, or a long C call run to its end. The children get
    SIGKILL: on SIGTERM Dask's workers print a traceback each (Dask clears their scratch
    directories when the next cluster starts).
    """
    import threading

    import psutil

    from formats import scratch

    children = psutil.Process().children(recursive=True)
    busy = [t for t in threading.enumerate()
            if t is not threading.current_thread() and not t.daemon and t.is_alive()]
    if not children and not busy and not at_once:
        return status
    for child in children:
        with contextlib.suppress(psutil.Error):
            child.kill()
    # The interpreter's clean-up is skipped: remove the scratch directories (a worker's jobs,
    # a study case's log) of this process and of the children just killed (a killed process
    # writes nothing more; waiting for them would let this process's threads restart helpers,
    # such as multiprocessing's resource tracker, which then print tracebacks).
    scratch.remove_owned(child.pid for child in children)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


# Longest error message printed: a hostile value (a 5 MB scene string) is cut, not echoed.
MAX_MESSAGE_CHARS = 500


def _one_line(exc: ReconError) -> str:
    """The message of ``exc``, in the command line's words (``options.message``), on one line
    of at most MAX_MESSAGE_CHARS characters."""
    text = " ".join(options.message(exc).split("\n"))
    if len(text) > MAX_MESSAGE_CHARS:
        # the start names the file or key, the end often says what is wrong: keep both
        keep = (MAX_MESSAGE_CHARS - 40) // 2
        text = (f"{text[:keep]} ... ({len(text) - 2 * keep:,} characters cut) ... "
                f"{text[-keep:]}")
    return text


if __name__ == "__main__":
    sys.exit(main())
