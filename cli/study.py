"""``recon study`` and ``recon report``: the paper's studies, and HTML reports of their results."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from cli.options import UsageError, add_command, add_sweep_options, show_required

# Repeated from recon/experiments/studies/__init__.py (STUDIES) so that ``recon --help`` imports
# nothing.
STUDY_NAMES = ("inclination", "duration", "slew", "patterns", "rso", "errors", "methods",
                "closed-loop", "pointing")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``study`` and ``report`` subcommands to ``recon``."""
    p = add_command(
        sub, "study", run_study, help="reproduce one of the paper's studies (or all) with charts",
        description="Run one of the paper's studies on Dask: simulate every case, register and "
                    "score it against the truth, then write the data (results.csv, "
                    "summary.json with each claim of the paper, our numbers and a verdict) and "
                    "the charts (PNG) to DIR. 'all' runs every study into DIR/NAME/. "
                    "'--list' names the studies.",
        epilog="examples:\n"
               "  recon study --list\n"
               "  recon study inclination -o out/inclination --quick\n"
               "  recon study all -o out/studies --resume\n"
               "  recon report out/studies -o report.html",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("name", nargs="?", metavar="NAME",
                   help=f"study: {', '.join(STUDY_NAMES)}, or all")
    p.add_argument("-o", "--output", type=Path, metavar="DIR", help="output directory")
    p.add_argument("--quick", action="store_true",
                   help="reduced version (minutes, for CI); verdicts of claims the reduced "
                        "runs cannot test say 'not tested'")
    add_sweep_options(p, resume_help="keep the finished cases in DIR and run only the others",
                      default="a local Dask cluster",
                      workers_help="cases at once on this machine: the worker processes of the "
                                   "local Dask cluster, or threads with --scheduler threads "
                                   "(default: one per core; 'serial' runs one at a time); not "
                                   "used with --scheduler ADDRESS, where the cluster's workers "
                                   "run them")
    p.add_argument("--list", action="store_true", help="list the studies and exit")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--size", choices=("tiny",), help=argparse.SUPPRESS)  # tests only
    show_required(p, "NAME", "-o DIR", alternatives=("--list",))

    p = add_command(
        sub, "report", run_report,
        help="one self-contained HTML page of a study, all studies or a comparison",
        description="Write one HTML page, readable offline (charts embedded), with the claims, "
                    "tables and charts of a 'recon study' directory (one study or 'all') or a "
                    "'recon compare' directory.")
    p.add_argument("input", type=Path, metavar="DIR", help="study or comparison directory")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="REPORT.html",
                   help="HTML file to write")


def run_study(args) -> int:
    from recon import api

    if args.list:
        for name, title in api.studies():
            print(f"{name:<12} {title}")
        print(f"{'all':<12} every study above, into DIR/NAME/")
        return 0
    if args.name is None or args.output is None:
        raise UsageError("NAME and -o DIR are required (or --list)")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be >= 1, got {args.workers}")
    size = args.size or ("quick" if args.quick else "full")
    options = {"size": size, "scheduler": args.scheduler, "resume": args.resume,
               "n_workers": args.workers}
    if args.name == "all":
        return _print_all(args, api.study_all(args.output, **options))
    result = api.study(args.name, args.output, **options)
    if args.json:
        print(json.dumps(result.to_dict(), indent=2))
        return 0
    print(f"{result.title} ({size}, {result.wall_time_s:.1f} s)")
    for c in result.claims:
        print(f"  [{c['verdict']}] {c['figure']}: {c['claim']}")
        print(f"      ours: {c['ours']}")
    if result.n_failed:
        print(f"  {result.n_failed} of {result.n_cases} cases failed:", file=sys.stderr)
        for f in result.failures:
            print(f"    {f['key']}: {f['reason']}", file=sys.stderr)
    print(f"wrote {args.output}: " + ", ".join(result.files))
    return 0


def _print_all(args, result) -> int:
    """What ``recon study all`` prints: a line per study, then the total."""
    index = result.index
    if args.json:
        print(json.dumps(index, indent=2))
        return 0
    for name, entry in index["studies"].items():
        verdicts = ", ".join(f"{n} {v}" for v, n in sorted(entry["verdicts"].items()))
        print(f"{name:<12} {entry['wall_time_s']:7.1f} s  {verdicts}"
              + (f"  ({entry['n_failed']} cases failed)" if entry["n_failed"] else ""))
    print(f"all studies: {index['wall_time_s']:.1f} s; wrote {args.output}/NAME/ and "
          f"{result.index_path}")
    return 0


def run_report(args) -> int:
    from recon import api

    path = api.report(args.input, args.output)
    print(f"wrote {path}")
    return 0
