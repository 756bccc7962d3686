"""``planes``: global multi-plane segmentation for man-made targets, as planar polygons.

A satellite bus, its panels and most of its appendages are a handful of planes. This method
finds them and returns one polygon per planar patch, or the closed polyhedron they bound.

1. **RANSAC.** Each hypothesis is one point with its oriented normal (one-point RANSAC: two
   random points fewer than the classic three, so 256 hypotheses find a plane holding 3% of
   the points with probability 1 - 0.97^256 > 0.9995). A point is an inlier of a plane when it is
   within ``threshold`` of it and its normal is within ``angle`` of the plane's. The best
   hypothesis, scored on a random subsample, is refined by least squares (SVD of its inliers,
   three rounds of refit and reselect); its inliers are split into connected patches on an
   in-plane occupancy grid; patches with ``min_points`` or more are kept and removed, and the
   search repeats until no plane is left or ``max_planes`` are found.
2. **Least-squares refinement.** Every point is reassigned to the nearest compatible plane and
   each plane is refitted to its points (one round of k-planes).
3. **Surface.** ``closure = "closed"`` intersects the planes' half-spaces (scipy's qhull) into a
   convex polyhedron; ``"open"`` returns each patch's in-plane convex hull as a polygon;
   ``"auto"`` closes only when 99% of the points lie inside every plane's half-space (within the
   threshold), i.e. when the target is convex, and the intersection is bounded.

The inlier threshold is ``threshold`` x max(3 x noise, spacing): three noise sigmas keep 99.7% of
a noisy plane's points; on noise-free clouds one sample spacing.

Curved parts are not modelled: points of a sphere or a dish either become many small facets or
stay unexplained, which ``-m auto`` sees in its held-out error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from formats.errors import MethodFailed
from recon.surfaces.methods import Method, MethodInput, Param, register, watertight

# Hypotheses are scored on at most this many random remaining points.
SCORE_SAMPLE = 20_000
# Least-squares refit-and-reselect rounds after RANSAC.
REFINE_ROUNDS = 3
# Fraction of points that must lie inside every half-space for "auto" to close the surface.
CONVEX_FRACTION = 0.99
# The polyhedron must stay within this factor of the cloud's bounding box (else: unbounded).
BOUNDED_FACTOR = 2.0


@dataclass
class PlanePatch:
    """One planar patch: plane ``normal . x = offset`` and the indices of its points."""

    normal: np.ndarray
    offset: float
    members: np.ndarray


def _fit(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares plane of (m, 3) points: unit normal and offset (``n . x = d``)."""
    centroid = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centroid, full_matrices=False)
    normal = vt[-1]
    return normal, float(normal @ centroid)


def _inliers(points, normals, normal, offset, threshold, cos_angle) -> np.ndarray:
    distance = np.abs(points @ normal - offset)
    return (distance < threshold) & (np.abs(normals @ normal) > cos_angle)


def _plane_basis(normal: np.ndarray) -> np.ndarray:
    """(2, 3) orthonormal in-plane axes u, v with u x v = normal."""
    helper = np.eye(3)[np.argmin(np.abs(normal))]
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    return np.stack([u, np.cross(normal, u)])


def _patches(uv: np.ndarray, cell: float) -> np.ndarray:
    """Connected-patch label (0..p-1) of in-plane points (m, 2) on an occupancy grid."""
    ij = np.floor((uv - uv.min(axis=0)) / cell).astype(np.int64)
    grid = np.zeros(ij.max(axis=0) + 3, dtype=bool)
    grid[ij[:, 0] + 1, ij[:, 1] + 1] = True
    # Close gaps of one cell (scan-line spacing) before labelling, 8-connected.
    closed = ndimage.binary_dilation(grid, structure=np.ones((3, 3), bool))
    labels, _ = ndimage.label(closed, structure=np.ones((3, 3), bool))
    _, label = np.unique(labels[ij[:, 0] + 1, ij[:, 1] + 1], return_inverse=True)
    return label


