"""Subcommand parsers and the command-line options several commands share: sweeps on Dask,
truth meshes, outputs, lists, and usage lines that show what is required."""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path

from formats.errors import ReconError

# Arguments (argparse ``dest``) that name what a command writes; every other argument that
# names an existing file is an input the command must not write over (``inputs_of``).
OUTPUT_DESTS = ("output", "refine_json")


# Options whose name is not the API parameter's with "-" for "_" (``memory_limit`` ->
# ``--memory-limit``): library errors name the parameter (``ReconError.argument``), the command
# line prints the option.
FLAGS = {"feature_angle_deg": "--feature-angle", "interval": "--refine-interval",
         "n_workers": "--workers", "output": "-o", "overrides": "--set", "params": "--param",
         "timeout_s": "--timeout"}


class UsageError(ReconError, ValueError):
    """Arguments that do not go together (an output that is one of the inputs...)."""


def flag(argument: str) -> str:
    """The option that sets the API parameter ``argument`` (``"overrides"`` -> ``"--set"``)."""
    return FLAGS.get(argument, "--" + argument.replace("_", "-"))


def message(exc: ReconError) -> str:
    """``exc``'s message as the command line says it: the API parameter it starts with, if any,
    named by its option (``--resume: ...`` where ``recon.api`` says ``resume: ...``)."""
    return exc.worded(flag)


def inputs_of(args: argparse.Namespace) -> list[str]:
    """Every argument value (or list item) of ``args`` that may name an input file: all but the
    outputs (``OUTPUT_DESTS``). ``formats.paths.protecting`` keeps those that are files."""
    values = []
    for dest, value in vars(args).items():
        if dest in OUTPUT_DESTS:
            continue
        for item in value if isinstance(value, list | tuple) else [value]:
            if isinstance(item, str | os.PathLike):
                values.append(item)
    return values


def outputs_of(args: argparse.Namespace) -> dict[str, Path]:
    """The output arguments (``OUTPUT_DESTS``) given in ``args``, by ``dest``."""
    return {dest: Path(v) for dest in OUTPUT_DESTS if (v := getattr(args, dest, None)) is not None}


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


class _ListAction(argparse.Action):
    """Collect a list option's items: ``--methods a,b`` (the one documented syntax), also
    ``--methods a b`` and ``--methods a --methods b``."""

    def __call__(self, parser, namespace, values, option_string=None):
        current = getattr(namespace, self.dest, None)
        items = [] if current is None or current is self.default else list(current)
        given = [item.strip() for value in values for item in value.split(",") if item.strip()]
        if not given:
            parser.error(f"{option_string} needs at least one name or value, got "
                         f"{' '.join(repr(v) for v in values)}")
        setattr(namespace, self.dest, items + given)


def add_list_option(parser, *flags: str, metavar: str, help: str, **options) -> None:
    """A list option, written ``--flag a,b`` (space-separated items are accepted too).

    The parsed value is a list of str, or the ``default`` when the option is not given. A path
    that space-separated items swallowed from the positional argument after them is handed back
    by ``reclaim_positional``.
    """
    parser.add_argument(*flags, nargs="+", action=_ListAction, metavar=f"{metavar}[,...]",
                        help=f"{help}; comma-separated", **options)


def _looks_like_path(text: str) -> bool:
    return "/" in text or bool(Path(text).suffix) or Path(text).exists()


def reclaim_positional(args, list_dest: str, positional_dest: str) -> None:
    """``--methods a b CLOUD``: give back to the positional argument the path that the list
    option swallowed (argparse hands every word up to the next option to the list)."""
    items = getattr(args, list_dest)
    if getattr(args, positional_dest) is None and items and _looks_like_path(items[-1]):
        setattr(args, positional_dest, items.pop())
        setattr(args, list_dest, items or None)


def show_required(parser: argparse.ArgumentParser, *shown: str, alternatives: tuple = ()
                  ) -> None:
    """Show ``shown`` (as they appear in the usage, e.g. ``SCENE``, ``-o LOG.h5``) as required
    in the usage line, and add the ``alternatives`` (e.g. ``--list``) as usage lines of their own.

    For arguments that argparse must treat as optional because an alternative such as
    ``--list`` runs without them; the command checks them itself. Call after every argument is
    added.
    """
    usage = parser.format_usage().removeprefix("usage: ").rstrip()
    # list options (add_list_option) read "--methods METHOD[,...]", not "X[,...] [X[,...] ...]"
    usage = re.sub(r"(\S+\[,\.\.\.\])\s+\[\1 \.\.\.\]", r"\1", usage)
    for text in shown:
        usage, found = re.subn(r"\[(" + re.escape(text) + r")\]", r"\1", usage)
        if not found:
            raise ValueError(f"{text!r} is not an optional item of the usage {usage!r}")
    prog = parser.prog
    lines = [usage.replace(prog, "%(prog)s", 1)]
    lines += [f"%(prog)s {alternative}" for alternative in alternatives]
    parser.usage = "\n       ".join(lines)


def _scheduler(text: str) -> str:
    """argparse type of ``--scheduler``: checked before any work starts (an address must answer
    as a Dask scheduler). argparse names the option (``argument --scheduler: ...``), so the
    message leaves out the parameter it starts with."""
    from recon import api

    try:
        return api.check_scheduler(text)
    except ReconError as exc:
        raise argparse.ArgumentTypeError(exc.worded(lambda _: "").strip()) from None


def add_sweep_options(parser, *, resume_help: str, default: str, workers_help: str) -> None:
    """``--scheduler``, ``--workers`` and ``--resume`` (``recon.api.check_scheduler``'s values).

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
    resume_help : str
        What ``--resume`` keeps, in the command's own words.
    default : str
        What runs the work when ``--scheduler`` is not given, in the help's words.
    workers_help : str
        What ``--workers N`` sets under each scheduler, in the command's own words
        (``recon.experiments.sweep.iterate``: a local pool or cluster of N; on a cluster given
        by address, the cluster's own workers run the work).
    """
    parser.add_argument("--scheduler", metavar="ADDRESS", type=_scheduler,
                        help=f"Dask scheduler address of an existing cluster (default: {default}"
                             "); 'threads' or 'serial' run without Dask")
    parser.add_argument("--workers", type=int, metavar="N", help=workers_help)
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
