"""Mesh reading (OBJ/PLY/STL) and point-cloud round trips (PLY, LAS, LAZ, HDF5)."""

from __future__ import annotations

import numpy as np
import pytest

from formats.cloud_io import LAS_SCALE_M, open_cloud_writer, read_cloud, write_cloud
from formats.errors import InputError
from formats.geometry import Cloud
from formats.mesh_io import read_mesh, write_mesh
from tests.conftest import SHARED_MESHES as MESHES


@pytest.fixture
def cloud():
    rng = np.random.default_rng(3)
    n = 2000
    return Cloud(rng.normal(0, 300, (n, 3)), {
        "time": np.sort(rng.uniform(0, 1e5, n)), "shot": np.arange(n, dtype=np.uint32),
        "beam": rng.integers(0, 5, n).astype(np.uint32), "range": rng.uniform(100, 900, n),
        "view_x": rng.normal(0, 700, n), "view_y": rng.normal(0, 700, n),
        "view_z": rng.normal(0, 700, n)})


@pytest.mark.parametrize("suffix", [".ply", ".h5", ".las", ".laz"])
def test_cloud_round_trip_keeps_attributes(tmp_path, cloud, suffix):
    path = write_cloud(tmp_path / f"cloud{suffix}", cloud)
    back = read_cloud(path)
    tolerance = 0.5 * LAS_SCALE_M if suffix in (".las", ".laz") else 0.0
    np.testing.assert_allclose(back.points, cloud.points, rtol=0, atol=tolerance * 1.0001)
    assert set(back.attributes) == set(cloud.attributes)
    for name, values in cloud.attributes.items():
        np.testing.assert_array_equal(back.attributes[name], values)
    np.testing.assert_array_equal(back.view_points, cloud.view_points)


def test_streamed_cloud_matches_whole_write(tmp_path, cloud):
    dtypes = {k: v.dtype for k, v in cloud.attributes.items()}
    with open_cloud_writer(tmp_path / "s.ply", len(cloud), dtypes) as w:
        for lo in range(0, len(cloud), 700):
            w.write(cloud.points[lo:lo + 700], {k: v[lo:lo + 700]
                                                for k, v in cloud.attributes.items()})
    write_cloud(tmp_path / "w.ply", cloud)
    assert (tmp_path / "s.ply").read_bytes() == (tmp_path / "w.ply").read_bytes()


def test_short_stream_leaves_no_file(tmp_path, cloud):
    with pytest.raises(InputError, match="wrote 10 rows"), \
            open_cloud_writer(tmp_path / "s.ply", len(cloud), {}) as w:
        w.write(cloud.points[:10], {})
    assert list(tmp_path.iterdir()) == []


def test_reads_a_cloud_written_by_open3d(tmp_path):
    import open3d as o3d

    pts = np.random.default_rng(0).normal(size=(500, 3))
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pcd.normals = o3d.utility.Vector3dVector(np.tile([0.0, 0.0, 1.0], (500, 1)))
    o3d.io.write_point_cloud(str(tmp_path / "o3d.ply"), pcd)
    back = read_cloud(tmp_path / "o3d.ply")
    np.testing.assert_allclose(back.points, pts)
    np.testing.assert_allclose(back.normals, np.tile([0.0, 0.0, 1.0], (500, 1)))


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl"])
def test_read_mesh_formats_agree(tmp_path, suffix):
    import trimesh

    vertices, faces = read_mesh(MESHES / "spot.obj")
    path = tmp_path / f"spot{suffix}"
    trimesh.Trimesh(vertices, faces, process=False).export(path)
    v2, f2 = read_mesh(path, scale=2.0)
    # STL has no shared vertices and stores float32: compare the triangles' corners.
    np.testing.assert_allclose(v2[f2], 2.0 * vertices[faces], rtol=1e-6, atol=1e-6)


def test_write_mesh_round_trip(tmp_path):
    vertices, faces = read_mesh(MESHES / "fandisk.obj")
    write_mesh(tmp_path / "f.ply", vertices, faces)
    v2, f2 = read_mesh(tmp_path / "f.ply")
    np.testing.assert_array_equal(v2, vertices)
    np.testing.assert_array_equal(f2, faces)


def test_bad_mesh_inputs(tmp_path):
    with pytest.raises(InputError, match=r"missing\.obj: no such file"):
        read_mesh(tmp_path / "missing.obj")
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(InputError, match=r"unknown mesh suffix '\.txt'"):
        read_mesh(tmp_path / "notes.txt")
    (tmp_path / "garbage.ply").write_bytes(b"\x00\x01garbage")
    with pytest.raises(InputError, match=r"garbage\.ply: "):
        read_mesh(tmp_path / "garbage.ply")
    write_cloud(tmp_path / "pts.ply", Cloud(np.zeros((3, 3))))
    with pytest.raises(InputError, match=r"pts\.ply: has no triangles"):
        read_mesh(tmp_path / "pts.ply")
    with pytest.raises(InputError, match="scale must be a positive number"):
        read_mesh(MESHES / "spot.obj", scale=-1.0)


