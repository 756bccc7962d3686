"""``recon reconstruct``, ``recon compare`` and ``recon stability``: surfaces from clouds."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from cli.options import (
    UsageError,
    add_command,
    add_list_option,
    add_sweep_options,
    add_truth_and_output_options,
    reclaim_positional,
    show_required,
)

# The CLI's defaults are the library's (recon/surfaces/isolation.py says where each comes from);
# they are repeated here only as help text, so that ``recon --help`` need not import numpy.
TIMEOUT_HELP = ("wall-clock limit of each method run, seconds (default: 600); a method at its "
                "defaults whose predicted time exceeds it is declined at once")
MEMORY_HELP = "address-space limit of each method run, MiB (default: 8192; 0: none)"
# What -m auto may be told of the target (recon.surfaces.auto.TARGET_KINDS, not imported: the
# CLI reaches recon only through recon.api, and the help stays light).
TARGET_KINDS = ("unknown", "natural")


def _add_target_kind(p: argparse.ArgumentParser) -> None:
    p.add_argument("--target-kind", choices=TARGET_KINDS, default="unknown",
                   help="what -m auto may assume of the target: 'natural' (an asteroid, a "
                        "comet) lets the ellipsoid stand for a far side the strikes leave "
                        "unseen, alone or completing the strikes' own surface where they are "
                        "(completed-poisson, taken when the held-out strikes favour it, or "
                        "fit it as well and the strikes reach across the body); "
                        "'unknown': the strikes and their rays alone decide "
                        "(default: %(default)s)")


def _add_input_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("preprocessing and normals")
    g.add_argument("--remove-outliers", action="store_true",
                   help="statistical outlier removal (20 neighbours, 2 standard deviations)")
    g.add_argument("--voxel", type=float, metavar="M",
                   help="voxel downsampling: average the points in cubes of M metres")
    g.add_argument("--normals-k", type=int, default=16, metavar="K",
                   help="neighbours of the PCA normals, doubled where they fit no plane "
                        "(default: %(default)s)")
    g.add_argument("--orient", choices=("centroid", "propagate"), default="centroid",
                   help="normal orientation for clouds without view points (with them the "
                        "sensor position always decides; default: %(default)s)")
    g.add_argument("--seed", type=int, default=0, help="seed of every random choice "
                                                       "(default: %(default)s)")


# What --workers sets (recon.experiments.sweep.iterate): without --scheduler and with
# 'threads', the runs at once, each waiting on its warm worker process; on a cluster given by
# address, the cluster's own workers run them; 'serial' runs one at a time.
_WORKERS_HELP = ("runs at once on this machine, each in its own worker process (default: one "
                 "per core; 'serial' runs one at a time); ")
WORKERS_HELP = {
    "compare": _WORKERS_HELP + "not used with --scheduler ADDRESS, where the cluster's "
                               "workers run them",
    "stability": _WORKERS_HELP + "with --scheduler ADDRESS the cluster's workers run them: "
                                 "give its size, which the grid's time estimate divides by",
}


def _add_run_options(p: argparse.ArgumentParser, *, sweep: bool) -> None:
    g = p.add_argument_group("runs")
    g.add_argument("--timeout", type=float, metavar="S", help=TIMEOUT_HELP)
    g.add_argument("--memory-limit", type=int, metavar="MB", help=MEMORY_HELP)
    if sweep:
        g.add_argument("--samples", type=int, metavar="N",
                       help="points sampled per side when scoring (default: compare samples "
                            "until the Chamfer distance's standard error is 2%% of it and the "
                            "F-score's 0.005; stability takes enough for a 2%% standard error "
                            "of each cell's Chamfer distance; fewer is faster and noisier)")
        add_sweep_options(g, resume_help="keep DIR/results.jsonl and skip the runs it holds",
                          default="threads, each method in its own worker process",
                          workers_help=WORKERS_HELP[p.prog.split()[-1]])


def _add_closing_options(p: argparse.ArgumentParser, *, preprocessing: bool, sweep: bool
                         ) -> None:
    """The options every command here ends with: ``--json``, the preprocessing and normals of
    the input cloud (when it takes one as it is), and the run limits (``sweep``: and Dask)."""
    p.add_argument("--json", action="store_true", help="print one JSON object")
    if preprocessing:
        _add_input_options(p)
    _add_run_options(p, sweep=sweep)


def register(sub: argparse._SubParsersAction) -> None:
    from recon import api  # light: formats.errors, and the cost table (JSON) for the help

    p = add_command(
        sub, "reconstruct", run_reconstruct,
        help="reconstruct a surface mesh from a cloud or a log",
        description="Reconstruct a triangle mesh from a point cloud (or a strike log, ingested "
                    "on the fly) with one method, run in its own process with time and memory "
                    "limits. '-m auto' chooses the method and resolution without the truth and "
                    "says why. Every surface comes with a predicted Chamfer distance and F-score "
                    "(a band, from the strikes and their rays, without the truth). "
                    "'--list-methods' lists the methods, their parameters and what "
                    "each default costs. " + api.method_cost())
    p.add_argument("input", nargs="?", metavar="INPUT",
                   help="point cloud (.ply, .las, .laz, .h5, .xyz, .pcd, .e57...) or strike log")
    p.add_argument("-m", "--method", default="poisson",
                   help="method name or 'auto' (default: %(default)s)")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="method parameter (repeatable), e.g. depth=9 or radii=0.5,1,2")
    p.add_argument("-o", "--output", type=Path, metavar="MESH.ply", help="mesh to write (.ply)")
    p.add_argument("--list-methods", action="store_true",
                   help="list the methods, their defaults and grids, and exit")
    add_list_option(p, "--auto-methods", metavar="METHOD",
                    help="restrict -m auto's candidate ladder to these methods (default: all)")
    p.add_argument("--holdout", type=float, default=0.25,
                   help="fraction of shots each of -m auto's folds holds out, in time blocks; "
                        "1 / holdout folds (default: %(default)s, 4 folds)")
    _add_target_kind(p)
    p.add_argument("--in-process", action="store_true",
                   help="run the method in this process (no isolation; a crash ends recon)")
    _add_closing_options(p, preprocessing=True, sweep=False)
    show_required(p, "INPUT", "-o MESH.ply", alternatives=("--list-methods",))

    p = add_command(
        sub, "compare", run_compare, help="compare every method on one cloud against the truth",
        description="Run every method at its defaults (--grid full: and its parameter grid), "
                    "each isolated in a warm worker process, one per core (or on Dask with "
                    "--scheduler); score each mesh against the truth; write DIR/results.csv, "
                    "DIR/results.json, DIR/speed_accuracy.png and the meshes; print the "
                    "ranking, the Pareto fronts and how long the full grid would take. "
                    + api.method_cost())
    p.add_argument("input", nargs="?", metavar="INPUT", help="point cloud or strike log")
    add_truth_and_output_options(
        p, truth_help="truth mesh file, or a strike log with its truth mesh", truth_required=True)
    add_list_option(p, "--methods", metavar="METHOD",
                    help="methods to run, e.g. --methods poisson,convex-hull (default: all)")
    p.add_argument("--grid", choices=("defaults", "full"), default="defaults",
                   help="'defaults': every method at its defaults, the Pareto front in "
                        "minutes; 'full': each method's parameter grid too (the output "
                        "estimates how long it takes; with --resume it adds to a defaults run). "
                        "Default: %(default)s")
    p.add_argument("--no-grid", action="store_true", help="same as --grid defaults")
    p.add_argument("--no-meshes", action="store_true", help="do not keep the meshes")
    p.add_argument("--auto", action="store_true",
                   help="also run -m auto and report where its choice ranks on the truth")
    _add_target_kind(p)
    _add_closing_options(p, preprocessing=True, sweep=True)
    show_required(p, "INPUT")

    p = add_command(
        sub, "stability", run_stability, help="failure maps over noise x density x outliers",
        description="Degrade a cloud (or re-simulate a scene) over range noise x point density "
                    "x outlier fraction, run every method on every cell (each isolated in a worker "
                    "process, or on Dask with --scheduler) and "
                    "write, per method, a failure map and an accuracy heatmap (PNG) with the "
                    "data (DIR/stability.csv, DIR/stability.json).")
    p.add_argument("source", nargs="?", metavar="SOURCE",
                   help="scene (preset name or .toml), point cloud, or strike log")
    add_truth_and_output_options(
        p, truth_help="truth mesh (default: the log's or the scene's)", truth_required=False)
    add_list_option(p, "--methods", metavar="METHOD", help="methods (default: all)")
    add_list_option(p, "--noise", metavar="M", default=["0", "0.3", "1"],
                    help="range noise levels, 3 sigma in metres (default: 0,0.3,1)")
    add_list_option(p, "--density", metavar="F", default=["1", "0.3", "0.1"],
                    help="fractions of the points kept (default: 1,0.3,0.1)")
    add_list_option(p, "--outliers", metavar="F", default=["0", "0.02"],
                    help="outlier fractions: points added uniformly in the cloud's box, as a "
                         "fraction of the kept points, from 0 to 1 (as many as the real ones; "
                         "default: 0,0.02)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="scene override, as for recon simulate (scenes only)")
    p.add_argument("--seed", type=int, default=0, help="seed (default: %(default)s)")
    _add_closing_options(p, preprocessing=False, sweep=True)
    show_required(p, "SOURCE")


def _positional(args, list_dest: str, positional_dest: str, what: str) -> None:
    """Reclaim the positional from a list option that swallowed it; refuse when it is absent."""
    reclaim_positional(args, list_dest, positional_dest)
    if getattr(args, positional_dest) is None:
        raise UsageError(f"{args.command} needs {what}")


def _preparation(args) -> dict:
    """The preparation options of the api's verbs."""
    return {"remove_outliers": args.remove_outliers, "voxel": args.voxel,
            "normals_k": args.normals_k, "orient": args.orient, "seed": args.seed}


