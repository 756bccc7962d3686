"""recon.api as the one front door: light to import, its verbs listed by ``dir(recon)``, Open3D and
trimesh objects taken where clouds and meshes are, and meshes written atomically, never over an
input."""

from __future__ import annotations

import inspect
import subprocess
import sys

import numpy as np
import pytest

from formats.errors import InputError
from formats.geometry import Cloud, Mesh
from formats.paths import protecting
from recon import api
from tests.recon.conftest import SPHERE_RADIUS, sphere_mesh, sphere_points

HEAVY = ("numpy", "h5py", "open3d", "scipy", "trimesh", "dask")


def test_importing_the_api_and_every_help_loads_nothing_heavy():
    """``import recon.api`` and ``recon [COMMAND] --help`` import none of the heavy libraries
    (what keeps ``recon --help`` instant: benchmarks/bench_startup.py times it)."""
    code = ("import contextlib, io, sys\n"
            "import recon.api\n"
            "from cli.main import build_parser, main\n"
            "sub = next(a for a in build_parser()._actions if a.dest == 'command')\n"
            "for argv in [['--help'], *([name, '--help'] for name in sub.choices)]:\n"
            "    with contextlib.redirect_stdout(io.StringIO()), "
            "contextlib.suppress(SystemExit):\n"
            "        main(argv)\n"
            f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=120, check=False)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


def test_the_package_lists_every_verb_of_the_api():
    import recon

    verbs = {name for name in api.__all__ if inspect.isfunction(getattr(api, name))}
    assert set(recon.VERBS) == verbs
    assert verbs <= set(dir(recon))
    assert recon.reconstruct_file is api.reconstruct_file


def _sphere_cloud(n=1500):
    points, view, _ = sphere_points(n)
    return Cloud(points, {"view_x": view[:, 0], "view_y": view[:, 1], "view_z": view[:, 2]})


def test_open3d_clouds_and_meshes_are_taken():
    import open3d as o3d

    points, _, _ = sphere_points(1500)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    surface = api.reconstruct(cloud, method="convex-hull", isolate=False)
    vertices, faces = sphere_mesh(3)
    truth = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices),
                                      o3d.utility.Vector3iVector(faces))
    report = api.score(surface, truth=truth, edges=False, n_truth_samples=3000,
                       coverage_points=3000)
    assert report.chamfer_m < 0.05 * SPHERE_RADIUS
    loaded = api.load(cloud)
    assert isinstance(loaded, Cloud) and np.array_equal(loaded.points, points)
    assert loaded.normals is None
    cloud.normals = o3d.utility.Vector3dVector(points / np.linalg.norm(points, axis=1)[:, None])
    assert np.allclose(api.load(cloud).normals, np.asarray(cloud.normals))


def test_trimesh_clouds_and_meshes_are_taken():
    import trimesh

    points, _, _ = sphere_points(1500)
    surface = api.reconstruct(trimesh.PointCloud(points), method="convex-hull", isolate=False)
    truth = trimesh.Trimesh(*sphere_mesh(3), process=False)
    report = api.score(trimesh.Trimesh(surface.vertices, surface.faces, process=False),
                       truth=truth, edges=False, n_truth_samples=3000, coverage_points=3000)
    assert report.chamfer_m < 0.05 * SPHERE_RADIUS
    assert isinstance(api.load(truth), Mesh) and api.load(truth).n_faces == len(truth.faces)


def test_an_open3d_object_that_is_no_cloud_or_mesh_is_named():
    import open3d as o3d

    with pytest.raises(api.ParameterError, match=r"open3d.*VoxelGrid is neither a point cloud nor"):
        api.load(o3d.geometry.VoxelGrid())


def test_reconstruct_writes_its_output_and_never_over_its_input(tmp_path):
    from formats.cloud_io import write_cloud
    from formats.mesh_io import read_mesh

    source = write_cloud(tmp_path / "cloud.ply", _sphere_cloud())
    before = source.read_bytes()
    with pytest.raises(api.ParameterError, match=r"cloud\.ply: is an input of this run"):
        api.reconstruct(source, method="convex-hull", isolate=False, output=source)
    assert source.read_bytes() == before
    surface = api.reconstruct(source, method="convex-hull", isolate=False,
                              output=tmp_path / "hull.ply")
    written = read_mesh(tmp_path / "hull.ply")
    assert np.array_equal(written.faces, surface.faces)
    assert np.allclose(written.vertices, surface.vertices)


def test_reconstruct_file_returns_a_result_with_the_run(tmp_path):
    from formats.cloud_io import write_cloud

    source = write_cloud(tmp_path / "cloud.ply", _sphere_cloud())
    result = api.reconstruct_file(source, tmp_path / "hull.ply", method="convex-hull",
                                  isolate=False)
    assert isinstance(result, api.ReconstructResult)
    assert result.input == str(source) and result.output == tmp_path / "hull.ply"
    assert result.n_points == 1500 and result.view_points and result.auto is None
    summary = result.to_dict()
    assert summary["method"] == "convex-hull" and summary["n_faces"] == result.surface.n_faces
    assert summary["estimate"] == result.estimate and "auto" not in summary
    with pytest.raises(api.ParameterError, match=r"holdout must be in \(0, 0.5\], got 0.9"):
        api.reconstruct_file(source, tmp_path / "x.ply", method="auto", holdout=0.9)
    assert not (tmp_path / "x.ply").exists()


