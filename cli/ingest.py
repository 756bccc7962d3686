"""``recon ingest`` (strikes or a mission's altimetry to a body-frame cloud), ``recon trajectory``
(the sensor's recorded poses as text or SPICE kernels), ``recon altimetry`` (a log as a mission's
altimetry product) and ``recon truth`` (the embedded mesh)."""

from __future__ import annotations

import argparse
from pathlib import Path

from cli.options import UsageError

# Seconds between two redraws of the refinement's bar while the main thread waits for it.
REFRESH_S = 0.5


def _add_epoch(parser, prefix: str = "") -> None:
    """``--epoch-utc`` / ``--epoch-et``: the epoch of a log's time 0 (``prefix`` says where it
    applies)."""
    epoch = parser.add_mutually_exclusive_group()
    epoch.add_argument("--epoch-utc", metavar="UTC",
                       help=f"{prefix}UTC of the log's time 0, e.g. 2019-02-13T01:00:00 "
                            "(default: the log's own epoch when its scene was SPICE-driven, "
                            "else the J2000 epoch)")
    epoch.add_argument("--epoch-et", type=float, metavar="ET",
                       help=f"{prefix}the same as TDB seconds past J2000")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ingest", help="register a strike log (or read altimetry) into a point "
                                      "cloud",
                       description="Place every strike in the target body frame using only the "
                                   "recorded poses and measurements (never the truth), keeping "
                                   "time, shot, beam, range and the view point per point. Or "
                                   "read a mission's laser altimetry: an OSIRIS-REx OLA Level-2 "
                                   "table through its PDS4 label (.xml) or a Hayabusa2 LIDAR "
                                   "Level-2 CSV (.csv), keeping time, ET, range and the "
                                   "spacecraft position per return; flagged returns are dropped "
                                   "and counted.")
    p.add_argument("log", help="strike log (.h5), OLA Level-2 label (.xml) or Hayabusa2 LIDAR "
                               "Level-2 CSV (.csv)")
    p.add_argument("-o", "--output", required=True, type=Path,
                   help="point cloud to write: .ply, .las, .laz or .h5")
    p.add_argument("--frame", choices=("body", "inertial"), default="body",
                   help="output frame (default: %(default)s; inertial is for debugging)")
    p.add_argument("--refine", action="store_true",
                   help="first estimate pose-knowledge errors (boresight misalignment, position "
                        "bias) from the agreement of passes, print each with its "
                        "uncertainty, and register with the corrected poses")
    p.add_argument("--refine-interval", type=float, metavar="SECONDS",
                   help="with --refine: also estimate slowly varying errors, piecewise-linear "
                        "with knots this far apart (default: constant errors only); the time "
                        "this takes is estimated first, said when over half a minute and "
                        "refused beyond a day")
    p.add_argument("--refine-spin", action="store_true",
                   help="with --refine: also estimate a correction of the target's spin rate")
    p.add_argument("--refine-json", type=Path, metavar="FILE",
                   help="with --refine: also write the estimates as JSON")
    p.add_argument("--follow", action="store_true",
                   help="read the strikes while `recon simulate --live -o LOG` writes them; "
                        "write the cloud once the log is complete")
    p.add_argument("--timeout", type=float, default=60.0, metavar="S",
                   help="--follow: give up after S seconds without a writer or new strikes "
                        "(default: %(default)g)")
    p.set_defaults(func=run_ingest)

    p = sub.add_parser("trajectory",
                       help="export the recorded sensor trajectory as text or SPICE kernels",
                       description="Write one line per shot: time [s], sensor position [m] and "
                                   "attitude (roll, pitch, yaw [rad] and the quaternion x y z w) "
                                   "in the body frame (as the ingested cloud) or the inertial "
                                   "frame, like the trajectory HELIOS++ writes beside its "
                                   "clouds. Or write the poses as SPICE kernels: an SPK (.bsp) "
                                   "of RECON_SENSOR relative to RECON_TARGET in J2000, or a CK "
                                   "(.bc) of the frames RECON_SENSOR_FRAME and "
                                   "RECON_TARGET_FIXED, with the frames kernel (.tf) and, for "
                                   "a CK, the clock kernel (.tsc) beside it.")
    p.add_argument("log", help="strike log (.h5)")
    p.add_argument("-o", "--output", required=True, type=Path, metavar="TRAJ.txt",
                   help="trajectory to write: .txt (space-separated), .csv, .bsp (SPK) or .bc "
                        "(CK)")
    p.add_argument("--frame", choices=("body", "inertial"),
                   help="text: frame of positions and attitudes (default: body); kernels hold "
                        "both frames")
    _add_epoch(p, "kernels: ")
    p.set_defaults(func=run_trajectory)

    p = sub.add_parser("altimetry", help="export a strike log as a mission's altimetry product",
                       description="Write the strikes, registered with the recorded poses, in "
                                   "the layout of OSIRIS-REx OLA Level 2 (a PDS4 binary table "
                                   "and its XML label; pulses that struck nothing become "
                                   "'no return' rows) or of Hayabusa2 LIDAR Level 2 (CSV); "
                                   "`recon ingest` reads both back.")
    p.add_argument("log", help="strike log (.h5)")
    p.add_argument("-o", "--output", required=True, type=Path, metavar="PRODUCT",
                   help="OLA Level-2 label to write (.xml, with the .dat table beside it) or "
                        "Hayabusa2 LIDAR Level-2 CSV (.csv)")
    _add_epoch(p)
    p.set_defaults(func=run_altimetry)

    p = sub.add_parser("truth", help="export the truth mesh embedded in a strike log",
                       description="Write the log's /truth/mesh as a binary PLY (metres, with "
                                   "its frame and source), a PDS vertex/plate table or a SPICE "
                                   "DSK type 2 kernel (km; body RECON_TARGET, frame "
                                   "RECON_TARGET_FIXED).")
    p.add_argument("log", help="strike log (.h5) with a truth group")
    p.add_argument("-o", "--output", required=True, type=Path,
                   help="mesh to write: .ply, .tab (PDS vertex/plate table) or .bds/.dsk (DSK)")
    p.add_argument("--units", choices=("km", "m"),
                   help="units of a .tab's coordinates (default: km, as PDS publishes shape "
                        "models; .ply is always m and a DSK km)")
    p.set_defaults(func=run_truth)


