"""``recon score``: score a cloud, mesh or strike log against a truth mesh."""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

# Rows of the readable table: (key in ScoreReport.to_dict(), label, unit).
_TABLE = (
    ("n_points", "points scored", ""),
    ("tau_m", "tau", "m"),
    ("accuracy_mean_m", "accuracy mean (test to truth)", "m"),
    ("accuracy_median_m", "accuracy median", "m"),
    ("accuracy_p95_m", "accuracy 95th percentile", "m"),
    ("completeness_mean_m", "completeness mean (truth to test)", "m"),
    ("completeness_p95_m", "completeness 95th percentile", "m"),
    ("chamfer_m", "Chamfer", "m"),
    ("chamfer_se_m", "Chamfer standard error", "m"),
    ("hausdorff_m", "Hausdorff", "m"),
    ("precision", "precision at tau", ""),
    ("recall", "recall at tau", ""),
    ("fscore", "F-score at tau", ""),
    ("fscore_se", "F-score standard error", ""),
    ("coverage", "coverage (area within tau)", ""),
    ("normal_consistency", "normal consistency", ""),
    ("edge_score", "edge score (0 best, 1 worst)", ""),
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("score", help="score a cloud, mesh or log against the truth mesh",
                       description="Accuracy, completeness, Chamfer, Hausdorff, precision, recall "
                                   "and F-score at tau, coverage and the edge metric of TEST "
                                   "against TRUTH (definitions: metrics/score.py).")
    p.add_argument("test", type=Path,
                   help="point cloud (.ply .las .laz .h5 .xyz .xyzn .csv ...), mesh (.ply .obj "
                        ".stl .off) or strike log (.h5, registered on the fly)")
    p.add_argument("--truth", type=Path,
                   help="truth mesh file, or a strike log with an embedded truth mesh (default: "
                        "TEST itself when it is a log with truth)")
    p.add_argument("--truth-scale", type=float, default=1.0,
                   help="factor applied to a truth mesh file's coordinates after --truth-units "
                        "(default: %(default)s)")
    p.add_argument("--truth-units", choices=("km", "m"),
                   help="units of a truth mesh file (default: km for PDS tables .tab, ICQ .icq "
                        "and SPICE DSK .bds/.dsk, which is always km; m for OBJ, PLY, STL)")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--tau", type=float, help="threshold of precision/recall/coverage [m]")
    group.add_argument("--tau-fraction", type=float,
                       help="threshold as a fraction of the truth's bounding-box diagonal "
                            "(default 0.01)")
    p.add_argument("--no-edges", action="store_true", help="skip the edge metric")
    p.add_argument("--edge-variant", choices=("weighted", "feature"), default="weighted",
                   help="weighted: every truth edge by length x dihedral angle (the paper's "
                        "metric); feature: only edges sharper than 30 deg (default: "
                        "%(default)s; 'recon edges' draws them)")
    p.add_argument("--precision", type=float, default=None,
                   help="relative standard error the scores are sampled to: the Chamfer "
                        "distance's at most this fraction of it, the F-score's, coverage's and "
                        "edge score's at most a quarter of it (default 0.02, i.e. 0.005 on "
                        "F); the achieved errors are reported (*_se)")
    p.add_argument("--seed", type=int, default=0, help="seed of the surface sampling")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def run(args) -> int:
    import sys

    from tqdm import tqdm

    from recon import api

    truth = api.default_truth(args.test) if args.truth is None else args.truth
    stages = 2 if args.no_edges else 3
    with warnings.catch_warnings(record=True) as caught, \
            tqdm(total=stages, desc="score", unit="stage", disable=None, leave=False,
                 delay=1.0) as bar:
        warnings.simplefilter("always")
        report = api.score(args.test, truth=truth, truth_scale=args.truth_scale,
                           truth_units=args.truth_units, tau=args.tau,
                           tau_fraction=args.tau_fraction, seed=args.seed,
                           precision=args.precision,
                           edges=not args.no_edges, edge_options={"variant": args.edge_variant},
                           progress=lambda stage: bar.update(1))
    from metrics.errors import FrameAssumedWarning

    for w in caught:
        kind = "note" if issubclass(w.category, FrameAssumedWarning) else "warning"
        print(f"recon score: {kind}: {w.message}", file=sys.stderr)
    result = report.to_dict()
    result |= {"test": str(args.test), "truth": str(truth)}
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"{args.test} ({result['test_kind']}) against {truth}")
    width = max(len(label) for _, label, _ in _TABLE)
    total = result.get("n_test_points")
    sampled = total is not None and total > result["n_points"]
    for key, label, unit in _TABLE:
        value = result.get(key)
        text = "n/a" if value is None else (f"{value:d}" if isinstance(value, int)
                                            else f"{value:.4g}")
        if key == "n_points" and sampled:
            text += f" of {total} (a seeded sample sized by the precision)"
        print(f"  {label:<{width}}  {text} {unit}".rstrip())
    if sampled:
        print("  the accuracy median, 95th percentile and Hausdorff are the sample's: a lone "
              "far point may be missed")
    return 0
