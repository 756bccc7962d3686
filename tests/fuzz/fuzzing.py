"""Seeded fuzz cases for the `recon` command: damaged logs, PLY/OBJ/LAS files, scenes and
argument values, and the hostile kinds of tests/fuzz/hostile.py (outputs that are inputs, report
directories, lying headers, unreadable files, scheduler addresses, bounds), each with what must
happen.

``make_inputs(dir)`` writes the valid inputs every case starts from; ``make_case(seed, inputs,
dir)`` damages one of them (or picks a hostile value) and returns a ``Case``: the command line
and whether it must fail. ``judge`` sorts a finished run into one of ``OUTCOMES``:

- ``clean``: exit 1, stderr one line ``recon CMD: error: ...`` (after argparse's usage lines)
  naming the damaged file or the key, and no output or partial file left;
- ``ok``: exit 0 on input that may be valid (a flipped bit in unused bytes, a valid value);
- ``traceback``: a traceback or an exit status other than 0 and 1;
- ``crash``: killed by a signal (the kernel's OOM killer, SIGSEGV, SIGABRT);
- ``messy``: exit 1 but not one clear line naming the file or key, or an output left behind;
- ``wrong``: exit 0 on input that must fail;
- ``hang``: no exit within the time limit (the runner's business);
- ``data loss``: a file the case protects (its input) changed or went;
- ``escape``: the run opened a file under the ``secrets`` directory (seen by strace,
  tests/fuzz/runner.py), or printed or wrote what one holds.

``tests/fuzz/test_fuzz.py`` runs a few tens of cases in CI (the first kinds in-process, every
hostile kind through a real process); ``benchmarks/fuzz.py`` runs a thousand or more through
real processes and prints the counts.
"""

from __future__ import annotations

import hashlib
import os
import random
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

OUTCOMES = ("clean", "ok", "traceback", "crash", "messy", "wrong", "hang", "data loss",
            "escape")
# The kinds of case, each as likely as its count here: the first ones damage files and values,
# the hostile ones (tests/fuzz/hostile.py) attack outputs, reports, headers, permissions,
# schedulers and bounds.
FIRST_KINDS = ("flip_log", "flip_log", "mutate_log", "mutate_log", "file", "file", "scene",
               "scene", "args", "path")
HOSTILE_KINDS = ("same_io", "same_io", "report", "report", "lying", "lying", "unreadable",
                 "unreadable", "scheduler", "bounds", "bounds")


