"""Truth meshes of the simulated targets, in metres, in the target body frame B.

Every builder returns a ``formats.geometry.Mesh`` (it unpacks as ``vertices, faces``):
``(n, 3) float64`` metres in B, centred on the body, and ``(m, 3) int64`` triangles,
counter-clockwise seen from outside (outward normals).

- :func:`ellipsoid`: the paper's tri-axial asteroid, an icosphere scaled onto the ellipsoid, so
  every vertex lies exactly on the surface;
- :func:`rso_a`, :func:`rso_b`: the paper's two satellite-shaped RSOs (Figure 13), each a union of
  closed, outward-oriented parts (boxes, spheres, cylinders) that touch or overlap, as in many
  spacecraft models (the shared ``hst_7.7k.obj`` is 173 closed parts). A few faces of a part lie
  inside another part (under the sphere and where masts meet the bus); they are never hit;
- :func:`load_mesh`: any mesh file recon reads (OBJ, PLY, STL, PDS table, ICQ, DSK), in metres.

Seeded, generated targets (satellites, faceted polyhedra, cratered asteroids) are built from
these primitives in sim/procedural.py.
"""

from __future__ import annotations

import numpy as np

from formats.geometry import Mesh
from formats.mesh_io import read_mesh

# Paper, "Model: Tri-Axial Ellipsoid": semi-axes along x, y and z [m].
ASTEROID_SEMI_AXES = (143.75, 86.25, 287.5)
# Segments around round parts of the RSOs: 32 keeps the chord error of a 1 m radius below 5 mm
# and the whole RSO near 1,200 triangles, the size of the box-and-panels mesh of the ray-casting
# benchmark (benchmarks/bench_simulate.py).
RSO_SEGMENTS = 32


# --------------------------------------------------------------------------- the asteroid


def icosphere(subdivisions: int) -> Mesh:
    """Unit sphere from a subdivided icosahedron.

    Parameters
    ----------
    subdivisions : int, >= 0
        Each subdivision splits every triangle into four: ``20 * 4**subdivisions`` faces.

    Returns
    -------
    vertices : (10 * 4**n + 2, 3) float64, unit vectors
    faces : (20 * 4**n, 3) int64, outward
    """
    if subdivisions < 0:
        raise ValueError(f"subdivisions must be >= 0, got {subdivisions}")
    t = (1.0 + 5.0 ** 0.5) / 2.0
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
                 dtype=np.float64)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]], dtype=np.int64)
    for _ in range(subdivisions):
        # The three edges of every face, (a, b), (b, c), (c, a), as one int64 key each.
        edges = np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        keys = edges[:, 0] * len(v) + edges[:, 1]
        _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
        ends = edges[first]
        mid = v[ends[:, 0]] + v[ends[:, 1]]
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        m = inverse.reshape(-1, 3) + len(v)   # midpoints of edges ab, bc, ca
        v = np.vstack([v, mid])
        a, b, c = f.T
        ab, bc, ca = m.T
        f = np.concatenate([np.stack(x, axis=1) for x in
                            ((a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca))])
    return Mesh(v, f)


def ellipsoid(semi_axes=ASTEROID_SEMI_AXES, subdivisions: int = 5) -> Mesh:
    """The paper's tri-axial ellipsoid asteroid, triangulated.

    Parameters
    ----------
    semi_axes : 3 floats, metres
        Semi-axes along body x, y and z; default the paper's 143.75, 86.25 and 287.5 m.
    subdivisions : int
        Icosphere subdivisions: ``20 * 4**subdivisions`` faces (5: 20,480).

    Returns
    -------
    vertices : (n, 3) float64, metres, body frame B; each lies on the ellipsoid
    faces : (m, 3) int64, outward
    """
    axes = np.asarray(semi_axes, dtype=np.float64)
    if axes.shape != (3,) or not np.all(np.isfinite(axes) & (axes > 0)):
        raise ValueError(f"semi_axes must be 3 positive lengths, got {semi_axes!r}")
    v, f = icosphere(subdivisions)
    return Mesh(v * axes, f)   # scaling by positive factors keeps the faces outward


# --------------------------------------------------------------------------- primitives


def _orient_outward(v: np.ndarray, f: np.ndarray, centre) -> np.ndarray:
    """Flip faces of a convex part whose normals point towards its centre."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    normal = np.cross(b - a, c - a)
    inward = np.einsum("ij,ij->i", normal, (a + b + c) / 3.0 - centre) < 0
    f = f.copy()
    f[inward] = f[inward][:, ::-1]
    return f


def box(lo, hi) -> Mesh:
    """Axis-aligned box from corner ``lo`` to corner ``hi`` [m]: 8 vertices, 12 faces."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], np.float64)
    v = lo + corners * (hi - lo)
    # Corner index = 4 i + 2 j + k; two triangles per side.
    f = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]], np.int64)
    return Mesh(v, _orient_outward(v, f, (lo + hi) / 2.0))


