"""The hostile kinds of fuzz case: outputs that are inputs, report directories that escape or are
damaged, headers that lie, files that cannot be read, addresses that are not Dask schedulers,
and values past every bound.

Each ``make_KIND(rng, inputs, directory)`` returns a ``Case`` (tests/fuzz/fuzzing.py) that
must fail in one line (or, for a valid variant, succeed) without changing its inputs
(``Case.protect``) or reading outside its directory (``inputs["secrets"]``).
"""

from __future__ import annotations

import json
import os
import random
import shutil
import struct
from pathlib import Path

from tests.fuzz.fuzzing import Case

# What the files of ``secrets/`` hold: a report page or an error line that shows it has read
# outside its directory.
SECRET = "recon-fuzz-secret-7f3a"
NEW_KINDS = ("same_io", "report", "lying", "unreadable", "scheduler", "bounds")


def make_secrets(directory: Path) -> Path:
    """Files outside every case directory that no case may read."""
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "secret.csv").write_text(f"a,b\n{SECRET},1\n")
    (directory / "secret.png").write_bytes(_png())
    (directory / "secret.json").write_text(json.dumps({"study": SECRET, "files": []}))
    study = directory / "study"
    study.mkdir(exist_ok=True)
    (study / "summary.json").write_text(json.dumps({"study": SECRET, "title": SECRET}))
    return directory


def _png() -> bytes:
    """A valid 1 x 1 PNG."""
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 1, 1, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\x00\x80")) + chunk(b"IEND", b""))


def _copy(src: Path, dst: Path) -> Path:
    shutil.copyfile(src, dst)
    return dst


# --------------------------------------------------------------------------- output = input


def make_same_io(rng: random.Random, inputs: dict, directory: Path) -> Case:
    """A command whose output is its own input: the same name, a symbolic link to it, or a hard
    link to it. The input must survive unchanged, and the run must be refused."""
    command = rng.choice(["ingest", "reconstruct", "simulate", "truth", "trajectory"])
    how = rng.choice(["same", "symlink", "hardlink"])
    source = {"ingest": "log", "reconstruct": "cloud_ply", "simulate": "scene",
              "truth": "log", "trajectory": "log"}[command]
    data = _copy(inputs[source], directory / f"in{inputs[source].suffix}")
    suffix = {"ingest": ".ply", "reconstruct": ".ply", "simulate": ".h5", "truth": ".ply",
              "trajectory": ".txt"}[command]
    if how == "same":
        out = data
    else:
        out = directory / f"out{suffix}"
        (os.symlink if how == "symlink" else os.link)(data, out)
    args = {"ingest": ["ingest", data, "-o", out],
            "reconstruct": ["reconstruct", data, "-o", out, "-m", "convex-hull", "--in-process"],
            "simulate": ["simulate", data, "-o", out],
            "truth": ["truth", data, "-o", out],
            "trajectory": ["trajectory", data, "-o", out]}[command]
    return Case(f"same_io:{command}:{how}", [str(a) for a in args], True,
                (data.name, out.name), protect=[data])


# --------------------------------------------------------------------------- report directories


_REPORT_ESCAPES = ("dotdot", "absolute", "symlink_csv", "symlink_png", "linked_study",
                   "linked_summary", "unlisted_png_link")
_REPORT_DAMAGE = ("summary_list", "summary_not_json", "summary_not_utf8", "files_string",
                  "files_numbers", "claims_dict", "claims_strings", "binary_csv", "huge_field",
                  "csv_not_utf8", "png_not_png", "results_list", "pareto_string",
                  "index_studies_list", "deep_json")


def _study_dir(directory: Path, **summary) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    base = {"study": "errors", "title": "Errors", "size": "quick", "claims": [],
            "files": ["table.csv", "chart.png"], "n_cases": 1, "n_failed": 0}
    (directory / "summary.json").write_text(json.dumps(base | summary))
    (directory / "table.csv").write_text("case,value\na,1\n")
    (directory / "chart.png").write_bytes(_png())
    return directory


