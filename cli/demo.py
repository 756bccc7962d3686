"""``recon demo``: the whole pipeline on a built-in scene (``recon.api.demo``)."""

from __future__ import annotations

import argparse
from pathlib import Path

# Repeated from recon/api.py as help text only, so that ``recon --help`` imports nothing heavy.
DEMO_SCENE = "asteroid-lrf-slew"
DEMO_METHOD = "screened-poisson"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the end-to-end demo on a built-in scene",
                       description="Simulate a built-in scene, register the strikes, reconstruct "
                                   "a surface and score cloud and surface against the truth.")
    p.add_argument("-o", "--output", default=Path("recon-demo"), type=Path,
                   help="directory for the demo's files (default: %(default)s)")
    p.add_argument("--scene", default=DEMO_SCENE,
                   help="preset name or scene file (default: %(default)s; see "
                        "`recon simulate --list`)")
    p.add_argument("--method", default=DEMO_METHOD,
                   help="reconstruction method (default: %(default)s)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="scene override, e.g. time.rotations=10 (repeatable)")
    p.set_defaults(func=run)


def run(args) -> int:
    from recon import api

    result = api.demo(args.output, scene=args.scene, method=args.method,
                      overrides=args.overrides, say=lambda text: print(text, flush=True))
    print()
    print(result.table())
    files = list(result.files.values())
    print(f"\nwrote {', '.join(str(f) for f in files[:-1])} and {files[-1]}")
    return 0