def digest(path: Path) -> str | None:
    """SHA-256 of a file's bytes (None when it is missing or not a file)."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None


@dataclass
class Case:
    """One fuzz case: ``recon ARGS`` and what must happen.

    Attributes
    ----------
    name : str
        What was damaged, for the report.
    args : list of str
    must_fail : bool
        Exit 0 is a wrong success.
    names : tuple of str
        One of these (a file name or a key) must appear in the error line.
    output : Path or None
        Must not exist after a failure (nor any ``.partial`` file beside it).
    protect : list of Path
        Inputs that must be the same bytes after the run (their digests are taken now).
    user : str or None
        Run as this user (``nobody``: file modes apply, as they do not to root).
    """

    name: str
    args: list[str]
    must_fail: bool
    names: tuple[str, ...]
    output: Path | None = None
    files: list[Path] = field(default_factory=list)
    protect: list[Path] = field(default_factory=list)
    user: str | None = None
    digests: dict = field(default_factory=dict)

    def __post_init__(self):
        self.digests = {path: digest(path) for path in self.protect}

    @property
    def kind(self) -> str:
        return self.name.split(":")[0]

    @property
    def hostile(self) -> bool:
        """A kind of tests/fuzz/hostile.py (run through a real process in CI)."""
        return self.kind in HOSTILE_KINDS


def make_inputs(directory: Path) -> dict[str, Path]:
    """The valid inputs: a log with truth, its truth mesh (PLY, OBJ), its cloud (PLY, LAS) and
    a scene file; small, so that every command on them takes seconds."""
    import sim
    from formats.cloud_io import write_cloud
    from formats.mesh_io import write_mesh
    from recon.registration.ingest import ingest

    directory.mkdir(parents=True, exist_ok=True)
    log = directory / "log.h5"
    sim.simulate(sim.load_scene("asteroid-cross", ["time.duration=3000",
                                                   "target.subdivisions=3"]), log, seed=0)
    from formats import StrikeLog

    with StrikeLog(log) as f:
        truth = f.truth_mesh()
    write_mesh(directory / "truth.ply", truth)
    import trimesh

    trimesh.Trimesh(truth.vertices, truth.faces, process=False).export(directory / "truth.obj")
    cloud = ingest(log)
    write_cloud(directory / "cloud.ply", cloud)
    write_cloud(directory / "cloud.las", cloud)
    (directory / "scene.toml").write_text('[sensor]\npattern = "cross"\n[time]\nduration = 600\n')
    from tests.fuzz.hostile import _study_dir, make_secrets

    return {"log": log, "truth_ply": directory / "truth.ply", "truth_obj": directory / "truth.obj",
            "cloud_ply": directory / "cloud.ply", "cloud_las": directory / "cloud.las",
            "scene": directory / "scene.toml", "study": _study_dir(directory / "study"),
            "secrets": make_secrets(directory.parent / "secrets")}


# --------------------------------------------------------------------------- damage


def _flip(data: bytearray, rng: random.Random, *, region: int | None = None) -> None:
    """Flip 1 to 8 bits, mostly in the first ``region`` bytes (headers, HDF5 metadata)."""
    for _ in range(rng.randint(1, 8)):
        top = min(len(data), region) if region and rng.random() < 0.8 else len(data)
        i = rng.randrange(top)
        data[i] ^= 1 << rng.randrange(8)


def _damaged_copy(src: Path, dst: Path, rng: random.Random) -> tuple[str, bool]:
    """Copy ``src`` to ``dst`` damaged; (what was done, whether it must fail)."""
    data = bytearray(src.read_bytes())
    how = rng.choice(["truncate", "flip", "flip", "garbage", "empty"])
    if how == "truncate":
        data = data[: rng.randrange(1, len(data) - 1)]
    elif how == "flip":
        _flip(data, rng, region=16384)
    elif how == "garbage":
        start = rng.randrange(len(data))
        data[start:start + 64] = bytes(rng.randrange(256) for _ in range(64))
    else:
        data = bytearray()
    dst.write_bytes(bytes(data))
    # A flip or garbage may hit bytes nothing reads; a truncated or empty file must fail.
    return how, how in ("truncate", "empty")


def _mutated_log(src: Path, dst: Path, rng: random.Random) -> tuple[str, bool]:
    """Copy a log and break one rule of SPEC.md with h5py; every mutation must fail."""
    import h5py

    shutil.copyfile(src, dst)
    secret = dst.with_suffix(".secret")
    secret.write_bytes(np.arange(300, dtype=np.float64).tobytes())
    choice = rng.choice(["nan", "range_max", "duplicate", "order", "quaternion", "external",
                         "link", "truth_point", "truth_mesh", "n_strikes", "attr_type",
                         "beam", "drop"])
    with h5py.File(dst, "r+") as f:
        n = f["strikes/range"].shape[0]
        row = rng.randrange(1, n)
        if choice == "nan":
            f["shots/sensor_position"][rng.randrange(f.attrs["n_shots"]), 1] = np.nan
        elif choice == "range_max":
            f["strikes/range"][row] = rng.choice([1e300, 1e6, 3000.5])
        elif choice == "duplicate":
            f["strikes/beam"][row] = f["strikes/beam"][row - 1]
            f["strikes/shot"][row] = f["strikes/shot"][row - 1]
        elif choice == "order":
            f["strikes/shot"][row] = f["strikes/shot"][row - 1] + 5
        elif choice == "quaternion":
            f["shots/target_attitude"][0, 3] = 0.5
        elif choice == "external":
            del f["truth/mesh/vertices"]
            f["truth/mesh"].create_dataset("vertices", shape=(100, 3), dtype="<f8",
                                           external=[(str(secret), 0, 2400)])
        elif choice == "link":
            del f["strikes/range"]
            f["strikes/range"] = h5py.ExternalLink(str(src), "/strikes/range")
        elif choice == "truth_point":
            f["truth/point"][row, 0] = np.inf
        elif choice == "truth_mesh":
            f["truth/mesh/vertices"][0, 0] += 1e-9
        elif choice == "n_strikes":
            f.attrs["n_strikes"] = np.int64(n + 7)
        elif choice == "attr_type":
            f.attrs["format_version"] = "one"
        elif choice == "beam":
            f["strikes/beam"][row] = 99
        else:
            del f[rng.choice(["shots/time", "strikes/shot", "sensor", "truth/facet"])]
    return choice, True


# --------------------------------------------------------------------------- hostile values


_BAD_SCENE = [
    ("time.step", ["-1", "0", "nan", "inf", "[1]", '"x"', "1e-300"]),
    ("time.duration", ["-5", "nan", "1e300", "true"]),
    ("orbit.radius", ["0", "-750", "1", "inf"]),
    ("orbit.inclination_deg", ["200", "-1", "nan"]),
    ("sensor.pattern", ["hexagon", "1", '""']),
    ("sensor.range_max", ["0", "-1", "nan"]),
    ("errors.dilation_subrays", ["0", "1000000000", "1.5"]),
    ("errors.range_sigma3", ["-1", "inf"]),
    ("target.subdivisions", ["9", "-1", "100"]),
    ("target.kind", ["mesh", "cube"]),
    ("target.spin_axis", ["[0,0,0]", "[1,2]", "[[1]]"]),
    ("slew.amplitude_deg", ["90", "-1"]),
    ("limits.rays", ["0", "-1", "nan"]),
    ("nosuch.key", ["1"]),
    ("time.nosuch", ["1"]),
]
_OK_SCENE = [("slew.amplitude_deg", "2"), ("orbit.inclination_deg", "60"),
             ("errors.range_sigma3", "0.3"), ("sensor.pattern", "cross")]
_BAD_ARGS = [
    ("score", "--tau", ["-1", "0", "nan", "inf"]),
    ("score", "--tau-fraction", ["-0.5", "0", "nan"]),
    ("score", "--truth-scale", ["0", "-2", "nan", "inf"]),
    ("reconstruct", "--voxel", ["-1", "0", "nan"]),
    ("reconstruct", "--normals-k", ["0", "-3", "1"]),
    ("reconstruct", "--timeout", ["0", "-1", "nan"]),
    ("reconstruct", "--memory-limit", ["-1"]),
    ("reconstruct", "--holdout", ["0", "1", "-0.2", "nan"]),
    ("reconstruct", "--param", ["depth=-1", "depth=x", "nosuch=1", "depth"]),
    ("simulate", "--seed", ["-1", "9223372036854775808"]),
]


def _special_path(kind: str, directory: Path) -> Path:
    path = directory / f"special-{kind}.h5"
    if kind == "dir":
        path.mkdir()
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "missing":
        pass
    else:
        return Path("/dev/zero")
    return path


def make_case(seed: int, inputs: dict, directory: Path, kind: str | None = None) -> Case:
    """Case number ``seed`` (the same seed gives the same case), its files in ``directory``;
    of ``kind`` when given (else drawn from ``FIRST_KINDS + HOSTILE_KINDS``). The hostile
    kinds need ``inputs["servers"]`` (tests/fuzz/runner.py's ``servers``)."""
    rng = random.Random(seed)
    directory.mkdir(parents=True, exist_ok=True)
    out = directory / "out.ply"
    drawn = rng.choice(FIRST_KINDS + HOSTILE_KINDS)   # drawn always: same stream after it
    kind = kind or drawn
    if kind in HOSTILE_KINDS:
        from tests.fuzz.hostile import MAKERS

        return MAKERS[kind](rng, inputs, directory)
    if kind in ("flip_log", "mutate_log"):
        bad = directory / "bad.h5"
        how, must = (_damaged_copy(inputs["log"], bad, rng) if kind == "flip_log"
                     else _mutated_log(inputs["log"], bad, rng))
        command = rng.choice(["validate", "info", "ingest", "score", "truth", "reconstruct"])
        if command == "info" and kind == "mutate_log":
            command = "validate"   # info reads the header only: data damage is validate's
        args = {"validate": ["validate", bad], "info": ["info", bad],
                "ingest": ["ingest", bad, "-o", out], "score": ["score", bad, "--no-edges"],
                "truth": ["truth", bad, "-o", out],
                "reconstruct": ["reconstruct", bad, "-o", out, "-m", "convex-hull",
                                "--in-process"]}[command]
        if kind == "mutate_log":   # what each command reads (SPEC.md): damage elsewhere
            reads_data = command in ("validate", "ingest", "score", "reconstruct")
            if how in ("truth_point", "truth_mesh"):
                must = command == "validate" or (how == "truth_mesh" and command in ("score",
                                                                                       "truth"))
            elif how in ("nan", "range_max", "duplicate", "order", "quaternion", "beam"):
                must = reads_data
        if command == "info" and how == "flip":
            must = False
        return Case(f"{kind}:{how}:{command}", [str(a) for a in args], must, (bad.name,),
                    out if command in ("ingest", "truth", "reconstruct") else None)
    if kind == "file":
        source = rng.choice(["truth_ply", "truth_obj", "cloud_ply", "cloud_las"])
        bad = directory / ("bad" + inputs[source].suffix)
        how, must = _damaged_copy(inputs[source], bad, rng)
        if source == "truth_obj" and how == "truncate":
            must = False   # OBJ is lines with no count: cut at a line end, it is a valid OBJ
        if source.startswith("truth"):
            args = ["score", inputs["cloud_ply"], "--truth", bad, "--no-edges"]
        else:
            args = rng.choice([["score", bad, "--truth", inputs["truth_ply"], "--no-edges"],
                               ["reconstruct", bad, "-o", out, "-m", "convex-hull",
                                "--in-process"]])
        return Case(f"file:{source}:{how}", [str(a) for a in args], must, (bad.name,),
                    out if "reconstruct" in args else None)
    if kind == "scene":
        log = directory / "run.h5"
        key, values = rng.choice(_BAD_SCENE)
        overrides = [f"{key}={rng.choice(values)}"]
        if rng.random() < 0.3:
            overrides.append("{}={}".format(*rng.choice([o for o in _OK_SCENE if o[0] != key])))
        args = ["simulate", inputs["scene"], "-o", log]
        for o in overrides:
            args += ["--set", o]
        if rng.random() < 0.3:   # the same damage in a scene file
            text = inputs["scene"].read_text() + "\n".join(
                f"[{k.split('.')[0]}]\n{k.split('.')[1]} = {v}" for k, v in
                (o.split("=", 1) for o in overrides if not o.startswith(("time.", "sensor."))))
            scene = directory / "bad.toml"
            scene.write_text(text)
            args = ["simulate", scene, "-o", log] + [
                a for o in overrides if o.startswith(("time.", "sensor."))
                for a in ("--set", o)]
        return Case(f"scene:{key}", [str(a) for a in args], True,
                    (key, key.split(".")[0], key.split(".")[-1], "scene"), log)
    if kind == "args":
        command, option, values = rng.choice(_BAD_ARGS)
        value = rng.choice(values)
        base = {"score": ["score", inputs["cloud_ply"], "--truth", inputs["truth_ply"],
                          "--no-edges"],
                "reconstruct": ["reconstruct", inputs["cloud_ply"], "-o", out, "-m",
                                "poisson", "--in-process"],
                "simulate": ["simulate", inputs["scene"], "-o", directory / "run.h5"]}[command]
        return Case(f"args:{command}{option}={value}", [str(a) for a in base] + [option, value],
                    True, (option, option.lstrip("-"), value.split("=")[0]),
                    out if command == "reconstruct" else directory / "run.h5")
    special = rng.choice(["dir", "fifo", "missing", "device"])
    path = _special_path(special, directory)
    command = rng.choice(["validate", "info", "ingest", "score", "reconstruct", "out"])
    if command == "out":
        target = path if special != "device" else _special_path("fifo", directory)
        args = ["ingest", inputs["log"], "-o", target]
        return Case(f"path:output-{special}", [str(a) for a in args], special != "missing",
                    (target.name,))
    args = {"validate": ["validate", path], "info": ["info", path],
            "ingest": ["ingest", path, "-o", out], "score": ["score", path],
            "reconstruct": ["reconstruct", path, "-o", out, "--in-process"]}[command]
    return Case(f"path:{special}:{command}", [str(a) for a in args], True, (path.name,),
                out if command in ("ingest", "reconstruct") else None)


# --------------------------------------------------------------------------- verdict


def judge(case: Case, status: int | None, err: str, *, opened=(), secrets: Path | None = None
          ) -> str:
    """The outcome of ``case`` that exited with ``status`` (None: killed at the time limit;
    negative: killed by that signal), having opened the files ``opened`` (what strace saw;
    empty when not traced); ``secrets`` is the directory no case may read."""
    if status is None:
        return "hang"
    if status < 0:
        return "crash"
    if any(digest(path) != before for path, before in case.digests.items()):
        return "data loss"
    if secrets is not None and _escaped(case, err, opened, Path(secrets)):
        return "escape"
    if "Traceback" in err or status not in (0, 1):
        return "traceback"
    if status == 0:
        return "wrong" if case.must_fail else "ok"
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("recon ") and ": error: " in ln]
    usage = [ln for ln in lines if ln.startswith(("usage:", " "))]
    if len(errors) != 1 or len(errors) + len(usage) != len(lines):
        return "messy"
    if not any(name in errors[0] for name in case.names):
        return "messy"
    if case.output is not None and (case.output.exists() and not case.output.is_dir()
                                    and not case.output.is_fifo()):
        return "messy"
    parent = case.output.parent if case.output is not None else None
    if parent is not None and any(".partial" in p.name for p in parent.iterdir()):
        return "messy"
    return "clean"


def _escaped(case: Case, err: str, opened, secrets: Path) -> bool:
    """The run opened a file under ``secrets`` (through any link), or its error or output
    shows what one holds."""
    from tests.fuzz.hostile import SECRET

    root = secrets.resolve()
    for path in opened:
        try:
            if Path(os.path.realpath(path)).is_relative_to(root):
                return True
        except (OSError, ValueError):
            continue
    if SECRET in err:
        return True
    output = case.output
    if output is not None and output.is_file() and output.stat().st_size < 50_000_000:
        return SECRET.encode() in output.read_bytes()
    return False
