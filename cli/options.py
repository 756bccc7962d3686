"""Command-line options shared by the commands that run sweeps on Dask."""

from __future__ import annotations


def add_sweep_options(parser, *, resume_help: str) -> None:
    """``--scheduler``, ``--workers`` and ``--resume`` (recon.experiments.sweep's schedulers).

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
    resume_help : str
        What ``--resume`` keeps, in the command's own words.
    """
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="Dask scheduler address of an existing cluster (default: a local "
                             "cluster); 'threads' or 'serial' run without Dask")
    parser.add_argument("--workers", type=int, metavar="N",
                        help="local workers (default: one per core)")
    parser.add_argument("--resume", action="store_true", help=resume_help)


