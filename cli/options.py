"""Subcommand parsers and the command-line options several commands share: sweeps on Dask,
truth meshes, outputs."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_command(subparsers, name: str, handler, **parser_options):
    """Add the subcommand ``name``, run by ``handler(args)``, and return its parser.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
    name : str
    handler : callable
        Called with the parsed arguments; returns the exit code (``args.func`` in cli/main.py).
    **parser_options
        ``help``, ``description``, ``epilog``... as for ``add_parser``.

    Returns
    -------
    argparse.ArgumentParser
    """
    parser = subparsers.add_parser(name, **parser_options)
    parser.set_defaults(func=handler)
    return parser


def _scheduler(text: str) -> str:
    """argparse type of ``--scheduler``: checked before any work starts."""
    from recon.experiments.sweep import SweepError, check_scheduler

    try:
        return check_scheduler(text)
    except SweepError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_sweep_options(parser, *, resume_help: str) -> None:
    """``--scheduler``, ``--workers`` and ``--resume`` (recon.experiments.sweep's schedulers).

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
    resume_help : str
        What ``--resume`` keeps, in the command's own words.
    """
    parser.add_argument("--scheduler", metavar="ADDRESS", type=_scheduler,
                        help="Dask scheduler address of an existing cluster (default: a local "
                             "cluster); 'threads' or 'serial' run without Dask")
    parser.add_argument("--workers", type=int, metavar="N",
                        help="local workers (default: one per core)")
    parser.add_argument("--resume", action="store_true", help=resume_help)




def add_truth_and_output_options(parser, *, truth_help: str, truth_required: bool) -> None:
    """``--truth`` and ``--truth-scale``, the mesh that surfaces are scored against, and ``-o``,
    the directory the scores are written to.

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
    truth_help : str
        Where the truth may come from, in the command's own words.
    truth_required : bool
        Whether the command needs ``--truth`` (it may find the truth in a log or a scene).
    """
    parser.add_argument("--truth", required=truth_required, help=truth_help)
    parser.add_argument("--truth-scale", type=float, default=1.0,
                        help="factor on a truth mesh file's coordinates (e.g. 1000 for km)")
    parser.add_argument("-o", "--output", type=Path, required=True, help="output directory")
