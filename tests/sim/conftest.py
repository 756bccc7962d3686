"""Helpers for the simulator tests: run a scene, read its log back the way SPEC.md says."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import sim
from formats.strike_log import StrikeLog


def run_scene(tmp_path: Path, scene, *overrides: str, seed: int = 0, name: str = "run.h5",
              **kwargs) -> tuple[dict, Path]:
    """Simulate a preset or scene file with overrides; return the summary and the log path."""
    path = tmp_path / name
    summary = sim.simulate(sim.load_scene(scene, list(overrides)), path, seed=seed,
                           progress=False, **kwargs)
    return summary, path


def registered_points(path: Path) -> np.ndarray:
    """Strike points in the body frame from the *recorded* values, by formats/SPEC.md:
    ``p_B = R(q_BI)^T (r_I + R(q_SI) (rho d_S))``, independent of the simulator's code."""
    out = []
    with StrikeLog(path) as log:
        for chunk in log.iter_chunks():
            i = chunk.shot - chunk.shot_offset
            s = chunk.shots
            p_i = s.sensor_position[i] + Rotation.from_quat(s.sensor_attitude[i]).apply(
                chunk.range[:, None] * chunk.direction)
            out.append(Rotation.from_quat(s.target_attitude[i]).inv().apply(p_i))
    return np.vstack(out) if out else np.zeros((0, 3))


def read_all(path: Path) -> dict[str, np.ndarray]:
    """Every dataset of a log, by HDF5 path."""
    data = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: data.__setitem__(name, obj[()])
                     if isinstance(obj, h5py.Dataset) else None)
    return data


def distance_to_mesh(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Exact float64 point-to-mesh distances with trimesh (independent of sim/raycast.py)."""
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    return trimesh.proximity.closest_point(mesh, points)[1]


def write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def box_obj(tmp_path) -> Path:
    """An OBJ of the box [-1, 1] x [-2, 2] x [-3, 3] m: every face at a different distance."""
    return write_obj(tmp_path / "box.obj", *sim.targets.box([-1, -2, -3], [1, 2, 3]))
