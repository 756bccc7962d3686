"""Where a fresh ``recon simulate`` spends its time against raw Embree on the same rays.

    python benchmarks/bench_sim_floor.py --work DIR             # medians of 3 (~2 min here)
    python benchmarks/bench_sim_floor.py --work DIR --repeats 5

The run is the ``simulate-lidar`` case of benchmarks/bench_user.py: ``recon simulate
asteroid-lidar --set time.rotations=2`` (3.17 M rays). Every command below runs in a fresh
process, the commands alternating, ``--repeats`` times (medians quoted); CPU time is user +
system of the process. Each is a floor or a part of ours:

- ``embreex``: the benchmark's floor, a fresh Python loading the pre-generated rays and casting
  them with embreex, one call per core at a time (bench_user's ``FLOOR_CAST``);
- ``open3d``: the same rays through Open3D's ``RaycastingScene.cast_rays`` (Embree inside,
  every core within a call), its import and the conversion to its ray tensor included;
- ``numpy``: a fresh Python importing numpy only (the start-up the floor and ours share);
- ``ours-imports``: a fresh Python importing what ``recon simulate`` must import
  (``sim.pipeline``: numpy, scipy's rotations, h5py, the log's writer);
- ``ours-no-log``: the imports, the scene, the plan and every chunk computed (rays, first-hit
  cast with barycentrics, float64 refinement, error models), nothing written;
- ``ours``: ``recon simulate`` as a user types it (the log written: deflate level 1 on the shot
  and beam indices, Fletcher-32 on every dataset);
- ``ours-open3d``: ``sim.simulate(..., backend="open3d")`` from a fresh Python.

The share of raw Embree printed is floor CPU / ours CPU (and the same for wall). What the table
says about the goal of 80 %: ``ours-imports`` plus the floor less ``numpy`` (the floor's cast,
the rays' loading included) is the least any simulator importing these libraries could cost;
its share is the ceiling with nothing else done.
No case asserts a time.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_user import FLOOR_CAST, LIDAR, PYTHON, ROOT, lidar_rays, recon, timed

FLOOR_OPEN3D = """
import sys, numpy as np, open3d as o3d
data = np.load(sys.argv[1])
scene = o3d.t.geometry.RaycastingScene()
scene.add_triangles(o3d.core.Tensor(data["vertices"]), o3d.core.Tensor(
    data["faces"].astype(np.uint32)))
hits = 0
for i in range(int(data["chunks"])):
    rays = o3d.core.Tensor(np.hstack([data[f"o{i}"], data[f"d{i}"]]))
    hits += int((scene.cast_rays(rays)["primitive_ids"].numpy() != 2**32 - 1).sum())
print(hits)
"""

IMPORTS = "import sim.pipeline"

NO_LOG = f"""
import sim
from sim import pipeline
plan = pipeline.make_plan(sim.load_scene({LIDAR[0]!r}, [{LIDAR[1]!r}]), seed=0)
print(sum(len(chunk.shot) for chunk in pipeline.iter_chunks(plan)))
pipeline.close_plan(plan)
"""

OPEN3D_SIM = f"""
import sys, sim
sim.simulate(sim.load_scene({LIDAR[0]!r}, [{LIDAR[1]!r}]), sys.argv[1], seed=0,
             progress=False, backend="open3d")
"""


def commands(work: Path, rays: Path) -> dict[str, callable]:
    """Each case's command line, built when run (a fresh output path each time)."""
    def out() -> Path:
        return Path(tempfile.mkdtemp(prefix="sim-", dir=work)) / "lidar.h5"

    return {
        "embreex": lambda: [PYTHON, "-c", FLOOR_CAST, str(rays)],
        "open3d": lambda: [PYTHON, "-c", FLOOR_OPEN3D, str(rays)],
        "numpy": lambda: [PYTHON, "-c", "import numpy"],
        "ours-imports": lambda: [PYTHON, "-c", IMPORTS],
        "ours-no-log": lambda: [PYTHON, "-c", NO_LOG],
        "ours": lambda: recon("simulate", LIDAR[0], "--set", LIDAR[1], "-o", out(), "--seed",
                              0),
        "ours-open3d": lambda: [PYTHON, "-c", OPEN3D_SIM, str(out())],
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--work", type=Path, default=None,
                        help="where the rays and logs go (default: a temporary directory)")
    parser.add_argument("--out", type=Path,
                        default=ROOT / "benchmarks" / "out" / "sim_floor.json")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-sim-floor-") as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        table = commands(work, lidar_rays(work))
        runs: dict[str, list[dict]] = {name: [] for name in table}
        load = [os.getloadavg()[0]]
        for _ in range(args.repeats):
            for name, command in table.items():
                runs[name].append(timed(command()))
        load.append(os.getloadavg()[0])
    med = {name: {k: statistics.median(r[k] for r in values) for k in ("wall_s", "cpu_s")}
           for name, values in runs.items()}
    floor = med["embreex"]
    print(f"medians of {args.repeats}, fresh processes, load {load[0]:.1f} -> {load[1]:.1f}")
    for name, m in med.items():
        print(f"{name:<14} {m['wall_s']:6.2f} s wall {m['cpu_s']:6.2f} s CPU | raw embreex's "
              f"share: {floor['wall_s'] / m['wall_s']:5.0%} wall {floor['cpu_s'] / m['cpu_s']:5.0%}"
              " CPU")
    least = med["ours-imports"]["cpu_s"] + floor["cpu_s"] - med["numpy"]["cpu_s"]
    print(f"ceiling: ours-imports + embreex - numpy = {least:.2f} s CPU, raw embreex's share "
          f"{floor['cpu_s'] / least:.0%} with nothing else done")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"cpus": os.cpu_count(), "load_1min": load, "medians": med,
                                    "runs": runs}, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
