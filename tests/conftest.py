"""Shared fixtures: small strike logs written directly with the format API (no simulator)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from formats import SensorInfo, Shots, StrikeLogWriter, TruthStrikes

# The real shape models beside the checkout (../shared/meshes; README there).
SHARED_MESHES = Path(__file__).resolve().parents[2] / "shared" / "meshes"
# Presets name shared shape models by file name, found through RECON_MESH_PATH (sim/scene.py):
# the tests look in the shared folder unless the environment names another.
os.environ.setdefault("RECON_MESH_PATH", str(SHARED_MESHES))
SPHERE_RADIUS_M = 50.0
ORBIT_RADIUS_M = 250.0


def icosphere(radius: float, subdivisions: int = 2) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)


def write_sphere_log(path, *, n_shots: int = 40, with_truth: bool = True,
                     reports_angles: bool = False, seed: int = 7) -> None:
    """A sensor circling a sphere in the x-y plane, boresight (+z of S) on the centre.

    The sphere stays inertially fixed (target attitude identity). Ranges are exact to the
    sphere of radius SPHERE_RADIUS_M, so registered points lie on it.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(n_shots) * 10.0
    phase = 2 * np.pi * t / (n_shots * 10.0)
    position = ORBIT_RADIUS_M * np.stack([np.cos(phase), np.sin(phase), np.zeros(n_shots)], 1)
    boresight = -position / ORBIT_RADIUS_M
    # S axes in I: z = boresight, y = inertial z, x = y cross z.
    y_axis = np.tile([0.0, 0.0, 1.0], (n_shots, 1))
    x_axis = np.cross(y_axis, boresight)
    sensor_q = Rotation.from_matrix(np.stack([x_axis, y_axis, boresight], axis=2)).as_quat()
    target_q = np.tile([0.0, 0.0, 0.0, 1.0], (n_shots, 1))
    beams = np.array([[0.0, 0.0, 1.0], [np.sin(0.05), 0.0, np.cos(0.05)]])
    sensor = SensorInfo("custom", beams, range_min=1.0, range_max=1000.0,
                        field_of_view=(0.0, 0.05, 0.0, 0.0), reports_angles=reports_angles)
    shot = np.repeat(np.arange(n_shots), 2)
    beam = np.tile([0, 1], n_shots)
    d_i = Rotation.from_quat(sensor_q[shot]).apply(beams[beam])
    origin = position[shot]
    # Ray-sphere intersection (near root).
    b = np.einsum("ij,ij->i", origin, d_i)
    c = np.einsum("ij,ij->i", origin, origin) - SPHERE_RADIUS_M**2
    rho = -b - np.sqrt(b * b - c)
    mesh = icosphere(SPHERE_RADIUS_M)
    truth = {}
    if with_truth:
        truth = {"truth_mesh": mesh}
    with StrikeLogWriter(path, sensor=sensor, target="sphere", scene="# test", seed=seed,
                         **truth) as log:
        true_shots = Shots(t, position, sensor_q, target_q) if with_truth else None
        log.write_shots(t, position, sensor_q, target_q, truth=true_shots)
        extra = {}
        if reports_angles:
            extra = {"azimuth_offset": rng.normal(0, 1e-4, len(shot)),
                     "elevation_offset": rng.normal(0, 1e-4, len(shot))}
        true_strikes = (TruthStrikes(origin + rho[:, None] * d_i, np.zeros(len(shot)), rho)
                        if with_truth else None)
        log.write_strikes(shot, beam, rho, truth=true_strikes, **extra)


@pytest.fixture
def sphere_log(tmp_path):
    """Path of a valid 40-shot, 80-strike log with truth."""
    path = tmp_path / "sphere.h5"
    write_sphere_log(path)
    return path


def registration_error(path, correction=None) -> float:
    """Mean distance [m] of a log's strikes registered with ``correction`` (a refinement's, or
    the recorded poses) from their true hit points (the log's truth)."""
    from formats import StrikeLog
    from recon.registration.ingest import ingest

    with StrikeLog(path) as log:
        truth = log.truth_strikes().point
    return float(np.linalg.norm(ingest(path, correction=correction).points - truth, axis=1)
                 .mean())


def python_on_zero_size_pty(script: str, *args: str) -> str:
    """Run ``python -c script args`` with stderr on a pseudo-terminal that reports 0 rows and 0
    columns (CI runners, ``script``); return what it drew there. The repository is on its path.
    """
    import fcntl
    import pty
    import struct
    import termios

    main, child = pty.openpty()
    fcntl.ioctl(child, termios.TIOCSWINSZ, struct.pack("HHHH", 0, 0, 0, 0))
    env = {k: v for k, v in os.environ.items()
           if k not in ("LINES", "COLUMNS", "TQDM_NROWS", "TQDM_NCOLS")}
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[1])
    proc = subprocess.Popen([sys.executable, "-c", script, *args], stderr=child,
                            stdout=subprocess.DEVNULL, env=env)
    os.close(child)
    chunks = []
    while True:
        try:
            data = os.read(main, 4096)
        except OSError:  # the child closed its end
            break
        if not data:
            break
        chunks.append(data)
    os.close(main)
    assert proc.wait(timeout=120) == 0
    return b"".join(chunks).decode(errors="replace")
