"""``recon demo``: the end-to-end run on a built-in scene, the first thing a new user tries."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the end-to-end demo on a built-in scene",
                       description="Write a small strike log, validate it and summarise it.")
    p.add_argument("-o", "--output", default="recon-demo", type=Path,
                   help="directory for the demo's files (default: %(default)s)")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotImplementedError
