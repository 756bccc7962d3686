"""Shape models in the forms they are published in: PDS vertex/plate tables, ICQ grids, SPICE DSK.

Where each layout is specified (the hand-made files below follow these, not recon's writers):

- PDS vertex/plate table, ``v``/``f`` form: the PDS Small Bodies Node radar shape models (Hudson,
  Ostro et al.): one ``v x y z`` row per vertex [km], then one ``f i j k`` row per facet, 1-based.
- PDS vertex/plate table, two-table form: the PDS SBN plate models (e.g. Gaskell's Eros and
  Itokawa "plate model" tables): a vertex count, rows ``id x y z`` [km], a plate count, rows
  ``id i j k`` naming vertex ids (1-based).
- ICQ: "The Implicitly Connected Quadrilateral Format", the document of Gaskell's shape models in
  the PDS SBN archives (e.g. the Hayabusa AMICA Itokawa shape model): Q, then 6 (Q+1)^2 rows
  ``x y z`` [km] with F = 1..6 outermost, then J, then I; facet f(I, J, F) is v(I, J), v(I, J+1),
  v(I+1, J+1), v(I+1, J); the cube faces unfold as 1 above 2, then 5 4 3 2 left to right, 6
  below 2, and their shared edges repeat vertices (v(I, 0, 2) = v(I, Q, 1), ...).
- SPICE DSK type 2: NAIF's DSK Required Reading and the dskw02/dskmi2 headers: plates of 1-based
  vertex indices, vertices in km in the segment's body-fixed frame.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from formats.errors import InputError, ReconError
from formats.mesh_io import default_units, read_mesh, write_mesh
from sim.targets import is_closed, signed_volume
from tests.conftest import SHARED_MESHES

SHARED = sorted(SHARED_MESHES.glob("*.obj")) if SHARED_MESHES.is_dir() else []
TETRA_KM = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
TETRA_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


# --------------------------------------------------------------------------- shared models


@pytest.mark.skipif(not SHARED, reason="the shared real meshes are not beside the checkout "
                                       "(../shared/meshes)")
@pytest.mark.parametrize("suffix", [".tab", ".bds"])
@pytest.mark.parametrize("name", [p.name for p in SHARED] or ["none"])
def test_shared_models_survive_every_format(tmp_path, name, suffix):
    # The shared OBJ files are in their source units (km for the asteroids; README there).
    model = read_mesh(SHARED_MESHES / name, units="km")
    written = write_mesh(tmp_path / f"model{suffix}", model)
    back = read_mesh(written)
    np.testing.assert_allclose(back.vertices, model.vertices, rtol=1e-14, atol=1e-9)
    np.testing.assert_array_equal(back.faces, model.faces)
    assert back.frame == ("body" if suffix == ".bds" else "unknown")


@pytest.mark.skipif(not SHARED, reason="the shared real meshes are not beside the checkout")
def test_v_f_form_of_a_shared_model(tmp_path):
    from formats.shape_models import write_pds_table

    model = read_mesh(SHARED_MESHES / "bennu_radar_2.7k.obj", units="km")
    write_pds_table(tmp_path / "bennu.tab", model.vertices, model.faces, form="v/f")
    back = read_mesh(tmp_path / "bennu.tab")
    np.testing.assert_allclose(back.vertices, model.vertices, rtol=1e-14)
    np.testing.assert_array_equal(back.faces, model.faces)


# --------------------------------------------------------------------------- hand-made files


def test_hand_made_v_f_table_in_km(tmp_path):
    path = tmp_path / "tetra.tab"
    path.write_text("".join(f"v {x:.3f} {y:.3f} {z:.3f}\n" for x, y, z in TETRA_KM)
                    + "".join(f"f {i + 1} {j + 1} {k + 1}\n" for i, j, k in TETRA_FACES))
    mesh = read_mesh(path)
    np.testing.assert_array_equal(mesh.vertices, TETRA_KM * 1000.0)
    np.testing.assert_array_equal(mesh.faces, TETRA_FACES)
    assert mesh.frame == "unknown" and default_units(path) == "km"
    np.testing.assert_array_equal(read_mesh(path, units="m").vertices, TETRA_KM)


def test_hand_made_two_table_form_with_ids_out_of_order(tmp_path):
    # ids need not be the row numbers: plates name ids
    ids = [4, 1, 3, 2]
    rows = "".join(f"  {i}  {x:.6E}  {y:.6E}  {z:.6E}\n" for i, (x, y, z) in
                   zip(ids, TETRA_KM, strict=True))
    plates = "".join(f"{n + 1} {ids[i]} {ids[j]} {ids[k]}\n"
                     for n, (i, j, k) in enumerate(TETRA_FACES))
    path = tmp_path / "plates.tab"
    path.write_text(f"4\n{rows}4\n{plates}")
    mesh = read_mesh(path)
    np.testing.assert_allclose(mesh.vertices[mesh.faces], TETRA_KM[TETRA_FACES] * 1000.0)
    assert signed_volume(*mesh) == pytest.approx(1e9 / 6)


def test_fortran_exponents_are_numbers(tmp_path):
    path = tmp_path / "d.tab"
    path.write_text("3\n1 0.0D+00 0.0D+00 0.0D0\n2 1.0D-03 0.0 0.0\n3 0.0 1.0d-3 0.0\n"
                    "1\n1 1 2 3\n")
    np.testing.assert_allclose(read_mesh(path).vertices[1:], [[1.0, 0, 0], [0, 1.0, 0]])


def _cube_point(face: int, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """A point of cube face 1..6 at grid coordinates u = -1 + 2 I / Q, w = -1 + 2 J / Q, laid
    out so that the ICQ document's shared-edge identities hold (checked below)."""
    one = np.ones_like(u)
    return np.stack({1: (u, -w, one), 2: (u, -one, -w), 3: (-one, -u, -w),
                     4: (-u, one, -w), 5: (one, u, -w), 6: (u, w, -one)}[face], axis=-1)


