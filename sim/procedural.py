"""Seeded, procedurally generated targets: spacecraft, faceted bodies and cratered asteroids.

Shapes that nobody tuned a method on: every size and placement is drawn from
``np.random.default_rng(seed)``, so the same seed gives the same bytes and a new seed a new
body. Each builder returns a ``formats.geometry.Mesh`` like those of sim/targets.py: vertices
``(n, 3) float64`` metres in the body frame B, faces ``(m, 3) int64`` counter-clockwise seen
from outside.

- :func:`satellite`: a bus (box), a thin parabolic dish on a mast, a boom with a box at its
  end and two to four thin solar panels on arms along +-x; a union of closed, outward parts that
  touch, as :func:`sim.targets.rso_a` (its dimensions: :func:`satellite_design`);
- :func:`polyhedron`: a convex faceted body, the hull of random points on a random ellipsoid
  (20 to 28 triangular facets);
- :func:`cratered_asteroid`: a closed, star-shaped, non-convex body: a perturbed ellipsoid with
  a large shallow concavity and bowl craters with raised rims.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from formats.geometry import Mesh
from sim.targets import RSO_SEGMENTS, axis_frame, box, combine, cylinder, icosphere

# --------------------------------------------------------------------------- ranges
# Satellite ranges (metres): small to medium spacecraft, the scale of the paper's RSOs (5 m bus,
# 20 m span). Bus edges 1-3 m; solar wings 4-8 m from the arm to the tip, each wing of one or two
# panels 1-2.5 m wide and 2-6 cm thick (rigid honeycomb panels); dish 0.5-1.5 m radius, its depth
# 10-25 % of its radius, a 3-5 cm shell; a 2-5 m boom carrying a 0.3-0.8 m box (a magnetometer
# or sensor head).
BUS_EDGE_M = (1.0, 3.0)
WING_LENGTH_M = (4.0, 8.0)
PANEL_WIDTH_M = (1.0, 2.5)
PANEL_THICKNESS_M = (0.02, 0.06)
PANEL_GAP_M = (0.1, 0.3)             # between two panels of one wing, bridged by the arm
PANELS = (2, 4)                      # panels in all, inclusive
ARM_SECTION_M = (0.08, 0.2)          # square arm from the bus to the first panel
ARM_LENGTH_M = (0.3, 1.0)            # beyond whatever clears the dish
WING_TILT_DEG = 60.0                 # panels turned about x by up to this, either way
DISH_RADIUS_M = (0.5, 1.5)
DISH_DEPTH_FRACTION = (0.10, 0.25)
DISH_THICKNESS_M = (0.03, 0.05)
MAST_RADIUS_M = (0.04, 0.08)
MAST_LENGTH_M = (0.3, 1.0)
BOOM_RADIUS_M = (0.04, 0.1)
BOOM_LENGTH_M = (2.0, 5.0)
END_BOX_EDGE_M = (0.3, 0.8)
# Mounting offsets of the dish mast and the boom on their bus faces, as a fraction of the
# face's half-edges: they stay near the face centre and clear of the wings' arms.
MOUNT_OFFSET_FRACTION = 0.3
DISH_RINGS = 8                       # rings of the dish's polar grid, centre to rim

# Polyhedron: 12-16 points in convex position give 20-28 triangles (2 n - 4); the ellipsoid's
# shorter axes are 50-100 % of the longest, so bodies range from round to elongated.
POLYHEDRON_POINTS = (12, 16)
AXIS_RATIO = (0.5, 1.0)
DEFAULT_POLYHEDRON_SIZE_M = 5.7      # longest extent, the size of a small spacecraft bus

# Cratered asteroid: an icosphere of 6 subdivisions (81,920 faces, a vertex every ~1 deg, 4.4 m
# on a 500 m body), so the smallest crater (3 deg) spans ~6 vertices. Crater depth/diameter
# 0.1-0.2 and rim height 0.04 diameter are those of fresh simple craters (Pike 1977, Melosh
# 1989 ch. 6). The large concavity, 30-45 deg across and 30-45 % of the radius deep (more than
# the 13-29 % sagitta of a sphere over that angle), leaves a 25-60 m deep pocket under the hull
# of a 500 m body, a non-convex waist as on Itokawa or Eros.
ASTEROID_SUBDIVISIONS = 6
DEFAULT_ASTEROID_SIZE_M = 500.0      # longest extent, near the paper's 575 m asteroid
ASTEROID_AXIS_RATIO = (0.55, 0.9)
CRATERS = (10, 20)
CRATER_RADIUS_DEG = (3.0, 15.0)
CRATER_DEPTH_TO_DIAMETER = (0.1, 0.2)
CRATER_RIM_TO_DIAMETER = 0.04
CRATER_RIM_REACH = 0.5               # the rim decays to zero half a crater radius outside it
CONCAVITY_RADIUS_DEG = (30.0, 45.0)
CONCAVITY_DEPTH_FRACTION = (0.30, 0.45)
BUMPS = 6                            # broad random bumps and dents, +-8 % of the radius
BUMP_AMPLITUDE_FRACTION = 0.08
BUMP_WIDTH_DEG = (30.0, 70.0)


def _check_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def _check_size(size) -> float:
    if not np.isfinite(size) or size <= 0:
        raise ValueError(f"size must be a positive length [m], got {size!r}")
    return float(size)


def _placed(mesh: Mesh, rotation: np.ndarray, offset) -> Mesh:
    """A part rotated (proper rotation, (3, 3), keeps faces outward) then moved by ``offset``."""
    v, f = mesh
    return Mesh(v @ rotation.T + np.asarray(offset, np.float64), f)


# --------------------------------------------------------------------------- the satellite


@dataclass(frozen=True)
class Panel:
    """One solar panel: a thin box along x from ``x0`` to ``x1`` [m] (signed: the wing's side),
    ``width`` along the wing's tilted z, ``thickness`` along its tilted y."""

    x0: float
    x1: float
    width: float
    thickness: float
    tilt_deg: float


@dataclass(frozen=True)
class SatelliteDesign:
    """Every dimension of a generated satellite [m, body frame B at the bus centre].

    Attributes
    ----------
    bus : (3,) float
        Edges of the bus box along x, y, z, centred on the origin.
    panels : tuple of Panel
        Two wings along +x and -x, each of one or two panels in a row.
    arm_section : float
        Edge of the square arms from the bus faces +-x to the panels (and across the gaps).
    dish_face, boom_face : (3,) int
        Outward normals of the bus faces carrying the dish mast and the boom (+-y or +-z).
    dish_mount, boom_mount : (3,) float
        Points on those faces where the mast and the boom start.
    mast_radius, mast_length : float
    dish_radius, dish_depth, dish_thickness : float
        The dish: a paraboloid cap of that rim radius and depth, opening away from the bus.
    boom_radius, boom_length : float
    end_box : (3,) float
        Edges of the box at the boom's end (the boom meets the centre of its inner face).
    """

    bus: tuple[float, float, float]
    panels: tuple[Panel, ...]
    arm_section: float
    dish_face: tuple[int, int, int]
    dish_mount: tuple[float, float, float]
    mast_radius: float
    mast_length: float
    dish_radius: float
    dish_depth: float
    dish_thickness: float
    boom_face: tuple[int, int, int]
    boom_mount: tuple[float, float, float]
    boom_radius: float
    boom_length: float
    end_box: tuple[float, float, float]


def _mount(rng, normal: np.ndarray, half: np.ndarray) -> np.ndarray:
    """A point on the bus face of outward ``normal``, near its centre."""
    offset = rng.uniform(-1.0, 1.0, 3) * MOUNT_OFFSET_FRACTION * half
    axis = int(np.argmax(np.abs(normal)))
    offset[axis] = normal[axis] * half[axis]
    return offset


def satellite_design(seed: int) -> SatelliteDesign:
    """Draw the dimensions of a satellite from ``seed`` (ranges: the module's constants).

    The dish and the boom sit on two different bus faces among +-y and +-z; the wings leave the
    +-x faces on arms long enough to clear the dish. Parts touch; none cuts another.
    """
    rng = np.random.default_rng(_check_seed(seed))
    bus = rng.uniform(*BUS_EDGE_M, 3)
    half = bus / 2.0
    faces = np.array([[0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
    dish_face, boom_face = faces[rng.permutation(4)[:2]]
    dish_mount, boom_mount = _mount(rng, dish_face, half), _mount(rng, boom_face, half)
    dish_radius = rng.uniform(*DISH_RADIUS_M)
    # The arms reach past the dish's rim along x, so no panel, however tilted, meets it.
    clear = max(0.0, abs(dish_mount[0]) + dish_radius - half[0])
    n_panels = int(rng.integers(PANELS[0], PANELS[1] + 1))
    per_wing = {2: (1, 1), 3: (2, 1), 4: (2, 2)}[n_panels]
    panels = []
    for side, count in zip((1.0, -1.0), per_wing, strict=True):
        start = half[0] + clear + rng.uniform(*ARM_LENGTH_M)
        gap = rng.uniform(*PANEL_GAP_M)
        length = (rng.uniform(*WING_LENGTH_M) - (count - 1) * gap) / count
        width, thickness = rng.uniform(*PANEL_WIDTH_M), rng.uniform(*PANEL_THICKNESS_M)
        tilt = rng.uniform(-WING_TILT_DEG, WING_TILT_DEG)
        for k in range(count):
            x0 = start + k * (length + gap)
            panels.append(Panel(float(side * x0), float(side * (x0 + length)), float(width),
                                float(thickness), float(tilt)))
    def floats(x):
        return tuple(float(e) for e in x)

    return SatelliteDesign(
        bus=floats(bus), panels=tuple(panels), arm_section=float(rng.uniform(*ARM_SECTION_M)),
        dish_face=tuple(int(x) for x in dish_face), dish_mount=floats(dish_mount),
        mast_radius=float(rng.uniform(*MAST_RADIUS_M)),
        mast_length=float(rng.uniform(*MAST_LENGTH_M)), dish_radius=float(dish_radius),
        dish_depth=float(dish_radius * rng.uniform(*DISH_DEPTH_FRACTION)),
        dish_thickness=float(rng.uniform(*DISH_THICKNESS_M)),
        boom_face=tuple(int(x) for x in boom_face), boom_mount=floats(boom_mount),
        boom_radius=float(rng.uniform(*BOOM_RADIUS_M)),
        boom_length=float(rng.uniform(*BOOM_LENGTH_M)),
        end_box=floats(rng.uniform(*END_BOX_EDGE_M, 3)))


def dish(radius: float, depth: float, thickness: float, *, rings: int = DISH_RINGS,
         segments: int = RSO_SEGMENTS) -> Mesh:
    """A closed, thin paraboloid cap opening towards +z, its back vertex at the origin.

    The back surface is ``z = depth * (r / radius)**2``, the front the same raised by
    ``thickness``; a strip joins them at the rim.

    Returns
    -------
    vertices : (2 * (rings * segments + 1), 3) float64, metres
    faces : (4 * rings * segments, 3) int64, outward
    """
    r = radius * np.arange(1, rings + 1) / rings
    phi = 2.0 * np.pi * np.arange(segments) / segments
    x, y = np.outer(r, np.cos(phi)).ravel(), np.outer(r, np.sin(phi)).ravel()
    z = np.repeat(depth * (r / radius) ** 2, segments)
    back = np.vstack([[0.0, 0.0, 0.0], np.stack([x, y, z], axis=1)])
    v = np.vstack([back, back + np.array([0.0, 0.0, thickness])])
    n = len(back)
    i = np.arange(segments)
    j = (i + 1) % segments
    # The back surface, seen from below (-z): fan at the centre, then quads between rings.
    tri = [np.stack([np.zeros(segments, np.int64), 1 + j, 1 + i], axis=1)]
    for k in range(rings - 1):
        a, b = 1 + k * segments + i, 1 + k * segments + j
        tri += [np.stack([a, b + segments, a + segments], axis=1),
                np.stack([a, b, b + segments], axis=1)]
    back_faces = np.concatenate(tri)
    front_faces = back_faces[:, ::-1] + n          # the same grid seen from above (+z)
    a, b = 1 + (rings - 1) * segments + i, 1 + (rings - 1) * segments + j
    rim = np.concatenate([np.stack([a, b, b + n], axis=1), np.stack([a, b + n, a + n], axis=1)])
    return Mesh(v, np.concatenate([back_faces, front_faces, rim]).astype(np.int64))


def satellite(seed: int = 0, *, segments: int = RSO_SEGMENTS) -> Mesh:
    """A seeded random spacecraft (its dimensions: :func:`satellite_design`).

    Parts, each closed and outward, touching where they meet: the bus box; per panel, a thin
    box turned by its wing's tilt about x, and the square arm from the bus (or the previous
    panel) to it; a mast from a +-y or +-z face carrying a thin paraboloid dish that opens away
    from the bus; on another of those faces a boom (cylinder) ending in a box.

    Parameters
    ----------
    seed : int, >= 0
    segments : int
        Segments around the round parts (the dish, the mast, the boom).

    Returns
    -------
    vertices : (n, 3) float64, metres, body frame B at the bus centre
    faces : (m, 3) int64, outward
    """
    d = satellite_design(seed)
    half = np.asarray(d.bus) / 2.0
    parts = [box(-half, half)]
    a = d.arm_section / 2.0
    inner = {1.0: half[0], -1.0: -half[0]}          # where each wing's next arm starts
    for p in d.panels:
        side = float(np.sign(p.x1))
        tilt = Rotation.from_euler("x", p.tilt_deg, degrees=True).as_matrix()
        lo, hi = sorted([inner[side], p.x0])
        parts.append(box([lo, -a, -a], [hi, a, a]))
        lo, hi = sorted([p.x0, p.x1])
        panel = box([lo, -p.thickness / 2, -p.width / 2], [hi, p.thickness / 2, p.width / 2])
        parts.append(_placed(panel, tilt, [0.0, 0.0, 0.0]))
        inner[side] = p.x1
    dish_axis = np.asarray(d.dish_face, np.float64)
    parts.append(cylinder(d.dish_mount, dish_axis, d.mast_radius,
                          d.mast_length + d.dish_thickness / 2, segments))
    parts.append(_placed(dish(d.dish_radius, d.dish_depth, d.dish_thickness,
                              segments=segments), axis_frame(dish_axis),
                         np.asarray(d.dish_mount) + d.mast_length * dish_axis))
    boom_axis = np.asarray(d.boom_face, np.float64)
    parts.append(cylinder(d.boom_mount, boom_axis, d.boom_radius, d.boom_length, segments))
    end = np.asarray(d.boom_mount) + d.boom_length * boom_axis
    edges = np.asarray(d.end_box)
    centre = end + boom_axis * edges / 2.0
    parts.append(box(centre - edges / 2.0, centre + edges / 2.0))
    return combine(*parts)


# --------------------------------------------------------------------------- the polyhedron


def _longest_extent(v: np.ndarray, size: float) -> np.ndarray:
    """Vertices centred on their bounding box and scaled so its longest edge is ``size``."""
    v = v - (v.min(axis=0) + v.max(axis=0)) / 2.0
    return v * (size / np.ptp(v, axis=0).max())


def _random_axes(rng, ratio) -> np.ndarray:
    """Semi-axes (3,) of a random ellipsoid: 1 and two ratios drawn from ``ratio``, in a
    random order."""
    return rng.permutation(np.array([1.0, *rng.uniform(*ratio, 2)]))


def polyhedron(seed: int = 0, size: float = DEFAULT_POLYHEDRON_SIZE_M) -> Mesh:
    """A seeded convex faceted body: the hull of 12-16 random points on a random ellipsoid.

    Every point is a vertex of the hull (points on an ellipsoid are in convex position), so it
    has ``2 n - 4`` triangular facets (20 to 28). The shape depends on the seed only; ``size``
    scales it, so two sizes of one seed are the same body.

    Parameters
    ----------
    seed : int, >= 0
    size : float, metres
        The longest edge of its bounding box (centred on the origin).

    Returns
    -------
    vertices : (n, 3) float64, metres, body frame B
    faces : (2 n - 4, 3) int64, outward
    """
    rng = np.random.default_rng(_check_seed(seed))
    size = _check_size(size)
    n = int(rng.integers(POLYHEDRON_POINTS[0], POLYHEDRON_POINTS[1] + 1))
    directions = rng.normal(size=(n, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    points = _longest_extent(directions * _random_axes(rng, AXIS_RATIO), size)
    hull = ConvexHull(points)
    # Keep the hull's vertices only, in their order; orient each facet away from the interior.
    used = np.unique(hull.simplices)
    index = np.full(n, -1, np.int64)
    index[used] = np.arange(len(used))
    v = points[used]
    f = index[hull.simplices]
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), (a + b + c) / 3 - v.mean(axis=0)) < 0
    f[inward] = f[inward][:, ::-1]
    return Mesh(v, f)


# --------------------------------------------------------------------------- the asteroid


def _crater_profile(s: np.ndarray, depth: float, rim: float) -> np.ndarray:
    """Height [m] of a bowl crater at ``s`` crater radii from its centre: a parabolic bowl
    ``depth`` below its rim, the rim ``rim`` above the ground, decaying to zero outside."""
    bowl = rim + depth * (s ** 2 - 1.0)
    outside = rim * np.clip((1.0 + CRATER_RIM_REACH - s) / CRATER_RIM_REACH, 0.0, 1.0) ** 3
    return np.where(s <= 1.0, bowl, outside)


def _angle(u: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Angles [rad] (n, k) between unit vectors u (n, 3) and centres (k, 3)."""
    return np.arccos(np.clip(u @ centres.T, -1.0, 1.0))


def _unit(rng, k: int) -> np.ndarray:
    x = rng.normal(size=(k, 3))
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def cratered_asteroid(seed: int = 0, size: float = DEFAULT_ASTEROID_SIZE_M, *,
                      subdivisions: int = ASTEROID_SUBDIVISIONS) -> Mesh:
    """A seeded, non-convex cratered asteroid: closed, star-shaped (never folds).

    Each icosphere vertex direction ``u`` is pushed to the radius of a random ellipsoid, times
    ``1 +`` broad random bumps and dents, minus one large smooth concavity, plus the height of
    10-20 bowl craters with rims (3-15 deg across); all in units of the mean radius, then the
    body is scaled to ``size``. Radii stay positive, so the mesh is closed and never folds.

    Parameters
    ----------
    seed : int, >= 0
    size : float, metres
        The longest edge of its bounding box (centred on the origin).
    subdivisions : int
        Of the icosphere: ``20 * 4**subdivisions`` faces (6: 81,920).

    Returns
    -------
    vertices : (n, 3) float64, metres, body frame B
    faces : (m, 3) int64, outward
    """
    rng = np.random.default_rng(_check_seed(seed))
    size = _check_size(size)
    u, f = icosphere(subdivisions)
    axes = _random_axes(rng, ASTEROID_AXIS_RATIO)
    radius = 1.0 / np.sqrt(((u / axes) ** 2).sum(axis=1))
    bumps = _unit(rng, BUMPS)
    width = np.radians(rng.uniform(*BUMP_WIDTH_DEG, BUMPS))
    amplitude = rng.uniform(-1.0, 1.0, BUMPS) * BUMP_AMPLITUDE_FRACTION
    radius = radius * (1.0 + (amplitude * np.exp(-(_angle(u, bumps) / width) ** 2)).sum(axis=1))
    mean = radius.mean()
    centre = _unit(rng, 1)
    reach = np.radians(rng.uniform(*CONCAVITY_RADIUS_DEG))
    depth = rng.uniform(*CONCAVITY_DEPTH_FRACTION) * mean
    s = np.clip(_angle(u, centre)[:, 0] / reach, 0.0, 1.0)
    radius = radius - depth * (1.0 - s ** 2) ** 2
    k = int(rng.integers(CRATERS[0], CRATERS[1] + 1))
    centres = _unit(rng, k)
    reach = np.radians(rng.uniform(*CRATER_RADIUS_DEG, k))
    diameter = 2.0 * reach * mean
    depths = rng.uniform(*CRATER_DEPTH_TO_DIAMETER, k) * diameter
    heights = _crater_profile(_angle(u, centres) / reach, depths, CRATER_RIM_TO_DIAMETER * diameter)
    radius = radius + heights.sum(axis=1)
    return Mesh(_longest_extent(u * radius[:, None], size), f)