def segment_planes(cloud: MethodInput, *, threshold: float, angle: float, max_planes: int,
                   min_points: int, hypotheses: int) -> list[PlanePatch]:
    """Find planar patches by one-point RANSAC with least-squares refinement.

    Parameters
    ----------
    cloud : MethodInput
    threshold : float, metres
        Inlier distance.
    angle : float, degrees
        Inlier normal deviation.
    max_planes : int
    min_points : int
        Smallest patch kept.
    hypotheses : int
        RANSAC hypotheses per plane.

    Returns
    -------
    list of PlanePatch
        Normals oriented like the points' normals (outward), largest patch first.
    """
    rng = np.random.default_rng(cloud.seed)
    points, normals = cloud.points, cloud.normals
    cos_angle = np.cos(np.radians(angle))
    cell = max(2.0 * cloud.spacing, threshold)
    remaining = np.ones(len(points), dtype=bool)
    found: list[PlanePatch] = []
    while len(found) < max_planes:
        pool = np.flatnonzero(remaining)
        if len(pool) < min_points:
            break
        seeds = rng.choice(pool, size=min(hypotheses, len(pool)), replace=False)
        sample = rng.choice(pool, size=min(SCORE_SAMPLE, len(pool)), replace=False)
        seed_n = normals[seeds]                                          # (h, 3)
        offsets = np.einsum("hi,hi->h", seed_n, points[seeds])
        distance = np.abs(points[sample] @ seed_n.T - offsets)          # (s, h)
        agree = np.abs(normals[sample] @ seed_n.T) > cos_angle
        best = int(np.argmax(((distance < threshold) & agree).sum(axis=0)))
        normal, offset = seed_n[best], float(offsets[best])
        for _ in range(REFINE_ROUNDS):
            members = pool[_inliers(points[pool], normals[pool], normal, offset, threshold,
                                    cos_angle)]
            if len(members) < 3:
                break
            normal, offset = _fit(points[members])
        members = pool[_inliers(points[pool], normals[pool], normal, offset, threshold,
                                cos_angle)]
        if len(members) < min_points:
            break
        label = _patches(points[members] @ _plane_basis(normal).T, cell)
        sizes = np.bincount(label)
        keep = sizes[label] >= min_points
        if not keep.any():
            break
        if np.mean(normals[members] @ normal) < 0:
            normal, offset = -normal, -offset
        found.append(PlanePatch(normal, offset, members[keep]))
        remaining[members[keep]] = False
    return _reassign(points, normals, found, threshold, cos_angle, min_points)


def _reassign(points, normals, found, threshold, cos_angle, min_points) -> list[PlanePatch]:
    """Least-squares refinement: hand each patch's points to their nearest compatible plane
    among all found (greedy early planes grab points near edges of later ones), then refit."""
    if not found:
        return found
    stack_n = np.stack([p.normal for p in found])                      # (m, 3)
    stack_d = np.array([p.offset for p in found])
    refined = []
    for i, patch in enumerate(found):
        mine = points[patch.members]
        distance = np.abs(mine @ stack_n.T - stack_d)                  # (k, m)
        compatible = np.abs(normals[patch.members] @ stack_n.T) > cos_angle
        owner = np.argmin(np.where(compatible, distance, np.inf), axis=1)
        members = patch.members[owner == i]
        if len(members) < min_points:
            members = patch.members
        normal, offset = _fit(points[members])
        if normal @ patch.normal < 0:
            normal, offset = -normal, -offset
        refined.append(PlanePatch(normal, offset, members))
    refined.sort(key=lambda p: -len(p.members))
    return refined


def closed_polyhedron(points: np.ndarray, patches: list[PlanePatch], threshold: float
                      ) -> tuple[np.ndarray, np.ndarray] | None:
    """Intersect the planes' inner half-spaces; None when not convex enough or unbounded."""
    from scipy.spatial import ConvexHull, HalfspaceIntersection, QhullError

    if len(patches) < 4:
        return None
    n = np.stack([p.normal for p in patches])
    d = np.array([p.offset for p in patches])
    outside = (points @ n.T - d).max(axis=1)
    if np.mean(outside <= threshold) < CONVEX_FRACTION:
        return None
    interior = points.mean(axis=0)
    if np.any(n @ interior - d >= -1e-9 * (1 + np.abs(d))):
        return None
    try:
        hs = HalfspaceIntersection(np.column_stack([n, -d]), interior)
        corners = hs.intersections
        if not np.all(np.isfinite(corners)):
            return None
        low, high = points.min(axis=0), points.max(axis=0)
        margin = BOUNDED_FACTOR * (high - low).max()
        if np.any(corners < low - margin) or np.any(corners > high + margin):
            return None
        hull = ConvexHull(corners)
    except QhullError:
        return None
    faces = hull.simplices.astype(np.int64)
    a, b, c = (corners[faces[:, i]] for i in range(3))
    flip = np.einsum("ij,ij->i", np.cross(b - a, c - a), hull.equations[:, :3]) < 0
    faces[flip] = faces[flip][:, ::-1]
    return corners, faces


