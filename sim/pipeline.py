"""Simulate a scene and stream its strike log (formats/SPEC.md).

The campaign is cut into chunks of shots holding about ``RAYS_PER_CHUNK`` rays. Worker threads
(one per core) each take a chunk through the whole pipeline, all of it batched over the chunk's
shots and beams:

1. times; target attitude, chaser orbit and sensor attitude (sim/motion.py);
2. every ray of the chunk in the body frame B (the mesh never moves): origins ``R_BI^T r_I``,
   directions ``R_BI^T R_SI d_S``;
3. one first-hit query for all of them (the backend releases the GIL, so the workers cast in
   parallel), then the exact float64 hit on the reported triangle (sim/raycast.py);
4. the error models on the recorded values (sim/noise.py), then the range limits.

The main thread writes finished chunks in order while the workers compute the next ones, so at
most ``CHUNKS_IN_FLIGHT`` chunks exist at a time and memory does not grow with the run.
"""

from __future__ import annotations

import math
import os
import time
from collections import deque
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from formats.atomic import check_space
from formats.errors import InputError, SceneError
from formats.paths import check_destination
from formats.strike_log import (
    DEFAULT_COMPRESSION,
    LOG_SUFFIXES,
    SensorErrors,
    SensorInfo,
    Shots,
    StrikeChunk,
    StrikeLogWriter,
    TruthStrikes,
    angles_to_directions,
    compression_filters,
    directions_to_angles,
)
from sim import noise, pose_errors
from sim.defaults import (
    CHUNKS_IN_FLIGHT,
    MAX_SEED,
    MAX_SHOTS_PER_CHUNK,
    PROGRESS_DELAY_S,
    RAYS_PER_CHUNK,
)
from sim.gap_seeking import GapSeeker
from sim.motion import (
    Orbit,
    SpiceGeometry,
    equatorial_frame,
    nominal_sensor_attitude,
    slew_rotation,
    target_attitude,
)
from sim.raycast import BACKENDS, DEFAULT_BACKEND, EmbreeBackend, ExactHits, Open3DBackend
from sim.scene import Scene
from sim.sensors import BeamPattern, beam_pattern, cone_pattern


@dataclass(frozen=True)
class Plan:
    """Everything fixed for a run, shared read-only by the worker threads."""

    scene: Scene
    seed: int
    step: float
    spin: dict | None              # None: a SPICE-driven target attitude
    orbit: Orbit | SpiceGeometry
    slew: dict | None
    pattern: BeamPattern
    errors: SensorErrors
    pose: pose_errors.PoseKnowledge | None   # pose-knowledge errors (sim/pose_errors.py)
    cone: tuple[np.ndarray, np.ndarray] | None
    caster: EmbreeBackend | Open3DBackend
    exact: ExactHits
    range_min: float
    range_max: float
    scale: float   # largest coordinate of any ray [m]: the sensor's distance from the centre


@dataclass
class Chunk:
    """One chunk's shots and strikes, ready to write."""

    time: np.ndarray
    position: np.ndarray            # true sensor position, I
    recorded_position: np.ndarray   # with pose-knowledge error
    sensor_attitude: np.ndarray     # true quaternion S->I
    target_attitude: np.ndarray     # true quaternion B->I
    recorded_sensor_attitude: np.ndarray   # with pose-knowledge error
    recorded_target_attitude: np.ndarray
    shot: np.ndarray
    beam: np.ndarray
    range: np.ndarray
    azimuth_offset: np.ndarray | None
    elevation_offset: np.ndarray | None
    point: np.ndarray
    facet: np.ndarray
    true_range: np.ndarray
    rays: int


