"""Entry point of the ``recon`` command.

Each subcommand lives in its own module under ``cli/`` exposing ``register(subparsers)``, which
adds its parser and sets ``func`` to the callable that runs it. Heavy packages are imported inside
those callables, so ``recon --help`` starts instantly.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from formats.errors import ReconError
from formats.version import __version__

# Subcommand modules, in the order `recon --help` lists them: the pipeline's order.
COMMAND_MODULES = (
    "cli.demo",
    "cli.simulate",
    "cli.logs",
    "cli.ingest",
    "cli.score",
    "cli.edges",
    "cli.reconstruct",
    "cli.study",
)


class _Parser(argparse.ArgumentParser):
    """argparse that exits with status 1 (not 2) on a usage error, like every other user error."""

    def error(self, message: str):
        self.print_usage(sys.stderr)
        self.exit(1, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="recon",
        description="Simulate LRF and LIDAR imaging of space objects, register the strikes into "
                    "the target body frame, reconstruct surfaces and score them against truth.")
    parser.add_argument("--version", action="version", version=f"recon {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``recon`` with ``argv`` (default: ``sys.argv[1:]``); return the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 1
    try:
        return int(args.func(args) or 0)
    except ReconError as exc:
        print(f"recon {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"recon {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
