"""``delaunay-balls``: Voronoi-based reconstruction from big Delaunay balls, noise-robust.

The paper's ref. 11 reconstructs with the Voronoi diagram of the samples. Its Voronoi vertices
are the centres of the Delaunay balls (circumspheres of the Delaunay tetrahedra); on a noisy
cloud most balls are small pockets between noisy samples, but the **big** ones approximate the
medial balls of the shape, inside or outside it. Robust Cocone (Dey and Goswami 2006, "Provable
surface reconstruction from noisy samples") keeps exactly these and returns the boundary of the
union of the inner big balls' tetrahedra; the power crust (Amenta, Choi and Kolluri 2001) does
the same with the poles, the farthest Voronoi vertices of each sample. This method follows that
recipe on scipy's qhull Delaunay triangulation:

1. **Denoise** (``denoise``; by default when the cloud's noise scale exceeds
   ``DENOISE_NOISE`` of its spacing): each point moves onto its robust local least-squares
   plane (``plane.project_to_planes``, 30 neighbours, weighted by each strike's recorded
   uncertainty with ``weighted``), so the pockets between noisy samples shrink. On clean
   clouds it would only add the plane's curvature bias.
2. **Delaunay** tetrahedralisation (qhull) of the points in general position
   (``_backends.general_position``: a seeded offset of 1e-4 spacings, without which noise-free
   or denoised, hence coplanar, samples stall qhull for minutes), each tetrahedron's
   circumcentre ``c`` (its Voronoi vertex) and radius ``r``.
3. **Big balls**, ``r > kappa * spacing``, are labelled by the oriented normals of their four
   samples: a medial ball touches the surface where it is tangent, so ``n_i . (c - p_i) / r``
   is near -1 for an inner ball and +1 for an outer one. Balls whose mean lies beyond
   ``+-CONFIDENT`` are seeds (Robust Cocone separates inner from outer balls by their union's
   components; the view-point oriented normals the log gives us make that a local test).
4. **Labelling by a minimum cut** (in place of Robust Cocone's Tight Cocone pass, which makes
   its output watertight): the tetrahedra form a graph whose edges are their shared triangles,
   with the triangles' areas as capacities; inner seeds connect to a source, outer seeds and the
   convex hull's outside to a sink. The minimum cut (scipy's ``maximum_flow``) is the least-area
   surface of Delaunay triangles that separates inner from outer balls: closed, through
   (denoised) samples, and it cuts straight across noise pockets and small gaps.

The result is watertight and interpolates the denoised points. Parts thinner than about
``kappa`` spacings hold no inner big ball and are cut away (a thin solar panel), as in Robust
Cocone, whose guarantees also assume dense sampling.
"""

from __future__ import annotations

import numpy as np

from formats.errors import MethodFailed
from recon.surfaces import uncertainty
from recon.surfaces.methods import Method, MethodInput, Param, register
from recon.surfaces.methods._backends import (
    CELL_FACETS,
    boundary_faces,
    general_position,
    source_side,
)
from recon.surfaces.methods.plane import project_to_planes

# Mean n . (c - p) / r beyond which a big ball is a seed: its four samples agree that the ball
# lies on one side (a medial ball gives 1; 0.5 allows ~60 deg of normal noise).
CONFIDENT = 0.5
# Neighbours and robust rounds of the denoising projection: the ``plane`` method's defaults.
DENOISE_K, DENOISE_ITERATIONS = 30, 2
# Automatic denoising above this noise / spacing: noise-free samples of a unit sphere at 6000
# points measure 0.03 (curvature), with 0.002 noise 0.05, with 0.01 noise 0.2; denoising halves
# the Chamfer distance at 0.2 and doubles it on clean clouds (measured on the sphere and box).
DENOISE_NOISE = 0.1
# Capacities are integers: areas in units of spacing^2 / AREA_UNITS; a seed's link to its
# terminal is SEED_CAPACITY (far above any triangle's), so seeds keep their label.
AREA_UNITS = 100.0
SEED_CAPACITY = 1 << 24