def axis_frame(axis) -> np.ndarray:
    """A right-handed orthonormal basis (3, 3) whose third column is ``axis``."""
    w = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(helper, w)
    u /= np.linalg.norm(u)
    return np.stack([u, np.cross(w, u), w], axis=1)


def sphere(centre, radius: float, segments: int = RSO_SEGMENTS) -> Mesh:
    """UV sphere [m] with ``segments`` meridians and ``segments // 2`` latitude bands."""
    n_lat = max(segments // 2, 2)
    theta = np.pi * np.arange(1, n_lat) / n_lat            # polar angles of the rings
    phi = 2.0 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.outer(np.sin(theta), np.cos(phi)), np.outer(np.sin(theta), np.sin(phi)),
                     np.outer(np.cos(theta), np.ones(segments))], axis=-1).reshape(-1, 3)
    v = np.vstack([ring, [[0, 0, 1], [0, 0, -1]]]) * radius + np.asarray(centre, np.float64)
    north, south = len(ring), len(ring) + 1
    i = np.arange(segments)
    j = (i + 1) % segments
    faces = [np.stack([np.full(segments, north), i, j], axis=1)]
    for r in range(n_lat - 2):
        a, b = r * segments + i, r * segments + j
        c, d = a + segments, b + segments
        faces += [np.stack([a, c, d], axis=1), np.stack([a, d, b], axis=1)]
    last = (n_lat - 2) * segments
    faces.append(np.stack([np.full(segments, south), last + j, last + i], axis=1))
    return Mesh(v, _orient_outward(v, np.concatenate(faces).astype(np.int64), centre))


def cylinder(base, axis, radius: float, length: float, segments: int = RSO_SEGMENTS) -> Mesh:
    """Closed cylinder [m] from the centre of its base along ``axis`` for ``length``."""
    frame = axis_frame(axis)
    phi = 2.0 * np.pi * np.arange(segments) / segments
    circle = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros(segments)], axis=1)
    top = circle + np.array([0.0, 0.0, length])
    local = np.vstack([circle, top, [[0, 0, 0], [0, 0, length]]])
    v = local @ frame.T + np.asarray(base, np.float64)
    i = np.arange(segments)
    j = (i + 1) % segments
    nb, nt = 2 * segments, 2 * segments + 1
    f = np.concatenate([np.stack([i, j, j + segments], axis=1),
                        np.stack([i, j + segments, i + segments], axis=1),
                        np.stack([np.full(segments, nb), j, i], axis=1),
                        np.stack([np.full(segments, nt), i + segments, j + segments], axis=1)])
    centre = np.asarray(base, np.float64) + frame[:, 2] * length / 2.0
    return Mesh(v, _orient_outward(v, f.astype(np.int64), centre))


def combine(*parts: Mesh) -> Mesh:
    """Concatenate meshes into one (no boolean union: parts may touch or overlap)."""
    vertices, faces, offset = [], [], 0
    for v, f in parts:
        vertices.append(v)
        faces.append(f + offset)
        offset += len(v)
    return Mesh(np.vstack(vertices), np.vstack(faces).astype(np.int64))


# --------------------------------------------------------------------------- the RSOs


def rso_a(segments: int = RSO_SEGMENTS) -> Mesh:
    """The paper's RSO-A: a 5 m cube bus, a sphere and a dish on +y, solar panels along x.

    Geometry (metres, body frame B at the bus centre; the paper gives only the 5 m bus and the
    20 m span along the panels' axis):

    - bus: cube of edge 5, ``[-2.5, 2.5]^3``;
    - sphere: radius 1.0 centred at (-1.2, 3.1, 0), protruding 1.6 from the +y face;
    - dish: a mast (radius 0.1) from the +y face to y = 3.5, then a disk of radius 1.0 and
      thickness 0.1 facing +y, at x = 1.2;
    - two solar panels 7 x 2.4 x 0.06 in the x-z plane, from |x| = 3 to 10, each on a 0.2 m
      square boom from the bus: the RSO spans x = -10 to 10 (20 m, "oblate along its x-axis").

    Returns
    -------
    vertices : (n, 3) float64, metres, B
    faces : (m, 3) int64, outward
    """
    parts = [box([-2.5, -2.5, -2.5], [2.5, 2.5, 2.5]),
             sphere([-1.2, 3.1, 0.0], 1.0, segments),
             cylinder([1.2, 2.5, 0.0], [0, 1, 0], 0.1, 1.0, segments),
             cylinder([1.2, 3.5, 0.0], [0, 1, 0], 1.0, 0.1, segments)]
    for s in (-1.0, 1.0):
        lo_b, hi_b = sorted([s * 2.5, s * 3.0])
        parts.append(box([lo_b, -0.1, -0.1], [hi_b, 0.1, 0.1]))
        lo_p, hi_p = sorted([s * 3.0, s * 10.0])
        parts.append(box([lo_p, -0.03, -1.2], [hi_p, 0.03, 1.2]))
    return combine(*parts)


