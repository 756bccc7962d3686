"""Hostile inputs and outputs through the real `recon` command: every case is refused with one
line on stderr and exit status 1, and no input is ever written over.

Each run is a real process (exit status, stderr, capabilities are process properties); the files
are tiny, so each case costs about an interpreter start.
"""

from __future__ import annotations

import os
import shlex
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]


def _command(args) -> list[str]:
    return [sys.executable, "-c", "from cli.main import main; import sys; sys.exit(main())",
            *map(str, args)]


def _run(*args, prefix: tuple[str, ...] = ()) -> tuple[int, str, str]:
    """``recon ARGS`` in a fresh process; ``prefix`` runs it through a shell wrapper (capsh)."""
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    command = [*prefix, "-c", shlex.join(_command(args))] if prefix else _command(args)
    proc = subprocess.run(command, capture_output=True, env=env, timeout=300)
    return proc.returncode, proc.stdout.decode(), proc.stderr.decode()


def _refused(args, *expected: str, prefix: tuple[str, ...] = ()) -> str:
    """Run ``recon ARGS``; require exit 1 and one line on stderr holding each ``expected``."""
    status, _, err = _run(*args, prefix=prefix)
    lines = err.strip().splitlines()
    assert status == 1, err
    assert len(lines) == 1, err
    assert lines[0].startswith(f"recon {args[0]}: error: "), err
    for text in expected:
        assert text in lines[0], err
    return lines[0]


@pytest.fixture
def cloud(sphere_log, tmp_path) -> Path:
    """An 80-point binary PLY cloud ingested from the sphere log."""
    from formats.cloud_io import write_cloud
    from recon.registration.ingest import ingest

    path = tmp_path / "cloud.ply"
    write_cloud(path, ingest(sphere_log))
    return path


# --------------------------------------------------------------------------- output = input


def _same_bytes_after(path: Path, run) -> None:
    before = path.read_bytes()
    run()
    assert path.read_bytes() == before
    assert not [p for p in path.parent.iterdir() if ".partial" in p.name]


@pytest.mark.parametrize("link", ["same", "symlink", "hardlink"])
def test_ingest_never_writes_over_its_log(link, sphere_log, tmp_path):
    out = {"same": sphere_log, "symlink": tmp_path / "link.h5",
           "hardlink": tmp_path / "hard.h5"}[link]
    if link == "symlink":
        out.symlink_to(sphere_log)
    elif link == "hardlink":
        os.link(sphere_log, out)
    _same_bytes_after(sphere_log, lambda: _refused(
        ["ingest", sphere_log, "-o", out], f"{out}: is an input of this run",
        "writing it would destroy the input"))


@pytest.mark.parametrize("command", ["reconstruct", "truth", "trajectory", "refine-json",
                                     "edges", "compare"])
def test_no_command_writes_over_its_input(command, cloud, sphere_log, tmp_path):
    victim = {"reconstruct": cloud, "truth": sphere_log, "trajectory": sphere_log,
              "refine-json": sphere_log, "edges": tmp_path / "e" / "edges.ply",
              "compare": cloud}[command]
    if command == "edges":   # the cloud sits where edges writes its edges.ply
        victim.parent.mkdir()
        shutil.copy(cloud, victim)
    args = {"reconstruct": ["reconstruct", cloud, "-o", cloud, "--in-process"],
            "truth": ["truth", sphere_log, "-o", sphere_log],
            "trajectory": ["trajectory", sphere_log, "-o", sphere_log],
            "refine-json": ["ingest", sphere_log, "-o", tmp_path / "c.ply", "--refine",
                            "--refine-json", sphere_log],
            "edges": ["edges", victim, "--truth", sphere_log, "-o", victim.parent],
            "compare": ["compare", cloud, "--truth", sphere_log, "-o", cloud]}[command]
    _same_bytes_after(victim, lambda: _refused(args, f"{victim}: is an input of this run"))