def test_bad_cloud_inputs(tmp_path):
    with pytest.raises(InputError, match=r"unknown point-cloud suffix '\.vtk'"):
        read_cloud(tmp_path / "a.vtk")
    with pytest.raises(InputError, match=r"unknown point-cloud suffix '\.xyz'"):
        write_cloud(tmp_path / "a.xyz", Cloud(np.zeros((1, 3))))
    with pytest.raises(InputError, match=r"a\.las: no such file"):
        read_cloud(tmp_path / "a.las")
    (tmp_path / "bad.las").write_bytes(b"LASF" + b"\x00" * 50)
    with pytest.raises(InputError, match=r"bad\.las: not a readable LAS"):
        read_cloud(tmp_path / "bad.las")
    with pytest.raises(InputError, match=r"points must be \(n, 3\)"):
        Cloud(np.zeros((4, 2)))
    with pytest.raises(InputError, match="beyond"):
        write_cloud(tmp_path / "far.las", Cloud(np.array([[1e6, 0, 0]])))


@pytest.mark.parametrize("suffix", [".ply", ".h5", ".las", ".laz"])
@pytest.mark.parametrize("with_normals", [False, True])
def test_streamed_cloud_equals_the_whole_read(tmp_path, cloud, suffix, with_normals):
    from formats.cloud_io import stream_cloud

    if with_normals:
        normals = np.random.default_rng(4).normal(size=(len(cloud), 3))
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        cloud = Cloud(cloud.points, cloud.attributes | dict(zip(("nx", "ny", "nz"), normals.T,
                                                                strict=True)))
    cloud = Cloud(cloud.points, cloud.attributes, frame="inertial")   # the file's frame kept
    path = write_cloud(tmp_path / f"c{suffix}", cloud)
    whole = read_cloud(path)
    frame, blocks = stream_cloud(path, 300)
    assert frame == "inertial"
    parts = list(blocks())
    assert frame == whole.frame and len(parts) == 7   # 2000 points in blocks of 300
    assert np.array_equal(np.concatenate([p for p, _ in parts]), whole.points)
    if with_normals:
        assert np.array_equal(np.concatenate([n for _, n in parts]), whole.normals)
    else:
        assert all(n is None for _, n in parts)
    assert len(list(blocks())) == 7   # a second pass reads the file again


def test_files_that_do_not_stream(tmp_path, cloud):
    from formats.cloud_io import stream_cloud

    text = tmp_path / "c.xyz"
    np.savetxt(text, cloud.points)
    ascii_ply = tmp_path / "ascii.ply"
    ascii_ply.write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                         "property float y\nproperty float z\nend_header\n1 2 3\n")
    mesh = tmp_path / "mesh.ply"
    write_mesh(mesh, np.eye(3), np.array([[0, 1, 2]]))
    assert all(stream_cloud(p, 100) is None for p in (text, ascii_ply, mesh))


def test_truncated_binary_ply_is_one_line(tmp_path, cloud):
    from formats.cloud_io import stream_cloud
    from formats.ply import read_header

    path = write_cloud(tmp_path / "c.ply", cloud)
    body = path.stat().st_size - read_header(path).offset
    path.write_bytes(path.read_bytes()[:-100])
    with pytest.raises(InputError, match=rf"c\.ply: the PLY header declares 2,000 vertex "
                                              rf"elements \({body:,} bytes\) but the body "
                                              rf"holds {body - 100:,} bytes"):
        stream_cloud(path, 300)


def test_hdf5_cloud_points_of_the_wrong_shape_are_one_line(tmp_path):
    import h5py

    from formats.cloud_io import CLOUD_FORMAT_NAME, CLOUD_FORMAT_VERSION, stream_cloud

    path = tmp_path / "flat.h5"
    with h5py.File(path, "w") as f:
        f.attrs.update({"format": CLOUD_FORMAT_NAME, "format_version": CLOUD_FORMAT_VERSION})
        f["points"] = np.zeros((10, 2))
        f.create_group("attributes")
    for read in (read_cloud, lambda p: stream_cloud(p, 4)):
        with pytest.raises(InputError, match=r"flat\.h5: /points has shape \(10, 2\), "
                                                  r"expected \(n, 3\)"):
            read(path)


@pytest.mark.parametrize(("value", "message"), [
    (1e200, "coordinates reach 1e\\+200 m"), (np.nan, "coordinates contain NaN or Inf")])
@pytest.mark.parametrize("suffix", [".ply", ".xyz", ".h5"])
def test_coordinates_beyond_reach_are_refused_naming_the_file(tmp_path, suffix, value,
                                                               message):
    """Finite but absurd coordinates (a damaged or mis-scaled file) overflow squared distances
    and leave KD-tree queries without neighbours; NaN has no place at all: refused on reading,
    with the file named."""
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, value, 0.0]])
    path = tmp_path / f"far{suffix}"
    if suffix == ".xyz":
        np.savetxt(path, points)
    else:
        write_cloud(path, Cloud(points))
    with pytest.raises(InputError, match=rf"far\{suffix}: {message}"):
        read_cloud(path)


def test_a_mesh_beyond_reach_is_refused(tmp_path):
    path = tmp_path / "far.ply"
    write_mesh(path, np.array([[0.0, 0, 0], [1e20, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    with pytest.raises(InputError, match=r"far\.ply: coordinates reach 1e\+20 m"):
        read_mesh(path)


def test_a_cloud_file_s_own_inconsistency_names_the_file(tmp_path):
    import h5py

    path = tmp_path / "c.h5"
    write_cloud(path, Cloud(np.eye(3), {"time": np.arange(3.0)}))
    with h5py.File(path, "a") as f:
        del f["attributes/time"]
        f["attributes/time"] = np.arange(2.0)
    with pytest.raises(InputError, match=r"c\.h5: attribute 'time' has 2 values for 3 points"):
        read_cloud(path)


