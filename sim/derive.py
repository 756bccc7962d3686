"""What a validated scene implies: the truth mesh, the orbit's mu and period, the campaign's
duration and shot count, and the error models in the units the log records.

Runs after sim/schema.py has checked every value against its declared bounds, so it only checks
what needs the derived quantities themselves (an orbit outside the target, a mass from the
density of a closed mesh, a duration of at least one step). Every problem raises
:class:`SceneError` with one line naming the key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from formats.errors import InputError, SceneError
from formats.strike_log import SensorErrors, estimate_log_bytes
from sim import procedural, sensors, targets
from sim.defaults import (
    BYTES_PER_FACE,
    BYTES_PER_RAY,
    CHUNKS_IN_FLIGHT,
    GRAVITATIONAL_CONSTANT,
    RAYS_PER_CHUNK,
)

# Scene units converted to SI where the log needs radians (sim/defaults.py: every angle key
# says its unit); each conversion happens once, here.
RADIANS_PER = {"deg": math.pi / 180.0, "mrad": 1e-3, "arcsec": math.pi / 180.0 / 3600.0}
# The attitude random walk is given per sqrt(hour) and recorded per sqrt(second).
SQRT_SECONDS_PER_HOUR = 60.0
# Shots are taken at t = k * step while t <= duration; the slack absorbs the rounding of
# duration / step (e.g. 0.5 rotations of 15480 s in 10 s steps is 774, not 773.9999999).
SHOT_COUNT_SLACK = 1e-9


@dataclass(frozen=True)
class Cost:
    """What a run will take, estimated before it starts.

    Attributes
    ----------
    shots, beams : int
    rays : int
        Rays cast: shots x beams x (1 + sub-rays of pulse dilation, when on).
    memory_bytes : int
        Peak memory: the chunks in flight (at least one shot each) and the mesh's structures.
    disk_bytes : int
        Size of the log if every pulse returned a strike (an upper bound).
    """

    shots: int
    beams: int
    rays: int
    memory_bytes: int
    disk_bytes: int

    def describe(self) -> str:
        return (f"{self.shots:,} shots x {self.beams:,} beams = {self.rays:.3g} rays, "
                f"~{self.memory_bytes / 2**20:,.0f} MiB of memory, up to "
                f"{self.disk_bytes / 1e6:,.0f} MB of log")


@dataclass(frozen=True, eq=False)
class Derived:
    """The quantities a scene implies (see :class:`sim.scene.Scene`, which extends it, for their
    meaning). Compared by identity: the fields hold arrays."""

    vertices: np.ndarray = field(repr=False)
    faces: np.ndarray = field(repr=False)
    target: str
    mu: float | None
    orbit_period: float | None
    duration: float
    n_shots: int
    errors: SensorErrors
    cost: Cost
    epoch_et: float | None


def derive(values: dict) -> Derived:
    """Build the mesh and derive the orbit, time line and error models of checked values.

    Parameters
    ----------
    values : dict of section -> dict of key -> value
        Checked by :func:`sim.schema.check_values`. ``target.attitude`` is normalised in place
        to a unit quaternion.

    Returns
    -------
    Derived

    Raises
    ------
    SceneError
        The mesh cannot be read, the orbit is inside the target, a density is given for an open
        mesh, rotations for a target that does not spin, the campaign is shorter than a step,
        or its cost is above ``[limits]``.
    """
    spice = values["orbit"]["kind"] == "spice"
    epoch_et = spice_epoch(values) if spice else None
    duration, n_shots = time_line(values["time"], values["target"].get("spin_period", math.inf),
                                  spice=spice)
    vertices, faces, label = target_mesh(values["target"])
    if not spice:
        q = np.asarray(values["target"]["attitude"])
        values["target"]["attitude"] = (q / np.linalg.norm(q)).tolist()
    errors = sensor_errors(values["errors"])
    run_cost = cost(values, n_shots, errors, n_vertices=len(vertices), n_faces=len(faces))
    check_cost(run_cost, values["limits"])
    if spice:
        check_spice_pose_errors(values)
        mu = period = None
    else:
        mu, period = orbit_mu_and_period(values["orbit"], vertices, faces)
        check_spin_knowledge(values["target"]["spin_period"],
                             values["errors"]["spin_period_error"])
    return Derived(vertices=vertices, faces=faces, target=label, mu=mu, orbit_period=period,
                   duration=duration, n_shots=n_shots, errors=errors, cost=run_cost,
                   epoch_et=epoch_et)


def spice_epoch(values: dict) -> float:
    """ET [s, TDB past J2000] of the first shot of a SPICE-driven scene (orbit.start_utc or
    orbit.start_et, exactly one)."""
    orbit = values["orbit"]
    given = [k for k in ("start_utc", "start_et") if k in orbit]
    if len(given) != 1:
        raise SceneError("orbit.kind = \"spice\" needs one of orbit.start_utc, orbit.start_et"
                         + (", not both" if given else ""))
    if "start_et" in orbit:
        return orbit["start_et"]
    from formats.errors import InputError
    from formats.spice import utc_to_et

    try:
        return utc_to_et(orbit["start_utc"], "orbit.start_utc")
    except InputError as exc:
        raise SceneError(str(exc)) from None


def check_spice_pose_errors(values: dict) -> None:
    """Refuse the pose-knowledge errors that need the spin model, and a slew on top of a sensor
    attitude read from kernels."""
    errors = values["errors"]
    for key in ("spin_axis_error_deg", "spin_period_error"):
        if errors[key] != 0:
            raise SceneError(f"errors.{key} needs the spin model of orbit.kind = \"kepler\"; "
                             "a SPICE-driven target's attitude comes from its frame")
    if "sensor_frame" in values["orbit"] and values["slew"].get("amplitude_deg", 0.0) > 0:
        raise SceneError("slew.amplitude_deg turns the nadir pointing; with orbit.sensor_frame "
                         "the sensor attitude comes from the kernels (leave the slew at 0)")


def cost(values: dict, n_shots: int, errors: SensorErrors, *, n_vertices: int, n_faces: int
         ) -> Cost:
    """Estimate a run's rays, memory and log size from checked values (sim/pipeline.py's
    chunking: about RAYS_PER_CHUNK rays a chunk, at least one shot, CHUNKS_IN_FLIGHT ahead)."""
    sensor = values["sensor"]
    beams = sensors.n_beams(sensor)
    per_shot = beams * (1 + (int(errors.pulse_dilation_subrays) if errors.dilation else 0))
    chunk = max(RAYS_PER_CHUNK, per_shot)
    memory = (CHUNKS_IN_FLIGHT + 1) * chunk * BYTES_PER_RAY + n_faces * BYTES_PER_FACE
    disk = estimate_log_bytes(n_shots, n_shots * beams,
                              reports_angles=sensors.PATTERNS[sensor["pattern"]].reports_angles,
                              truth=True, n_vertices=n_vertices, n_faces=n_faces)
    return Cost(shots=n_shots, beams=beams, rays=n_shots * per_shot, memory_bytes=memory,
                disk_bytes=disk)


def check_cost(run: Cost, limits: dict) -> None:
    """Refuse a run above ``[limits]``, naming the limit and the estimate."""
    for key, value, limit in (("rays", run.rays, limits["rays"]),
                              ("memory_mb", run.memory_bytes / 2**20, limits["memory_mb"]),
                              ("disk_mb", run.disk_bytes / 1e6, limits["disk_mb"])):
        if value > limit:
            raise SceneError(f"limits.{key} = {limit:g}: this scene needs {value:.3g} "
                             f"({run.describe()}); reduce it or raise limits.{key} in the "
                             "scene file or an override")


def target_mesh(target: dict) -> tuple[np.ndarray, np.ndarray, str]:
    """The truth mesh of ``[target]``: vertices (n, 3) float64 [m, body frame B], faces (m, 3)
    int64 and the short target name the log records."""
    kind = target["kind"]
    if kind == "ellipsoid":
        return (*targets.ellipsoid(target["semi_axes"], target["subdivisions"]), "asteroid")
    if kind == "rso-a":
        return (*targets.rso_a(), "rso-a")
    if kind == "rso-b":
        return (*targets.rso_b(), "rso-b")
    if kind == "satellite":
        return (*procedural.satellite(target["seed"]), f"satellite:seed={target['seed']}")
    if kind in ("polyhedron", "cratered-asteroid"):
        build = procedural.polyhedron if kind == "polyhedron" else procedural.cratered_asteroid
        size = target.get("size")
        vertices, faces = build(target["seed"]) if size is None else build(target["seed"], size)
        return vertices, faces, f"{kind}:seed={target['seed']}" + (
            "" if size is None else f",size={size:g}")
    try:
        vertices, faces = targets.load_mesh(target["path"], target["scale"],
                                            center=target["center"], units=target.get("units"))
    except InputError as exc:
        hint = ("" if Path(target["path"]).is_absolute() else
                " (a preset's mesh is looked up in the current directory and the directories "
                "of RECON_MESH_PATH; or set target.path to the file in the scene file or an "
                "override)")
        raise SceneError(f"target.path: {exc}{hint}") from None
    return vertices, faces, f"mesh:{Path(target['path']).name}"


def orbit_mu_and_period(orbit: dict, vertices: np.ndarray, faces: np.ndarray
                        ) -> tuple[float, float]:
    """Gravitational parameter [m^3/s^2] and period [s] of the circular orbit of ``[orbit]``.

    From ``period`` if given, else ``mu``, else ``density`` times the mesh's volume.
    """
    radius = orbit["radius"]
    reach = targets.bounding_radius(vertices)
    if radius <= reach:
        raise SceneError(f"orbit.radius = {radius:g} m puts the orbit inside the target (its "
                         f"farthest point is {reach:.4g} m from the centre)")
    if "period" in orbit:
        period = orbit["period"]
        return 4.0 * math.pi ** 2 * radius ** 3 / period ** 2, period
    if "mu" in orbit:
        mu = orbit["mu"]
    else:
        volume = targets.signed_volume(vertices, faces)
        if not targets.is_closed(faces) or volume <= 0:
            raise SceneError("orbit.density cannot give a mass: the target mesh is not closed; "
                             "give orbit.mu or orbit.period instead")
        mu = GRAVITATIONAL_CONSTANT * orbit["density"] * volume
    return mu, 2.0 * math.pi * math.sqrt(radius ** 3 / mu)


def time_line(time: dict, spin_period: float, *, spice: bool = False) -> tuple[float, int]:
    """Duration [s] of ``[time]`` and its number of shots, at ``t = k * step``."""
    step = time["step"]
    if "duration" in time:
        duration, key = time["duration"], "time.duration"
    else:
        if spice:
            raise SceneError("time.rotations needs the spin model of orbit.kind = \"kepler\"; "
                             "give time.duration for a SPICE-driven scene")
        if math.isinf(spin_period):
            raise SceneError("time.rotations needs a spinning target (target.spin_period is "
                             "inf); give time.duration instead")
        duration, key = time["rotations"] * spin_period, "time.rotations"
    ratio = duration / step
    if not math.isfinite(ratio):
        raise SceneError(f"{key} gives {duration:g} s in steps of {step:g} s: more shots than "
                         "can be counted")
    n_shots = math.floor(ratio + SHOT_COUNT_SLACK)
    if n_shots < 1:
        raise SceneError(f"{key} gives {duration:g} s, shorter than one time.step ({step:g} s)")
    return duration, n_shots


def check_spin_knowledge(spin_period: float, error: float) -> None:
    """The known spin period, ``spin_period + error`` [s], must be a positive spin period."""
    if error == 0:
        return
    if math.isinf(spin_period):
        raise SceneError("errors.spin_period_error needs a spinning target (target.spin_period "
                         "is inf)")
    if spin_period + error <= 0:
        raise SceneError(f"errors.spin_period_error = {error:g} s makes the known spin period "
                         f"{spin_period + error:g} s; it must stay positive")


def sensor_errors(errors: dict) -> SensorErrors:
    """A scene's ``[errors]`` section as the log records it: 3-sigma values in SI units.

    The one conversion from scene units (degrees, milliradians) to radians; the pulse-dilation
    cone is recorded only when dilation is on (SPEC.md: zero when the model is off).
    """
    on = errors["dilation_alpha"] > 0
    return SensorErrors(
        range_sigma3=errors["range_sigma3"],
        azimuth_sigma3=errors["azimuth_sigma3_deg"] * RADIANS_PER["deg"],
        elevation_sigma3=errors["elevation_sigma3_deg"] * RADIANS_PER["deg"],
        position_sigma3=errors["position_sigma3"],
        pulse_dilation_alpha=errors["dilation_alpha"],
        pulse_dilation_half_angle=(errors["dilation_half_angle_mrad"] * RADIANS_PER["mrad"]
                                   if on else 0.0),
        pulse_dilation_subrays=float(errors["dilation_subrays"]) if on else 0.0,
        boresight_misalignment=tuple(v * RADIANS_PER["deg"]
                                     for v in errors["boresight_misalignment_deg"]),
        attitude_bias=tuple(v * RADIANS_PER["arcsec"] for v in errors["attitude_bias_arcsec"]),
        attitude_walk=errors["attitude_walk_arcsec"] * RADIANS_PER["arcsec"]
        / SQRT_SECONDS_PER_HOUR,
        position_bias=tuple(errors["position_bias"]),
        position_bias_inertial=tuple(errors["position_bias_inertial"]),
        position_drift=errors["position_drift"],
        position_drift_time=errors["position_drift_time"] if errors["position_drift"] > 0
        else 0.0,
        spin_axis_error=errors["spin_axis_error_deg"] * RADIANS_PER["deg"],
        spin_period_error=errors["spin_period_error"],
        time_tag_offset=errors["time_tag_offset"])
