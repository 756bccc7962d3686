"""Fuzz `recon` through real processes: damaged logs, PLY/OBJ/LAS files, scenes, argument
values and special paths (tests/fuzz/fuzzing.py), and the hostile kinds (tests/fuzz/hostile.py:
outputs that are inputs, report directories, lying headers, unreadable files run as ``nobody``,
scheduler addresses, bounds); print how each run ended.

    python benchmarks/fuzz.py --cases 1000 --jobs 2

The target: 0 tracebacks, 0 hangs, 0 crashes, 0 wrong successes, 0 data loss, 0 escapes. A case
hangs when it has not exited after ``--limit`` seconds (default 120: every case runs on small
inputs in seconds). Each run is traced with strace where it is installed (escapes: a file
opened under the secrets directory) and bounded in memory (tests/fuzz/runner.py). Cases are
seeded: case N is the same damage on every run. The shared inputs are hashed before and after:
a change is data loss too.
"""

from __future__ import annotations

import argparse
import collections
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tests.fuzz.fuzzing import (  # noqa: E402
    FIRST_KINDS,
    HOSTILE_KINDS,
    OUTCOMES,
    digest,
    judge,
    make_case,
    make_inputs,
)
from tests.fuzz.runner import STRACE, can_drop_privileges, run_case, servers  # noqa: E402

GOOD = ("clean", "ok")


def one(seed: int, inputs: dict, root: Path, limit: float, kind: str | None):
    directory = root / f"case{seed:05d}"
    case = make_case(seed, inputs, directory, kind)
    if case.user is not None and not can_drop_privileges():
        return seed, case.name, "skipped", "needs root and setpriv"
    status, err, opened = run_case(case, directory, limit=limit)
    return seed, case.name, judge(case, status, err, opened=opened,
                                  secrets=inputs["secrets"]), err


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=1000)
    parser.add_argument("--first", type=int, default=0, help="first seed")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--limit", type=float, default=120.0, help="hang limit, seconds")
    parser.add_argument("--kind", choices=sorted(set(FIRST_KINDS + HOSTILE_KINDS)),
                        help="only cases of this kind")
    args = parser.parse_args()
    start = time.perf_counter()
    counts: collections.Counter = collections.Counter()
    kinds: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    bad = []
    with tempfile.TemporaryDirectory(prefix="recon-fuzz-") as tmp, servers() as addresses:
        root = Path(tmp)
        inputs = make_inputs(root / "inputs") | {"servers": addresses}
        shared = {name: digest(path) for name, path in inputs.items()
                  if isinstance(path, Path) and path.is_file()}
        with ThreadPoolExecutor(args.jobs) as pool:
            seeds = range(args.first, args.first + args.cases)
            for seed, name, outcome, err in pool.map(
                    lambda s: one(s, inputs, root, args.limit, args.kind), seeds):
                counts[outcome] += 1
                kinds[name.split(":")[0]][outcome] += 1
                if outcome not in (*GOOD, "skipped"):
                    bad.append((seed, name, outcome, err.strip().splitlines()[-3:]))
        changed = [name for name, before in shared.items() if digest(inputs[name]) != before]
    print(f"{args.cases} cases (seeds {args.first}..{args.first + args.cases - 1}) in "
          f"{time.perf_counter() - start:.0f} s; files opened seen by "
          f"{'strace' if STRACE else 'nothing (no strace: escapes only by content)'}")
    print("  ".join(f"{o}: {counts[o]}" for o in OUTCOMES)
          + (f"  skipped: {counts['skipped']}" if counts["skipped"] else ""))
    for kind, c in sorted(kinds.items()):
        print(f"  {kind:<12}" + "  ".join(f"{o} {c[o]}" for o in (*OUTCOMES, "skipped")
                                           if c[o]))
    if changed:
        print(f"data loss: shared inputs changed: {', '.join(changed)}")
    for seed, name, outcome, tail in bad:
        print(f"seed {seed} {name}: {outcome}: {' | '.join(tail)[:300]}")
    return 0 if not bad and not changed else 1


if __name__ == "__main__":
    sys.exit(main())