def test_simulate_never_writes_over_its_scene(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text('[target]\nkind = "ellipsoid"\n')
    _same_bytes_after(scene, lambda: _refused(["simulate", scene, "-o", scene],
                                              f"{scene}: is an input of this run"))


def test_simulate_output_must_be_hdf5(tmp_path):
    out = tmp_path / "o.ply"
    _refused(["simulate", "asteroid-lrf", "-o", out],
             f"{out}: a strike log is an HDF5 file; name it .h5 or .hdf5")
    assert not out.exists()


# --------------------------------------------------------------------------- lying PLY files


def _ascii_ply(path: Path, *, n_vertices: int, vertices, faces=(), n_faces=None,
               fmt="ascii 1.0", blank_line: bool = False) -> Path:
    lines = ["ply", f"format {fmt}", f"element vertex {n_vertices}", "property float x",
             "property float y", "property float z"]
    if len(faces) or n_faces is not None:
        lines += [f"element face {len(faces) if n_faces is None else n_faces}",
                  "property list uchar int vertex_indices"]
    lines += ["end_header", *(" ".join(map(str, v)) for v in vertices)]
    if blank_line:
        lines.insert(len(lines) - len(vertices) + 2, "")
    lines += [" ".join(map(str, [len(f), *f])) for f in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def _binary_mesh(path: Path, *, n_faces: int, faces) -> Path:
    head = ("ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n"
            "property float y\nproperty float z\nelement face " + str(n_faces) +
            "\nproperty list uchar int vertex_indices\nend_header\n").encode()
    body = np.random.default_rng(0).normal(size=(4, 3)).astype("<f4").tobytes()
    for f in faces:
        body += struct.pack("<B", len(f)) + np.asarray(f, "<i4").tobytes()
    path.write_bytes(head + body)
    return path


POINTS = np.random.default_rng(1).normal(0, 50, (100, 3)).round(3)
TETRA = POINTS[:4]


@pytest.mark.parametrize("case, expected", [
    ("middle-endian", "PLY format 'binary_middle_endian 1.0' is not one of ascii, "
                      "binary_little_endian, binary_big_endian"),
    ("version-2", "PLY version '2.0' is not supported"),
    ("400-of-100", "the PLY header declares 400 vertex elements (400 lines) but the body has "
                   "100 lines"),
    ("empty-line", "line 3 of the ASCII PLY body is empty"),
    ("extra-values", "line 1 of the ASCII PLY body holds 4 values where a vertex element has 3"),
])
def test_lying_ply_cloud_is_one_line(case, expected, tmp_path, sphere_log):
    path = tmp_path / f"{case}.ply"
    if case == "middle-endian":
        _ascii_ply(path, n_vertices=100, vertices=POINTS, fmt="binary_middle_endian 1.0")
    elif case == "version-2":
        _ascii_ply(path, n_vertices=100, vertices=POINTS, fmt="ascii 2.0")
    elif case == "400-of-100":
        _ascii_ply(path, n_vertices=400, vertices=POINTS)
    elif case == "extra-values":
        _ascii_ply(path, n_vertices=100, vertices=np.c_[POINTS, np.ones(100)])
    else:
        _ascii_ply(path, n_vertices=100, vertices=POINTS, blank_line=True)
    _refused(["score", path, "--truth", sphere_log, "--no-edges"], f"{path}: {expected}")


@pytest.mark.parametrize("case, expected", [
    ("ascii-1000", "declares 4 vertex and 1,000 face elements (1,004 lines) but the body has "
                   "6 lines"),
    ("ascii-1e12", "declares 4 vertex and 1,000,000,000,000 face elements"),
    ("binary-1000", "declares 4 vertex and 1,000 face elements (at least 13,048 bytes) but the "
                    "body holds 74 bytes"),
    ("binary-1e12", "declares 4 vertex and 1,000,000,000,000 face elements"),
    ("face-of-0", "face 1 has 0 vertex indices; a face needs at least 3"),
    ("face-of-2", "face 1 has 2 vertex indices; a face needs at least 3"),
    ("binary-face-of-2", "declares 4 vertex and 2 face elements (at least 74 bytes) but the "
                         "body holds 66 bytes"),
    ("missing-vertex", "faces index vertices that do not exist"),
])
def test_lying_truth_mesh_is_one_line(case, expected, tmp_path, cloud):
    path = tmp_path / f"{case}.ply"
    two = [[0, 1, 2], [1, 2, 3]]
    if case.startswith("ascii"):
        _ascii_ply(path, n_vertices=4, vertices=TETRA, faces=two,
                   n_faces=1000 if case == "ascii-1000" else 10**12)
    elif case in ("binary-1000", "binary-1e12"):
        _binary_mesh(path, n_faces=1000 if case == "binary-1000" else 10**12, faces=two)
    elif case == "binary-face-of-2":
        _binary_mesh(path, n_faces=2, faces=[[0, 1], [1, 2]])
    elif case == "missing-vertex":
        _binary_mesh(path, n_faces=2, faces=[[0, 1, 2], [1, 2, 9]])
    else:
        _ascii_ply(path, n_vertices=4, vertices=TETRA,
                   faces=[[0, 1, 2], [] if case == "face-of-0" else [1, 2], [1, 2, 3]])
    _refused(["score", cloud, "--truth", path, "--no-edges"], f"{path}: ", expected)


# --------------------------------------------------------------------------- PCD, LAS, text


def test_pcd_rows_shorter_than_the_fields_are_one_line(tmp_path, sphere_log):
    path = tmp_path / "short.pcd"
    header = ["VERSION 0.7", "FIELDS x y z intensity", "SIZE 4 4 4 4", "TYPE F F F F",
              "COUNT 1 1 1 1", "WIDTH 100", "HEIGHT 1", "VIEWPOINT 0 0 0 1 0 0 0",
              "POINTS 100", "DATA ascii"]
    path.write_text("\n".join(header + [" ".join(map(str, p)) for p in POINTS]) + "\n")
    _refused(["score", path, "--truth", sphere_log, "--no-edges"],
             f"{path}: the PCD header declares 100 points of 4 values but the body has 100 "
             "rows of 3")


def _las(path: Path, *, count: int | None = None, scale_x: float | None = None) -> Path:
    import laspy

    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales, header.offsets = np.full(3, 0.01), np.zeros(3)
    las = laspy.LasData(header)
    las.x, las.y, las.z = POINTS[:, 0], POINTS[:, 1], POINTS[:, 2]
    las.write(path)
    data = bytearray(path.read_bytes())
    if count is not None:   # LAS 1.4: number of point records, uint64 at byte 247
        data[247:255] = struct.pack("<Q", count)
    if scale_x is not None:   # x scale factor, float64 at byte 131
        data[131:139] = struct.pack("<d", scale_x)
    path.write_bytes(bytes(data))
    return path


@pytest.mark.parametrize("case, expected", [
    ("count-2^60", "the LAS header declares 1,152,921,504,606,846,976 points but the file holds "
                   "100"),
    ("scale-0", "LAS scale factors must be finite and non-zero, got 0, 0.01, 0.01"),
])
def test_lying_las_header_is_one_line(case, expected, tmp_path, sphere_log):
    path = _las(tmp_path / f"{case}.las", **({"count": 2**60} if case == "count-2^60"
                                             else {"scale_x": 0.0}))
    _refused(["score", path, "--truth", sphere_log, "--no-edges"], f"{path}: {expected}")


@pytest.mark.parametrize("suffix", [".xyz", ".txt", ".asc"])
def test_empty_text_cloud_is_one_line_without_numpy_warning(suffix, tmp_path, sphere_log):
    path = tmp_path / f"empty{suffix}"
    path.write_text("# x y z\n\n")
    _refused(["score", path, "--truth", sphere_log], f"{path}: holds no points")


# --------------------------------------------------------------------------- file system


def _without_file_permissions_bypass() -> tuple[str, ...]:
    """A shell wrapper under which file permissions hold: root without CAP_DAC_OVERRIDE and
    CAP_DAC_READ_SEARCH (capsh), none for other users; skips where neither works."""
    if os.geteuid() != 0:
        return ()
    if shutil.which("capsh") is None:
        pytest.skip("root without capsh: file permissions cannot be made to hold")
    return ("capsh", "--drop=cap_dac_override,cap_dac_read_search", "--")


def _refused_unprivileged(args, *expected: str) -> None:
    _refused(args, *expected, prefix=_without_file_permissions_bypass())


def test_unreadable_input_is_one_line(cloud, sphere_log):
    cloud.chmod(0)
    _refused_unprivileged(["score", cloud, "--truth", sphere_log],
                          f"{cloud}: cannot be read (Permission denied)")


def test_read_only_output_directory_is_one_line(cloud, sphere_log, tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    _refused_unprivileged(["ingest", sphere_log, "-o", locked / "c.ply"],
                          f"{locked / 'c.ply'}: cannot write in {locked} (Permission denied)")
    _refused_unprivileged(["compare", cloud, "--truth", sphere_log, "-o", locked / "sub"],
                          f"-o {locked / 'sub'}: cannot create the directory (Permission "
                          "denied)")


def test_kernel_file_as_input_is_one_line(tmp_path):
    _refused(["trajectory", "/proc/self/mem", "-o", tmp_path / "t.txt"],
             "/proc/self/mem: is a file of the kernel's /proc file system, not a data file")


def test_output_name_too_long_is_one_line(sphere_log, tmp_path):
    line = _refused(["ingest", sphere_log, "-o", tmp_path / ("a" * 5000 + ".ply")],
                    "cannot be written (File name too long)", "characters cut")
    assert len(line) < 600


def test_compare_output_file_that_is_a_directory_is_one_line(cloud, sphere_log, tmp_path):
    out = tmp_path / "out"
    (out / "results.csv").mkdir(parents=True)
    status, _, err = _run("compare", cloud, "--truth", sphere_log, "-o", out, "--methods",
                          "convex-hull", "--json")
    assert status == 1, err
    assert err.strip().splitlines()[-1] == (f"recon compare: error: {out / 'results.csv'}: is a "
                                            "directory; give the name of a file to write")
    assert "Traceback" not in err


# --------------------------------------------------------------------------- strike logs


def test_validate_checks_range_min(sphere_log, tmp_path):
    path = tmp_path / "below.h5"
    shutil.copy(sphere_log, path)
    with h5py.File(path, "r+") as f:
        ranges = f["strikes/range"][()]
        f["sensor"].attrs["range_min"] = ranges.min()
        ranges[3] = np.nextafter(ranges.min(), 0.0)   # one ulp below
        f["strikes/range"][...] = ranges
        if "truth" in f:
            del f["truth"]
    _refused(["validate", path], f"{path}: strike 3 has range", "below the sensor's range_min")


def test_log_whose_time_does_not_increase_is_refused_without_strikes(sphere_log, tmp_path):
    """10**9 shots declared (unwritten chunks: a small file) with times all 0 and no strikes:
    refused at the first block, not ingested into an empty cloud."""
    path = tmp_path / "stuck.h5"
    shutil.copy(sphere_log, path)
    with h5py.File(path, "r+") as f:
        for ds in f["shots"].values():
            ds.resize(10**9, axis=0)
        f["shots/time"][:40] = 0.0
        for ds in f["strikes"].values():
            ds.resize(0, axis=0)
        del f["truth"]
        f.attrs["n_shots"], f.attrs["n_strikes"] = np.int64(10**9), np.int64(0)
    assert path.stat().st_size < 1 << 20
    out = tmp_path / "c.ply"
    _refused(["ingest", path, "-o", out], f"{path}: time does not increase at shot 1")
    assert not out.exists()
    _refused(["validate", path], f"{path}: ")


# --------------------------------------------------------------------------- bounds


def test_poisson_depth_beyond_its_range_is_one_line_in_process(cloud, tmp_path):
    _refused(["reconstruct", cloud, "-o", tmp_path / "m.ply", "-m", "poisson", "--param",
              "depth=100", "--in-process"],
             "method 'poisson': parameter depth must be from 1 to 14, got 100")


def test_scene_value_that_overflows_is_one_line(tmp_path):
    _refused(["simulate", "asteroid-lrf", "-o", tmp_path / "o.h5", "--set",
              "orbit.radius=1e300"],
             "orbit.radius must lie within 1e-15 to 1e+15 m in magnitude, got 1e+300")


@pytest.mark.parametrize("value", [",", ""])
def test_methods_without_names_is_a_usage_error(value, cloud, sphere_log, tmp_path):
    status, _, err = _run("compare", cloud, "--truth", sphere_log, "-o", tmp_path / "o",
                          "--methods", value)
    assert status == 1
    assert err.strip().splitlines()[-1] == (f"recon compare: error: --methods needs at least one "
                                            f"name or value, got {value!r}")
    assert "Traceback" not in err and not (tmp_path / "o").exists()


@pytest.mark.parametrize("command, args, expected", [
    ("stability", ["--samples", "100000000000"],
     "--samples must be at most 14,316,557, got 100,000,000,000: scoring them would need "
     "about"),
    ("compare", ["--samples", "1000000000"], "--samples must be at most 14,316,557, got "
                                             "1,000,000,000"),
    ("stability", ["--outliers", "1000000"], "--outliers level 1e+06 is out of range (must be "
                                             "[0, 1])"),
    ("stability", ["--outliers", "1.5"], "--outliers level 1.5 is out of range"),
    ("stability", ["--noise", ",".join(f"{i / 1000:g}" for i in range(1000)),
                   "--density", ",".join(f"{i / 1000:g}" for i in range(1, 1001))],
     "noise, density and outliers make 2,000,000 cells; with 1 method(s) that is 2,000,000 "
     "runs, at least"),
])
def test_sweeps_refuse_absurd_sizes_before_any_work(command, args, expected, cloud, sphere_log,
                                                    tmp_path):
    """Refused up front, not run to a result that blames the method (a memory failure in
    every cell) or to a sweep of weeks."""
    out = tmp_path / "o"
    _refused([command, cloud, "--truth", sphere_log, "-o", out, "--methods", "convex-hull",
              *args], expected)
    assert not out.exists()


def test_tiny_voxel_is_one_line_without_numpy_warning(cloud, tmp_path):
    _refused(["reconstruct", cloud, "-o", tmp_path / "m.ply", "--voxel", "1e-300",
              "--in-process"], "voxel 1e-300 m is too small for the cloud")


def test_title_is_drawn_literally(cloud, sphere_log, tmp_path):
    out = tmp_path / "edges"
    status, _, err = _run("edges", cloud, "--truth", sphere_log, "-o", out, "--title",
                          r"$\frac{a}{$")
    assert status == 0, err
    assert "Traceback" not in err and (out / "edges.png").stat().st_size > 0


# --------------------------------------------------------------------------- declared sizes


def _declare(path: Path, *keys: str, rows: int) -> Path:
    """Replace the datasets ``keys`` of ``path`` by ones of ``rows`` rows, none written (a
    declared shape costs nothing on disk)."""
    with h5py.File(path, "r+") as f:
        for key in keys:
            tail, dtype = f[key].shape[1:], f[key].dtype
            del f[key]
            f.create_dataset(key, shape=(rows, *tail), dtype=dtype, chunks=(1024, *tail))
    return path


@pytest.mark.parametrize("command", [["validate"], ["info"], ["trajectory", "-o", "t.txt"],
                                     ["ingest", "-o", "c.ply"]])
def test_huge_beam_directions_are_one_line(command, sphere_log, tmp_path):
    _declare(sphere_log, "sensor/beam_directions", rows=2**34)
    args = [command[0], sphere_log, *(tmp_path / a if "." in a else a for a in command[1:])]
    _refused(args, f"{sphere_log}: /sensor/beam_directions declares shape (17179869184, 3)",
             "of memory but only")


@pytest.mark.parametrize("command", ["truth", "score"])
def test_huge_truth_mesh_is_one_line(command, cloud, sphere_log, tmp_path):
    _declare(sphere_log, "truth/mesh/vertices", "truth/mesh/faces", rows=2**36)
    args = {"truth": ["truth", sphere_log, "-o", tmp_path / "m.ply"],
            "score": ["score", cloud, "--truth", sphere_log]}[command]
    _refused(args, f"{sphere_log}: /truth/mesh/vertices declares shape (68719476736, 3)")


def test_huge_hdf5_cloud_is_one_line(sphere_log, tmp_path):
    from formats.cloud_io import write_cloud
    from recon.registration.ingest import ingest

    cloud = tmp_path / "c.h5"
    write_cloud(cloud, ingest(sphere_log))
    _declare(cloud, "points", rows=2**36)
    _refused(["reconstruct", cloud, "-m", "convex-hull", "-o", tmp_path / "m.ply"],
             f"{cloud}: /points declares shape (68719476736, 3)")
    assert not (tmp_path / "m.ply").exists()


@pytest.mark.parametrize("command", ["reconstruct", "edges"])
def test_log_too_large_to_register_in_memory_is_refused_up_front(command, tmp_path):
    """A log can declare more strikes than any memory holds (a compressed one of a few MB held
    1e8): commands that register it whole refuse before reading a strike; `recon ingest`
    streams."""
    from tests.conftest import write_sphere_log

    log = tmp_path / "big.h5"
    write_sphere_log(log)
    rows = 2**40
    _declare(log, "strikes/shot", "strikes/beam", "strikes/range", "truth/point",
             "truth/facet", "truth/range", rows=rows)
    with h5py.File(log, "r+") as f:
        f.attrs["n_strikes"] = rows
    args = {"reconstruct": ["reconstruct", log, "-m", "convex-hull", "-o", tmp_path / "m.ply"],
            "edges": ["edges", log, "-o", tmp_path / "e"]}[command]
    _refused(args, f"{log}: registering its {rows:,} strikes in memory needs about",
             "register it to a cloud file instead (recon ingest), which streams")
    assert not (tmp_path / "m.ply").exists()
