"""``recon simulate``: simulate a scene (a preset or a TOML file) into a strike log."""

from __future__ import annotations

import argparse
import json
import sys

from cli.options import message, show_required


def register(subparsers) -> None:
    """Add the ``simulate`` subcommand to ``recon``."""
    parser = subparsers.add_parser(
        "simulate", help="simulate a scene into a strike log",
        description="Simulate a chaser imaging a spinning target with an LRF or LIDAR and write "
                    "the strike log. SCENE is a preset name (--list shows them) or a TOML file "
                    "stating what differs from the defaults.",
        epilog="examples:\n"
               "  recon simulate asteroid-lrf -o run.h5 --set time.duration=3600\n"
               "  recon simulate my-scene.toml -o run.h5 --seed 7 --set slew.amplitude_deg=3\n"
               "  recon simulate --list\n"
               "  recon simulate --keys",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("scene", nargs="?", metavar="SCENE", help="preset name or scene TOML")
    parser.add_argument("-o", "--output", metavar="LOG.h5", help="strike log to write")
    parser.add_argument("--seed", type=int, default=0, metavar="N",
                        help="seed of the error models (default 0); same seed, same data")
    parser.add_argument("--set", action="append", default=[], dest="overrides",
                        metavar="SECTION.KEY=VALUE",
                        help="override a scene key, e.g. time.duration=3600 or "
                             "sensor.field_of_view_deg=[1.2,1.2]; repeatable")
    parser.add_argument("--list", action="store_true", help="list the presets and exit")
    parser.add_argument("--keys", action="store_true",
                        help="list every scene key with its default and unit, and exit")
    parser.add_argument("--live", action="store_true",
                        help="write in HDF5 SWMR mode so that `recon ingest LOG --follow` reads "
                             "the strikes while they are written")
    parser.add_argument("--compression", metavar="lzf|gzip[:LEVEL]|none",
                        help="filter of the log's datasets: gzip (deflate with shuffle, which "
                             "every HDF5 tool reads; the default), gzip:LEVEL (0-9), lzf "
                             "(h5py's own filter, unreadable by other HDF5 tools) or none")
    parser.add_argument("--json", action="store_true", help="print the run summary as JSON")
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                        help="show a progress bar (default: on a terminal, after 2 s)")
    parser.set_defaults(func=run, parser=parser)
    show_required(parser, "SCENE", "-o LOG.h5", alternatives=("--list", "--keys"))


def run(args) -> int:
    from recon import api

    if args.keys:
        _print_keys(api.scene_keys())
        return 0
    if args.list:
        presets = api.presets()
        if args.json:
            print(json.dumps([{"name": n, "description": d} for n, d in presets], indent=2))
        else:
            width = max(len(n) for n, _ in presets)
            for name, description in presets:
                print(f"{name:<{width}}  {description}")
        return 0
    if args.scene is None or args.output is None:
        args.parser.error("SCENE and -o LOG.h5 are required (or --list, --keys)")
    try:
        api.check_seed(args.seed)
    except api.ParameterError as exc:
        args.parser.error(message(exc))
    summary = api.simulate(args.scene, args.output, seed=args.seed, overrides=args.overrides,
                           progress=args.progress, live=args.live,
                           compression=args.compression).summary
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"wrote {summary['path']}: {summary['shots']:,} shots, {summary['strikes']:,} "
              f"strikes of {summary['pulses']:,} pulses ({summary['target']}, "
              f"{summary['pattern']}) in {summary['wall_time_s']:.2f} s", file=sys.stdout)
    return 0


def _print_keys(schema: dict) -> None:
    """The scene schema: ``[section]`` then ``key = default  unit  meaning`` per line."""
    for section, keys in schema.items():
        print(f"[{section}]")
        for name, default, unit, meaning in keys:
            unit = f"[{unit}]" if unit else ""
            print(f"  {name + ' = ' + default:<46s} {unit:<19s} {meaning}")
