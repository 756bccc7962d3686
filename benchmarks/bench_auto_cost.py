"""``recon reconstruct -m auto`` against ``recon compare`` on the same cloud, timed in one session.

    python benchmarks/bench_auto_cost.py --suite DIR       # the suite's costliest auto clouds
    python benchmarks/bench_auto_cost.py --suite DIR --clouds satellite-d-cross-noisy
    python benchmarks/bench_auto_cost.py --suite DIR --baseline OLD   # an older auto beside
    python benchmarks/bench_auto_cost.py --quick           # a small generated satellite, once

The auto suite's cost column (``benchmarks/suite.py``) times auto anew against a compare time
recorded when the compare ran, possibly in a quieter hour; here both run in the same session,
alternately, each a fresh process as a user types it:

- compare: ``recon compare LOG --truth LOG -o DIR --grid full --samples 20000``, the suite's
  compare (every method at its defaults and its grid, scored on ``suite.SAMPLES`` samples a
  side, the meshes kept) without its unweighted twins of the weighted methods, which the
  command does not run: if anything, the ratio is a little higher than against the suite's;
- auto: ``recon reconstruct LOG -o MESH.ply -m auto`` (with ``--target-kind`` as the suite
  states the cloud's target), everything the command does: ingest, preparation, the choice, the
  refit on every strike, the estimate, the written mesh;
- with ``--baseline DIR``: the same two commands run from the source tree ``DIR`` (e.g. an
  export of an older commit, ``git archive COMMIT | tar -x -C DIR``), alternating with the
  others: the ratio before a change and after it, measured side by side.

Each is repeated ``--repeats`` times (median quoted). CPU time is the process's user + system
time with every child it waited for (``RUSAGE_CHILDREN``: the warm workers included). The
ratios auto / compare are printed for wall and CPU time with the 1-minute load average before
and after each cloud (the machine may be shared: CPU ratios travel better than wall ones). No
time is asserted.

Clouds: ``--suite DIR`` reads the strike logs a suite run left in ``DIR/logs`` (read only;
every output goes to ``--work``), default ``DEFAULT_CLOUDS``, the clouds with the highest
auto / compare ratio in the suite's report. Without ``--suite``, ``QUICK_CLOUD`` is simulated
in its quick form (``suite.simulate(quick=True)``: a quarter of a rotation) into ``--work``.
The table goes to ``--out`` (Markdown, and JSON beside it); measured numbers are recorded in
``benchmarks/results_auto_cost.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT))

import suite  # noqa: E402  (benchmarks/suite.py: the clouds, their logs and the score samples)
from bench_user import timed  # noqa: E402  (a fresh process's wall and CPU time)
from tqdm import tqdm  # noqa: E402

PYTHON = sys.executable
# The ``recon`` command of a source tree, run by this interpreter (the tree first on the path).
RECON = [PYTHON, "-c", "import sys; from cli.main import main; sys.exit(main())"]
# The suite's clouds where auto cost the most of compare's time (docs/auto-suite.md): W, a
# small cloud where the fixed part (start-up, imports, preparation, refit) weighs most.
DEFAULT_CLOUDS = ("satellite-w-lidar-noisy", "satellite-d-cross-noisy",
                  "satellite-k-lidar-noisy", "satellite-i-slew-noisy",
                  "satellite-j-cross-noisy")
# The cloud of the quick form: a generated satellite under the 5-beam cross, simulated short.
QUICK_CLOUD = "satellite-d-cross-noisy"
# The commands timed per cloud: this tree's compare and auto, the baseline tree's.
SIDES = ("compare", "auto", "baseline compare", "baseline auto")


def compare_command(log: Path, out: Path) -> list[str]:
    """The suite's compare of ``log`` as a command (module docstring)."""
    return [*RECON, "compare", str(log), "--truth", str(log), "-o", str(out), "--grid", "full",
            "--samples", str(suite.SAMPLES)]


def auto_command(log: Path, out: Path, target_kind: str) -> list[str]:
    return [*RECON, "reconstruct", str(log), "-o", str(out), "-m", "auto",
            "--target-kind", target_kind]


def measure(name: str, log: Path, work: Path, repeats: int, baseline: Path | None, *,
            quick: bool = False) -> dict:
    """Alternate compare and auto (and the baseline's) ``repeats`` times on the suite cloud
    ``name`` (its strike log ``log``; ``quick``: the quick form's); medians and ratios."""
    kind = suite.CLOUDS[name].target_kind
    trees = {"compare": ROOT, "auto": ROOT, "baseline compare": baseline,
             "baseline auto": baseline}
    runs: dict[str, list[dict]] = {side: [] for side in SIDES if trees[side] is not None}
    load = [os.getloadavg()[0]]
    order = [(i, side) for i in range(repeats) for side in runs]
    for i, side in tqdm(order, desc=name, unit="run", disable=None, leave=False):
        out = work / f"{name}-{side.replace(' ', '-')}-{i}"
        argv = (compare_command(log, out) if side.endswith("compare")
                else auto_command(log, out.with_suffix(".ply"), kind))
        runs[side].append(timed(argv, trees[side]))
        shutil.rmtree(out, ignore_errors=True)   # a compare keeps its meshes: 50 MB
        out.with_suffix(".ply").unlink(missing_ok=True)
    load.append(os.getloadavg()[0])
    result = {"cloud": name + (" (quick form)" if quick else ""), "repeats": repeats,
              "load_1min": load}
    for side, values in runs.items():
        result[side] = {k: statistics.median(v[k] for v in values) for k in ("wall_s", "cpu_s")}
        result[side]["runs"] = values
    for tree in ("", "baseline "):
        if f"{tree}auto" in result:
            result[f"{tree}ratio"] = {k: result[f"{tree}auto"][k] / result[f"{tree}compare"][k]
                                      for k in ("wall_s", "cpu_s")}
    return result


