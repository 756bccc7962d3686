"""``recon reconstruct``, ``recon compare`` and ``recon stability``: surfaces from clouds."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from cli.options import add_sweep_options

# The CLI's defaults are the library's (recon/surfaces/isolation.py says where each comes from);
# they are
# repeated here only as help text, so that ``recon --help`` need not import numpy.
TIMEOUT_HELP = "wall-clock limit of each method run, seconds (default: 600)"
MEMORY_HELP = "address-space limit of each method run, MiB (default: 8192; 0: none)"


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


def _add_run_options(p: argparse.ArgumentParser, *, sweep: bool) -> None:
    g = p.add_argument_group("runs")
    g.add_argument("--timeout", type=float, metavar="S", help=TIMEOUT_HELP)
    g.add_argument("--memory-limit", type=int, metavar="MB", help=MEMORY_HELP)
    if sweep:
        g.add_argument("--samples", type=int, metavar="N",
                       help="points sampled per side when scoring (default: metrics' 200000; "
                            "fewer is faster and noisier)")
        add_sweep_options(g, resume_help="keep DIR/results.jsonl and skip the runs it holds")


def _methods_arg(text: list[str] | None) -> list[str] | None:
    if not text:
        return None
    return [name for item in text for name in item.split(",") if name]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reconstruct", help="reconstruct a surface mesh from a cloud or a log",
        description="Reconstruct a triangle mesh from a point cloud (or a strike log, ingested "
                    "on the fly) with one method, run in its own process with time and memory "
                    "limits. '-m auto' chooses the method and resolution without the truth and "
                    "says why. '--list-methods' lists the methods and their parameters.")
    p.add_argument("input", nargs="?", help="point cloud (.ply, .las, .laz, .h5) or strike log")
    p.add_argument("-m", "--method", default="poisson",
                   help="method name or 'auto' (default: %(default)s)")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="method parameter (repeatable), e.g. depth=9 or radii=0.5,1,2")
    p.add_argument("-o", "--output", type=Path, help="mesh to write (.ply)")
    p.add_argument("--list-methods", action="store_true",
                   help="list the methods, their defaults and grids, and exit")
    p.add_argument("--auto-methods", nargs="+", metavar="METHOD",
                   help="candidates of -m auto (default: every method and its grid)")
    p.add_argument("--holdout", type=float, default=0.1,
                   help="fraction of points -m auto holds out (default: %(default)s)")
    p.add_argument("--in-process", action="store_true",
                   help="run the method in this process (no isolation; a crash ends recon)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    _add_input_options(p)
    _add_run_options(p, sweep=False)
    p.set_defaults(func=run_reconstruct)

    p = sub.add_parser(
        "compare", help="compare every method on one cloud against the truth",
        description="Run every method with its defaults and a small parameter grid, each "
                    "isolated, on Dask; score each mesh against the truth; write "
                    "DIR/results.csv, DIR/results.json, DIR/speed_accuracy.png and the meshes; "
                    "print the ranking.")
    p.add_argument("input", help="point cloud or strike log")
    p.add_argument("--truth", required=True,
                   help="truth mesh file, or a strike log with its truth mesh")
    p.add_argument("--truth-scale", type=float, default=1.0,
                   help="factor on a truth mesh file's coordinates (e.g. 1000 for km)")
    p.add_argument("-o", "--output", type=Path, required=True, help="output directory")
    p.add_argument("--methods", nargs="+", metavar="METHOD",
                   help="methods to run (default: all)")
    p.add_argument("--no-grid", action="store_true", help="defaults only, no parameter grid")
    p.add_argument("--no-meshes", action="store_true", help="do not keep the meshes")
    p.add_argument("--auto", action="store_true",
                   help="also run -m auto and report where its choice ranks on the truth")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    _add_input_options(p)
    _add_run_options(p, sweep=True)
    p.set_defaults(func=run_compare)

    p = sub.add_parser(
        "stability", help="failure maps over noise x density x outliers",
        description="Degrade a cloud (or re-simulate a scene) over range noise x point density "
                    "x outlier fraction, run every method on every cell (isolated, on Dask) and "
                    "write, per method, a failure map and an accuracy heatmap (PNG) with the "
                    "data (DIR/stability.csv, DIR/stability.json).")
    p.add_argument("source", help="scene (preset name or .toml), point cloud, or strike log")
    p.add_argument("--truth", help="truth mesh (default: the log's or the scene's)")
    p.add_argument("--truth-scale", type=float, default=1.0,
                   help="factor on a truth mesh file's coordinates (e.g. 1000 for km)")
    p.add_argument("-o", "--output", type=Path, required=True, help="output directory")
    p.add_argument("--methods", nargs="+", metavar="METHOD", help="methods (default: all)")
    p.add_argument("--noise", default="0,0.3,1",
                   help="range noise levels, 3 sigma in metres (default: %(default)s)")
    p.add_argument("--density", default="1,0.3,0.1",
                   help="fractions of the points kept (default: %(default)s)")
    p.add_argument("--outliers", default="0,0.02",
                   help="outlier fractions (default: %(default)s)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="scene override, as for recon simulate (scenes only)")
    p.add_argument("--seed", type=int, default=0, help="seed (default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    _add_run_options(p, sweep=True)
    p.set_defaults(func=run_stability)


def _limits(args) -> dict:
    from recon.surfaces.isolation import DEFAULT_MEMORY_MB, DEFAULT_TIMEOUT_S
    from recon.surfaces.reconstruct import InputError

    timeout = DEFAULT_TIMEOUT_S if args.timeout is None else args.timeout
    if not timeout > 0:
        raise InputError(f"--timeout must be positive, got {args.timeout}")
    memory = DEFAULT_MEMORY_MB if args.memory_limit is None else args.memory_limit
    if memory < 0:
        raise InputError(f"--memory-limit must be >= 0, got {args.memory_limit}")
    return {"timeout_s": timeout, "memory_mb": memory or None}


def _score_options(args) -> dict | None:
    from recon.surfaces.reconstruct import InputError

    if args.samples is None:
        return None
    if args.samples < 100:
        raise InputError(f"--samples must be at least 100, got {args.samples}")
    return {"n_truth_samples": args.samples, "n_test_samples": args.samples,
            "coverage_points": 2 * args.samples}


def _load(args):
    """Read, preprocess and prepare the input cloud.

    Returns the preprocessed ``PointCloud`` (points and view points) and its ``MethodInput``.
    """
    from recon.inputs import load_cloud
    from recon.surfaces.prepare import InputError, prepare, preprocess

    cloud = load_cloud(args.input)
    if args.voxel is not None and not args.voxel > 0:
        raise InputError(f"--voxel must be a positive size in metres, got {args.voxel}")
    cloud = preprocess(cloud, remove_outliers=args.remove_outliers, voxel=args.voxel)
    prepared = prepare(cloud.points, view_points=cloud.view_points, k=args.normals_k,
                       fallback=args.orient, seed=args.seed)
    return cloud, prepared


def _list_methods() -> int:
    from recon.surfaces import methods

    for name in methods.available():
        spec = methods.get(name)
        print(f"{name} [{spec.kind}]: {spec.summary}")
        for key, param in spec.params.items():
            default = "auto" if param.default is None else param.default
            print(f"    {key} = {default}  ({param.doc})")
        for overrides in spec.grid:
            print(f"    grid: {' '.join(f'{k}={v}' for k, v in overrides.items())}")
    return 0


def run_reconstruct(args) -> int:
    from recon.surfaces.reconstruct import InputError

    if args.list_methods:
        return _list_methods()
    if not args.input or args.output is None:
        raise InputError("reconstruct needs INPUT and -o MESH.ply (or --list-methods)")
    if args.output.suffix.lower() != ".ply":
        raise InputError(f"-o must name a .ply file, got {args.output}")
    from recon.surfaces import methods

    auto = args.method == "auto"
    if auto and args.param:
        raise InputError("--param cannot be combined with -m auto")
    spec = None if auto else methods.get(args.method)
    overrides = {} if auto else spec.parse(args.param)
    limits = _limits(args)
    cloud, prepared = _load(args)
    summary: dict = {"input": str(args.input), "n_points": len(prepared.points),
                     "spacing_m": prepared.spacing, "noise_m": prepared.noise,
                     "view_points": cloud.view_points is not None}
    if auto:
        from recon.experiments.auto import choose, format_choice
        from recon.experiments.cases import variants

        candidates = variants(_methods_arg(args.auto_methods)) if args.auto_methods else None
        choice = choose(cloud.points, view_points=cloud.view_points, candidates=candidates,
                        holdout=args.holdout, seed=args.seed, k=args.normals_k,
                        fallback=args.orient, **limits)
        if not args.json:
            print(format_choice(choice))
        summary["auto"] = choice.to_dict()
        method, overrides = choice.run, None
    else:
        method = spec.bind(overrides)
        overrides = None
    from tqdm import tqdm

    from formats.mesh_io import write_mesh
    from recon.surfaces.reconstruct import reconstruct

    # One opaque library call: show the elapsed time and the child's stage, not a fraction.
    with tqdm(desc=method.label, bar_format="{desc} {elapsed}{postfix}", disable=None, leave=False,
              delay=2.0) as bar:
        surface = reconstruct(prepared, method=method, params=overrides,
                              isolate=not args.in_process, **limits,
                              on_wait=lambda stage: bar.set_postfix_str(stage))
    write_mesh(args.output, surface.vertices, surface.faces)
    summary.update(method=method.method, params=surface.params, output=str(args.output),
                   n_vertices=len(surface.vertices), n_faces=len(surface.faces),
                   **surface.info)
    if args.json:
        from recon.experiments.sweep import to_jsonable

        print(json.dumps(to_jsonable(summary), indent=2))
    else:
        print(f"{method.method}: {len(surface.faces)} faces "
              f"({'watertight' if surface.info['watertight'] else 'open'}) in "
              f"{surface.info['wall_time_s']:.2f} s; wrote {args.output}")
    return 0


def _check_methods(names):
    from recon.surfaces import methods

    for name in names or []:
        methods.get(name)
    return names


def run_compare(args) -> int:
    from recon.experiments.compare import compare
    from recon.inputs import load_truth

    names = _check_methods(_methods_arg(args.methods))
    limits = _limits(args)
    truth = load_truth(args.truth, scale=args.truth_scale)
    cloud, prepared = _load(args)
    if not args.json:
        print(f"compare: {len(prepared.points)} points (spacing {prepared.spacing:.3g} m, noise "
              f"{prepared.noise:.3g} m), truth {len(truth[1])} faces -> {args.output}")
    report = compare(prepared, truth, args.output, names=names, grid=not args.no_grid,
                     scheduler=args.scheduler, n_workers=args.workers, resume=args.resume,
                     keep_meshes=not args.no_meshes, title=f"{Path(args.input).name}",
                     score_options=_score_options(args),
                     fingerprint={"input": str(args.input), "truth": str(args.truth),
                                  "voxel": args.voxel, "remove_outliers": args.remove_outliers,
                                  "normals_k": args.normals_k, "grid": not args.no_grid},
                     **limits)
    if args.auto:
        from recon.experiments.auto import choose, format_choice
        from recon.experiments.cases import variants
        from recon.experiments.compare import agreement
        from recon.experiments.sweep import to_jsonable

        candidates = variants(names, grid=not args.no_grid)
        choice = choose(cloud.points, view_points=cloud.view_points, candidates=candidates,
                        seed=args.seed, k=args.normals_k, fallback=args.orient, **limits)
        verdict = agreement(report["records"], choice.run.key)
        report["auto"] = {"choice": choice.to_dict(), "agreement": verdict}
        (args.output / "auto.json").write_text(
            json.dumps(to_jsonable(report["auto"]), indent=2) + "\n")
    if args.json:
        from recon.experiments.sweep import to_jsonable

        print(json.dumps(to_jsonable({k: v for k, v in report.items() if k != "table"}),
                         indent=2, default=str))
        return 0
    print(report["table"])
    for metric, front in (("Chamfer", report["pareto_chamfer"]),
                          ("F-score", report["pareto_fscore"])):
        print(f"Pareto front (time vs {metric}): " + ", ".join(
            f"{r['label']} ({r['wall_time_s']:.2g} s)" for r in front))
    if args.auto:
        print(format_choice(choice))
        v = report["auto"]["agreement"]
        print(f"auto vs truth: auto's choice ranks {v['rank']} of {v['n_ranked']} on Chamfer "
              f"(best: {v['best_label']}); same run: {'yes' if v['same_run'] else 'no'}, same "
              f"method: {'yes' if v['same_method'] else 'no'}, Chamfer ratio to the best: "
              f"{v['chamfer_ratio']:.3g}")
    print(f"wrote {report['csv']}, {report['json']}, {report['png']}")
    return 0


def _levels(text: str, name: str) -> list[float]:
    from recon.experiments.stability import StabilityError

    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise StabilityError(f"--{name} must be comma-separated numbers, got {text!r}") from None


def run_stability(args) -> int:
    from recon.experiments.stability import StabilityError, simulate_levels, stability
    from recon.inputs import is_strike_log, load_cloud, load_truth

    names = _check_methods(_methods_arg(args.methods))
    limits = _limits(args)
    noise = _levels(args.noise, "noise")
    density = _levels(args.density, "density")
    outliers = _levels(args.outliers, "outliers")
    source = Path(args.source)
    is_file = source.is_file() and source.suffix.lower() != ".toml"
    if is_file:
        if args.overrides:
            raise StabilityError("--set applies to scenes only, not to a cloud or a log")
        cloud = load_cloud(source)
        if args.truth:
            truth = load_truth(args.truth, scale=args.truth_scale)
        elif is_strike_log(source):
            truth = load_truth(source)
        else:
            raise StabilityError(f"{source}: a cloud needs --truth")
        clouds = {"base": (cloud.points, cloud.view_points, False)}
    else:
        # Validate levels before simulating anything.
        from recon.experiments.stability import _check_levels

        _check_levels("noise", noise, 0.0, None)
        clouds, truth = simulate_levels(args.source, noise, args.output,
                                        overrides=args.overrides, seed=args.seed)
        if args.truth:
            truth = load_truth(args.truth, scale=args.truth_scale)
    report = stability(args.output, clouds=clouds, truth=truth, names=names, noise=noise,
                       density=density, outliers=outliers, seed=args.seed,
                       scheduler=args.scheduler, n_workers=args.workers, resume=args.resume,
                       score_options=_score_options(args),
                       fingerprint={"source": str(args.source), "overrides": args.overrides,
                                    "truth": str(args.truth)}, **limits)
    if args.json:
        from recon.experiments.sweep import to_jsonable

        print(json.dumps(to_jsonable({"csv": str(report["csv"]), "json": str(report["json"]),
                                      "pngs": [str(p) for p in report["pngs"]],
                                      "failure_rate": report["failure_rate"]}), indent=2))
        return 0
    for method, rate in report["failure_rate"].items():
        print(f"{method:<24} failed in {rate:6.1%} of the cells")
    print(f"wrote {report['csv']}, {report['json']} and {len(report['pngs'])} charts to "
          f"{args.output}")
    return 0
