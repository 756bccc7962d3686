"""The visibility method's minimum cut: Boykov-Kolmogorov (``_min_cut``) against scipy's Dinic.

    python benchmarks/bench_min_cut.py --suite DIR      # the suite's logs in DEFAULT_CLOUDS
    python benchmarks/bench_min_cut.py --log LOG.h5 [--log ...]

For each strike log the visibility method (``recon.surfaces.methods.visibility``, its defaults)
runs on the log as ``recon reconstruct -m visibility`` prepares it (``load_prepared``: ingest,
normals, spacing, the recorded noise; no missed beams), and the graph it hands to its minimum
cut is kept. On that graph the cut recon uses (``_backends.source_side``: the summed arcs, then
Boykov-Kolmogorov compiled with numba) and the baseline, scipy's Dinic maximum flow with a
breadth-first search of its residual graph (the cut it replaced), each run ``--repeats`` times;
the medians, their ratio and whether the two sides are identical are printed. The numba kernels
are loaded before the clock starts (their import is a worker's start-up, ``WORKER_PRELOAD``).
No time is asserted; measured numbers are recorded in docs/decisions.md.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from unittest import mock

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

# A clean cross over a natural body (noise-free strikes along lines: many Delaunay cells per
# strike) and a noisy LIDAR satellite (the suite's usual visibility choice).
DEFAULT_CLOUDS = ("castalia-cross-clean", "satellite-w-lidar-noisy")


def visibility_graph(log: Path) -> tuple:
    """The arguments the visibility method at its defaults hands to ``source_side`` on ``log``:
    ``(n_nodes, rows, cols, capacity, source, sink)``."""
    from formats.errors import MethodFailed
    from recon.surfaces.methods import visibility
    from recon.surfaces.prepare import load_prepared

    _, prepared = load_prepared(log)
    kept = []

    def keep(*args):
        kept.append(args)
        return np.ones(args[0], dtype=bool)   # every cell outside: the method stops there

    defaults = {name: p.default for name, p in visibility.METHOD.params.items()}
    with mock.patch.object(visibility, "source_side", keep):
        try:
            visibility.run(prepared, **defaults)
        except MethodFailed:   # every cell outside leaves no surface: expected
            pass
    return kept[0]


def dinic_source_side(n, rows, cols, capacity, source, sink) -> np.ndarray:
    """The baseline: scipy's Dinic maximum flow, then the nodes the source reaches in its
    residual graph."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, maximum_flow

    graph = coo_matrix((np.concatenate([capacity, np.zeros_like(capacity)]).astype(np.int64),
                        (np.concatenate([rows, cols]), np.concatenate([cols, rows]))),
                       shape=(n, n)).tocsr()
    graph.sum_duplicates()
    graph.data = np.minimum(graph.data, np.iinfo(np.int32).max).astype(np.int32)
    flow = maximum_flow(graph, source, sink, method="dinic").flow
    residual = (graph - flow).tocsr()
    residual.data = (residual.data > 0).astype(np.int32)
    residual.eliminate_zeros()
    side = np.zeros(n, dtype=bool)
    side[breadth_first_order(residual, source, directed=True, return_predecessors=False)] = True
    return side


def timed(function, graph, repeats: int, bar) -> tuple[float, np.ndarray]:
    """Median wall time [s] of ``function(*graph)`` over ``repeats`` runs, and its result; each
    run moves the progress ``bar``."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        side = function(*graph)
        times.append(time.perf_counter() - start)
        bar.update(1)
    return statistics.median(times), side


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", type=Path, help="a suite run's output (its logs/ are read)")
    parser.add_argument("--log", type=Path, action="append", default=[],
                        help="a strike log (repeatable)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    logs = list(args.log) + ([args.suite / "logs" / f"{name}.h5" for name in DEFAULT_CLOUDS]
                             if args.suite else [])
    if not logs:
        parser.error("give --suite DIR or --log LOG.h5")
    for log in logs:
        if not log.is_file():
            parser.error(f"{log}: no such strike log")

    from tqdm import tqdm

    from recon.surfaces.methods import _min_cut  # noqa: F401  (the kernels, before the clock)
    from recon.surfaces.methods._backends import source_side

    print("| log | cells | arcs | Dinic s | Boykov-Kolmogorov s | ratio | identical |")
    print("|---|---|---|---|---|---|---|")
    bar = tqdm(total=len(logs) * (1 + 2 * args.repeats), desc="min cut", unit="step",
               leave=False)
    for log in logs:
        graph = visibility_graph(log)
        bar.update(1)
        baseline_s, expected = timed(dinic_source_side, graph, args.repeats, bar)
        ours_s, side = timed(source_side, graph, args.repeats, bar)
        bar.clear()
        print(f"| {log.stem} | {graph[0] - 2:,} | {len(graph[1]):,} | {baseline_s:.2f} | "
              f"{ours_s:.2f} | {ours_s / baseline_s:.2f} | "
              f"{'yes' if np.array_equal(side, expected) else 'NO'} |", flush=True)
    bar.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
