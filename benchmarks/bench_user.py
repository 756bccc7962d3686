"""The commands a user types, timed as a user runs them: fresh processes, beside their floors.

    python benchmarks/bench_user.py            # every case, medians of 3 (~30 min here)
    python benchmarks/bench_user.py --quick    # the two score cases once, small inputs (CI)
    python benchmarks/bench_user.py --cases score-surface,compare-rso-a

Each case is one command line exactly as a user types it (``recon ...``, run through this
checkout's interpreter), and for most a floor: a fresh Python doing the same work with the bare
libraries. Ours and the floor run alternately, ``--repeats`` times (median quoted), each in a
fresh process; CPU time is the process's user + system time with every child it waited for
(``RUSAGE_CHILDREN``: recon's warm workers included). The ratio ours / floor is printed for
wall and CPU time with the load average before and after (the machine may be shared: CPU
ratios travel better than wall ones). No case asserts a time.

Cases (inputs made once in ``--work``, seed 0):

- ``score-surface``, ``score-surface-no-edges``: ``recon score surf.ply --truth truth.ply
  --json`` (and with ``--no-edges``), surf.ply the demo scene's Open3D Poisson surface;
  floor: Open3D reads both meshes, samples 200k points on each, ``RaycastingScene.
  compute_distance`` both ways.
- ``score-cloud``: ``recon score cloud.ply --truth truth.ply --json`` on the demo cloud; floor:
  the cloud side by ``RaycastingScene``, the truth's 200k samples to the cloud by Open3D's
  nearest neighbours.
- ``compare-3``: ``recon compare cloud.ply --truth truth.ply --methods
  poisson,ball-pivoting,convex-hull --no-grid -o DIR``; floor: one fresh Python making bare
  Open3D fits of the three methods (normals by Open3D, flipped away from the centroid) and
  scoring each mesh as the score floor does.
- ``compare-rso-a``, ``compare-rso-b``: the default ``recon compare`` of the ``rso-a-lrf`` and
  ``rso-b-lrf`` presets (no floor; goal: every method finishes or declines, a few minutes).
- ``study-quick``: ``recon study all --quick`` (no floor; goal under 3 minutes idle).
- ``score-per-million``: the cost of each extra million points scored, ``recon score
  noisy-4000000.ply --truth truth.ply --json`` less the same on noisy-1000000.ply (the truth's
  surface sampled 4 M / 1 M times, seed 1, with Gaussian noise of 1/3 % of its diagonal, 1
  sigma), divided by 3;
  ``score-per-million-no-edges`` the same with ``--no-edges``. Floor: the score floor on the
  same two clouds, differenced the same way.
- ``simulate-lidar``: ``recon simulate asteroid-lidar --set time.rotations=2 -o X.h5 --seed 0``
  (3.17 M rays); floor: a fresh Python loading the very same rays (made once by
  ``sim.pipeline.chunk_rays``, saved as .npy) and casting them with embreex, one call per core
  at a time (the first-hit query only). The ratio printed is ours / floor, so the simulator's
  share of raw Embree is its inverse.

The demo scene is ``asteroid-lrf-slew`` (77,400 shots). ``--quick`` makes the demo inputs from
10 rotations instead of 50 and runs the two surface score cases once.
Results go to ``--out`` (default ``benchmarks/out/user.json``) and are printed; numbers measured
on this project's machine are recorded in ``benchmarks/results_user.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PYTHON = sys.executable
# The ``recon`` script installed beside this interpreter, as a user runs it.
RECON = ([str(Path(PYTHON).parent / "recon")] if (Path(PYTHON).parent / "recon").exists()
         else [PYTHON, "-c", "import sys; from cli.main import main; sys.exit(main())"])
DEMO_SCENE = "asteroid-lrf-slew"
# The floor's samples per side (metrics' fixed-count default; a score to its default precision
# draws its samples from as many and scores as many as its stated precision needs).
SAMPLES = 200_000
# The per-million case's clouds, and the noise on them as a fraction of the truth's diagonal.
MILLION_SIZES = (1_000_000, 4_000_000)
MILLION_NOISE = 0.01 / 3
LIDAR = ("asteroid-lidar", "time.rotations=2")

FLOOR_LIB = """
import sys, numpy as np, open3d as o3d

