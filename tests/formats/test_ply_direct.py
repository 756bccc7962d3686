"""The direct binary PLY path (``formats.ply._read_fixed_binary``) reads what trimesh's parser
reads, for the files other tools write; files it does not take fall back to trimesh."""

import numpy as np
import pytest

from formats import ply
from formats.errors import InputError


def _trimesh_read(path):
    """Columns and faces through trimesh's parser (the reference)."""
    from trimesh.exchange.ply import load_ply

    with open(path, "rb") as fh:
        loaded = load_ply(fh, prefer_color="vertex")
    vertex = loaded["metadata"]["_ply_raw"]["vertex"]["data"]
    columns = {k: np.asarray(vertex[k]).reshape(-1) for k in vertex.dtype.names}
    faces = loaded.get("faces")
    return columns, None if faces is None or len(faces) == 0 else np.asarray(faces)


def _files(tmp_path):
    import open3d as o3d
    import trimesh

    sphere = trimesh.creation.icosphere(2)
    paths = {}
    paths["trimesh"] = tmp_path / "trimesh.ply"
    sphere.export(paths["trimesh"])
    paths["big-endian"] = tmp_path / "big.ply"
    vertices = np.zeros(len(sphere.vertices), dtype=[(k, ">f8") for k in "xyz"])
    for i, k in enumerate("xyz"):
        vertices[k] = sphere.vertices[:, i]
    faces = np.zeros(len(sphere.faces), dtype=[("n", "u1"), ("v", ">i4", (3,))])
    faces["n"], faces["v"] = 3, sphere.faces
    paths["big-endian"].write_bytes(
        f"ply\nformat binary_big_endian 1.0\nelement vertex {len(vertices)}\n".encode()
        + b"property double x\nproperty double y\nproperty double z\n"
        + f"element face {len(faces)}\n".encode()
        + b"property list uchar int vertex_indices\nend_header\n"
        + vertices.tobytes() + faces.tobytes())
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(sphere.vertices),
                                     o3d.utility.Vector3iVector(sphere.faces))
    mesh.compute_vertex_normals()
    paths["open3d"] = tmp_path / "open3d.ply"
    o3d.io.write_triangle_mesh(str(paths["open3d"]), mesh)
    paths["recon"] = tmp_path / "recon.ply"
    ply.write_ply(paths["recon"], {"x": sphere.vertices[:, 0], "y": sphere.vertices[:, 1],
                                   "z": sphere.vertices[:, 2],
                                   "id": np.arange(len(sphere.vertices))},
                  faces=sphere.faces, metadata={"frame": "body"})
    paths["cloud"] = tmp_path / "cloud.ply"
    ply.write_ply(paths["cloud"], {k: np.linspace(0, 1, 7) for k in "xyz"})
    return paths


def test_direct_read_equals_trimesh(tmp_path):
    for kind, path in _files(tmp_path).items():
        header = ply.read_header(path)
        direct = ply._read_fixed_binary(path, header)
        assert direct is not None, kind
        columns, faces = direct
        want_columns, want_faces = _trimesh_read(path)
        assert list(columns) == list(want_columns), kind
        for name in columns:
            np.testing.assert_array_equal(columns[name], want_columns[name], err_msg=kind)
            assert columns[name].dtype.isnative
        if want_faces is None:
            assert faces is None
        else:
            np.testing.assert_array_equal(faces, want_faces, err_msg=kind)
            assert faces.dtype == np.int64


def test_quads_and_ascii_fall_back_to_trimesh(tmp_path):
    quads = tmp_path / "quad.ply"
    body = np.zeros(4, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    body["x"], body["y"] = [0, 1, 1, 0], [0, 0, 1, 1]
    face = np.zeros(1, dtype=[("n", "u1"), ("v", "<i4", (4,))])
    face["n"], face["v"] = 4, [0, 1, 2, 3]
    quads.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 4\n"
                      b"property float x\nproperty float y\nproperty float z\n"
                      b"element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                      + body.tobytes() + face.tobytes())
    assert ply._read_fixed_binary(quads, ply.read_header(quads)) is None
    _, faces, _ = ply.read_ply(quads)
    assert faces.tolist() == [[0, 1, 2, 3]]   # as trimesh parses it
    text = tmp_path / "ascii.ply"
    text.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                    "property float y\nproperty float z\nelement face 1\n"
                    "property list uchar int vertex_indices\nend_header\n"
                    "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    assert ply._read_fixed_binary(text, ply.read_header(text)) is None
    assert ply.read_ply(text)[1].tolist() == [[0, 1, 2]]


def test_direct_read_refuses_indices_beyond_the_vertices(tmp_path):
    path = tmp_path / "bad.ply"
    ply.write_ply(path, {k: np.zeros(3) for k in "xyz"}, faces=np.array([[0, 1, 3]]))
    with pytest.raises(InputError, match="faces index vertices that do not exist"):
        ply.read_ply(path)
