"""Fuzz `recon` through real processes: damaged logs, PLY/OBJ/LAS files, scenes, argument
values and special paths (tests/fuzz/fuzzing.py), and print how each run ended.

    python benchmarks/fuzz.py --cases 600 --jobs 2

Issue 13's target: 0 tracebacks, 0 hangs and 0 wrong successes. A case hangs when it has not
exited after ``--limit`` seconds (default 120: every case runs on small inputs in seconds, and
the structural check of an HDF5 file gives up after 10 s). Cases are seeded: case N is the
same damage on every run.
"""

from __future__ import annotations

import argparse
import collections
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tests.fuzz.fuzzing import OUTCOMES, judge, make_case, make_inputs  # noqa: E402


def run_case(seed: int, inputs: dict, root: Path, limit: float) -> tuple[int, str, str, str]:
    directory = root / f"case{seed:04d}"
    case = make_case(seed, inputs, directory)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([sys.executable, "-c", "import sys; from cli.main import main; "
                             "sys.exit(main())", *case.args], cwd=directory, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        _, err = proc.communicate(timeout=limit)
        status = proc.returncode
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, 9)
        _, err = proc.communicate()
        status = None
    err = err.decode(errors="replace")
    return seed, case.name, judge(case, status, err), err


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=600)
    parser.add_argument("--first", type=int, default=0, help="first seed")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--limit", type=float, default=120.0, help="hang limit, seconds")
    args = parser.parse_args()
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="recon-fuzz-") as tmp:
        root = Path(tmp)
        inputs = make_inputs(root / "inputs")
        counts: collections.Counter = collections.Counter()
        kinds: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
        bad = []
        with ThreadPoolExecutor(args.jobs) as pool:
            seeds = range(args.first, args.first + args.cases)
            for seed, name, outcome, err in pool.map(
                    lambda s: run_case(s, inputs, root, args.limit), seeds):
                counts[outcome] += 1
                kinds[name.split(":")[0]][outcome] += 1
                if outcome not in ("clean", "ok"):
                    bad.append((seed, name, outcome, err.strip().splitlines()[-3:]))
    print(f"{args.cases} cases (seeds {args.first}..{args.first + args.cases - 1}) in "
          f"{time.perf_counter() - start:.0f} s")
    print("  ".join(f"{o}: {counts[o]}" for o in OUTCOMES))
    for kind, c in sorted(kinds.items()):
        print(f"  {kind:<12}" + "  ".join(f"{o} {c[o]}" for o in OUTCOMES if c[o]))
    for seed, name, outcome, tail in bad:
        print(f"seed {seed} {name}: {outcome}: {' | '.join(tail)[:300]}")
    return 0 if not bad else 1


if __name__ == "__main__":
    sys.exit(main())
