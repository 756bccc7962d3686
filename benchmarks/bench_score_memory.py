"""Peak memory of ``recon score`` on a strike log as the log grows: it should stay flat.

Three LIDAR logs of the ``asteroid-lidar`` preset, 1x, 2x and 4x as long (``time.duration``),
are simulated once (seeded) into a temporary directory; each is scored by ``recon score LOG
--json`` in a fresh process, ``--repeats`` times in turn, and the process's peak resident memory
(VmHWM, its own high-water mark) is read at its end. Printed per size: strikes, median peak RSS,
its ratio to the 1x log's (target: at most 1.1 at 4x, i.e. flat), and the median wall time.
Scoring holds up to ``metrics.defaults.STREAM_BLOCK`` points (1 M) for each nearest-distance
query, so a 1x log smaller than that sits below the plateau. The edge metric (the default) is
streamed too (``metrics.edges_stream``: slabs of ``EDGE_SLAB_POINTS``, 0.5 M, one pass over
the log each); ``--no-edges`` shows the rest of the scoring alone.

Then, with the edge metric, the cost of streaming it: on the largest log, in this process, the
edge metric alone by ``edge_report`` on the gathered points (``ingest_points``: the log read
once, the cloud held) against ``EdgeStream`` over ``iter_points`` (the log read once per pass),
medians of the repeats, with the passes it made; the two reports are checked equal.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_score_memory.py                # ~5 min here
    PYTHONPATH=. .venv/bin/python benchmarks/bench_score_memory.py --no-edges
    PYTHONPATH=. .venv/bin/python benchmarks/bench_score_memory.py --duration 2000 --repeats 3
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without relying on the installed package

# Runs `recon score` in this process and prints its peak RSS [kB] last on stderr. VmHWM is the
# high-water mark of this process's own address space (getrusage's ru_maxrss would carry the
# parent's across fork and exec).
_CHILD = """
import sys
from cli.main import main
status = main(sys.argv[1:])
hwm = next(line for line in open('/proc/self/status') if line.startswith('VmHWM'))
print('PEAK_KB', hwm.split()[1], file=sys.stderr)
sys.exit(status)
"""


def score_run(log: Path, extra: list[str]) -> tuple[float, float, dict]:
    """Peak RSS [MB], wall time [s] and the JSON report of one ``recon score`` in a child."""
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", _CHILD, "score", str(log), "--json", *extra],
                          capture_output=True, text=True, check=False,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"recon score {log} failed:\n{proc.stderr}")
    peak_kb = int(proc.stderr.rsplit("PEAK_KB", 1)[1].split()[0])
    return peak_kb / 1024, wall, json.loads(proc.stdout)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=7500.0,
                        help="time.duration of the 1x log [s] (default: %(default)s, "
                             "about 0.58 M strikes)")
    parser.add_argument("--sizes", default="1,2,4", help="log lengths in units of the 1x log")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-edges", action="store_true", help="score without the edge metric")
    args = parser.parse_args(argv)
    if args.repeats < 3:
        parser.error("--repeats must be >= 3 (medians)")
    import sim
    from formats import StrikeLog

    sizes = [float(s) for s in args.sizes.split(",")]
    extra = ["--no-edges"] if args.no_edges else []
    with tempfile.TemporaryDirectory() as tmp:
        logs = {}
        for size in sizes:
            path = Path(tmp) / f"lidar-{size:g}x.h5"
            scene = sim.load_scene("asteroid-lidar", [f"time.duration={args.duration * size}"])
            sim.simulate(scene, path, seed=0, progress=False)
            with StrikeLog(path) as log:
                logs[size] = (path, log.n_strikes)
        peaks = {size: [] for size in sizes}
        walls = {size: [] for size in sizes}
        for _ in range(args.repeats):   # sizes in turn: each sees the same load
            for size in sizes:
                peak, wall, _ = score_run(logs[size][0], extra)
                peaks[size].append(peak)
                walls[size].append(wall)
        edge_cost = None if args.no_edges else edge_cost_line(logs[sizes[-1]], args.repeats)
    base = statistics.median(peaks[sizes[0]])
    print(f"recon score {' '.join(extra)} on asteroid-lidar logs, medians of {args.repeats}")
    print(f"{'size':>5} {'strikes':>10} {'peak RSS MB':>12} {'ratio':>6} {'wall s':>7}")
    for size in sizes:
        peak = statistics.median(peaks[size])
        print(f"{size:>4g}x {logs[size][1]:>10,} {peak:>12.0f} {peak / base:>6.2f} "
              f"{statistics.median(walls[size]):>7.1f}")
    ratio = statistics.median(peaks[sizes[-1]]) / base
    print(f"peak RSS {sizes[-1]:g}x / {sizes[0]:g}x = {ratio:.2f} (target <= 1.10: "
          f"{'met' if ratio <= 1.10 else 'MISSED'})")
    if edge_cost:
        print(edge_cost)
    return 0


def edge_cost_line(log: tuple[Path, int], repeats: int) -> str:
    """Median wall time of the edge metric gathered and streamed on one log (module docs)."""
    from metrics.edges import edge_report
    from metrics.edges_stream import EdgeStream
    from recon.api import truth_of
    from recon.registration.ingest import ingest_points, iter_points

    path, strikes = log
    mesh = truth_of(path)
    gathered, streamed, passes = [], [], []

    def blocks():
        passes.append(1)
        return iter_points(path)
    for _ in range(repeats):
        start = time.perf_counter()
        whole = edge_report(ingest_points(path), mesh)
        gathered.append(time.perf_counter() - start)
        start = time.perf_counter()
        passes.clear()
        stream = EdgeStream(mesh)
        for points in blocks():
            stream.add(points)
        report = stream.report(blocks)
        streamed.append(time.perf_counter() - start)
        if report.to_dict() != whole.to_dict():
            raise SystemExit(f"streamed edge report differs: {report} != {whole}")
    g, s = statistics.median(gathered), statistics.median(streamed)
    return (f"edge metric alone on {strikes:,} strikes (log read included), medians of "
            f"{repeats}: gathered {g:.1f} s, streamed {s:.1f} s in {len(passes)} passes "
            f"({s / g:.2f}x)")


if __name__ == "__main__":
    sys.exit(main())