def score(test, truth, n):
    \"\"\"Mean of both directions' mean distances: Open3D float32 queries.\"\"\"
    samples = np.asarray(truth.sample_points_uniformly(n).points, dtype=np.float32)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(truth))
    if isinstance(test, o3d.geometry.TriangleMesh):
        points = np.asarray(test.sample_points_uniformly(n).points, dtype=np.float32)
        own = o3d.t.geometry.RaycastingScene()
        own.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(test))
        back = own.compute_distance(o3d.core.Tensor(samples)).numpy()
    else:
        points = np.asarray(test.points, dtype=np.float32)
        nns = o3d.core.nns.NearestNeighborSearch(o3d.core.Tensor(points))
        nns.knn_index()
        back = np.sqrt(nns.knn_search(o3d.core.Tensor(samples), 1)[1].numpy()[:, 0])
    there = scene.compute_distance(o3d.core.Tensor(points)).numpy()
    return float(there.mean() + back.mean()) / 2
"""

# Score one file: a mesh when it has triangles, else a cloud.
FLOOR_SCORE = FLOOR_LIB + """
test, truth, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
mesh = o3d.io.read_triangle_mesh(test)
print(score(mesh if len(mesh.triangles) else o3d.io.read_point_cloud(test),
            o3d.io.read_triangle_mesh(truth), n))
"""

# The rays of a saved simulation cast by embreex, one call per core at a time.
FLOOR_CAST = """
import sys, os, numpy as np
from concurrent.futures import ThreadPoolExecutor
from embreex import mesh_construction, rtcore_scene
data = np.load(sys.argv[1])
scene = rtcore_scene.EmbreeScene()
mesh_construction.TriangleMesh(scene, data["vertices"], data["faces"])
chunks = [(data[f"o{i}"], data[f"d{i}"]) for i in range(int(data["chunks"]))]
with ThreadPoolExecutor(os.cpu_count()) as pool:
    hits = sum(int((h >= 0).sum()) for h in pool.map(
        lambda od: scene.run(od[0], od[1], query="INTERSECT"), chunks))
print(hits)
"""

# The three methods' bare fits (normals by Open3D, flipped to face away from the centroid),
# each mesh scored in the same process.
FLOOR_COMPARE = FLOOR_LIB + """
cloud, truth, n = sys.argv[1], o3d.io.read_triangle_mesh(sys.argv[2]), int(sys.argv[3])
pcd = o3d.io.read_point_cloud(cloud)
pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(16))
pcd.orient_normals_towards_camera_location(pcd.get_center())
pcd.normals = o3d.utility.Vector3dVector(-np.asarray(pcd.normals))
spacing = float(np.median(np.asarray(pcd.compute_nearest_neighbor_distance())))
poisson, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=9)
radii = o3d.utility.DoubleVector([r * spacing for r in (1.5, 3.0, 6.0)])
pivot = o3d.geometry.TriangleMesh.create_from_point_cloud_ball_pivoting(pcd, radii)
hull, _ = pcd.compute_convex_hull()
print([score(mesh, truth, n) for mesh in (poisson, pivot, hull)])
"""


def timed(argv: list[str], tree: Path = ROOT) -> dict:
    """Run ``argv`` to completion in the source tree ``tree`` (its directory first on the
    path); its wall time and CPU time (user + system, children it waited for included) in
    seconds."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(argv, cwd=tree, capture_output=True,
                          env=os.environ | {"PYTHONPATH": str(tree)})
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"failed ({done.returncode}): {' '.join(argv)}\n"
                         f"{done.stderr.decode(errors='replace')[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu}


def recon(*args: str) -> list[str]:
    return [*RECON, *map(str, args)]


def floor_python(script: str, *args) -> list[str]:
    return [PYTHON, "-c", script, *map(str, args)]


def prepare_inputs(work: Path, *, rotations: int | None) -> dict[str, Path]:
    """The demo scene's log, cloud, truth and Poisson surface, made once in ``work``."""
    work.mkdir(parents=True, exist_ok=True)
    files = {"log": work / "demo.h5", "cloud": work / "cloud.ply", "truth": work / "truth.ply",
             "surf": work / "surf.ply"}
    if not files["surf"].exists():
        extra = [] if rotations is None else ["--set", f"time.rotations={rotations}"]
        steps = [recon("simulate", DEMO_SCENE, "-o", files["log"], "--seed", 0, *extra),
                 recon("ingest", files["log"], "-o", files["cloud"]),
                 recon("truth", files["log"], "-o", files["truth"]),
                 recon("reconstruct", files["cloud"], "-m", "poisson", "-o", files["surf"])]
        for step in steps:
            timed(step)
    return files