def _icq_grid(q: int, semi_axes) -> np.ndarray:
    """(6, Q+1, Q+1, 3) vertices v[F-1, J, I] of an ellipsoid, km."""
    j, i = np.meshgrid(np.arange(q + 1), np.arange(q + 1), indexing="ij")
    u, w = -1 + 2 * i / q, -1 + 2 * j / q
    cube = np.stack([_cube_point(f, u, w) for f in range(1, 7)])
    direction = cube / np.linalg.norm(cube, axis=-1, keepdims=True)
    scale = 1 / np.sqrt(np.sum((direction / semi_axes) ** 2, axis=-1, keepdims=True))
    return np.round(direction * scale, 9)


def test_the_icq_test_grid_has_the_documented_shared_edges():
    q = 4
    v = _icq_grid(q, np.array([1.0, 1.0, 1.0]))   # v[F-1, J, I]
    r = np.arange(q + 1)
    np.testing.assert_array_equal(v[1, 0, r], v[0, q, r])            # v(I,0,2) = v(I,Q,1)
    np.testing.assert_array_equal(v[2, 0, r], v[0, r, 0])            # v(I,0,3) = v(0,I,1)
    np.testing.assert_array_equal(v[3, 0, r], v[0, 0, q - r])        # v(I,0,4) = v(Q-I,0,1)
    np.testing.assert_array_equal(v[4, 0, r], v[0, q - r, q])        # v(I,0,5) = v(Q,Q-I,1)
    np.testing.assert_array_equal(v[5, 0, r], v[1, q, r])            # v(I,0,6) = v(I,Q,2)
    np.testing.assert_array_equal(v[5, q, r], v[3, q, q - r])        # v(I,Q,6) = v(Q-I,Q,4)
    np.testing.assert_array_equal(v[2, r, q], v[1, r, 0])            # v(Q,I,3) = v(0,I,2)
    np.testing.assert_array_equal(v[5, r, 0], v[2, q, q - r])        # v(0,I,6) = v(Q-I,Q,3)


@pytest.mark.parametrize("suffix", [".icq", ".tab"])
def test_hand_made_icq_grid(tmp_path, suffix):
    q, axes = 6, np.array([0.3, 0.2, 0.15])
    grid = _icq_grid(q, axes)
    path = tmp_path / f"shape{suffix}"
    path.write_text(f"{q:>5d}\n" + "".join(f"{x:12.6f}{y:12.6f}{z:12.6f}\n"
                                           for x, y, z in grid.reshape(-1, 3)))
    mesh = read_mesh(path)
    assert mesh.n_vertices == 6 * q * q + 2 and mesh.n_faces == 12 * q * q
    assert is_closed(mesh.faces)   # the edges were welded: every edge has its twin
    assert signed_volume(*mesh) > 0   # outward normals
    on_ellipsoid = np.sum((mesh.vertices / (axes * 1000.0)) ** 2, axis=1)
    np.testing.assert_allclose(on_ellipsoid, 1.0, atol=1e-4)


def test_hand_made_dsk_written_with_spice_directly(tmp_path):
    # A DSK made by NAIF's own calls (not recon's writer), in a built-in body-fixed frame.
    import spiceypy as sp

    path = tmp_path / "tetra.bds"
    plates = TETRA_FACES + 1
    size = 10_000
    spaixd, spaixi = sp.dskmi2(TETRA_KM - 0.25, plates, 5.0, 4, size, size, size, False,
                               100_007 + 2 * size)
    corpar = np.zeros(10)
    r_min, r_max = sp.dskrb2(TETRA_KM - 0.25, plates, 1, corpar)
    handle = sp.dskopn(str(path), "tetra", 0)
    sp.dskw02(handle, 499, 7, 2, "IAU_MARS", 1, corpar, -np.pi, np.pi, -np.pi / 2, np.pi / 2,
              r_min, r_max, -1e9, 1e9, TETRA_KM - 0.25, plates, spaixd, spaixi)
    sp.dskcls(handle, True)
    mesh = read_mesh(path)
    np.testing.assert_allclose(mesh.vertices, (TETRA_KM - 0.25) * 1000.0)
    np.testing.assert_array_equal(mesh.faces, TETRA_FACES)
    assert mesh.frame == "body"


