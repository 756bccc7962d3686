"""``recon validate`` and ``recon info``: check a strike log and summarise it."""

from __future__ import annotations

import argparse
import json
import math


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("validate", help="check a strike log against formats/SPEC.md",
                       description="Check every row of a strike log against the format spec. "
                                   "Exit 0 when valid, 1 with the reason otherwise.")
    p.add_argument("log", help="strike log (.h5)")
    p.set_defaults(func=run_validate)

    p = sub.add_parser("info", help="summarise a strike log",
                       description="Counts, time span, sensor, target and whether truth is "
                                   "present.")
    p.add_argument("log", help="strike log (.h5)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run_info)


def run_validate(args) -> int:
    from tqdm import tqdm

    from formats import StrikeLog

    with StrikeLog(args.log) as log:
        total = log.n_shots + log.n_strikes
        with tqdm(total=total, unit="row", disable=None, leave=False, desc="validate") as bar:
            log.validate(progress=bar.update)
        print(f"{args.log}: valid strike log v{log.attrs['format_version']} "
              f"({log.n_shots} shots, {log.n_strikes} strikes)")
    return 0


def _describe_sensor(sensor: dict) -> str:
    import numpy as np

    fov = [math.degrees(a) for a in sensor["field_of_view"]]
    text = f"{sensor['pattern']}, {sensor['n_beams']} beam(s)"
    if any(fov):
        text += (f", field of view az {fov[0]:+.3g}..{fov[1]:+.3g} deg, "
                 f"el {fov[2]:+.3g}..{fov[3]:+.3g} deg")
    text += f", range {sensor['range_min']:g}..{sensor['range_max']:g} m"
    errors = {k: v for k, v in sensor["errors"].items() if any(np.atleast_1d(v))}
    text += "; errors: " + (", ".join(
        f"{k}=" + ",".join(f"{x:g}" for x in np.atleast_1d(v)) for k, v in errors.items())
        or "none")
    return text


def run_info(args) -> int:
    from formats import StrikeLog

    with StrikeLog(args.log) as log:
        summary = log.summary()
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    span = ("empty" if summary["time_start_s"] is None else
            f"{summary['time_start_s']:g} .. {summary['time_end_s']:g} s "
            f"({summary['duration_s'] / 3600:.3g} h)")
    rows = [
        ("log", summary["path"]),
        ("format", f"{summary['format']} v{summary['format_version']}, by "
                   f"{summary['producer']}, {summary['created_utc']}"),
        ("target", summary["target"]),
        ("seed", summary["seed"]),
        ("shots", summary["n_shots"]),
        ("strikes", f"{summary['n_strikes']} of {summary['n_pulses']} pulses"),
        ("time", span),
        ("sensor", _describe_sensor(summary["sensor"])),
        ("truth", "present" if summary["has_truth"] else "absent"),
    ]
    if summary.get("epoch_et") is not None:   # a SPICE-driven scene: ET of time 0
        from formats.spice import et_to_utc

        rows.insert(7, ("epoch", f"ET {summary['epoch_et']:.6f} s (UTC "
                                 f"{et_to_utc(summary['epoch_et'])[0]})"))
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"{key:<{width}}  {value}")
    return 0