def _check_ingest_options(args) -> None:
    """Refuse options of ``recon ingest`` that do not go together."""
    if not args.timeout > 0:
        raise UsageError(f"--timeout must be a positive number of seconds, got {args.timeout:g}")
    if args.follow and args.refine:
        raise UsageError("--follow and --refine do not go together: refinement needs the "
                         "whole log (run ingest --refine once the log is complete)")
    for given, flag in ((args.refine_interval is not None, "--refine-interval"),
                        (args.refine_json is not None, "--refine-json"),
                        (args.refine_spin, "--refine-spin")):
        if given and not args.refine:
            raise UsageError(f"{flag} needs --refine")
    if args.refine_json is not None:
        from formats.paths import check_destination

        try:
            check_destination(args.refine_json, UsageError)
        except UsageError as exc:
            raise UsageError(f"--refine-json {exc}") from None


def _refine(args):
    """``--refine``: estimate the pose-knowledge errors, print them (and write them).

    The refinement runs in a thread while this one redraws the bar and waits: a step of a large
    fit is one long call into LAPACK (an eigen-decomposition, a normal matrix) that a signal
    cannot interrupt, but the wait can, and the interrupted command leaves at once
    (``cli.main``).
    """
    import json
    import sys
    import threading

    from tqdm import tqdm

    from formats.atomic import write_text_atomically
    from recon import api

    # The bar counts the refinement's estimated seconds: a percentage, and the time left.
    with tqdm(total=1.0, disable=None, leave=False, desc="refine",
              bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}]") as bar:
        def step(done: float, total: float) -> None:
            bar.total = total
            bar.update(done - bar.n)

        def say(line: str) -> None:
            tqdm.write(line)
            sys.stdout.flush()   # before the work, also into a pipe

        outcome = {}

        def work() -> None:
            try:
                outcome["refinement"] = api.refine(
                    args.log, interval=args.refine_interval, spin=args.refine_spin,
                    progress=step, announce=say)
            except BaseException as exc:   # re-raised in the main thread
                outcome["error"] = exc

        worker = threading.Thread(target=work, name="recon-refine")
        worker.start()
        while worker.is_alive():
            worker.join(REFRESH_S)
            bar.refresh()
    if "error" in outcome:
        raise outcome["error"]
    refinement = outcome["refinement"]
    for line in refinement.lines():
        print(line)
    if args.refine_json is not None:
        write_text_atomically(args.refine_json, json.dumps(refinement.to_dict(), indent=2) + "\n",
                              error=UsageError)
        print(f"wrote the estimates to {args.refine_json}")
    return refinement


