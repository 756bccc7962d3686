"""Strike-log storage: write time, read time and size with no compression, lzf and gzip levels.

A 10-million-strike log shaped like a scanning-LIDAR campaign (10 strikes per shot, a smooth
orbit and attitude, noisy ranges), with its truth group, written by the real StrikeLogWriter in
1-million-strike blocks and read back through StrikeLog.iter_chunks. The baseline is "none";
``--compressions`` lists the filters to measure (default: none, lzf and gzip at levels 1, 4, 6
and 9).

    .venv/bin/python benchmarks/bench_log_compression.py            # 10 M strikes, 3 repeats
    .venv/bin/python benchmarks/bench_log_compression.py --quick    # 200 k strikes, 1 repeat

``--scene PRESET`` measures the real pipeline instead: ``recon simulate PRESET --compression C``
(the simulator with its Embree ray casting) and ``recon ingest`` of the log, per compression, with
simulate time also as a ratio against lzf's in the same run (the default's budget: 1.3x):

    .venv/bin/python benchmarks/bench_log_compression.py --scene asteroid-lidar --repeats 1
    .venv/bin/python benchmarks/bench_log_compression.py --scene asteroid-lrf-slew
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from formats import SensorInfo, Shots, StrikeLog, StrikeLogWriter, TruthStrikes
from formats.strike_log import angles_to_directions, compression_filters

STRIKES_PER_SHOT = 10
BLOCK = 1_000_000
COMPRESSIONS = ("none", "lzf", "gzip:1", "gzip:4", "gzip:6", "gzip:9")


def synthetic_blocks(n_strikes: int, seed: int = 0):
    """Yield (shots, truth shots, strike columns, truth strikes) blocks of a plausible campaign."""
    rng = np.random.default_rng(seed)
    for lo in range(0, n_strikes, BLOCK):
        n = min(BLOCK, n_strikes - lo)
        n_shots = n // STRIKES_PER_SHOT
        s0 = lo // STRIKES_PER_SHOT
        t = (s0 + np.arange(n_shots)) * 10.0
        phase = 2 * np.pi * t / 20_000.0
        pos = 750.0 * np.stack([np.cos(phase), np.sin(phase), 0.1 * np.sin(phase)], 1)
        att = Rotation.from_rotvec(np.outer(phase, [0, 0, 1.0])).as_quat()
        tgt = Rotation.from_rotvec(np.outer(2 * np.pi * t / 15480.0, [0, 0, 1.0])).as_quat()
        shot = np.repeat(s0 + np.arange(n_shots), STRIKES_PER_SHOT)
        beam = np.tile(np.arange(STRIKES_PER_SHOT), n_shots)
        true_range = 600.0 + 50.0 * rng.random(n)
        point = rng.normal(0, 150.0, (n, 3))
        yield ((t, pos, att, tgt), Shots(t, pos, att, tgt),
               (shot, beam, true_range + rng.normal(0, 0.1, n)),
               TruthStrikes(point, rng.integers(0, 20_480, n), true_range))


def write_log(path: Path, n_strikes: int, compression: str) -> float:
    beams = angles_to_directions(np.linspace(-0.1, 0.1, STRIKES_PER_SHOT),
                                 np.zeros(STRIKES_PER_SHOT))
    sensor = SensorInfo("grid", beams, range_min=1.0, range_max=5000.0,
                        field_of_view=(-0.1, 0.1, 0.0, 0.0))
    blocks = list(synthetic_blocks(n_strikes))  # generate outside the timed region
    mesh = (np.zeros((3, 3)), np.array([[0, 1, 2]]))
    start = time.perf_counter()
    with StrikeLogWriter(path, sensor=sensor, target="bench", truth_mesh=mesh,
                         compression=compression) as log:
        for shots, truth_shots, strikes, truth in blocks:
            log.write_shots(*shots, truth=truth_shots)
            log.write_strikes(*strikes, truth=truth)
    return time.perf_counter() - start


def read_log(path: Path) -> float:
    start = time.perf_counter()
    with StrikeLog(path) as log:
        n = sum(len(chunk) for chunk in log.iter_chunks())
        log.truth_strikes()
    assert n > 0
    return time.perf_counter() - start


def scene_rows(scene: str, repeats: int, compressions):
    """Yield ``(compression, median simulate s, median ingest s, log MB)`` of a preset, in the
    order of ``compressions``, each as soon as it is measured."""
    from recon import api
    from recon.registration.ingest import ingest_to_file

    with tempfile.TemporaryDirectory() as tmp:
        for compression in compressions:
            path, cloud = Path(tmp) / "log.h5", Path(tmp) / "cloud.h5"
            w, r = [], []
            for _ in range(repeats):
                path.unlink(missing_ok=True)
                start = time.perf_counter()
                api.simulate(scene, path, seed=0, compression=compression)
                w.append(time.perf_counter() - start)
                cloud.unlink(missing_ok=True)
                start = time.perf_counter()
                ingest_to_file(path, cloud)
                r.append(time.perf_counter() - start)
            size = path.stat().st_size / 1e6
            path.unlink()
            yield compression, statistics.median(w), statistics.median(r), size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="200 k strikes, one repeat")
    parser.add_argument("--scene", help="simulate and ingest this preset instead")
    parser.add_argument("--repeats", type=int, default=3, help="repeats with --scene")
    parser.add_argument("--compressions", default=",".join(COMPRESSIONS),
                        help="comma-separated filters to measure, the first the baseline "
                             "(default: %(default)s)")
    args = parser.parse_args()
    compressions = args.compressions.split(",")
    for name in compressions:
        compression_filters(name)
    if args.scene:
        print(f"recon simulate {args.scene} and recon ingest; median of {args.repeats}; ratios "
              f"against {compressions[0]!r} (x) and lzf (x lzf) measured in this run")
        print(f"{'compression':<12}{'simulate s':>11}{'ingest s':>10}{'size MB':>9}"
              f"{'simulate x':>11}{'ingest x':>9}{'size x':>8}{'sim x lzf':>10}"
              f"{'ingest x lzf':>13}", flush=True)
        rows = []
        for row in scene_rows(args.scene, args.repeats, compressions):
            rows.append(row)
            name, w, r, s = row
            base = rows[0]
            lzf = next((x for x in rows if x[0] == "lzf"), None)
            vs_lzf = (f"{w / lzf[1]:10.2f}{r / lzf[2]:13.2f}" if lzf else f"{'':10}{'':13}")
            print(f"{name:<12}{w:11.2f}{r:10.2f}{s:9.1f}{w / base[1]:11.2f}{r / base[2]:9.2f}"
                  f"{s / base[3]:8.2f}{vs_lzf}", flush=True)
        return
    n_strikes, repeats = (200_000, 1) if args.quick else (10_000_000, 3)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for compression in compressions:
            path = Path(tmp) / f"{compression}.h5"
            w = [write_log(path, n_strikes, compression) for _ in range(repeats)]
            r = [read_log(path) for _ in range(repeats)]
            rows[compression] = (statistics.median(w), statistics.median(r),
                                 path.stat().st_size / 1e6)
            path.unlink()
    base_w, base_r, base_s = rows[compressions[0]]
    print(f"strike log, {n_strikes:,} strikes ({n_strikes // STRIKES_PER_SHOT:,} shots) with "
          f"truth; median of {repeats}; ratios against {compressions[0]!r} measured in this run")
    print(f"{'compression':<12}{'write s':>9}{'read s':>9}{'size MB':>9}{'write x':>9}"
          f"{'read x':>8}{'size x':>8}{'Mstrikes/s write':>18}")
    for name, (w, r, s) in rows.items():
        print(f"{name:<12}{w:9.2f}{r:9.2f}{s:9.0f}{w / base_w:9.2f}{r / base_r:8.2f}"
              f"{s / base_s:8.2f}{n_strikes / w / 1e6:18.2f}")


if __name__ == "__main__":
    main()