def rso_b(segments: int = RSO_SEGMENTS) -> Mesh:
    """The paper's RSO-B: two stacked cubes, two cylinders, a pole with a disk, one panel.

    Geometry (metres, body frame B at the joint of the two cubes; the paper describes only the
    parts and the 20 m span along x, "less oblate than RSO A but [with] more fine detail"):

    - lower cube: edge 4, ``[-2, 2] x [-2, 2] x [-4, 0]``; upper cube: edge 3, ``[-1.5, 1.5]^2
      x [0, 3]``;
    - two cylindrical protrusions from the lower cube along +y and -y: radius 0.6, length 1.2 and
      radius 0.4, length 2.0, at z = -2;
    - a pole (radius 0.1) along +x from the upper cube (x = 1.5) at z = 1.5, ending in a disk of
      radius 1.5 and thickness 0.1 facing +x, its outer face at x = 10;
    - one solar panel 7.5 x 2 x 0.06 in the x-z plane from x = -2.5 to -10 at z in [-3, -1], on a
      0.2 m square boom from the lower cube: the RSO spans x = -10 to 10 (20 m).

    Returns
    -------
    vertices : (n, 3) float64, metres, B
    faces : (m, 3) int64, outward
    """
    return combine(box([-2.0, -2.0, -4.0], [2.0, 2.0, 0.0]),
                   box([-1.5, -1.5, 0.0], [1.5, 1.5, 3.0]),
                   cylinder([0.0, 2.0, -2.0], [0, 1, 0], 0.6, 1.2, segments),
                   cylinder([0.0, -2.0, -2.0], [0, -1, 0], 0.4, 2.0, segments),
                   cylinder([1.5, 0.0, 1.5], [1, 0, 0], 0.1, 8.4, segments),
                   cylinder([9.9, 0.0, 1.5], [1, 0, 0], 1.5, 0.1, segments),
                   box([-2.5, -0.1, -2.1], [-2.0, 0.1, -1.9]),
                   box([-10.0, -0.03, -3.0], [-2.5, 0.03, -1.0]))


# --------------------------------------------------------------------------- user meshes


def load_mesh(path, scale: float = 1.0, *, center: bool = False,
              units: str | None = None) -> Mesh:
    """Read a triangle mesh (OBJ, PLY, STL, PDS table, ICQ, DSK) in metres: the target's shape,
    whose coordinates define the body frame B.

    Parameters
    ----------
    path : str or Path
    scale : float, > 0
        Factor after the unit conversion (e.g. 1000 for an OBJ model in km read as metres).
    center : bool
        Translate the mesh so its volume centroid (vertex mean for an open mesh) is the origin.
    units : {"km", "m"}, optional
        Units of the file (default: km for PDS tables, ICQ and DSK, metres otherwise;
        formats.mesh_io.read_mesh).

    Returns
    -------
    vertices : (n, 3) float64, metres, body frame B
    faces : (m, 3) int64

    Raises
    ------
    InputError
        The file is missing, unreadable or has no triangles, or ``scale`` is not positive
        (formats.mesh_io.read_mesh).
    """
    vertices, faces = read_mesh(path, scale=scale, units=units)
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    if center:
        vertices = vertices - centroid(vertices, faces)
    return Mesh(vertices, faces)


# --------------------------------------------------------------------------- properties


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Enclosed volume [m^3] by the divergence theorem; positive for outward faces."""
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)


def centroid(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Volume centroid (3,) of a closed mesh [m]; the vertex mean if the mesh is not closed."""
    if not is_closed(faces):
        return vertices.mean(axis=0)
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    w = np.einsum("ij,ij->i", a, np.cross(b, c))
    if abs(w.sum()) < 1e-300:
        return vertices.mean(axis=0)
    return ((a + b + c) * w[:, None]).sum(axis=0) / (4.0 * w.sum())


def is_closed(faces: np.ndarray) -> bool:
    """True when every directed edge has exactly one opposite twin: closed, consistently
    oriented."""
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).astype(np.int64)
    n = int(directed.max()) + 1 if len(directed) else 0
    forward = directed[:, 0] * n + directed[:, 1]
    backward = directed[:, 1] * n + directed[:, 0]
    if len(np.unique(forward)) != len(forward):
        return False
    return bool(np.all(np.isin(backward, forward, assume_unique=True)))


def bounding_radius(vertices: np.ndarray) -> float:
    """Largest distance [m] of a vertex from the body-frame origin."""
    return float(np.sqrt(np.max(np.einsum("ij,ij->i", vertices, vertices))))
