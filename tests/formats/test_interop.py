"""Files that the tools of the field open whole, and files they write that recon reads.

Round trips through every installed library (Open3D, trimesh, pymeshlab, laspy, h5py, pye57;
CloudCompare's command line when it is on PATH), ASCII PLY, text clouds, PCD and E57 written by
other tools, and the frame, units and provenance every file recon writes carries.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess

import numpy as np
import pytest

from formats.cloud_io import LAS_SCAN_ANGLE_STEP_DEG, read_cloud, write_cloud
from formats.errors import InputError, ReconError
from formats.geometry import Cloud, Mesh
from formats.mesh_io import read_mesh, write_mesh
from formats.ply import read_ply, read_ply_metadata
from formats.version import __version__
from tests.conftest import icosphere


@pytest.fixture
def cloud():
    """An inertial-frame cloud with every attribute ingest writes, and normals."""
    rng = np.random.default_rng(5)
    n = 300
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return Cloud(rng.normal(0, 100, (n, 3)), {
        "time": np.sort(rng.uniform(0, 1e5, n)), "shot": np.arange(n, dtype=np.uint32),
        "beam": rng.integers(0, 5, n).astype(np.uint32), "range": rng.uniform(100, 900, n),
        "azimuth": rng.uniform(-0.1, 0.1, n), "elevation": rng.uniform(-0.1, 0.1, n),
        "view_x": rng.normal(0, 700, n), "view_y": rng.normal(0, 700, n),
        "view_z": rng.normal(0, 700, n)}, normals=normals, frame="inertial")


# --------------------------------------------------------------------------- item 1: ASCII PLY


def test_reads_ascii_ply_from_open3d(tmp_path):
    import open3d as o3d

    pts = np.random.default_rng(0).normal(size=(50, 3))
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pcd.normals = o3d.utility.Vector3dVector(np.tile([0.0, 0.0, 1.0], (50, 1)))
    o3d.io.write_point_cloud(str(tmp_path / "a.ply"), pcd, write_ascii=True)
    back = read_cloud(tmp_path / "a.ply")
    np.testing.assert_allclose(back.points, pts, atol=1e-5)  # Open3D writes 6 digits
    np.testing.assert_allclose(back.normals, np.tile([0.0, 0.0, 1.0], (50, 1)))


def test_reads_ascii_ply_mesh_from_trimesh(tmp_path):
    import trimesh

    from recon.inputs import load_geometry

    vertices, faces = icosphere(10.0, 1)
    trimesh.Trimesh(vertices, faces, process=False).export(tmp_path / "m.ply", encoding="ascii")
    mesh = load_geometry(tmp_path / "m.ply")
    assert isinstance(mesh, Mesh)
    np.testing.assert_allclose(mesh.vertices, vertices, atol=1e-6)
    np.testing.assert_array_equal(mesh.faces, faces)


# --------------------------------------------------------------------------- item 2: metadata


@pytest.mark.parametrize("suffix", [".ply", ".las", ".laz", ".h5"])
def test_every_cloud_file_records_frame_units_source_version(tmp_path, cloud, suffix):
    path = write_cloud(tmp_path / f"c{suffix}", cloud, source="run.h5")
    back = read_cloud(path)
    assert back.frame == "inertial"
    assert set(back.attributes) == set(cloud.attributes)
    if suffix == ".ply":
        assert read_ply_metadata(path) == {"frame": "inertial", "units": "m",
                                           "source": "run.h5", "recon_version": __version__}
    elif suffix == ".h5":
        import h5py

        with h5py.File(path) as f:
            assert (f.attrs["frame"], f.attrs["units"], f.attrs["source"]) == (
                "inertial", "m", "run.h5")
            assert dict(f["points"].attrs) == {"units": "m", "frame": "inertial"}
            assert f["attributes/time"].attrs["units"] == "s"
            assert f["attributes/view_x"].attrs["frame"] == "inertial"
    else:
        import laspy

        las = laspy.read(path)
        (recon_vlr,) = [v for v in las.header.vlrs if v.user_id == "recon"]
        meta = json.loads(recon_vlr.record_data)
        assert (meta["frame"], meta["units"], meta["source"], meta["recon_version"]) == (
            "inertial", "m", "run.h5", __version__)
        wkt = las.header.vlrs.get("WktCoordinateSystemVlr")[0].string
        assert "inertial" in wkt and 'UNIT["metre",1' in wkt
        assert las.header.global_encoding.wkt


def test_mesh_file_records_frame_and_reads_it_back(tmp_path):
    vertices, faces = icosphere(10.0, 1)
    path = write_mesh(tmp_path / "m.ply", Mesh(vertices, faces, frame="inertial"),
                      source="run.h5")
    assert read_mesh(path).frame == "inertial"
    assert read_ply_metadata(path)["source"] == "run.h5"


def test_file_in_other_units_is_refused(tmp_path):
    (tmp_path / "km.ply").write_text("ply\nformat ascii 1.0\ncomment units km\nelement vertex 1\n"
                                     "property float x\nproperty float y\nproperty float z\n"
                                     "end_header\n1 2 3\n")
    with pytest.raises(InputError, match=r"km\.ply: file says units 'km'"):
        read_cloud(tmp_path / "km.ply")


def test_score_refuses_a_cloud_recorded_in_another_frame(tmp_path, sphere_log):
    from cli.main import main
    from recon import api

    api.ingest(sphere_log, frame="inertial", output=tmp_path / "inertial.ply")
    with pytest.raises(ReconError, match="inertial frame but truth in the body frame"):
        api.score(tmp_path / "inertial.ply", truth=sphere_log)
    assert main(["score", str(tmp_path / "inertial.ply"), "--truth", str(sphere_log)]) == 1


# --------------------------------------------------------------------------- item 3: LAS


def test_las_follows_asprs_conventions(tmp_path, cloud):
    import laspy

    las = laspy.read(write_cloud(tmp_path / "c.las", cloud))
    assert np.all(las.return_number == 1) and np.all(las.number_of_returns == 1)
    np.testing.assert_array_equal(las.gps_time, cloud.attributes["time"])
    np.testing.assert_array_equal(las.point_source_id, cloud.attributes["beam"])
    degrees = np.asarray(las.scan_angle) * LAS_SCAN_ANGLE_STEP_DEG
    np.testing.assert_allclose(np.deg2rad(degrees), cloud.attributes["azimuth"],
                               atol=np.deg2rad(LAS_SCAN_ANGLE_STEP_DEG))
    assert np.any(las.scan_angle != 0)
    described = {d.name: d.description for d in las.point_format.extra_dimensions}
    assert described["range"] == "measured range [m]"
    assert all(described.values())
    assert las.header.generating_software.startswith("recon ")


def test_ingested_lidar_las_keeps_scan_angles(tmp_path):
    import laspy

    from recon import api
    from tests.conftest import write_sphere_log

    write_sphere_log(tmp_path / "lidar.h5", reports_angles=True)
    cloud = api.ingest(tmp_path / "lidar.h5", output=tmp_path / "c.las")
    las = laspy.read(tmp_path / "c.las")
    assert np.count_nonzero(las.scan_angle) > len(las.points) / 2
    degrees = np.rad2deg(cloud.attributes["azimuth"])
    np.testing.assert_array_equal(las.scan_angle, np.round(degrees / LAS_SCAN_ANGLE_STEP_DEG))


# --------------------------------------------------------------------------- item 4: PLY


def test_ply_columns_are_read_whole_by_open3d_tensor_reader(tmp_path, cloud):
    import open3d as o3d

    path = write_cloud(tmp_path / "c.ply", cloud)
    pcd = o3d.t.io.read_point_cloud(str(path))
    np.testing.assert_allclose(pcd.point.positions.numpy(), cloud.points)
    np.testing.assert_allclose(pcd.point.normals.numpy(), cloud.normals)
    for name in ("shot", "beam", "time", "range"):
        np.testing.assert_array_equal(pcd.point[f"scalar_{name}"].numpy().ravel(),
                                      cloud.attributes[name])


def test_ply_round_trip_through_trimesh(tmp_path, cloud):
    import trimesh

    path = write_cloud(tmp_path / "c.ply", cloud)
    loaded = trimesh.load(path)
    np.testing.assert_allclose(loaded.vertices, cloud.points)
    raw = loaded.metadata["_ply_raw"]["vertex"]["data"]
    np.testing.assert_array_equal(raw["scalar_beam"], cloud.attributes["beam"])
    back = tmp_path / "back.ply"
    loaded.export(back)
    np.testing.assert_allclose(read_cloud(back).points, cloud.points)


def test_mesh_round_trip_through_pymeshlab_keeps_normals(tmp_path):
    import pymeshlab

    vertices, faces = icosphere(10.0, 2)
    path = write_mesh(tmp_path / "m.ply", vertices, faces)
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    m = ms.current_mesh()
    np.testing.assert_allclose(m.vertex_matrix(), vertices)
    np.testing.assert_array_equal(m.face_matrix(), faces)
    written = Mesh(vertices, faces).vertex_normals
    np.testing.assert_allclose(m.vertex_normal_matrix(), written, atol=1e-6)
    # an icosphere's area-weighted vertex normals are close to its radial directions
    radial = vertices / np.linalg.norm(vertices, axis=1, keepdims=True)
    np.testing.assert_allclose(written, radial, atol=0.03)
    ms.save_current_mesh(str(tmp_path / "back.ply"))
    np.testing.assert_allclose(read_mesh(tmp_path / "back.ply").vertices, vertices, atol=1e-5)


def test_reconstructed_mesh_has_vertex_normals(tmp_path):
    vertices, faces = icosphere(10.0, 2)
    columns, _, _ = read_ply(write_mesh(tmp_path / "m.ply", vertices, faces))
    normals = np.stack([columns[k] for k in ("nx", "ny", "nz")], axis=1)
    assert np.all(np.einsum("ij,ij->i", normals, vertices) > 0)  # outward


@pytest.mark.skipif(shutil.which("CloudCompare") is None, reason="CloudCompare not installed")
def test_ply_is_read_whole_by_cloudcompare(tmp_path, cloud):
    path = write_cloud(tmp_path / "c.ply", cloud)
    out = tmp_path / "cc.asc"
    subprocess.run(["CloudCompare", "-SILENT", "-AUTO_SAVE", "OFF", "-O", str(path),
                    "-C_EXPORT_FMT", "ASC", "-ADD_HEADER", "-SEP", "SPACE", "-PREC", "12",
                    "-SAVE_CLOUDS", "FILE", str(out)],
                   check=True, capture_output=True, timeout=120,
                   env=os.environ | {"QT_QPA_PLATFORM": "offscreen"})
    header = out.read_text().splitlines()[0].lstrip("/").split()
    assert {"X", "Y", "Z", "Nx", "Ny", "Nz", "time", "shot", "beam", "range"} <= set(header)
    table = np.loadtxt(out, comments="//")
    np.testing.assert_allclose(table[:, header.index("shot")], cloud.attributes["shot"])
    np.testing.assert_allclose(table[:, :3], cloud.points, atol=1e-6)


def test_ply_columns_beyond_int32_are_refused(tmp_path):
    big = Cloud(np.zeros((1, 3)), {"shot": np.array([2**31], dtype=np.uint32)})
    with pytest.raises(InputError, match="'scalar_shot' has values beyond the int32"):
        write_cloud(tmp_path / "big.ply", big)
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- item 10: inputs


def test_reads_text_clouds(tmp_path):
    pts = np.random.default_rng(1).normal(size=(20, 3))
    normals = np.tile([0.0, 1.0, 0.0], (20, 1))
    np.savetxt(tmp_path / "a.xyz", pts)
    np.savetxt(tmp_path / "b.txt", np.hstack([pts, normals]), delimiter=",")
    np.savetxt(tmp_path / "c.asc", np.hstack([pts, normals[:, :1]]), header="X Y Z intensity",
               comments="//")
    helios = np.hstack([pts, np.arange(20)[:, None], np.ones((20, 7))])  # HELIOS++: 11 columns
    np.savetxt(tmp_path / "h.xyz", helios)
    np.testing.assert_allclose(read_cloud(tmp_path / "a.xyz").points, pts)
    b = read_cloud(tmp_path / "b.txt")
    np.testing.assert_allclose(b.normals, normals)
    c = read_cloud(tmp_path / "c.asc")
    assert set(c.attributes) == {"intensity"}
    h = read_cloud(tmp_path / "h.xyz")
    np.testing.assert_array_equal(h.attributes["column_4"], np.arange(20))
    assert len(h.attributes) == 8
    (tmp_path / "bad.xyz").write_text("1 2 three\n")
    with pytest.raises(InputError, match=r"bad\.xyz: not a text point cloud"):
        read_cloud(tmp_path / "bad.xyz")
    (tmp_path / "two.xyz").write_text("1 2\n")
    with pytest.raises(InputError, match="at least 3 columns"):
        read_cloud(tmp_path / "two.xyz")


def test_reads_pcd_written_by_open3d(tmp_path):
    import open3d as o3d

    pts = np.random.default_rng(2).normal(size=(40, 3))
    pcd = o3d.t.geometry.PointCloud(o3d.core.Tensor(pts))
    pcd.point.normals = o3d.core.Tensor(np.tile([1.0, 0.0, 0.0], (40, 1)))
    pcd.point.intensity = o3d.core.Tensor(np.arange(40, dtype=np.float32)[:, None])
    o3d.t.io.write_point_cloud(str(tmp_path / "a.pcd"), pcd)
    back = read_cloud(tmp_path / "a.pcd")
    np.testing.assert_allclose(back.points, pts)
    np.testing.assert_allclose(back.normals, np.tile([1.0, 0.0, 0.0], (40, 1)))
    np.testing.assert_array_equal(back.attributes["intensity"], np.arange(40))
    (tmp_path / "bad.pcd").write_text("nonsense")
    with pytest.raises(InputError, match=r"bad\.pcd: not a readable PCD"):
        read_cloud(tmp_path / "bad.pcd")


def test_reads_e57_written_by_pye57(tmp_path):
    pye57 = pytest.importorskip("pye57")
    pts = np.random.default_rng(4).normal(size=(30, 3))
    e57 = pye57.E57(str(tmp_path / "a.e57"), mode="w")
    e57.write_scan_raw({"cartesianX": pts[:, 0], "cartesianY": pts[:, 1],
                        "cartesianZ": pts[:, 2], "intensity": np.linspace(0, 1, 30)})
    e57.close()
    back = read_cloud(tmp_path / "a.e57")
    np.testing.assert_allclose(back.points, pts)
    np.testing.assert_allclose(back.attributes["intensity"], np.linspace(0, 1, 30))
    (tmp_path / "bad.e57").write_bytes(b"\x00" * 100)
    with pytest.raises(InputError, match=r"bad\.e57: not a readable E57"):
        read_cloud(tmp_path / "bad.e57")


def test_surface_of_an_inertial_cloud_is_refused_by_score():
    from recon import api

    vertices, faces = icosphere(10.0, 2)
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(400, 3))
    cloud = Cloud(10.0 * directions / np.linalg.norm(directions, axis=1, keepdims=True),
                  frame="inertial")
    surface = api.reconstruct(cloud, method="convex-hull", isolate=False)
    assert surface.frame == "inertial"
    with pytest.raises(ReconError, match="inertial frame but truth in the body frame"):
        api.score(surface, truth=Mesh(vertices, faces))