def run_ingest(args) -> int:
    from tqdm import tqdm

    from recon import api

    if api.is_altimetry(args.log):
        return _ingest_altimetry(args)
    _check_ingest_options(args)
    refinement = _refine(args) if args.refine else None
    with tqdm(unit="strike", unit_scale=True, disable=None, leave=False,
              desc="ingest (following)" if args.follow else "ingest") as bar:
        def advance(done: int, total: int) -> None:
            bar.total = total
            bar.update(done)

        if args.follow:
            result = api.follow(args.log, args.output, frame=args.frame, progress=advance,
                                timeout_s=args.timeout)
        else:
            result = api.ingest_file(args.log, args.output, frame=args.frame, progress=advance,
                                     refinement=refinement)
    print(f"wrote {result.n_points} points ({args.frame} frame"
          + (", refined poses" if result.refined else "") + f") to {args.output}")
    return 0


def _ingest_altimetry(args) -> int:
    """``recon ingest PRODUCT``: a mission's altimetry, already in the body frame."""
    from recon import api

    given = [name for name, on in (("--refine", args.refine), ("--follow", args.follow),
                                   ("--frame inertial", args.frame != "body")) if on]
    if given:
        raise UsageError(f"{args.log}: {', '.join(given)} apply to strike logs; an "
                         "altimetry product is read as its body-frame returns")
    result = api.ingest_altimetry(args.log, args.output)
    dropped = result.dropped
    print(f"read {result.n_points} returns of {result.product} {args.log}; dropped "
          + (", ".join(f"{n} {why}" for why, n in dropped.items()) if dropped else "none"))
    print(f"wrote {result.n_points} points (body frame) to {args.output}")
    return 0


def _epoch(args) -> float | None:
    if args.epoch_utc is None:
        return args.epoch_et
    from formats.spice import utc_to_et

    return utc_to_et(args.epoch_utc, "--epoch-utc")


def run_altimetry(args) -> int:
    from recon import api

    result = api.export_altimetry(args.log, args.output, epoch_et=_epoch(args))
    extra = f" and {result.n_no_return} no-return rows" if result.n_no_return else ""
    print(f"wrote {result.n_returns} returns{extra} ({result.product}) to "
          + ", ".join(str(p) for p in result.written))
    return 0


def run_trajectory(args) -> int:
    from recon import api

    if api.is_kernel(args.output):
        if args.frame is not None:
            raise UsageError("--frame is for text trajectories: an SPK is in J2000 (the "
                             "log's inertial frame) and a CK holds the body frame too")
        result = api.trajectory(args.log, args.output, epoch_et=_epoch(args))
        print(f"wrote {result.n_shots} poses from ET {result.epoch_et:.6f} to "
              + ", ".join(str(p) for p in result.written))
        return 0
    if args.epoch_utc is not None or args.epoch_et is not None:
        raise UsageError("--epoch-utc and --epoch-et are for kernels (.bsp, .bc)")
    result = api.trajectory(args.log, args.output, frame=args.frame or "body")
    print(f"wrote {result.n_shots} poses ({result.frame} frame) to {args.output}")
    return 0


def run_truth(args) -> int:
    from formats import StrikeLog
    from formats.mesh_io import write_mesh

    with StrikeLog(args.log) as log:
        truth = log.truth_mesh()
    write_mesh(args.output, truth, source=Path(args.log).name, units=args.units)
    print(f"wrote truth mesh ({truth.n_vertices} vertices, {truth.n_faces} faces) to "
          f"{args.output}")
    return 0