def _limits(args) -> dict:
    return {"timeout": args.timeout, "memory_limit": args.memory_limit}


class _StageBar:
    """The elapsed time and the isolated child's stage, shown once a run takes over 2 s (one
    opaque library call: no fraction to show). Created on the first report, closed on exit."""

    def __init__(self, desc: str):
        self.desc, self.bar = desc, None

    def __call__(self, stage: str) -> None:
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(desc=self.desc, bar_format="{desc} {elapsed}{postfix}", disable=None,
                            leave=False, delay=2.0)
        self.bar.set_postfix_str(stage)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.close()


def _print_json(value: dict) -> None:
    print(json.dumps(value, indent=2, default=str))


def _estimate_line(estimate: dict) -> str:
    """The truth-free predicted Chamfer distance and F-score of a reconstruction, one line."""
    return (f"predicted without the truth ({estimate['source']} residuals): Chamfer "
            f"{estimate['chamfer_m']:.3g} m [{estimate['chamfer_low_m']:.3g}, "
            f"{estimate['chamfer_high_m']:.3g}], F-score at {estimate['tau_m']:.3g} m "
            f"{estimate['fscore']:.3f} [{estimate['fscore_low']:.3f}, "
            f"{estimate['fscore_high']:.3f}]; {estimate['measured_m'][0]:.3g} m of the Chamfer "
            f"measured by the strikes, {estimate['proxied_m'][0]:.3g} m stood for by a proxy "
            f"where no strike is; {estimate['unsupported']:.0%} of the surface far from any "
            f"strike, {estimate['holes']:.1%} of strikes in holes, "
            f"{estimate['violated']:.1%} of beams cut before their strike")


