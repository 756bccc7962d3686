"""``recon ingest`` (strikes to a body-frame cloud), ``recon trajectory`` (the sensor's recorded
poses as text) and ``recon truth`` (the embedded mesh)."""

from __future__ import annotations

import argparse
from pathlib import Path


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
    p.set_defaults(func=run_ingest)

    p = sub.add_parser("trajectory", help="export the recorded sensor trajectory as text",
                       description="Write one line per shot: time [s], sensor position [m] and "
                                   "attitude (roll, pitch, yaw [rad] and the quaternion x y z w) "
                                   "in the body frame (as the ingested cloud) or the inertial "
                                   "frame, like the trajectory HELIOS++ writes beside its "
                                   "clouds.")
    p.add_argument("log", help="strike log (.h5)")
    p.add_argument("-o", "--output", required=True, type=Path, metavar="TRAJ.txt",
                   help="trajectory to write: .txt (space-separated) or .csv")
    p.add_argument("--frame", choices=("body", "inertial"), default="body",
                   help="frame of positions and attitudes (default: %(default)s)")
    p.set_defaults(func=run_trajectory)

    p = sub.add_parser("truth", help="export the truth mesh embedded in a strike log",
                       description="Write the log's /truth/mesh as a binary PLY.")
    p.add_argument("log", help="strike log (.h5) with a truth group")
    p.add_argument("-o", "--output", required=True, type=Path, help="mesh to write (.ply)")
    p.set_defaults(func=run_truth)


def run_ingest(args) -> int:
    from tqdm import tqdm

    from recon.registration.ingest import ingest_to_file

    with tqdm(unit="strike", unit_scale=True, disable=None, leave=False, desc="ingest") as bar:
        def advance(done: int, total: int) -> None:
            bar.total = total
            bar.update(done)

        summary = ingest_to_file(args.log, args.output, frame=args.frame, progress=advance)
    print(f"wrote {summary['n_points']} points ({args.frame} frame) to {args.output}")
    return 0


def run_trajectory(args) -> int:
    from recon.registration.trajectory import export_trajectory

    summary = export_trajectory(args.log, args.output, frame=args.frame)
    print(f"wrote {summary['n_shots']} poses ({args.frame} frame) to {args.output}")
    return 0


def run_truth(args) -> int:
    from formats import StrikeLog
    from formats.mesh_io import write_mesh

    with StrikeLog(args.log) as log:
        truth = log.truth_mesh()
    write_mesh(args.output, truth, source=Path(args.log).name)
    print(f"wrote truth mesh ({truth.n_vertices} vertices, {truth.n_faces} faces) to "
          f"{args.output}")
    return 0