def make_plan(scene: Scene, *, seed: int, backend: str = DEFAULT_BACKEND) -> Plan:
    """Turn a scene into the fixed parts of a run (builds the ray-casting structures; loads the
    kernels of a SPICE-driven scene, which :func:`close_plan` unloads)."""
    if backend not in BACKENDS:
        raise SceneError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    target, orbit, slew, sensor = (scene.values[s] for s in ("target", "orbit", "slew", "sensor"))
    spin = the_orbit = None
    if orbit["kind"] == "spice":
        the_orbit = SpiceGeometry(kernels=orbit["kernels"], observer=orbit["observer"],
                                  target=orbit["target"], inertial_frame=orbit["inertial_frame"],
                                  target_frame=orbit["target_frame"],
                                  sensor_frame=orbit.get("sensor_frame"),
                                  epoch_et=scene.epoch_et)   # opened last, below
    else:
        spin = {"spin_period": target["spin_period"], "spin_axis": target["spin_axis"],
                "attitude": target["attitude"]}
        spin_axis_inertial = Rotation.from_quat(target["attitude"]).apply(target["spin_axis"])
        change = orbit.get("change_inclination_deg")
        the_orbit = Orbit(radius=orbit["radius"], mu=scene.mu,
                          inclination=math.radians(orbit["inclination_deg"]),
                          node=math.radians(orbit["node_deg"]),
                          phase=math.radians(orbit["phase_deg"]),
                          frame=equatorial_frame(spin_axis_inertial),
                          change_time=orbit.get("change_time"),
                          change_inclination=None if change is None else math.radians(change))
    the_slew = None
    if slew.get("amplitude_deg", 0.0) > 0:
        the_slew = {"amplitude": math.radians(slew["amplitude_deg"]), "period": slew["period"],
                    "axis": slew["axis"], "phase": math.radians(slew["phase_deg"])}
    pattern = beam_pattern(sensor)
    errors = scene.errors
    cone = (cone_pattern(int(errors.pulse_dilation_subrays), errors.pulse_dilation_half_angle)
            if errors.dilation else None)
    step = scene.values["time"]["step"]
    pose = pose_errors.plan_knowledge(errors, seed=seed, n_shots=scene.n_shots, step=step,
                                      spin=spin, orbit=the_orbit)
    plan = Plan(scene=scene, seed=seed, step=step, spin=spin, orbit=the_orbit, slew=the_slew,
                pattern=pattern, errors=errors, pose=pose, cone=cone,
                caster=BACKENDS[backend](scene.vertices, scene.faces),
                exact=ExactHits(scene.vertices, scene.faces),
                range_min=sensor["range_min"], range_max=sensor["range_max"],
                scale=orbit.get("radius", 0.0))
    if isinstance(the_orbit, SpiceGeometry):   # the kernels stay loaded until close_plan
        try:
            check_spice_geometry(the_orbit.open(), scene)
        except InputError as exc:
            the_orbit.close()
            raise SceneError(f"[orbit] kind = spice: {exc}") from None
        except BaseException:
            the_orbit.close()
            raise
    return plan


def check_spice_geometry(geometry: SpiceGeometry, scene: Scene) -> None:
    """Evaluate a SPICE-driven scene's poses at its first and last shots, so that a missing
    kernel, name or frame, or a trajectory inside the target, is one line before any work."""
    t = np.array([0.0, (scene.n_shots - 1) * scene.values["time"]["step"]])
    position, _ = geometry.state(t)
    geometry.target_attitude(t)
    if geometry.sensor_frame is not None:
        geometry.sensor_attitude(t)
    reach = float(np.linalg.norm(scene.vertices, axis=1).max())
    inside = np.linalg.norm(position, axis=1) <= reach
    if inside.any():
        raise SceneError(f"orbit.kernels put {geometry.observer} "
                         f"{np.linalg.norm(position[np.argmax(inside)]):.4g} m from "
                         f"{geometry.target} at t = {t[np.argmax(inside)]:g} s, inside the "
                         f"target (its farthest point is {reach:.4g} m from the centre)")


def close_plan(plan: Plan) -> None:
    """Release what a plan holds beyond memory: the kernels of a SPICE-driven scene."""
    if isinstance(plan.orbit, SpiceGeometry):
        plan.orbit.close()