# The words for ``Surface.closure``.
CLOSURE = {"watertight": "watertight", "closed": "closed, touching itself at some edges",
           "open": "open"}


def run_reconstruct(args) -> int:
    from recon import api

    if args.list_methods:
        print(api.method_listing())
        return 0
    reclaim_positional(args, "auto_methods", "input")
    if not args.input or args.output is None:
        raise UsageError("reconstruct needs INPUT and -o MESH.ply (or --list-methods)")
    if args.output.suffix.lower() != ".ply":
        raise UsageError(f"-o must name a .ply file, got {args.output}")
    auto = args.method == "auto"
    if auto and args.param:
        raise UsageError("--param cannot be combined with -m auto")
    with _StageBar(args.method) as bar:
        result = api.reconstruct_file(
            args.input, args.output, method=args.method, params=args.param,
            auto_methods=args.auto_methods, holdout=args.holdout,
            target_kind=args.target_kind, isolate=not args.in_process,
            on_wait=bar, say=None if args.json else print,
            own_process=getattr(args, "own_process", False), **_preparation(args),
            **_limits(args))
    if args.json:
        _print_json(result.to_dict())
    else:
        surface = result.surface
        print(f"{surface.method}: {surface.n_faces} faces ({CLOSURE[surface.closure]}) in "
              f"{surface.info['wall_time_s']:.2f} s; wrote {args.output}")
        print(_estimate_line(result.estimate))
    return 0


