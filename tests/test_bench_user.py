"""The user-command benchmark's harness (benchmarks/bench_user.py): the per-million difference,
the per-million clouds and the raw-cast floor, on tiny inputs. No timing is asserted."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from benchmarks import bench_user
from formats.mesh_io import write_mesh
from formats.ply import read_ply


def test_per_million_is_the_difference_over_the_millions_between(monkeypatch):
    costs = {"large": {"wall_s": 10.0, "cpu_s": 7.0}, "small": {"wall_s": 4.0, "cpu_s": 1.0}}
    monkeypatch.setattr(bench_user, "timed", lambda argv: costs[argv[0]])
    out = bench_user.run_commands({"plus": [["large"]], "minus": [["small"]]})
    millions = (bench_user.MILLION_SIZES[1] - bench_user.MILLION_SIZES[0]) / 1e6
    assert out == {"wall_s": 6.0 / millions, "cpu_s": 6.0 / millions}


def test_million_clouds_sample_the_truth_with_noise(tmp_path, monkeypatch):
    monkeypatch.setattr(bench_user, "MILLION_SIZES", (100, 400))
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    truth = tmp_path / "truth.ply"
    write_mesh(truth, vertices, faces)
    paths = bench_user.million_clouds(tmp_path, truth)
    for n, path in paths.items():
        columns, faces_read, metadata = read_ply(path)
        assert len(columns["x"]) == n and faces_read is None
        assert metadata["units"] == "m"
    again = bench_user.million_clouds(tmp_path, truth)   # made once, then reused
    assert again == paths


def test_raw_cast_floor_counts_hits(tmp_path):
    rays = tmp_path / "rays.npz"
    o = np.array([[0.2, 0.2, 1.0], [5.0, 5.0, 1.0]], np.float32)
    d = np.array([[0, 0, -1.0], [0, 0, -1.0]], np.float32)
    np.savez(rays, vertices=np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32),
             faces=np.array([[0, 1, 2]], np.int32), chunks=1, o0=o, d0=d)
    out = subprocess.run([sys.executable, "-c", bench_user.FLOOR_CAST, str(rays)],
                         capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "1"