def test_save_writes_meshes_and_clouds_and_refuses_an_input(tmp_path):
    from formats.cloud_io import read_cloud
    from formats.mesh_io import read_mesh

    mesh = Mesh(*sphere_mesh(2))
    path = api.save(mesh, tmp_path / "sphere.ply")
    assert np.array_equal(read_mesh(path).faces, mesh.faces)
    cloud = _sphere_cloud(300)
    saved = read_cloud(api.save(cloud, tmp_path / "cloud.h5"))
    assert np.array_equal(saved.points, cloud.points)
    assert np.allclose(saved.view_points, cloud.view_points)
    before = path.read_bytes()
    with protecting([path]), pytest.raises(api.ParameterError, match="is an input of this run"):
        api.save(Mesh(*sphere_mesh(1)), path)
    assert path.read_bytes() == before
    with pytest.raises(api.ParameterError, match=r"units apply to \.tab meshes"):
        api.save(cloud, tmp_path / "c.ply", units="km")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cloud.h5", "sphere.ply"]


_OWN_PROCESS = ("import os, sys\n"
                "from recon import api\n"
                "api._own_process(sys.argv[1])\n"
                "import numpy\n"
                "plotly = sys.modules.get('open3d.visualization.draw_plotly')\n"
                "print(os.environ.get('OPENBLAS_NUM_THREADS'), plotly is not None and "
                "plotly.__doc__.startswith('left out'))\n")


@pytest.mark.parametrize(("method", "given", "threads"),
                         [("auto", None, "1"), ("auto", "3", "3"), ("poisson", None, None)])
def test_a_process_of_its_own_runs_auto_on_one_blas_thread_without_plotly(method, given,
                                                                          threads):
    """``reconstruct_file(own_process=True)`` (the ``recon`` command): Open3D's plotly drawing
    is left out; for auto, numpy's BLAS gets one thread unless the user set a count."""
    import os

    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    result = subprocess.run([sys.executable, "-c", _OWN_PROCESS, method], capture_output=True,
                            text=True, timeout=120, check=False, env=env)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == [str(threads), "True"]


def test_only_the_recon_command_itself_owns_its_process(monkeypatch, tmp_path):
    """``cli.main.main(argv)`` called by a program (a test) does not set up the caller's
    process; the ``recon`` command (no argv) does."""
    from cli.main import main

    seen = []

    def reconstruct_file(*args, own_process=False, **kwargs):
        seen.append(own_process)
        raise api.ParameterError("stop here")

    monkeypatch.setattr(api, "reconstruct_file", reconstruct_file)
    argv = ["reconstruct", str(tmp_path / "in.ply"), "-o", str(tmp_path / "out.ply")]
    (tmp_path / "in.ply").write_bytes(b"")
    assert main(argv) == 1
    monkeypatch.setattr(sys, "argv", ["recon", *argv])
    assert main() == 1
    assert seen == [False, True]


def test_the_estimate_is_prepared_beside_an_isolated_fit_with_the_same_numbers(tmp_path):
    """What the estimate needs of the cloud is made while the worker fits: the result is the
    estimate made after the fit."""
    from formats.cloud_io import write_cloud
    from recon.surfaces import estimate as estimate_module
    from recon.surfaces.reconstruct import estimate_of

    source = write_cloud(tmp_path / "cloud.ply", _sphere_cloud())
    surface = api.reconstruct(source, method="convex-hull")   # isolated: prepared beside it
    assert len(estimate_module._CONTEXTS) >= 1
    estimate_module._CONTEXTS.clear()
    again = estimate_of(surface, api.load(source)).to_dict()
    assert surface.info["estimate"] == again


def test_beside_drops_its_functions_exception_and_keeps_the_bodys():
    def fails():
        raise ValueError("raised again where its result is needed")

    with api._beside(fails):
        pass
    with pytest.raises(KeyError), api._beside(fails):
        raise KeyError("the body's")
    ran = []
    with api._beside(ran.append, 1), api._beside(None, 2):
        pass
    assert ran == [1]


def test_auto_refuses_a_cloud_the_preparation_refuses_with_the_preparations_error(tmp_path):
    """Under ``method="auto"`` every strike is prepared in a thread while the choice is made;
    a cloud the preparation refuses still gets its error, not the choice's (which would
    have said that 40 points hold too few out)."""
    from formats.cloud_io import write_cloud

    source = write_cloud(tmp_path / "cloud.ply", Cloud(np.ones((40, 3))))
    for method in ("auto", "poisson"):
        with pytest.raises(InputError, match="all points coincide"):
            api.reconstruct_file(source, tmp_path / "out.ply", method=method)
    assert not (tmp_path / "out.ply").exists()


def test_later_runs_its_function_once_where_it_is_run_first_and_keeps_its_error():
    import threading

    calls = []

    def counted(value):
        calls.append(threading.current_thread().name)
        return value

    later = api._Later(counted, 7)
    thread = threading.Thread(target=later.run, name="preparing")
    thread.start()
    thread.join()
    assert later.result() == 7 and later.result() == 7 and calls == ["preparing"]
    assert api._Later(counted, 8).result() == 8 and calls[-1] == "MainThread"

    def fails():
        raise ValueError("kept for the caller")

    refused = api._Later(fails)
    refused.run()   # in the thread that runs it: nothing raised there
    with pytest.raises(ValueError, match="kept for the caller"):
        refused.result()