def circumspheres(points: np.ndarray, simplices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Circumcentres (m, 3) and radii (m,) of tetrahedra ``simplices`` (m, 4) of ``points``."""
    p0 = points[simplices[:, 0]]
    edges = points[simplices[:, 1:]] - p0[:, None, :]                  # (m, 3, 3)
    rhs = 0.5 * np.einsum("mij,mij->mi", edges, edges)
    det = np.linalg.det(edges)
    good = np.abs(det) > 1e-12 * np.einsum("mij,mij->m", edges, edges) ** 1.5
    offset = np.full((len(simplices), 3), np.inf)
    offset[good] = np.linalg.solve(edges[good], rhs[good][..., None])[..., 0]
    return p0 + offset, np.linalg.norm(offset, axis=1)


def min_cut_labels(n_cells: int, pairs: np.ndarray, capacity: np.ndarray, inside: np.ndarray,
                   outside: np.ndarray, boundary: np.ndarray, boundary_capacity: np.ndarray
                   ) -> np.ndarray:
    """Inside/outside labels of cells by a minimum s-t cut.

    Parameters
    ----------
    n_cells : int
    pairs : (e, 2) int64
        Adjacent cells; ``capacity`` (e,) int64 each, both ways.
    inside, outside : (n_cells,) bool
        Seeds tied to the source (inside) or the sink (outside).
    boundary : (b,) int64
        Cells on the outside of the domain, tied to the sink with ``boundary_capacity`` (b,).

    Returns
    -------
    (n_cells,) bool
        True on the source (inside) side of the minimum cut.
    """
    source, sink = n_cells, n_cells + 1
    seed_in, seed_out = np.flatnonzero(inside), np.flatnonzero(outside)
    rows = np.concatenate([pairs[:, 0], pairs[:, 1], np.full(len(seed_in), source), seed_out,
                           boundary])
    cols = np.concatenate([pairs[:, 1], pairs[:, 0], seed_in, np.full(len(seed_out), sink),
                           np.full(len(boundary), sink)])
    caps = np.concatenate([capacity, capacity, np.full(len(seed_in), SEED_CAPACITY),
                           np.full(len(seed_out), SEED_CAPACITY), boundary_capacity])
    return source_side(n_cells + 2, rows, cols, caps, source, sink)[:n_cells]


def run(cloud: MethodInput, *, kappa: float, denoise: bool | None, weighted: bool
        ) -> tuple[np.ndarray, np.ndarray]:
    """Watertight surface of Delaunay triangles separating inner from outer big balls.

    Parameters
    ----------
    cloud : MethodInput
    kappa : float
        A Delaunay ball is big when its radius exceeds ``kappa`` x spacing.
    denoise : bool or None
        Project the points onto robust local planes first; None: when ``cloud.noise`` exceeds
        ``DENOISE_NOISE`` x spacing.
    weighted : bool
        Weight the denoising by the recorded uncertainty (``MethodInput.sigma``) when known.

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64, counter-clockwise seen from outside
    """
    from scipy.spatial import Delaunay, QhullError

    points, normals = cloud.points, cloud.normals
    if len(points) < 5:
        raise MethodFailed(f"delaunay-balls: need at least 5 points, got {len(points)}")
    if denoise is None:
        denoise = cloud.noise > DENOISE_NOISE * cloud.spacing
    if denoise:
        points, normals = project_to_planes(
            points, normals, k=DENOISE_K, iterations=DENOISE_ITERATIONS,
            neighbours=cloud.neighbours,
            weights=uncertainty.weights(cloud.sigma if weighted else None, len(points)))
    points = general_position(points, cloud.spacing, cloud.seed)
    try:
        tri = Delaunay(points)
    except QhullError as exc:
        raise MethodFailed(f"delaunay-balls: qhull failed ({str(exc).strip().splitlines()[0]})"
                           ) from None
    simplices = tri.simplices.astype(np.int64)
    neighbors = tri.neighbors.astype(np.int64)
    centre, radius = circumspheres(points, simplices)
    finite = np.isfinite(radius)
    side = np.zeros(len(simplices))
    side[finite] = np.einsum("mki,mki->m", normals[simplices[finite]],
                             centre[finite, None, :] - points[simplices[finite]]) / (
        4.0 * radius[finite])
    big = finite & (radius > kappa * cloud.spacing)
    inside, outside = big & (side < -CONFIDENT), big & (side > CONFIDENT)
    if not inside.any():
        raise MethodFailed(f"delaunay-balls: no inner Delaunay ball is bigger than {kappa:g} x "
                           f"spacing ({kappa * cloud.spacing:.3g} m); lower kappa")

    triples = simplices[:, CELL_FACETS]                                                 # (m, 4, 3)
    a, b, c = (points[triples[..., i]] for i in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=2)                        # (m, 4)
    units = np.maximum(1, np.round(AREA_UNITS * area / cloud.spacing**2)).astype(np.int64)
    cell, face = np.nonzero(neighbors >= 0)
    other = neighbors[cell, face]
    once = cell < other
    pairs = np.column_stack([cell[once], other[once]])
    hull_cell, hull_face = np.nonzero(neighbors < 0)
    label = min_cut_labels(len(simplices), pairs, units[cell[once], face[once]], inside,
                           outside, hull_cell, units[hull_cell, hull_face])

    faces = boundary_faces(points, simplices, neighbors, label)
    if len(faces) == 0:
        raise MethodFailed("delaunay-balls: the minimum cut left no surface")
    return points, faces


METHOD = register(Method(
    name="delaunay-balls", run=run, kind="interpolating",
    summary="Voronoi-based: big Delaunay balls (Robust Cocone, power crust) split by a "
            "least-area cut",
    params={
        # 1 x spacing: the least-area cut rounds off convex corners where no seed reaches
        # them, so seeds go as close to the surface as the noise allows. Measured on 6000
        # samples of the 2 x 1 x 0.5 box (Chamfer / diagonal, clean and with 0.01 noise):
        # kappa 1: 0.0003 / 0.0022, 1.5: 0.0007 / 0.0031, 2: 0.0015 / 0.0041.
        # Up to 100 spacings: beyond, no Delaunay ball of a sampled surface is big.
        "kappa": Param(1.0, float, "big ball radius / spacing", minimum=0.0, maximum=100.0),
        "denoise": Param(None, bool, "project onto robust local planes first (default: when "
                         "the noise exceeds a tenth of the spacing)"),
        "weighted": Param(True, bool, "weight the denoising by the recorded error model"),
    },
    grid=({"kappa": 3.0}, {"denoise": True})))