def test_recon_dsk_is_read_by_spice_itself(tmp_path):
    import spiceypy as sp

    from tests.conftest import icosphere

    vertices, faces = icosphere(250.0, 2)   # metres
    write_mesh(tmp_path / "ball.bds", vertices, faces)
    handle = sp.dasopr(str(tmp_path / "ball.bds"))
    try:
        dladsc = sp.dlabfs(handle)
        descriptor = sp.dskgd(handle, dladsc)
        assert (descriptor.center, descriptor.dtype) == (-998, 2)
        assert sp.dskz02(handle, dladsc) == (len(vertices), len(faces))
        np.testing.assert_allclose(sp.dskv02(handle, dladsc, 1, len(vertices)),
                                   vertices / 1000.0)
        # a ray from 1 km out along +x meets the 0.25 km sphere's facets near 0.25 km
        _plate, point, found = sp.dskx02(handle, dladsc, [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0])
        assert found and 0.24 < point[0] <= 0.25 + 1e-12
    finally:
        sp.dascls(handle)


# --------------------------------------------------------------------------- units


def test_units_are_explicit_and_dsk_is_km(tmp_path):
    write_mesh(tmp_path / "t.bds", TETRA_KM * 1000.0, TETRA_FACES)
    with pytest.raises(InputError, match=r"t\.bds: the file is in km, not m"):
        read_mesh(tmp_path / "t.bds", units="m")
    with pytest.raises(InputError, match="units must be km or m, got 'mi'"):
        read_mesh(tmp_path / "t.bds", units="mi")
    write_mesh(tmp_path / "m.tab", TETRA_KM * 1000.0, TETRA_FACES, units="m")
    np.testing.assert_allclose(read_mesh(tmp_path / "m.tab", units="m").vertices,
                               TETRA_KM * 1000.0)
    with pytest.raises(InputError, match=r"\.bds files are written in km, not m"):
        write_mesh(tmp_path / "x.bds", TETRA_KM, TETRA_FACES, units="m")


def test_a_ply_that_says_km_is_read_in_km(tmp_path):
    from formats.ply import write_ply

    write_ply(tmp_path / "km.ply", dict(zip("xyz", TETRA_KM.T, strict=True)),
              faces=TETRA_FACES, metadata={"units": "km"})
    np.testing.assert_allclose(read_mesh(tmp_path / "km.ply").vertices, TETRA_KM * 1000.0)
    with pytest.raises(InputError, match="the file is in km, not m"):
        read_mesh(tmp_path / "km.ply", units="m")


# --------------------------------------------------------------------------- bad files


BAD_TABLES = {
    "vertex count": ("5\n1 0 0 0\n2 1 0 0\n3 0 1 0\n1\n1 1 2 3\n", r"says 5 vertices"),
    "plate count": ("3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n2\n1 1 2 3\n",
                    r"says 3 vertices and 2 plates, which take 22 words; the file holds 18"),
    "plate index": ("3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n1\n1 1 2 9\n",
                    r"plate 1 names vertex 9, which the vertex table does not hold"),
    "repeated ids": ("3\n1 0 0 0\n1 1 0 0\n3 0 1 0\n1\n1 1 2 3\n", r"vertex ids repeat"),
    "not a number": ("3\n1 0 0 0\n2 1 zero 0\n3 0 1 0\n1\n1 1 2 3\n",
                     r"holds 'zero', not a number \(line 3\)"),
    "no count": ("one 0 0 0\n", r"expected the vertex \(or ICQ Q\) count"),
    "facet index": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
                    r"facet 1 names vertex 4; the file has vertices 1..3"),
    "facet zero": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", r"facet 1 names vertex 0"),
    "facet fraction": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 2.5\n", r"must be whole numbers"),
    "short row": ("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", r"do not make rows of four"),
    "other tag": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nq 1 2 3\n", r"rows must start with v or f"),
    "no facets": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 1\n", r"has no facets"),
    "empty": ("", r"is empty"),
    "icq edges": ("1\n" + "".join(f"{i} {i} {i}\n" for i in range(24)),
                  r"the ICQ faces do not meet at the cube's edges \(24 distinct vertices, a "
                  r"valid Q = 1 grid has 8\)"),
}