def million_clouds(work: Path, truth: Path) -> dict[int, Path]:
    """The per-million case's noisy clouds of the truth's surface, made once in ``work``."""
    paths = {n: work / f"noisy-{n}.ply" for n in MILLION_SIZES}
    if all(p.exists() for p in paths.values()):
        return paths
    sys.path.insert(0, str(ROOT))
    import numpy as np

    from formats.mesh_io import read_mesh
    from formats.ply import write_ply
    from metrics.inputs import bbox_diagonal
    from metrics.sampling import sample_surface

    mesh = read_mesh(truth)
    sigma = MILLION_NOISE * bbox_diagonal(mesh.vertices)
    for n, path in paths.items():
        points, _ = sample_surface(mesh, n, seed=1)
        points += np.random.default_rng(1).normal(0.0, sigma, points.shape)
        write_ply(path, {k: points[:, i] for i, k in enumerate("xyz")},
                  metadata={"frame": mesh.frame, "units": "m"})
    return paths


def lidar_rays(work: Path) -> Path:
    """The ``simulate-lidar`` case's mesh and rays, as the simulator builds them, saved once."""
    path = work / "lidar-rays.npz"
    if path.exists():
        return path
    sys.path.insert(0, str(ROOT))
    import numpy as np

    import sim
    from sim import pipeline

    plan = pipeline.make_plan(sim.load_scene(LIDAR[0], [LIDAR[1]]), seed=0)
    rays = [pipeline.chunk_rays(plan, *bound).float32() for bound in pipeline.chunk_bounds(plan)]
    arrays = {f"{side}{i}": a for i, pair in enumerate(rays) for side, a in zip("od", pair,
                                                                                strict=True)}
    np.savez(path, vertices=plan.scene.vertices.astype(np.float32),
             faces=plan.scene.faces.astype(np.int32), chunks=len(rays), **arrays)
    pipeline.close_plan(plan)
    return path


def rso_log(work: Path, preset: str) -> Path:
    log = work / f"{preset}.h5"
    if not log.exists():
        timed(recon("simulate", preset, "-o", log, "--seed", 0))
    return log


def cases(work: Path, files: dict[str, Path]) -> dict[str, tuple]:
    """Each case: (our command, the floor's command or None), built lazily."""
    surf, cloud, truth = files["surf"], files["cloud"], files["truth"]

    def compare_dir() -> Path:
        return Path(tempfile.mkdtemp(prefix="compare-", dir=work))

    def floor_compare() -> list[list[str]]:
        return [floor_python(FLOOR_COMPARE, cloud, truth, SAMPLES)]

    return {
        "score-surface": (lambda: [recon("score", surf, "--truth", truth, "--json")],
                          lambda: [floor_python(FLOOR_SCORE, surf, truth, SAMPLES)]),
        "score-surface-no-edges": (
            lambda: [recon("score", surf, "--truth", truth, "--json", "--no-edges")],
            lambda: [floor_python(FLOOR_SCORE, surf, truth, SAMPLES)]),
        "score-cloud": (lambda: [recon("score", cloud, "--truth", truth, "--json")],
                        lambda: [floor_python(FLOOR_SCORE, cloud, truth, SAMPLES)]),
        "compare-3": (lambda: [recon("compare", cloud, "--truth", truth, "--methods",
                                     "poisson,ball-pivoting,convex-hull", "--no-grid", "-o",
                                     compare_dir())], floor_compare),
        "compare-rso-a": (lambda: [recon("compare", rso_log(work, "rso-a-lrf"), "--truth",
                                         rso_log(work, "rso-a-lrf"), "-o", compare_dir())],
                          None),
        "compare-rso-b": (lambda: [recon("compare", rso_log(work, "rso-b-lrf"), "--truth",
                                         rso_log(work, "rso-b-lrf"), "-o", compare_dir())],
                          None),
        "study-quick": (lambda: [recon("study", "all", "--quick", "-o", compare_dir())], None),
        "score-per-million": per_million(work, truth, ()),
        "score-per-million-no-edges": per_million(work, truth, ("--no-edges",)),
        "simulate-lidar": (
            lambda: [recon("simulate", LIDAR[0], "--set", LIDAR[1], "-o",
                           Path(tempfile.mkdtemp(prefix="sim-", dir=work)) / "lidar.h5",
                           "--seed", 0)],
            lambda: [floor_python(FLOOR_CAST, lidar_rays(work))]),
    }


