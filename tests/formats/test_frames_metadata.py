"""Frames and metadata: files that record no frame are read in the frame "unknown" and said so;
recon's files say their frame, source and the units of every column; .xyzn and .csv clouds."""

from __future__ import annotations

import json
import warnings

import h5py
import numpy as np
import pytest

from formats.cloud_io import read_cloud, write_cloud
from formats.errors import InputError
from formats.geometry import Cloud
from formats.mesh_io import read_mesh, write_mesh
from formats.ply import read_ply_metadata
from metrics.errors import FrameAssumedWarning
from tests.conftest import SPHERE_RADIUS_M, icosphere


def _sphere_points(n: int = 400, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    return SPHERE_RADIUS_M * d / np.linalg.norm(d, axis=1, keepdims=True)


# --------------------------------------------------------------------------- unknown frames


def test_files_of_other_tools_are_read_in_the_unknown_frame(tmp_path):
    import trimesh

    np.savetxt(tmp_path / "c.xyz", _sphere_points())
    assert read_cloud(tmp_path / "c.xyz").frame == "unknown"
    vertices, faces = icosphere(10.0, 1)
    trimesh.Trimesh(vertices, faces).export(tmp_path / "m.obj")
    trimesh.Trimesh(vertices, faces).export(tmp_path / "m.ply")
    assert read_mesh(tmp_path / "m.obj").frame == "unknown"
    assert read_mesh(tmp_path / "m.ply").frame == "unknown"
    # recon's own files keep the frame they say
    write_cloud(tmp_path / "body.ply", Cloud(_sphere_points()))
    assert read_cloud(tmp_path / "body.ply").frame == "body"
    write_mesh(tmp_path / "body_mesh.ply", vertices, faces)
    assert read_mesh(tmp_path / "body_mesh.ply").frame == "body"


def test_an_unknown_cloud_is_written_and_read_back_as_unknown(tmp_path):
    cloud = Cloud(_sphere_points(), frame="unknown")
    for suffix in (".ply", ".h5", ".las"):
        write_cloud(tmp_path / f"u{suffix}", cloud)
        assert read_cloud(tmp_path / f"u{suffix}").frame == "unknown", suffix


def test_score_of_an_unknown_cloud_against_a_body_truth_notes_it(tmp_path, capsys, sphere_log):
    from cli.main import main

    np.savetxt(tmp_path / "c.xyz", _sphere_points())
    assert main(["score", str(tmp_path / "c.xyz"), "--truth", str(sphere_log),
                 "--no-edges", "--json"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"recon score: note: test {tmp_path / 'c.xyz'} records no frame (unknown); "
                   "compared as if in the truth's body frame"]


def test_score_api_warns_once_and_still_refuses_two_known_frames():
    from metrics import score

    truth = icosphere(SPHERE_RADIUS_M, 3)
    unknown = Cloud(_sphere_points(), frame="unknown")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        report = score(unknown, truth, edges=False)
    assert [w.category for w in caught] == [FrameAssumedWarning]
    assert report.accuracy_mean_m < 1.0   # the points lie on the truth sphere
    with pytest.raises(InputError, match="in the inertial frame but truth in the body"):
        score(Cloud(_sphere_points(), frame="inertial"), truth, edges=False)


def test_score_of_a_body_cloud_against_an_obj_truth_notes_the_truth(tmp_path):
    import trimesh

    from recon import api

    trimesh.Trimesh(*icosphere(SPHERE_RADIUS_M, 3)).export(tmp_path / "truth.obj")
    with pytest.warns(FrameAssumedWarning, match=r"^the truth records no frame \(unknown\); "
                                                 r"compared as if in the body frame of test"):
        api.score(Cloud(_sphere_points()), truth=tmp_path / "truth.obj", edges=False)


# --------------------------------------------------------------------------- .xyzn and .csv


def test_xyzn_clouds(tmp_path):
    points = _sphere_points(50)
    normals = points / SPHERE_RADIUS_M
    np.savetxt(tmp_path / "c.xyzn", np.hstack([points, normals]))
    cloud = read_cloud(tmp_path / "c.xyzn")
    np.testing.assert_allclose(cloud.points, points)
    np.testing.assert_allclose(cloud.normals, normals)
    np.savetxt(tmp_path / "bad.xyzn", points)
    with pytest.raises(InputError, match=r"bad\.xyzn: an \.xyzn file has 6 columns "
                                              r"\(x y z nx ny nz\), found 3"):
        read_cloud(tmp_path / "bad.xyzn")


def test_csv_clouds_with_a_header_row(tmp_path):
    points = _sphere_points(30)
    intensity = np.arange(30.0)
    normals = points / SPHERE_RADIUS_M
    table = np.column_stack([intensity, points[:, 2], points[:, 0], points[:, 1], normals])
    np.savetxt(tmp_path / "c.csv", table, delimiter=",",
               header="intensity,Z,X,Y,nx,ny,nz", comments="")
    cloud = read_cloud(tmp_path / "c.csv")
    np.testing.assert_allclose(cloud.points, points)
    np.testing.assert_allclose(cloud.normals, normals)
    np.testing.assert_array_equal(cloud.attributes["intensity"], intensity)
    assert cloud.frame == "unknown"
    np.savetxt(tmp_path / "plain.csv", points, delimiter=",")   # no header: x, y, z in order
    np.testing.assert_allclose(read_cloud(tmp_path / "plain.csv").points, points)


@pytest.mark.parametrize(("header", "message"), [
    ("a,b,c", r"the header row must name columns x, y and z once each \(found 'a, b, c'\)"),
    ("x,y,z,x", r"must name columns x, y and z once each"),
    ("x,y,z,w", r"the header names 4 columns but the rows hold 3"),
    ("\x1b[2Jx,\x07b,c", r"\(found '\\x1b\[2jx, \\x07b, c'\)"),   # control characters escaped
])
def test_bad_csv_headers(tmp_path, header, message):
    path = tmp_path / "bad.csv"
    np.savetxt(path, _sphere_points(5), delimiter=",", header=header, comments="")
    with pytest.raises(InputError, match=message) as caught:
        read_cloud(path)
    assert str(caught.value).startswith(str(path))


# --------------------------------------------------------------------------- units and source


def test_hdf5_cloud_columns_say_their_units(tmp_path):
    n = 20
    cloud = Cloud(_sphere_points(n), {"range": np.ones(n), "time": np.arange(n, dtype=float),
                                      "intensity": np.ones(n)})
    write_cloud(tmp_path / "c.h5", cloud)
    with h5py.File(tmp_path / "c.h5") as f:
        units = {k: ds.attrs["units"] for k, ds in f["attributes"].items()}
        assert f["points"].attrs["units"] == "m"
    assert units == {"range": "m", "time": "s", "intensity": "unknown"}


def test_las_extra_bytes_say_their_units(tmp_path):
    import laspy

    n = 20
    cloud = Cloud(_sphere_points(n), {"range": np.ones(n), "azimuth": np.zeros(n),
                                      "shot": np.arange(n, dtype=np.uint32),
                                      "intensity_raw": np.ones(n)})
    write_cloud(tmp_path / "c.las", cloud)
    with laspy.open(tmp_path / "c.las") as reader:
        header = reader.header
        described = {d.name: d.description for d in header.point_format.extra_dimensions}
        vlr = next(v for v in header.vlrs if v.user_id == "recon")
    assert described == {"range": "measured range [m]", "azimuth": "measured azimuth in S [rad]",
                         "shot": "shot index in source log [1]",
                         "intensity_raw": "intensity_raw [unknown]"}
    assert json.loads(vlr.record_data)["attribute_units"] == {
        "range": "m", "azimuth": "rad", "shot": "1", "intensity_raw": "unknown"}


def test_meshes_recon_writes_say_their_source(tmp_path, sphere_log):
    from cli.main import main

    assert main(["truth", str(sphere_log), "-o", str(tmp_path / "truth.ply")]) == 0
    metadata = read_ply_metadata(tmp_path / "truth.ply")
    assert (metadata["source"], metadata["frame"], metadata["units"]) == \
        (sphere_log.name, "body", "m")