def shots_per_chunk(plan: Plan) -> int:
    """Shots per chunk: about RAYS_PER_CHUNK rays, counting every sub-ray a pulse may cast."""
    subrays = int(plan.errors.pulse_dilation_subrays) if plan.errors.dilation else 0
    rays_per_shot = plan.pattern.n_beams * (1 + subrays)
    return int(min(max(RAYS_PER_CHUNK // rays_per_shot, 1), MAX_SHOTS_PER_CHUNK))


def poses(plan: Plan, t: np.ndarray, offset: np.ndarray | None = None
          ) -> tuple[np.ndarray, Rotation, np.ndarray]:
    """True poses at times ``t`` (n,) [s].

    ``offset`` (n, 3, 3), from a closed-loop law (sim/gap_seeking.py), sends sensor vectors to
    the nominal sensor frame; without it the scene's fixed law (nadir or the slew) applies.

    Returns
    -------
    position : (n, 3) float64, metres, I
    target : Rotation, B->I
    sensor : (n, 3, 3) float64, matrices sending S vectors to I
    """
    position, along_track = plan.orbit.state(t)
    if plan.spin is None:   # SPICE-driven
        rot_bi = plan.orbit.target_attitude(t)
        if plan.orbit.sensor_frame is not None:
            m_si = plan.orbit.sensor_attitude(t)
            return position, rot_bi, m_si if offset is None else m_si @ offset
    else:
        rot_bi = target_attitude(t, **plan.spin)
    m_si = nominal_sensor_attitude(position, along_track)
    if offset is not None:
        m_si = m_si @ offset
    elif plan.slew is not None:
        m_si = m_si @ slew_rotation(t, **plan.slew).as_matrix()
    return position, rot_bi, m_si


def _dilation(plan: Plan, index: int, origins: np.ndarray, directions: np.ndarray,
              true_range: np.ndarray) -> tuple[np.ndarray, int]:
    """Pulse-dilation displacement (h, 3) [m, B] of each strike, and the sub-rays cast."""
    polar, azimuth = plan.cone
    h, m = len(directions), len(polar)
    d = directions
    helper = np.where((np.abs(d[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    u = np.cross(d, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(d, u)
    lateral = (np.cos(azimuth)[None, :, None] * u[:, None, :]
               + np.sin(azimuth)[None, :, None] * w[:, None, :])
    sub = np.cos(polar)[None, :, None] * d[:, None, :] + np.sin(polar)[None, :, None] * lateral
    face = plan.caster.first_hit(np.repeat(origins.astype(np.float32), m, axis=0),
                                 sub.reshape(-1, 3).astype(np.float32)).reshape(h, m)
    hit = face >= 0
    normal = plan.exact.normals[np.where(hit, face, 0)]
    cos_incidence = np.abs(np.einsum("hmi,hmi->hm", sub, normal))
    sigma = noise.dilation_sigma(plan.errors.pulse_dilation_alpha, true_range, cos_incidence, hit)
    rng = noise.stream(plan.seed, noise.STREAM_DILATION, index)
    return sigma[:, None] * rng.standard_normal((h, 3)), h * m


@dataclass
class Rays:
    """A chunk's shots and the rays of all their pulses, in the body frame B."""

    time: np.ndarray          # (n,) s
    position: np.ndarray      # (n, 3) m, I: true sensor position
    target: Rotation          # B->I
    sensor: np.ndarray        # (n, 3, 3): sends S vectors to I
    to_body: np.ndarray       # (n, 3, 3): sends S vectors to B
    origin: np.ndarray        # (n, 3) m, B: sensor position
    direction: np.ndarray     # (n * b, 3) unit vectors, B: true firing direction of each pulse

    def float32(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-ray origins and directions (n * b, 3) float32, as the backends take them."""
        b = len(self.direction) // len(self.time)
        return (np.repeat(self.origin.astype(np.float32), b, axis=0),
                self.direction.astype(np.float32))


def chunk_rays(plan: Plan, index: int, first: int, stop: int,
               offset: np.ndarray | None = None, *, nominal: tuple | None = None) -> Rays:
    """Poses of shots ``first .. stop - 1`` and every pulse's ray (chunk number ``index``);
    ``nominal``: :func:`poses` of those shots without the ``offset``, when already computed."""
    errors, pattern = plan.errors, plan.pattern
    t = np.arange(first, stop, dtype=np.float64) * plan.step
    n, b = len(t), pattern.n_beams
    if nominal is None:
        position, rot_bi, m_si = poses(plan, t, offset)
    else:
        position, rot_bi, m_si = nominal
        m_si = m_si if offset is None else m_si @ offset
    m_ib = rot_bi.as_matrix().transpose(0, 2, 1)
    origin = np.einsum("nij,nj->ni", m_ib, position)          # sensor in B
    m_sb = m_ib @ m_si                                         # sends S vectors to B
    # The true firing direction of every pulse, in S, then in B.
    if errors.angles and not pattern.reports_angles:          # pointing error of a fixed LRF
        rng = noise.stream(plan.seed, noise.STREAM_POINTING, index)
        d_az, d_el = noise.angle_errors(errors, rng, n * b)
        fired = angles_to_directions(np.tile(pattern.azimuth, n) - d_az,
                                     np.tile(pattern.elevation, n) - d_el).reshape(n, b, 3)
    else:
        fired = pattern.directions[None]
    direction = np.matmul(fired, m_sb.transpose(0, 2, 1)).reshape(-1, 3)
    return Rays(time=t, position=position, target=rot_bi, sensor=m_si, to_body=m_sb,
                origin=origin, direction=direction)


def compute_chunk(plan: Plan, index: int, first: int, stop: int,
                  offset: np.ndarray | None = None, *, nominal: tuple | None = None) -> Chunk:
    """Simulate shots ``first .. stop - 1`` (chunk number ``index``), with the attitude
    ``offset`` of :func:`poses` when a closed-loop law commands it (``nominal``: the poses of
    those shots without it, when already computed)."""
    errors, pattern = plan.errors, plan.pattern
    rays = chunk_rays(plan, index, first, stop, offset, nominal=nominal)
    t, position, origin, direction, m_sb = (rays.time, rays.position, rays.origin,
                                            rays.direction, rays.to_body)
    n, b = len(t), pattern.n_beams
    origins32, directions32 = rays.float32()
    face, u, v = plan.caster.first_hit_uv(origins32, directions32)
    pulse = np.flatnonzero(face >= 0)
    shot = pulse // b if b > 1 else pulse
    # np.take: row gathers several times faster than fancy indexing.
    o, d = np.take(origin, shot, axis=0), np.take(direction, pulse, axis=0)
    scale = max(plan.scale, float(np.abs(origin).max(initial=0.0)))
    true_range, facet, hit = plan.exact.refine(o, d, *(np.take(a, pulse) for a in (face, u, v)),
                                               scale=scale)
    if not hit.all():
        pulse, shot, o, d = pulse[hit], shot[hit], o[hit], d[hit]
        true_range, facet = true_range[hit], facet[hit]
    beam = pulse - shot * b
    point = true_range[:, None] * d
    point += o
    h, cast = len(pulse), n * b

    # What the sensor records.
    recorded = true_range
    az_off = el_off = None
    if pattern.reports_angles:
        az_off, el_off = np.zeros(h), np.zeros(h)
    if errors.dilation:
        shift, sub_rays = _dilation(plan, index, o, d, true_range)
        cast += sub_rays
        if pattern.reports_angles:
            seen = np.einsum("hji,hj->hi", m_sb[shot], point + shift - o)   # R_SB (p' - o)
            recorded = np.linalg.norm(seen, axis=1)
            az, el = directions_to_angles(seen / recorded[:, None])
            az_off, el_off = az - pattern.azimuth[beam], el - pattern.elevation[beam]
        else:
            recorded = true_range + np.einsum("ij,ij->i", shift, d)
    if errors.angles and pattern.reports_angles:
        d_az, d_el = noise.angle_errors(errors, noise.stream(plan.seed, noise.STREAM_ANGLES,
                                                             index), h)
        az_off, el_off = az_off + d_az, el_off + d_el
    if errors.range_sigma > 0:
        rng = noise.stream(plan.seed, noise.STREAM_RANGE, index)
        recorded = recorded + rng.normal(0.0, errors.range_sigma, h)
    in_range = (recorded >= plan.range_min) & (recorded <= plan.range_max) & (recorded > 0)
    if not in_range.all():
        keep = np.flatnonzero(in_range)
        shot, beam, recorded, point, facet, true_range = (
            a[keep] for a in (shot, beam, recorded, point, facet, true_range))
        if az_off is not None:
            az_off, el_off = az_off[keep], el_off[keep]

    sensor_q, target_q = Rotation.from_matrix(rays.sensor).as_quat(), rays.target.as_quat()
    recorded_position, recorded_sensor, recorded_target = position, sensor_q, target_q
    if plan.pose is not None:
        recorded_position, recorded_sensor, recorded_target = pose_errors.record(
            plan.pose, first, t, lambda times: poses(plan, times, offset))
    if errors.position_sigma > 0:
        rng = noise.stream(plan.seed, noise.STREAM_POSITION, index)
        recorded_position = recorded_position + rng.normal(0.0, errors.position_sigma, (n, 3))
    return Chunk(time=t, position=position, recorded_position=recorded_position,
                 sensor_attitude=sensor_q, target_attitude=target_q,
                 recorded_sensor_attitude=recorded_sensor,
                 recorded_target_attitude=recorded_target, shot=shot + first, beam=beam,
                 range=recorded, azimuth_offset=az_off, elevation_offset=el_off, point=point,
                 facet=facet.astype(np.uint32), true_range=true_range, rays=cast)


def chunk_bounds(plan: Plan) -> list[tuple[int, int, int]]:
    """``(index, first shot, stop shot)`` of every chunk of the campaign."""
    n_shots, size = plan.scene.n_shots, shots_per_chunk(plan)
    return [(i, k, min(k + size, n_shots)) for i, k in enumerate(range(0, n_shots, size))]


def iter_chunks(plan: Plan, *, workers: int | None = None) -> Iterator[Chunk]:
    """Compute the campaign's chunks in order, ``workers`` at a time (default: one per core)."""
    bounds = chunk_bounds(plan)
    workers = min(workers or os.cpu_count() or 1, len(bounds))
    if workers <= 1:
        for bound in bounds:
            yield compute_chunk(plan, *bound)
        return
    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="recon-sim")
    pending: deque = deque()
    todo = iter(bounds)
    try:
        for bound in todo:
            pending.append(pool.submit(compute_chunk, plan, *bound))
            if len(pending) >= max(CHUNKS_IN_FLIGHT, workers):
                break
        while pending:
            chunk = pending.popleft().result()
            bound = next(todo, None)
            if bound is not None:
                pending.append(pool.submit(compute_chunk, plan, *bound))
            yield chunk
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def recorded_strikes(plan: Plan, chunk: Chunk, first: int) -> StrikeChunk:
    """What the log records of a chunk of shots ``first ..``, as a reader yields it: recorded
    poses, ranges and measured directions (never the truth)."""
    direction = plan.pattern.directions[chunk.beam]
    if plan.pattern.reports_angles:
        az, el = directions_to_angles(direction)
        direction = angles_to_directions(az + chunk.azimuth_offset, el + chunk.elevation_offset)
    return StrikeChunk(start=0, shot=chunk.shot, beam=chunk.beam, range=chunk.range,
                       direction=direction,
                       shots=Shots(chunk.time, chunk.recorded_position,
                                   chunk.recorded_sensor_attitude,
                                   chunk.recorded_target_attitude), shot_offset=first)


def iter_closed_loop(plan: Plan) -> Iterator[Chunk]:
    """The campaign under the gap-seeking law: one replanning interval at a time, each planned
    from the strikes recorded before it (sim/gap_seeking.py). The interval's poses are
    computed once, for the law and the simulation alike."""
    attitude = plan.scene.values["attitude"]
    law = GapSeeker(step=plan.step, max_rate=math.radians(attitude["max_rate_deg_s"]),
                    max_offset=math.radians(attitude["max_offset_deg"]),
                    poses=lambda t: poses(plan, t), beams=plan.pattern.directions)
    size = max(1, round(attitude["replan_s"] / plan.step))
    for index, first in enumerate(range(0, plan.scene.n_shots, size)):
        stop = min(first + size, plan.scene.n_shots)
        t = np.arange(first, stop, dtype=np.float64) * plan.step
        position, target, nominal = poses(plan, t)
        offset = law.command(t, (position, target, nominal))
        chunk = compute_chunk(plan, index, first, stop, offset,
                              nominal=(position, target, nominal))
        law.observe(recorded_strikes(plan, chunk, first))
        yield chunk


def sensor_info(plan: Plan) -> SensorInfo:
    """The log's description of the sensor."""
    p = plan.pattern
    return SensorInfo(pattern=p.recorded_as, beam_directions=p.directions, range_min=plan.range_min,
                      range_max=plan.range_max, field_of_view=tuple(float(a) for a in
                                                                     p.field_of_view),
                      reports_angles=p.reports_angles, errors=plan.errors)


def simulate(scene: Scene, path, *, seed: int, progress: bool | None = None,
             backend: str = DEFAULT_BACKEND, workers: int | None = None,
             live: bool = False, compression: str = DEFAULT_COMPRESSION) -> dict:
    """Simulate ``scene`` and write its strike log to ``path``.

    Parameters
    ----------
    scene : Scene
        From :func:`sim.load_scene`.
    path : str or Path
        Destination ``.h5``; written under a temporary name and moved into place when complete.
    seed : int, >= 0
        Seed of every error model; the same seed gives the same datasets.
    progress : bool, None or callable
        Show a progress bar (None: only on a terminal, and only once the run has lasted
        ``PROGRESS_DELAY_S``); a callable is called as ``progress(shots_done, shots_total)``
        after each block of shots instead (no bar).
    backend : {"embree", "open3d"}
        Ray-casting backend (sim/raycast.py).
    workers : int, optional
        Worker threads (default: one per core).
    live : bool
        Write the log in HDF5 SWMR mode, readable while it is written
        (``formats.strike_log.follow``).
    compression : str
        Filter of the log's datasets: ``"gzip"``, ``"gzip:LEVEL"`` (0-9), ``"lzf"`` or
        ``"none"`` (``formats.StrikeLogWriter``; default deflate, which every HDF5 tool reads).

    Returns
    -------
    dict
        ``path``, ``scene``, ``target``, ``pattern``, ``beams``, ``shots``, ``pulses``,
        ``strikes``, ``rays_cast``, ``duration_s``, ``orbit_period_s``, ``mu``,
        ``inclination_change_s`` (None when no change happens during the run), ``seed``,
        ``backend``,
        ``wall_time_s``, ``rays_per_s``.
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or \
            not 0 <= seed <= MAX_SEED:
        raise SceneError(f"seed must be a non-negative integer of at most {MAX_SEED}, got "
                         f"{seed!r}")
    seed = int(seed)
    if Path(path).suffix.lower() not in LOG_SUFFIXES:
        raise SceneError(f"{path}: a strike log is an HDF5 file; name it "
                         f"{' or '.join(LOG_SUFFIXES)}")
    compression_filters(compression)   # a bad name fails before the ray casting
    check_destination(path, SceneError)
    check_space(path, scene.cost.disk_bytes, SceneError)
    start = time.perf_counter()
    plan = make_plan(scene, seed=seed, backend=backend)
    try:
        return _simulate(plan, path, progress=progress, backend=backend, workers=workers,
                         live=live, compression=compression, start=start)
    finally:
        close_plan(plan)


def _simulate(plan: Plan, path, *, progress, backend, workers, live, compression,
              start) -> dict:
    """:func:`simulate` once its plan is made (``start``: ``perf_counter`` at its start)."""
    scene, seed = plan.scene, plan.seed
    strikes = rays = shots = 0
    report = progress if callable(progress) else None
    bar = tqdm(total=scene.n_shots, unit="shot", desc=f"simulate {scene.name}",
               delay=PROGRESS_DELAY_S,
               disable=None if progress is None else report is not None or not progress)
    with bar, StrikeLogWriter(path, sensor=sensor_info(plan), target=scene.target,
                              scene=scene.to_toml(), seed=seed,
                              truth_mesh=(scene.vertices, scene.faces),
                              expected_shots=scene.n_shots,
                              expected_strikes=scene.n_shots * plan.pattern.n_beams,
                              live=live, compression=compression) as log:
        if scene.epoch_et is not None:
            log.write_epoch(scene.epoch_et)
        closed_loop = scene["attitude.mode"] == "gaps"
        for chunk in (iter_closed_loop(plan) if closed_loop else
                      iter_chunks(plan, workers=workers)):
            log.write_shots(chunk.time, chunk.recorded_position, chunk.recorded_sensor_attitude,
                            chunk.recorded_target_attitude,
                            truth=Shots(chunk.time, chunk.position, chunk.sensor_attitude,
                                        chunk.target_attitude))
            log.write_strikes(chunk.shot, chunk.beam, chunk.range,
                              azimuth_offset=chunk.azimuth_offset,
                              elevation_offset=chunk.elevation_offset,
                              truth=TruthStrikes(chunk.point, chunk.facet, chunk.true_range))
            strikes += len(chunk.shot)
            rays += chunk.rays
            bar.update(len(chunk.time))
            shots += len(chunk.time)
            if report is not None:
                report(shots, scene.n_shots)
    wall = time.perf_counter() - start
    change = plan.orbit.maneuver_time
    return {"path": str(path), "scene": scene.name, "target": scene.target,
            "pattern": plan.pattern.pattern, "beams": plan.pattern.n_beams,
            "shots": scene.n_shots, "pulses": scene.n_shots * plan.pattern.n_beams,
            "strikes": strikes, "rays_cast": rays, "duration_s": scene.duration,
            "orbit_period_s": scene.orbit_period, "mu": scene.mu,
            "inclination_change_s": change if change is not None and change < scene.duration
            else None, "seed": seed,
            "backend": backend, "wall_time_s": wall, "rays_per_s": rays / wall if wall else 0.0}