def per_million(work: Path, truth: Path, extra: tuple[str, ...]) -> tuple:
    """Ours and the floor on the 4 M cloud, each less the same on the 1 M cloud (``measure``
    divides the difference by the millions between them)."""
    def side(make):
        def commands():
            small, large = million_clouds(work, truth).values()
            return {"plus": [make(large)], "minus": [make(small)]}
        return commands
    return (side(lambda cloud: recon("score", cloud, "--truth", truth, "--json", *extra)),
            side(lambda cloud: floor_python(FLOOR_SCORE, cloud, truth, SAMPLES)))


def run_commands(commands) -> dict:
    """Times of a list of commands run one after another, summed; for ``{"plus": [...],
    "minus": [...]}`` (``per_million``), the plus commands' less the minus commands', per
    million points between them."""
    if isinstance(commands, dict):
        plus, minus = run_commands(commands["plus"]), run_commands(commands["minus"])
        millions = (MILLION_SIZES[1] - MILLION_SIZES[0]) / 1e6
        return {k: (plus[k] - minus[k]) / millions for k in plus}
    total = {"wall_s": 0.0, "cpu_s": 0.0}
    for command in commands:
        one = timed(command)
        total = {k: total[k] + one[k] for k in total}
    return total


def measure(name: str, ours, floor, repeats: int) -> dict:
    """Alternate ours and the floor ``repeats`` times; medians and ratios."""
    runs: dict[str, list[dict]] = {"ours": [], "floor": []}
    load = [os.getloadavg()[0]]
    for _ in range(repeats):
        runs["ours"].append(run_commands(ours()))
        if floor is not None:
            runs["floor"].append(run_commands(floor()))
    load.append(os.getloadavg()[0])
    out = {"case": name, "repeats": repeats, "load_1min": load}
    for side, values in runs.items():
        if values:
            out[side] = {k: statistics.median(v[k] for v in values) for k in ("wall_s", "cpu_s")}
    if floor is not None:
        out["ratio_wall"] = out["ours"]["wall_s"] / out["floor"]["wall_s"]
        out["ratio_cpu"] = out["ours"]["cpu_s"] / out["floor"]["cpu_s"]
    return out


def line(result: dict) -> str:
    ours = result["ours"]
    text = (f"{result['case']:<24} ours {ours['wall_s']:7.1f} s wall {ours['cpu_s']:7.1f} s CPU")
    if "floor" in result:
        floor = result["floor"]
        text += (f" | floor {floor['wall_s']:6.1f} s wall {floor['cpu_s']:6.1f} s CPU | ratio "
                 f"{result['ratio_wall']:.2f} wall {result['ratio_cpu']:.2f} CPU")
    low, high = result["load_1min"]
    return text + f" | load {low:.1f} -> {high:.1f}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="small demo inputs, the surface score cases once")
    parser.add_argument("--cases", help="comma-separated case names (default: all)")
    parser.add_argument("--repeats", type=int, default=None,
                        help="runs of each side (default 3; 1 with --quick)")
    parser.add_argument("--work", type=Path, default=None,
                        help="where inputs and outputs go (default: a temporary directory)")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "user.json")
    args = parser.parse_args(argv)
    repeats = args.repeats or (1 if args.quick else 3)
    with tempfile.TemporaryDirectory(prefix="bench-user-") as tmp:
        work = args.work or Path(tmp)
        files = prepare_inputs(work, rotations=10 if args.quick else None)
        table = cases(work, files)
        names = (args.cases.split(",") if args.cases else
                 ["score-surface", "score-surface-no-edges"] if args.quick else list(table))
        unknown = sorted(set(names) - set(table))
        if unknown:
            parser.error(f"--cases: unknown case {unknown[0]!r} (cases: {', '.join(table)})")
        results = []
        for name in names:
            ours, floor = table[name]
            results.append(measure(name, ours, floor, repeats))
            print(line(results[-1]), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"cpus": os.cpu_count(), "results": results}, indent=2)
                        + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