def run_compare(args) -> int:
    from recon import api

    _positional(args, "methods", "input", "INPUT (a point cloud or strike log)")
    result = api.compare(args.input, truth=args.truth, output=args.output, methods=args.methods,
                         grid="defaults" if args.no_grid else args.grid,
                         truth_scale=args.truth_scale, samples=args.samples, auto=args.auto,
                         target_kind=args.target_kind, scheduler=args.scheduler,
                         n_workers=args.workers, resume=args.resume,
                         keep_meshes=not args.no_meshes, say=None if args.json else print,
                         **_preparation(args), **_limits(args))
    if args.json:
        _print_json(result.to_dict())
        return 0
    print(result.table)
    for metric, front in (("Chamfer", result.pareto_chamfer),
                          ("F-score", result.pareto_fscore)):
        print(f"Pareto front (time vs {metric}): " + ", ".join(
            f"{r['label']} ({r['wall_time_s']:.2g} s)" for r in front))
    print(result.full_grid_text)
    if args.auto:
        print(result.auto_text)
    print(f"wrote {result.csv}, {result.json}, {result.png}")
    return 0


def _levels(values: list[str], name: str) -> tuple[float, ...]:
    """Grid levels from the command line's ``--NAME`` items."""
    try:
        return tuple(float(v) for v in values)
    except ValueError:
        raise UsageError(f"--{name} must be comma-separated numbers, got "
                         f"{','.join(values)!r}") from None


def run_stability(args) -> int:
    from recon import api

    _positional(args, "methods", "source", "SOURCE (a scene, point cloud or strike log)")
    result = api.stability(args.source, output=args.output, truth=args.truth,
                           truth_scale=args.truth_scale, overrides=args.overrides,
                           methods=args.methods, noise=_levels(args.noise, "noise"),
                           density=_levels(args.density, "density"),
                           outliers=_levels(args.outliers, "outliers"), seed=args.seed,
                           samples=args.samples, scheduler=args.scheduler,
                           n_workers=args.workers, resume=args.resume, **_limits(args))
    if args.json:
        _print_json(result.to_dict())
        return 0
    for method, rate in result.failure_rate.items():
        print(f"{method:<24} failed in {rate:6.1%} of the cells")
    print(f"wrote {result.csv}, {result.json} and {len(result.pngs)} charts to {args.output}")
    return 0