def make_report(rng: random.Random, inputs: dict, directory: Path) -> Case:
    """``recon report DIR``: DIR lists or links files outside it, or holds damaged files; one
    in eight is a valid directory that must give a page."""
    secrets = inputs["secrets"]
    out = directory / "page.html"
    if rng.random() < 0.125:
        study = _study_dir(directory / "study")
        return Case("report:valid", ["report", str(study), "-o", str(out)], False, (), out,
                    protect=[study / "summary.json"])
    if rng.random() < 0.5:
        how = rng.choice(_REPORT_ESCAPES)
        study = _study_dir(directory / "study")
        names: tuple[str, ...] = ("summary.json", "outside")
        if how == "dotdot":
            rel = os.path.relpath(secrets / "secret.csv", study)
            _study_dir(study, files=["table.csv", rel])
        elif how == "absolute":
            _study_dir(study, files=["table.csv", str(secrets / rng.choice(["secret.csv",
                                                                           "secret.png"]))])
        elif how in ("symlink_csv", "symlink_png"):
            ext = how[-3:]
            os.symlink(secrets / f"secret.{ext}", study / f"linked.{ext}")
            _study_dir(study, files=["table.csv", f"linked.{ext}"])
            names = (f"linked.{ext}",)
        elif how == "unlisted_png_link":
            os.symlink(secrets / "secret.png", study / "linked.png")
            names = ("linked.png",)
        elif how == "linked_summary":
            (study / "summary.json").unlink()
            os.symlink(secrets / "secret.json", study / "summary.json")
            names = ("summary.json",)
        else:   # a study directory of an "all" directory that is a link leaving it
            top = directory / "all"
            top.mkdir()
            study.rename(top / "errors")
            os.symlink(secrets / "study", top / "slew")
            study, names = top, ("slew",)
        return Case(f"report:escape:{how}", ["report", str(study), "-o", str(out)], True,
                    names, out)
    how = rng.choice(_REPORT_DAMAGE)
    study = _study_dir(directory / "study")
    target, data = {
        "summary_list": ("summary.json", b"[1, 2]"),
        "summary_not_json": ("summary.json", b"{oops"),
        "summary_not_utf8": ("summary.json", b'{"title": "\xff\xfe"}'),
        "files_string": ("summary.json", json.dumps({"files": "table.csv"}).encode()),
        "files_numbers": ("summary.json", json.dumps({"files": [1, 2]}).encode()),
        "claims_dict": ("summary.json", json.dumps({"claims": {"a": 1}}).encode()),
        "claims_strings": ("summary.json", json.dumps({"claims": ["x"]}).encode()),
        "binary_csv": ("table.csv", bytes(rng.randrange(256) for _ in range(2000))),
        "huge_field": ("table.csv", b'a,b\n"' + b"x" * 200_000 + b'",1\n'),
        "csv_not_utf8": ("table.csv", b"a,b\n\xff\xfe,1\n"),
        "png_not_png": ("chart.png", b"GIF89a" + bytes(64)),
        "results_list": ("results.json", b"[]"),
        "pareto_string": ("results.json", json.dumps({"pareto_chamfer": "x"}).encode()),
        "index_studies_list": ("index.json", json.dumps({"studies": [1]}).encode()),
        "deep_json": ("summary.json", b"[" * 100_000 + b"]" * 100_000),
    }[how]
    if target in ("results.json",):   # a comparison directory
        study = directory / "cmp"
        study.mkdir()
    elif target == "index.json":      # an "all" directory
        top = directory / "all"
        top.mkdir()
        study.rename(top / "errors")
        study = top
    (study / target).write_bytes(data)
    return Case(f"report:damage:{how}", ["report", str(study), "-o", str(out)], True,
                (target,), out)


# --------------------------------------------------------------------------- lying headers


def _ply_header_and_body(path: Path) -> tuple[list[bytes], bytes]:
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    return data[:end].split(b"\n")[:-1], data[end:]