def _pair(result: dict, tree: str = "") -> str:
    """One tree's medians and ratio, for ``line``."""
    c, a, r = result[f"{tree}compare"], result[f"{tree}auto"], result[f"{tree}ratio"]
    return (f"{tree}compare {c['wall_s']:5.1f} s wall {c['cpu_s']:5.1f} s CPU, auto "
            f"{a['wall_s']:5.1f} / {a['cpu_s']:5.1f} s: ratio {r['wall_s']:.2f} wall "
            f"{r['cpu_s']:.2f} CPU")


def line(result: dict) -> str:
    """One cloud's medians and ratios, one line."""
    text = f"{result['cloud']:<28} {_pair(result)}"
    if "baseline ratio" in result:
        text += f" | {_pair(result, 'baseline ')}"
    low, high = result["load_1min"]
    return text + f" | load {low:.1f} -> {high:.1f}"


def markdown(results: list[dict], command: str) -> str:
    """The table of ``results`` as Markdown, headed by the command that made it."""
    trees = ["baseline ", ""] if any("baseline ratio" in r for r in results) else [""]
    head = "| cloud |" + "".join(
        f" {tree}compare wall / CPU s | {tree}auto wall / CPU s | {tree}auto / compare wall "
        f"| {tree}auto / compare CPU |" for tree in trees) + " load (1 min) |"
    rows = [f"`{command}`", "", head, "|" + "---|" * (head.count("|") - 1)]
    for r in results:
        row = f"| {r['cloud']} |"
        for tree in trees:
            c, a, ratio = r[f"{tree}compare"], r[f"{tree}auto"], r[f"{tree}ratio"]
            row += (f" {c['wall_s']:.1f} / {c['cpu_s']:.1f} | {a['wall_s']:.1f} / "
                    f"{a['cpu_s']:.1f} | {ratio['wall_s']:.2f} | {ratio['cpu_s']:.2f} |")
        low, high = r["load_1min"]
        rows.append(row + f" {low:.1f} -> {high:.1f} |")
    return "\n".join(rows) + "\n"


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", type=Path, help="a suite run's output (its logs/ are read)")
    parser.add_argument("--clouds", help="comma-separated suite cloud names (with --suite; "
                                         f"default: {','.join(DEFAULT_CLOUDS)})")
    parser.add_argument("--quick", action="store_true",
                        help=f"without --suite: {QUICK_CLOUD} in its quick form, once")
    parser.add_argument("--repeats", type=int, default=None,
                        help="runs of each command per cloud (default 3; 1 with --quick)")
    parser.add_argument("--baseline", type=Path,
                        help="a source tree whose auto is timed beside (e.g. an older commit's)")
    parser.add_argument("--work", type=Path,
                        help="where outputs go (default: a temporary directory)")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "auto_cost.md",
                        help="the Markdown table (JSON beside it, .json)")
    args = parser.parse_args(argv)
    if args.clouds and args.suite is None:
        parser.error("--clouds needs --suite (without it the quick cloud is simulated)")
    if args.suite is not None and not (args.suite / "logs").is_dir():
        parser.error(f"--suite: {args.suite} has no logs/ folder (a suite run's --out)")
    if args.baseline is not None and not (args.baseline / "cli" / "main.py").is_file():
        parser.error(f"--baseline: {args.baseline} is not a recon source tree (no cli/main.py)")
    if args.repeats is not None and args.repeats < 1:
        parser.error(f"--repeats must be at least 1, got {args.repeats}")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    repeats = args.repeats or (1 if args.quick else 3)
    with tempfile.TemporaryDirectory(prefix="bench-auto-cost-") as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        if args.suite is None:
            logs = {QUICK_CLOUD: suite.simulate(suite.CLOUDS[QUICK_CLOUD], work, quick=True)}
        else:
            names = args.clouds.split(",") if args.clouds else list(DEFAULT_CLOUDS)
            unknown = [n for n in names if n not in suite.CLOUDS]
            if unknown:
                raise SystemExit(f"--clouds: unknown suite cloud {unknown[0]!r}")
            logs = {n: args.suite / "logs" / f"{n}.h5" for n in names}
            missing = [str(p) for p in logs.values() if not p.is_file()]
            if missing:
                raise SystemExit(f"--suite: no strike log {missing[0]}")
        results = []
        for name, log in logs.items():
            results.append(measure(name, log, work, repeats, args.baseline,
                                   quick=args.suite is None))
            print(line(results[-1]), flush=True)
    command = "python benchmarks/bench_auto_cost.py " + " ".join(
        argv if argv is not None else sys.argv[1:])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(markdown(results, command.strip()))
    args.out.with_suffix(".json").write_text(json.dumps(
        {"cpus": os.cpu_count(), "command": command.strip(), "results": results}, indent=2)
        + "\n")
    print(f"wrote {args.out} and {args.out.with_suffix('.json')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