@pytest.mark.parametrize("case", sorted(BAD_TABLES))
def test_bad_tables_are_one_line_errors_naming_the_file(tmp_path, case):
    text, message = BAD_TABLES[case]
    path = tmp_path / "bad.tab"
    path.write_text(text)
    with pytest.raises(ReconError, match=message) as caught:
        read_mesh(path)
    assert str(caught.value).startswith(str(path)) and "\n" not in str(caught.value)


def test_a_file_that_is_not_a_dsk(tmp_path):
    path = tmp_path / "junk.bds"
    path.write_bytes(b"DAS/DSK " + bytes(range(256)) * 8)
    with pytest.raises(InputError, match=r"junk\.bds: not a readable DSK file") as caught:
        read_mesh(path)
    assert "\n" not in str(caught.value)


def test_cli_truth_writes_each_format(tmp_path, sphere_log):
    from cli.main import main
    from formats import StrikeLog

    with StrikeLog(sphere_log) as log:
        truth = log.truth_mesh()
    for name in ("t.bds", "t.tab", "t.ply"):
        assert main(["truth", str(sphere_log), "-o", str(tmp_path / name)]) == 0
        back = read_mesh(tmp_path / name)
        np.testing.assert_allclose(back.vertices, truth.vertices, rtol=1e-14, atol=1e-9)
    assert main(["truth", str(sphere_log), "-o", str(tmp_path / "t.obj")]) == 1


# --------------------------------------------------------------------------- scenes


def test_a_scene_simulated_on_its_own_dsk_reproduces_the_log(tmp_path):
    from cli.main import main
    from formats import StrikeLog
    from recon import api

    first = api.simulate("asteroid-cross", tmp_path / "a.h5", seed=3,
                         overrides=["time.duration=2000"]).path
    assert main(["truth", str(first), "-o", str(tmp_path / "shape.bds")]) == 0
    again = api.simulate("asteroid-cross", tmp_path / "b.h5", seed=3,
                         overrides=["time.duration=2000", "target.kind=mesh",
                                    f"target.path={tmp_path / 'shape.bds'}"]).path
    with StrikeLog(first) as a, StrikeLog(again) as b:
        assert b.attrs["target"] == "mesh:shape.bds"
        np.testing.assert_allclose(b.truth_mesh().vertices, a.truth_mesh().vertices,
                                   rtol=1e-14, atol=1e-9)
        for x, y in zip(a.strikes(), b.strikes(), strict=True):
            np.testing.assert_allclose(y, x, rtol=0, atol=1e-9)   # metres


@pytest.mark.parametrize("units", [None, "m"])
def test_a_scene_takes_an_icq_target_in_its_units(tmp_path, units):
    from formats import StrikeLog
    from recon import api

    q, axes = 4, np.array([0.3, 0.2, 0.15]) * (1000.0 if units == "m" else 1.0)
    path = tmp_path / "shape.icq"
    path.write_text(f"{q}\n" + "".join(f"{x:.9f} {y:.9f} {z:.9f}\n"
                                       for x, y, z in _icq_grid(q, axes).reshape(-1, 3)))
    keys = ["time.duration=600", "target.kind=mesh", f"target.path={path}"]
    log = api.simulate("asteroid-cross", tmp_path / "icq.h5", seed=0,
                       overrides=keys + ([f"target.units={units}"] if units else [])).path
    with StrikeLog(log) as reader:
        truth = reader.truth_mesh()
        assert reader.n_strikes > 0
    extent = truth.vertices.max(axis=0) - truth.vertices.min(axis=0)
    np.testing.assert_allclose(extent, [600.0, 400.0, 300.0], rtol=0.02)   # metres


def test_score_and_edges_take_the_truth_units(tmp_path, sphere_log, capsys):
    from cli.main import main
    from formats import StrikeLog

    with StrikeLog(sphere_log) as log:
        truth = log.truth_mesh()
    write_mesh(tmp_path / "truth_m.tab", truth, units="m")
    assert main(["score", str(sphere_log), "--no-edges", "--json"]) == 0   # its own truth
    expected = json.loads(capsys.readouterr().out)["accuracy_mean_m"]
    assert main(["score", str(sphere_log), "--truth", str(tmp_path / "truth_m.tab"),
                 "--truth-units", "m", "--no-edges", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["accuracy_mean_m"] == pytest.approx(expected)
    # read as km (the default for .tab), the truth is 1000 times too big: a stated warning
    assert main(["score", str(sphere_log), "--truth", str(tmp_path / "truth_m.tab"),
                 "--no-edges", "--json"]) == 0
    assert "probably km against m" in capsys.readouterr().err
    assert main(["edges", str(sphere_log), "--truth", str(tmp_path / "truth_m.tab"),
                 "--truth-units", "m", "-o", str(tmp_path / "edges"), "--json"]) == 0