def open_polygons(points: np.ndarray, patches: list[PlanePatch], cell: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Each connected patch's in-plane convex hull, fan-triangulated, facing outward."""
    from scipy.spatial import ConvexHull, QhullError

    vertices, faces = [], []
    count = 0
    for patch in patches:
        basis = _plane_basis(patch.normal)
        uv = points[patch.members] @ basis.T
        label = _patches(uv, cell)
        for part in range(label.max() + 1):
            piece = uv[label == part]
            try:
                ring = piece[ConvexHull(piece).vertices]      # counter-clockwise in (u, v)
            except QhullError:                                # collinear or too few points
                continue
            corner = ring @ basis + patch.offset * patch.normal
            m = len(ring)
            fan = np.column_stack([np.zeros(m - 2), np.arange(1, m - 1), np.arange(2, m)])
            vertices.append(corner)
            faces.append(fan.astype(np.int64) + count)
            count += m
    if not faces:
        raise MethodFailed("planes: no patch has a two-dimensional outline")
    return np.concatenate(vertices), np.concatenate(faces)


def run(cloud: MethodInput, *, threshold: float, angle: float, max_planes: int,
        min_fraction: float, hypotheses: int, closure: str) -> tuple[np.ndarray, np.ndarray]:
    """Planar-polygon surface of the cloud.

    Parameters
    ----------
    cloud : MethodInput
    threshold : float
        Inlier distance in units of max(3 x noise, spacing).
    angle : float
        Inlier normal deviation [deg].
    max_planes : int
    min_fraction : float
        Smallest patch as a fraction of the points (at least 10 points).
    hypotheses : int
        RANSAC hypotheses per plane.
    closure : {"auto", "closed", "open"}

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64, counter-clockwise seen from outside
    """
    metres = float(threshold) * max(3.0 * cloud.noise, cloud.spacing)
    min_points = max(10, int(np.ceil(min_fraction * len(cloud.points))))
    patches = segment_planes(cloud, threshold=metres, angle=angle, max_planes=max_planes,
                             min_points=min_points, hypotheses=hypotheses)
    if not patches:
        raise MethodFailed(f"planes: no plane with at least {min_points} points within "
                           f"{metres:.3g} m")
    if closure in ("auto", "closed"):
        closed = closed_polyhedron(cloud.points, patches, metres)
        if closed is not None:
            return closed
        if closure == "closed":
            raise MethodFailed("planes: the planes do not bound a convex polyhedron around "
                               "the points (use closure=open)")
    return open_polygons(cloud.points, patches, max(2.0 * cloud.spacing, metres))


def parameter_count(vertices: np.ndarray, faces: np.ndarray) -> int:
    """Free parameters of a planar model: 3 per distinct plane (normal and offset); open
    polygons add 2 per outline corner (its position in its plane). A closed polyhedron's
    corners follow from its planes."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    offset = np.einsum("ij,ij->i", normal, a)
    scale = float(np.ptp(vertices, axis=0).max()) or 1.0
    planes = np.unique(np.round(np.column_stack([normal, offset / scale]), 6), axis=0)
    return 3 * len(planes) + (0 if watertight(faces) else 2 * len(vertices))


METHOD = register(Method(
    name="planes", run=run, kind="planar", parameters=parameter_count,
    summary="RANSAC + least-squares multi-plane segmentation, planar polygons (man-made targets)",
    params={
        # 1 x max(3 sigma, spacing): see the module docstring.
        "threshold": Param(1.0, float, "inlier distance / max(3 noise, spacing)", minimum=0.0,
                           maximum=100.0),
        # 30 deg: PCA normals of 16 neighbours stay within it at the paper's LRF noise.
        "angle": Param(30.0, float, "inlier normal deviation [deg]", minimum=0.0,
                       maximum=90.0),
        # 30 planes: RSO-A has 6 bus faces, 4 panel faces and a dish; room for small parts.
        "max_planes": Param(30, int, "most planes found", minimum=1, maximum=1000),
        # 0.5 %: a 1 m x 1 m patch on RSO-A's ~300 m^2 of surface.
        "min_fraction": Param(0.005, float, "smallest patch / points", minimum=0.0,
                              maximum=1.0),
        # 256: see the module docstring (3% planes found with probability > 0.9995).
        "hypotheses": Param(256, int, "RANSAC hypotheses per plane", minimum=1,
                            maximum=100_000),
        "closure": Param("auto", str, "closed polyhedron, open polygons, or auto (if convex)",
                         choices=("auto", "closed", "open")),
    },
    grid=({"closure": "open"}, {"threshold": 2.0}, {"max_planes": 100})))