def _ascii_ply(vertices, faces=None, *, n_vertices=None, n_faces=None, blank=False,
               face_lines=None) -> bytes:
    head = ["ply", "format ascii 1.0", f"element vertex {n_vertices or len(vertices)}",
            "property float x", "property float y", "property float z"]
    if faces is not None or face_lines is not None:
        count = n_faces if n_faces is not None else len(face_lines or faces)
        head += [f"element face {count}", "property list uchar int vertex_indices"]
    lines = [" ".join(f"{c:.6f}" for c in v) for v in vertices]
    if blank:
        lines.insert(len(lines) // 2, "")
    lines += face_lines if face_lines is not None else [
        "3 " + " ".join(str(int(i)) for i in f) for f in (faces if faces is not None else [])]
    return ("\n".join([*head, "end_header", *lines]) + "\n").encode()


def make_lying(rng: random.Random, inputs: dict, directory: Path) -> Case:
    """A PLY, LAS or PCD file whose header disagrees with its body."""
    from formats.cloud_io import read_cloud
    from formats.mesh_io import read_mesh

    points = read_cloud(inputs["cloud_ply"]).points[:100]
    truth = read_mesh(inputs["truth_ply"])
    how = rng.choice(["ply_more_vertices", "ply_fewer_vertices", "ply_middle_endian",
                      "ply_version_2", "ascii_more_vertices", "ascii_blank_line",
                      "mesh_more_faces", "mesh_huge_faces", "mesh_two_vertex_face",
                      "mesh_zero_vertex_face", "las_count", "las_scale", "pcd_points",
                      "pcd_short_rows"])
    out = directory / "out.ply"
    is_mesh = how.startswith("mesh")
    if how.startswith("ply"):
        header, body = _ply_header_and_body(inputs["cloud_ply"])
        for i, line in enumerate(header):
            if line.startswith(b"element vertex"):
                n = int(line.split()[-1])
                if how == "ply_more_vertices":
                    header[i] = b"element vertex %d" % (n + rng.choice([1, 300, 10**12]))
                elif how == "ply_fewer_vertices":
                    header[i] = b"element vertex %d" % max(1, n - rng.choice([1, 50]))
            if line.startswith(b"format") and how == "ply_middle_endian":
                header[i] = b"format binary_middle_endian 1.0"
            if line.startswith(b"format") and how == "ply_version_2":
                header[i] = line.replace(b"1.0", b"2.0")
        bad = directory / "bad.ply"
        bad.write_bytes(b"\n".join(header) + b"\n" + body)
    elif how.startswith("ascii"):
        bad = directory / "bad.ply"
        bad.write_bytes(_ascii_ply(points, n_vertices=400 if how == "ascii_more_vertices"
                                   else None, blank=how == "ascii_blank_line"))
    elif is_mesh:
        bad = directory / "bad.ply"
        vertices, faces = truth.vertices, truth.faces[:2]
        if how == "mesh_more_faces":
            data = _ascii_ply(vertices, faces, n_faces=rng.choice([1000, 10**12]))
        elif how == "mesh_huge_faces":
            data = _ascii_ply(vertices, faces, n_faces=10**12)
        elif how == "mesh_two_vertex_face":
            data = _ascii_ply(vertices, face_lines=["3 0 1 2", "2 0 1"])
        else:
            data = _ascii_ply(vertices, face_lines=["3 0 1 2", "0"])
        bad.write_bytes(data)
    elif how.startswith("las"):
        bad = directory / "bad.las"
        data = bytearray(inputs["cloud_las"].read_bytes())
        if how == "las_count":
            data[247:255] = struct.pack("<Q", 2**60)
            data[107:111] = struct.pack("<I", 0)
        else:
            axis = rng.randrange(3)
            data[131 + 8 * axis:139 + 8 * axis] = struct.pack("<d", 0.0)
        bad.write_bytes(bytes(data))
    else:
        bad = directory / "bad.pcd"
        rows = [" ".join(f"{c:.6f}" for c in p) for p in points[:50]]
        declared = 1000 if how == "pcd_points" else 50
        fields = "x y z" if how == "pcd_points" else "x y z intensity"
        if how == "pcd_short_rows":
            rows = [" ".join(r.split()[:2]) for r in rows]
        n_fields = len(fields.split())
        bad.write_text("\n".join([
            "# .PCD v0.7", "VERSION 0.7", f"FIELDS {fields}", "SIZE " + " ".join(["4"] * n_fields),
            "TYPE " + " ".join(["F"] * n_fields), "COUNT " + " ".join(["1"] * n_fields),
            f"WIDTH {declared}", "HEIGHT 1", "VIEWPOINT 0 0 0 1 0 0 0", f"POINTS {declared}",
            "DATA ascii", *rows]) + "\n")
    if is_mesh:
        args = ["score", inputs["cloud_ply"], "--truth", bad, "--no-edges"]
        out = None
    else:
        args = rng.choice([["score", bad, "--truth", inputs["truth_ply"], "--no-edges"],
                           ["reconstruct", bad, "-o", out, "-m", "convex-hull",
                            "--in-process"]])
        out = out if "reconstruct" in args else None
    # Blank lines between ASCII rows are whitespace to some readers: the count still matches,
    # so reading it or refusing it in one line are both right.
    return Case(f"lying:{how}", [str(a) for a in args], how != "ascii_blank_line", (bad.name,),
                out, protect=[bad])


# --------------------------------------------------------------------------- unreadable files


def make_unreadable(rng: random.Random, inputs: dict, directory: Path) -> Case:
    """Inputs that cannot be read (mode 000, run as an unprivileged user), an output directory
    that cannot be written, and /proc entries given as inputs."""
    how = rng.choice(["mode000", "mode000", "read_only_output", "proc"])
    if how == "mode000":
        source = rng.choice(["log", "cloud_ply", "truth_ply", "cloud_las", "scene"])
        bad = _copy(inputs[source], directory / f"locked{inputs[source].suffix}")
        os.chmod(bad, 0)
        out = directory / "out.ply"
        args = {"log": rng.choice([["validate", bad], ["info", bad], ["ingest", bad, "-o", out],
                                   ["score", bad, "--no-edges"]]),
                "cloud_ply": ["reconstruct", bad, "-o", out, "-m", "convex-hull",
                              "--in-process"],
                "truth_ply": ["score", inputs["cloud_ply"], "--truth", bad, "--no-edges"],
                "cloud_las": ["score", bad, "--truth", inputs["truth_ply"], "--no-edges"],
                "scene": ["simulate", bad, "-o", directory / "run.h5"]}[source]
        return Case(f"unreadable:mode000:{source}", [str(a) for a in args], True, (bad.name,),
                    out if "-o" in args else None, user="nobody")
    if how == "read_only_output":
        locked = directory / "locked"
        locked.mkdir()
        os.chmod(locked, 0o555)
        command = rng.choice(["ingest", "simulate", "compare", "report"])
        out = locked / ("out" if command in ("compare",) else
                        {"ingest": "out.ply", "simulate": "run.h5", "report": "page.html"}
                        [command])
        args = {"ingest": ["ingest", inputs["log"], "-o", out],
                "simulate": ["simulate", inputs["scene"], "-o", out],
                "compare": ["compare", inputs["cloud_ply"], "--truth", inputs["truth_ply"],
                            "-o", out / "sub", "--methods", "convex-hull"],
                "report": ["report", inputs["study"], "-o", out]}[command]
        return Case(f"unreadable:read_only_output:{command}", [str(a) for a in args], True,
                    ("locked", out.name), user="nobody")
    entry = rng.choice(["/proc/self/mem", "/proc/self/status", "/proc/self/maps",
                        "/proc/self/environ"])
    command = rng.choice(["validate", "trajectory", "score", "reconstruct", "simulate"])
    args = {"validate": ["validate", entry],
            "trajectory": ["trajectory", entry, "-o", directory / "t.txt"],
            "score": ["score", entry, "--truth", inputs["truth_ply"], "--no-edges"],
            "reconstruct": ["reconstruct", entry, "-o", directory / "out.ply", "--in-process"],
            "simulate": ["simulate", entry, "-o", directory / "run.h5"]}[command]
    return Case(f"unreadable:proc:{command}", [str(a) for a in args], True,
                (entry, Path(entry).name))


# --------------------------------------------------------------------------- schedulers


def make_scheduler(rng: random.Random, inputs: dict, directory: Path) -> Case:
    """``--scheduler`` at a loopback address that is not a Dask scheduler (the runner's
    servers: plain HTTP, garbage, a closed port)."""
    server = rng.choice(["http", "garbage", "closed"])
    address = inputs["servers"][server]
    if rng.random() < 0.3:   # written without the protocol
        address = address.removeprefix("tcp://")
    command = rng.choice(["study", "compare", "stability"])
    out = directory / "out"
    args = {"study": ["study", "duration", "-o", out, "--quick"],
            "compare": ["compare", inputs["cloud_ply"], "--truth", inputs["truth_ply"], "-o",
                        out, "--methods", "convex-hull"],
            "stability": ["stability", inputs["cloud_ply"], "--truth", inputs["truth_ply"],
                          "-o", out, "--methods", "convex-hull"]}[command]
    return Case(f"scheduler:{server}:{command}", [str(a) for a in args]
                + ["--scheduler", address], True, ("--scheduler",))


# --------------------------------------------------------------------------- bounds


_BOUNDS = [
    ("reconstruct", ["-m", "poisson", "--param", "depth=100", "--in-process"], "depth"),
    ("reconstruct", ["-m", "poisson", "--param", "depth=0", "--in-process"], "depth"),
    ("reconstruct", ["-m", "poisson", "--param", "depth=1e9"], "depth"),
    ("reconstruct", ["-m", "ball-pivoting", "--param", "radii=-1", "--in-process"], "radii"),
    ("reconstruct", ["-m", "ball-pivoting", "--param", "radii=0", "--in-process"], "radii"),
    ("reconstruct", ["-m", "convex-hull", "--voxel", "1e-300", "--in-process"], "--voxel"),
    ("scene", ["--set", "orbit.radius=1e300"], "orbit.radius"),
    ("scene", ["--set", "target.radius=1e300"], "target"),
    ("scene", ["--set", "time.duration=1e300"], "time.duration"),
    ("scene", ["--set", "orbit.radius=1e300", "--set", "time.step=1e-300"], "orbit"),
    ("compare", ["--methods", ","], "--methods"),
    ("compare", ["--methods", ""], "--methods"),
    ("edges", ["--title", "$\\frac{a}{$"], "--title"),
]


def make_bounds(rng: random.Random, inputs: dict, directory: Path) -> Case:
    """Values past a declared bound: method parameters, scene values that overflow, empty
    method lists, a voxel of 1e-300 m; and free text with mathtext in it (which must be drawn
    literally: a valid case)."""
    command, extra, name = rng.choice(_BOUNDS)
    out = directory / "out.ply"
    base = {"reconstruct": ["reconstruct", inputs["cloud_ply"], "-o", out],
            "scene": ["simulate", inputs["scene"], "-o", directory / "run.h5"],
            "compare": ["compare", inputs["cloud_ply"], "--truth", inputs["truth_ply"], "-o",
                        directory / "cmp"],
            "edges": ["edges", inputs["cloud_ply"], "--truth", inputs["truth_ply"], "-o",
                      directory / "edges"]}[command]
    # A title is text, drawn as written; a voxel of 1e-300 m may be refused or run (as no
    # voxel), but quietly either way.
    must_fail = command != "edges" and "--voxel" not in extra
    return Case(f"bounds:{command}:{' '.join(extra)[:40]}", [str(a) for a in base + extra],
                must_fail, (name, name.lstrip("-"), name.split(".")[0]),
                out if command == "reconstruct" else None)


MAKERS = {"same_io": make_same_io, "report": make_report, "lying": make_lying,
          "unreadable": make_unreadable, "scheduler": make_scheduler, "bounds": make_bounds}
