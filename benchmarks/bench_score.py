"""Speed of ``metrics.score`` (exact, float64) against Open3D's float32 queries, same run.

Each case scores one test against one truth; the floor is Open3D's own float32 distance queries
on the same query points, in both directions:

- accuracy: ``RaycastingScene.compute_distance`` of the test points (a cloud's points, or the
  samples drawn on a test mesh) to the truth;
- completeness and coverage: the truth samples and the coverage lattice to the test, with
  ``RaycastingScene.compute_distance`` on a new scene of a test mesh (its BVH build included,
  as ours includes the test mesh's set-up), or ``core.nns.NearestNeighborSearch`` (float32
  KNN, k = 1) on a test cloud.

Ours is ``score(test, truth, edges=False)`` against a ``metrics.Truth`` built once (as a
comparison, a study and a stability sweep use it): the test mesh's sampling and set-up, both
exact queries and every statistic. The edge metric is timed by ``bench_edge_metric.py``.
Targets: ours / Open3D <= 1.5 for the surface, the cloud and the coarse meshes, <= 3 for the
track cloud (points along three rings: a nearest-neighbour worst case). Also printed: the same
score against a fresh truth each time (the truth's set-up included) and the exact distance query
alone.

Cases: the Eros model (49k faces, km -> m) and the paper's asteroid (the ``asteroid-lrf``
preset's 20k-face ellipsoid); per truth a 150k-face surface (Open3D Poisson, depth 9, of 2e5
noisy samples, decimated), a 77,400-point cloud (noise 0.1 m), on Eros the track cloud, and two
coarse test meshes far from most truth samples (the exact query's slow path): the cloud's
convex hull (as the ``convex-hull`` method makes it) and a ~500-face polyhedron (as ``planes``
makes: the intersection of the half-spaces of 125 facets of the truth's convex hull).
``--cases`` picks some of them.
Times are medians of ``--repeats`` (>= 3) repeats after one warm-up; within a repeat ours and
Open3D run in turn, so both see the same load on the shared cores.

    .venv/bin/python benchmarks/bench_score.py            # ~3 minutes here
    .venv/bin/python benchmarks/bench_score.py --quick    # tiny sizes, seconds (CI)
    .venv/bin/python benchmarks/bench_score.py --cases hull polyhedron    # coarse meshes only
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without relying on the installed package
MESH = ROOT.parent / "shared" / "meshes" / "eros_gaskell_49k.obj"
TARGET = {"surface": 1.5, "cloud": 1.5, "tracks": 3.0, "hull": 1.5, "polyhedron": 1.5}
CLOUD_POINTS = 77_400  # the rso-a-lrf and asteroid-lrf presets' shots
NOISE_M = 0.1
SURFACE_FACES = 150_000  # the "150k-face surface"
POLYHEDRON_PLANES = 125  # ~4 triangles per plane: a ~500-face polyhedron, as `planes` makes


def interleaved(fns: dict, repeats: int) -> tuple[dict, dict]:
    """Median wall time and last result of each function, run in turn within each repeat."""
    times = {name: [] for name in fns}
    results = {}
    for _ in range(repeats):
        for name, fn in fns.items():
            start = time.perf_counter()
            results[name] = fn()
            times[name].append(time.perf_counter() - start)
    return {name: statistics.median(t) for name, t in times.items()}, results


def truths(quick: bool) -> list[tuple[str, object]]:
    import trimesh

    import sim
    from metrics import Mesh

    if quick or not MESH.exists():
        sphere = trimesh.creation.icosphere(4, radius=1000.0)
        return [("icosphere", Mesh(np.asarray(sphere.vertices), np.asarray(sphere.faces)))]
    eros = trimesh.load(MESH, process=False)
    scene = sim.load_scene("asteroid-lrf")
    vertices = np.asarray(eros.vertices) * 1000.0
    return [("eros", Mesh(vertices - vertices.mean(axis=0), np.asarray(eros.faces))),
            ("asteroid", Mesh(np.asarray(scene.vertices), np.asarray(scene.faces)))]


def surface(truth, n: int, depth: int, seed: int, max_faces: int = SURFACE_FACES):
    """A reconstruction-like mesh: Open3D Poisson of noisy surface samples, decimated to at
    most ``max_faces`` faces (quadric decimation)."""
    import open3d as o3d

    from metrics import Mesh, sample_surface

    points, faces = sample_surface(truth, n, seed=seed)
    rng = np.random.default_rng(seed)
    points = points + rng.normal(scale=NOISE_M, size=points.shape)
    a, b, c = (truth.vertices[truth.faces[faces, i]] for i in range(3))
    normals = np.cross(b - a, c - a)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.normals = o3d.utility.Vector3dVector(normals / np.linalg.norm(normals, axis=1)[:, None])
    mesh, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=depth)
    if len(mesh.triangles) > max_faces:
        mesh = mesh.simplify_quadric_decimation(max_faces)
    return Mesh(np.asarray(mesh.vertices), np.asarray(mesh.triangles))


def cloud(truth, n: int, seed: int) -> np.ndarray:
    from metrics import sample_surface

    points, _ = sample_surface(truth, n, seed=seed)
    return points + np.random.default_rng(seed).normal(scale=NOISE_M, size=points.shape)


def tracks(truth, n: int, seed: int) -> np.ndarray:
    """Points along the truth's sections by three planes z = const (an LRF's tracks)."""
    import trimesh

    tm = trimesh.Trimesh(truth.vertices, truth.faces, process=False)
    lo, hi = truth.vertices[:, 2].min(), truth.vertices[:, 2].max()
    segments = np.concatenate([trimesh.intersections.mesh_plane(tm, [0, 0, 1], [0, 0, z])
                               for z in np.linspace(lo, hi, 5)[1:-1]])
    rng = np.random.default_rng(seed)
    pick = rng.integers(0, len(segments), n)
    t = rng.random((n, 1))
    points = segments[pick, 0] + t * (segments[pick, 1] - segments[pick, 0])
    return points + rng.normal(scale=NOISE_M, size=points.shape)


def hull(truth, n: int, seed: int):
    """The convex hull of ``cloud(truth, n, seed)``."""
    return outward(cloud(truth, n, seed))


def outward(points: np.ndarray):
    """The convex hull of the points as a mesh, faces counter-clockwise seen from outside (as
    the ``convex-hull`` and ``planes`` methods orient them)."""
    from scipy.spatial import ConvexHull

    from metrics import Mesh

    qhull = ConvexHull(points)
    used, faces = np.unique(qhull.simplices, return_inverse=True)
    faces = faces.reshape(-1, 3)
    a, b, c = (points[used][faces[:, i]] for i in range(3))
    flip = np.einsum("ij,ij->i", np.cross(b - a, c - a), qhull.equations[:, :3]) < 0
    faces[flip] = faces[flip][:, ::-1]
    return Mesh(points[used], faces)


def polyhedron(truth, planes: int):
    """A `planes`-like closed polyhedron: the intersection of the half-spaces below ``planes``
    facets of the truth's convex hull, those whose normals are nearest to a Fibonacci sphere's
    directions (spread, so bounded); coarse, and enclosing the truth."""
    from scipy.spatial import ConvexHull, HalfspaceIntersection

    qhull = ConvexHull(truth.vertices)
    k = np.arange(planes) + 0.5
    z, angle = 1.0 - 2.0 * k / planes, np.pi * (1.0 + 5.0**0.5) * k
    directions = np.column_stack([np.sqrt(1.0 - z * z) * np.cos(angle),
                                  np.sqrt(1.0 - z * z) * np.sin(angle), z])
    chosen = np.unique((directions @ qhull.equations[:, :3].T).argmax(axis=1))
    interior = truth.vertices[qhull.vertices].mean(axis=0)
    return outward(HalfspaceIntersection(qhull.equations[chosen], interior).intersections)


def open3d_floor(test, truth_scene, queries32: np.ndarray, test_points32: np.ndarray):
    """Open3D's float32 queries of both directions (see the module docstring)."""
    import open3d as o3d

    from metrics import Mesh

    truth_scene.compute_distance(test_points32)
    if isinstance(test, Mesh):
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(test.vertices.astype(np.float32), test.faces.astype(np.uint32))
        return scene.compute_distance(queries32).numpy()
    search = o3d.core.nns.NearestNeighborSearch(o3d.core.Tensor(test.astype(np.float32)))
    search.knn_index()
    _, distance2 = search.knn_search(o3d.core.Tensor(queries32), 1)
    return np.sqrt(distance2.numpy()[:, 0])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="tiny sizes (CI smoke run)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--cases", nargs="+", choices=list(TARGET), default=list(TARGET),
                        help="which tests to score (default: all)")
    args = parser.parse_args(argv)
    if args.repeats < 3 and not args.quick:
        parser.error("--repeats must be >= 3 (medians)")

    import open3d as o3d

    from metrics import Mesh, MeshDistance, Truth, defaults, sample_surface, score

    n_cloud = 5_000 if args.quick else CLOUD_POINTS
    # Fixed counts (the same points both sides query); a score to a precision would size them.
    options = ({"n_truth_samples": 20_000, "n_test_samples": 20_000, "coverage_points": 40_000}
               if args.quick else {"n_truth_samples": defaults.TRUTH_SAMPLES,
                                   "n_test_samples": defaults.TEST_MESH_SAMPLES,
                                   "coverage_points": defaults.COVERAGE_POINTS})
    n_samples = options.get("n_truth_samples", defaults.TRUTH_SAMPLES)
    n_test = options.get("n_test_samples", defaults.TEST_MESH_SAMPLES)
    print(f"medians of {args.repeats} repeats; load average {os.getloadavg()[0]:.1f} on "
          f"{os.cpu_count()} cores; score options: "
          f"{'smaller (quick)' if args.quick else 'metrics fixed-count defaults'}")
    header = (f"{'truth':<10}{'test':<26}{'ours s':>8}{'open3d s':>10}{'ratio':>7}{'target':>8}"
              f"{'fresh truth s':>15}{'query only s':>14}")
    print(header)
    print("-" * len(header))
    ok = True
    for truth_name, truth in truths(args.quick):
        prepared = Truth(truth)
        truth_scene = o3d.t.geometry.RaycastingScene()
        truth_scene.add_triangles(truth.vertices.astype(np.float32),
                                  truth.faces.astype(np.uint32))
        tests = {"surface": partial(surface, truth, 200_000 if not args.quick else 20_000,
                                    7 if args.quick else 9, seed=1),
                 "cloud": partial(cloud, truth, n_cloud, seed=2),
                 "tracks": partial(tracks, truth, n_cloud, seed=3),
                 "hull": partial(hull, truth, n_cloud, seed=2),
                 "polyhedron": partial(polyhedron, truth, POLYHEDRON_PLANES)}
        if not (truth_name == "eros" or args.quick):
            del tests["tracks"]
        for kind, build in tests.items():
            if kind not in args.cases:
                continue
            test = build()
            is_mesh = isinstance(test, Mesh)
            # The same points both sides query: ours draws them inside score (same seeds).
            test_points = sample_surface(test, n_test, seed=defaults.SEED)[0] if is_mesh \
                else test
            _, lattice, _ = prepared.lattice(options.get("coverage_points",
                                                              defaults.COVERAGE_POINTS))
            truth_points = prepared.samples(n_samples, [defaults.SEED, 1])[0]
            queries32 = np.concatenate([truth_points, lattice]).astype(np.float32)
            points32 = test_points.astype(np.float32)
            queries = np.concatenate([truth_points, lattice])
            run = {"ours": lambda t=test, p=prepared: score(t, p, edges=False, **options),
                   "open3d": lambda t=test, s=truth_scene, q=queries32, p=points32:
                   open3d_floor(t, s, q, p)}
            interleaved(run, 1)  # warm-up: BVHs, thread pools, the Truth's samples
            times, results = interleaved(run, args.repeats)
            fresh, _ = interleaved({"fresh": lambda t=test, m=truth: score(t, m, edges=False,
                                                                           **options)}, 1)
            query = "-"
            if is_mesh:
                distance = MeshDistance(test)
                query_time, _ = interleaved({"q": lambda d=distance, q=queries: d.query(q)},
                                            args.repeats)
                query = f"{query_time['q']:.2f}"
            ratio = times["ours"] / times["open3d"]
            ok &= ratio <= TARGET[kind]
            label = f"{kind} ({len(test.faces)} faces)" if is_mesh else \
                f"{kind} ({len(test)} points)"
            print(f"{truth_name:<10}{label:<26}{times['ours']:>8.2f}{times['open3d']:>10.2f}"
                  f"{ratio:>7.2f}{'<= ' + str(TARGET[kind]):>8}{fresh['fresh']:>15.2f}"
                  f"{query:>14}")
            report = results["ours"]
            completeness = report.completeness_distances
            err = np.abs(completeness - results["open3d"][:len(completeness)]).max()
            print(f"{'':<10}agreement with Open3D (float32) on completeness: max |diff| "
                  f"{err:.2e} m; Chamfer {report.chamfer_m:.4g} m, F {report.fscore:.3f}")
    if args.quick:
        print("quick run: the targets apply to the full sizes")
    else:
        print("targets met" if ok else "TARGETS MISSED (see table)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
