"""``recon ingest`` (strikes to a body-frame cloud) and ``recon truth`` (the embedded mesh)."""

from __future__ import annotations

import argparse
from pathlib import Path

from formats.errors import ReconError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ingest", help="register a strike log into a point cloud",
                       description="Place every strike in the target body frame using only the "
                                   "recorded poses and measurements (never the truth), keeping "
                                   "time, shot, beam, range and the view point per point.")
    p.add_argument("log", help="strike log (.h5)")
    p.add_argument("-o", "--output", required=True, type=Path,
                   help="point cloud to write: .ply, .las, .laz or .h5")
    p.add_argument("--frame", choices=("body", "inertial"), default="body",
                   help="output frame (default: %(default)s; inertial is for debugging)")
    p.add_argument("--follow", action="store_true",
                   help="read the strikes while `recon simulate --live -o LOG` writes them; "
                        "write the cloud once the log is complete")
    p.add_argument("--timeout", type=float, default=60.0, metavar="S",
                   help="--follow: give up after S seconds without a writer or new strikes "
                        "(default: %(default)g)")
    p.set_defaults(func=run_ingest)

    p = sub.add_parser("truth", help="export the truth mesh embedded in a strike log",
                       description="Write the log's /truth/mesh as a binary PLY.")
    p.add_argument("log", help="strike log (.h5) with a truth group")
    p.add_argument("-o", "--output", required=True, type=Path, help="mesh to write (.ply)")
    p.set_defaults(func=run_truth)


def run_ingest(args) -> int:
    from tqdm import tqdm

    from recon.registration.ingest import ingest_following, ingest_to_file

    if not args.timeout > 0:
        raise ReconError(f"--timeout must be a positive number of seconds, got "
                         f"{args.timeout:g}")
    with tqdm(unit="strike", unit_scale=True, disable=None, leave=False,
              desc="ingest (following)" if args.follow else "ingest") as bar:
        def advance(done: int, total: int) -> None:
            bar.total = total
            bar.update(done)

        if args.follow:
            summary = ingest_following(args.log, args.output, frame=args.frame,
                                       progress=advance, timeout_s=args.timeout)
        else:
            summary = ingest_to_file(args.log, args.output, frame=args.frame, progress=advance)
    print(f"wrote {summary['n_points']} points ({args.frame} frame) to {args.output}")
    return 0


def run_truth(args) -> int:
    from formats import StrikeLog
    from formats.mesh_io import write_mesh

    with StrikeLog(args.log) as log:
        truth = log.truth_mesh()
    write_mesh(args.output, truth)
    print(f"wrote truth mesh ({truth.n_vertices} vertices, {truth.n_faces} faces) to "
          f"{args.output}")
    return 0
