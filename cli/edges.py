"""``recon edges``: the edge points of a cloud against the truth, as a PLY and a picture."""

from __future__ import annotations

import json

from cli.options import add_command, add_truth_and_output_options


def register(sub) -> None:
    p = add_command(
        sub, "edges", run, help="find a cloud's edge points and draw them against the truth",
        description="Run the paper's edge metric on CLOUD against TRUTH and write DIR/edges.ply "
                    "(the points with a per-point label: 0 surface, 1 detected edge point near a "
                    "truth feature edge, 2 false edge point), DIR/edges.png (the paper's Figs. "
                    "15, 17, 19: detected edge points blue, false ones red, missed truth edges "
                    "drawn) and DIR/edges.json (the scores). Definitions: metrics/edges.py.")
    p.add_argument("test", metavar="CLOUD",
                   help="point cloud (.ply .las .laz .h5), strike log (.h5, registered on the "
                        "fly) or mesh (sampled)")
    add_truth_and_output_options(
        p, truth_required=False,
        truth_help="truth mesh file, or a strike log with an embedded truth mesh (default: "
                   "CLOUD itself when it is a log with truth)")
    p.add_argument("--truth-units", choices=("km", "m"),
                   help="units of a truth mesh file (default: km for .tab, .icq, .bds/.dsk; m for "
                        "OBJ, PLY, STL)")
    p.add_argument("--variant", choices=("weighted", "feature"), default="weighted",
                   help="weighted: every truth edge by length x dihedral angle (the paper's "
                        "metric); feature: only edges sharper than the feature angle (default: "
                        "%(default)s)")
    p.add_argument("--k", type=int, help="neighbourhood size (default 16)")
    p.add_argument("--threshold", type=float,
                   help="leave-one-out drop of the surface variation that makes an edge point "
                        "(default 0.0005 at k = 16)")
    p.add_argument("--feature-angle", type=float, metavar="DEG",
                   help="dihedral angle above which a truth edge is a feature edge (default 30)")
    p.add_argument("--title", help="title of the picture")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of a mesh's surface samples and of the points drawn")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args) -> int:
    from tqdm import tqdm

    from recon import api

    options = {"variant": args.variant}
    for key, value in (("k", args.k), ("threshold", args.threshold),
                       ("feature_angle_deg", args.feature_angle)):
        if value is not None:
            options[key] = value
    truth = api.default_truth(args.test) if args.truth is None else args.truth
    with tqdm(total=3, desc="edges", unit="stage", disable=None, leave=False, delay=1.0) as bar:
        result = api.edges(args.test, truth=truth, truth_scale=args.truth_scale,
                           truth_units=args.truth_units,
                           output=args.output, seed=args.seed, title=args.title,
                           edge_options=options, progress=lambda stage: bar.update(1))
    report, counts = result.report, result.counts
    if args.json:
        print(json.dumps(result.to_dict(), indent=2))
        return 0
    print(f"{args.test} against {truth}: edge score {report.score:.4g} ({report.variant})")
    print(f"  {counts['true_edge_points']:,} detected edge points near a feature edge, "
          f"{counts['false_edge_points']:,} false, {counts['surface_points']:,} surface points")
    print(f"  missed truth edges: {counts['missed_feature_edges']:,} feature, "
          f"{counts['missed_gentle_edges']:,} gentle")
    print(f"wrote {', '.join(str(p) for p in result.files.values())}")
    return 0
