"""``recon recover``: the committed rows of a live log whose writer died, as a complete log."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "recover", help="turn the file of a crashed live writer into a complete log",
        description="A log written with `recon simulate --live` whose writer was killed leaves "
                    "its hidden temporary file beside the log (.LOG.h5.partial-PID-*.live). "
                    "Copy the rows it had committed into a complete, valid log and say what "
                    "was lost. The temporary file is left as it is.")
    p.add_argument("partial", help="the writer's temporary file, or the path of the log it was "
                                   "writing (its newest temporary file beside it is used)")
    p.add_argument("-o", "--output", required=True, help="complete strike log to write (.h5)")
    p.set_defaults(func=run)


def run(args) -> int:
    from tqdm import tqdm

    from formats.strike_log.recover import recover

    with tqdm(unit="row", disable=None, leave=False, desc="recover") as bar:
        recovery = recover(args.partial, args.output, progress=bar.update)
    print(recovery.describe())
    return 0
