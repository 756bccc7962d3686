"""``visibility``: Delaunay cells labelled inside or outside by the sensor-to-strike rays.

Labatut, Pons and Keriven 2009 ("Robust and efficient surface reconstruction from range data",
Computer Graphics Forum 28(8)), with their soft visibility for noisy data (also Jancosek and
Pajdla 2011, "Multi-view reconstruction preserving weakly-supported surfaces"). Every strike
was seen from a sensor position (``MethodInput.view_points``, the cloud's ``view_x/y/z``): the
segment from the sensor to the strike crossed empty space, and the body lies just behind the
strike. On the Delaunay tetrahedralisation of the strikes that evidence becomes a graph cut:

1. **Denoise** (``denoise``; by default when the recorded noise along the normals exceeds
   ``DENOISE_NOISE`` of the spacing): each strike moves onto its robust local plane
   (``plane.project_to_planes``, neighbours on its own side only, weighted by the recorded
   uncertainty with ``weighted``). A surface of Delaunay triangles passes through the strikes
   themselves, so without this it would be as rough as the noise. Each plane averages
   ``denoise_neighbours`` strikes: enough to bring the noise along the normal down to
   ``DENOISE_RESIDUAL`` spacings (``(noise / (DENOISE_RESIDUAL x spacing))^2``), at least
   ``DENOISE_K`` and at most ``DENOISE_K_MAX`` (a larger plane rounds edges and curved parts
   more). On noisy LIDAR clouds of generated satellites (noise 0.8 spacings: 60 strikes a
   plane instead of 30) this lowered the Chamfer distance of the surface carved by the missed
   beams by 3 to 13 % on six of seven (the seventh lost 5 %); their cross LRF clouds (noise
   0.45 spacings) keep about 30.
2. **Delaunay** tetrahedralisation (qhull) of the strikes, exact copies merged and the rest
   jittered by ``JITTER`` spacings (seeded) so that coplanar and cospherical samples (a box's
   faces, a scan grid) make no flat cells. The jitter moves only the triangulation's
   combinatorics; the mesh keeps the unjittered positions.
3. **Rays, walked cell to cell, all together.** Each strike's ray leaves it towards its sensor,
   starting in the cell of its vertex's star that the ray enters (``first_cells``); every ray
   is advanced one cell per step across the facet through which it leaves its cell
   (barycentric coordinates along the ray, ``Cells``; ``Delaunay.neighbors``), until it
   leaves the convex hull, reaches the cell holding its sensor or has taken ``max_steps``
   steps. Cost is bounded before it starts: at most ``n x max_steps`` cell visits
   for ``n`` strikes, each a few vectorised operations. A facet crossed at distance ``d`` from
   the strike gets the free-space weight ``1 - exp(-d^2 / 2 sigma^2)`` (soft visibility:
   near the strike the evidence is only as sure as the strike's position), on the directed
   edge from the sensor's side to the strike's side: it is paid when the cell nearer the
   sensor is outside and the other inside. The sensor's cell (or the last one reached) is tied
   to the outside with weight 1, and the cell ``behind`` sigmas behind the strike to the
   inside with weight 1.
4. **Missed beams** (``MethodInput.misses``, a strike log's beams that struck nothing,
   ``recon.registration.misses``; none for a cloud file): each crossed free space over its whole
   free span, so every cell it crosses there is voted outside as the sensor-to-strike rays vote
   (``miss_inflow``). One Embree cast against the convex hull's facets finds where each enters
   the hull (``hull_entries``; a beam whose free span begins inside the hull is left out), and
   ``walk_rays`` walks it from there to the end of its span or out of the hull (at most
   ``MISS_STEPS x max_steps`` cells: it crosses the whole hull). A facet it crosses at
   distance ``r`` from the facet's nearest vertex weighs ``1 - exp(-r^2 / 2 s^2)``, ``s`` that
   vertex's scale before denoising (a beam that grazed a strike says little), on the edge from
   the far side into the near side: both ends of the span are outside, so each cell along it
   left inside costs a facet where the beam leaves it. Without them, the cut may close
   over space no sensor-to-strike ray crossed (a gap seen from no side, a concavity between
   parts); the missed beams through it open it. On 45 tuning clouds of the auto suite this
   lowered the geometric mean of the Chamfer distance to 0.81 of the cut without them (0.70 on
   the 26 generated satellites, 23 better); a cell is labelled whole, so where a large cell a
   miss crosses also holds body no strike reached, it is lost (Itokawa under the LIDAR +55 %,
   satellite E +20 %; docs/decisions.md).
5. **Surface quality** (the paper's ``E_qual``): each facet also costs ``beta (1 - min(cos
   phi, cos psi))``, phi and psi the angles at which the circumspheres of its two cells cut
   its plane: small for the facets of a well-sampled surface, whose cells' empty spheres
   barely cross it.
6. **Minimum s-t cut** (scipy's ``maximum_flow``, Dinic): source = outside (the infinite cells
   beyond the convex hull are the source itself), sink = inside. Capacities are integers: the
   weights in units of ``1 / CAPACITY_UNITS`` of one ray, rounded (a facet of weight 0 still
   costs one unit, so no edge is free), capped at the int32 limit. The outside is what the
   source reaches in the residual graph.
7. **Surface**: the facets between inside and outside cells, oriented outwards. It is closed
   (the boundary of a union of cells), passes through the (denoised) strikes, and may touch
   itself at an edge or a vertex where two inside cells meet only there.

``sigma``, the soft-visibility scale of each ray, is by default the recorded 1-sigma
uncertainty of the strike along its beam (``MethodInput.sigma`` over the cosine of the
incidence), else the cloud's noise scale; after denoising it is divided by the square root of
the strikes each local plane averages (``denoise_neighbours``; on the 77,400-strike RSO-A LRF
cloud, with 30 a plane, this took the Chamfer distance from 0.361 to 0.311 m and the F-score
from 0.838 to 0.846: with the raw noise as its scale, the soft visibility let the rays carve
away the denoised thin panels); it is floored at ``MIN_SIGMA`` spacings.

A cloud without view points (a plain point file) is refused with ``MethodFailed``: the method
has no rays to use, and normals alone would only give back what the surface already says.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from formats.errors import MethodFailed
from recon.surfaces import uncertainty
from recon.surfaces.methods import Method, MethodInput, Param, register
from recon.surfaces.methods._backends import CELL_FACETS, boundary_faces, source_side
from recon.surfaces.methods.plane import project_to_planes

# Automatic denoising above this noise / spacing. Measured with beta 0: on 3000 strikes of the
# 2 x 1 x 0.5 m box with 1 cm range noise (0.2 spacings) denoising rounds the edges (worst
# point 0.10 m inside against 0.03 m without; Chamfer 4.4 against 4.2 mm); on 3000 strikes of a
# unit sphere with 2 cm noise (0.3 spacings) it lowers the mean accuracy from 12.1 to 9.5 mm.
DENOISE_NOISE = 0.25
# Fewest neighbours and the robust rounds of the denoising projection: the ``plane`` method's
# defaults.
DENOISE_K, DENOISE_ITERATIONS = 30, 2
# Noise along the normal left after denoising, spacings: each plane averages
# (noise / (DENOISE_RESIDUAL x spacing))^2 strikes, from DENOISE_K to DENOISE_K_MAX. Measured on
# the auto suite's 20 noisy generated satellites (tuning clouds; Chamfer distance of the surface
# carved by the missed beams, against 30 strikes a plane): the LIDAR clouds (noise 0.75-0.85
# spacings) take 60 and gain 3-13 % on six of seven (one loses 5 %), the single-beam slews
# (0.8-0.95) take 60 and gain 1-6 %, the cross LRF clouds (0.4-0.5) keep 30-38 and move by
# under 2 %. A uniform 60 cost the cross clouds up to 13 % (rounded edges). Without the cap
# (up to 128 a plane) the geometric mean gains 4 % instead of 2.6 %, but two slews lose 2 and 5 %
# and leave 10 % of the best run's Chamfer distance: the cap was chosen on them.
DENOISE_RESIDUAL, DENOISE_K_MAX = 0.08, 60
# Planes, not quadrics: a quadric removes a plane's curvature bias (sphere above: 4.1 against
# 8.6 mm) but the quadric fit was 13.7 of the denoising's 25 s on the 77,400-strike RSO-A cloud.
DENOISE_ORDER = 1
# Jitter of the triangulated positions, spacings: far below any feature, far above rounding
# (1e-5 x a 1 m spacing is 10 um, against ~1e-13 m double precision at 1 km).
JITTER = 1e-5
# Rays whose first cells are found together (bounds the memory: ~30 cells around a vertex).
STAR_BLOCK = 65536
# Smallest soft-visibility scale, spacings (a noise-free cloud would otherwise divide by zero).
MIN_SIGMA = 1e-3
# Smallest |cos(incidence)| when turning the normal uncertainty into one along the ray (the
# uncertainty module's own cap).
MIN_COS = uncertainty.MIN_COS
# Inside parts smaller than this many cubes of the spacing (or of the median sigma, if larger)
# are dropped: smaller than what the sampling or the noise resolves (a regular cell of edge 2
# spacings holds 0.94), they are slivers between strikes and blobs of noise. On the RSO-A cross
# LRF cloud of one rotation (0.1 m noise): 52 of 73 pieces, 0.5 % of the faces.
MIN_PART_VOLUME = 1.0
# Capacities are integers in units of 1 / CAPACITY_UNITS of one ray's weight.
CAPACITY_UNITS = 1000
# A missed beam walks up to MISS_STEPS x ``max_steps`` cells: it crosses the whole hull, where a
# strike's ray leaves from the surface. On the clean RSO-B cross LRF cloud (5,696 strikes) 1,386
# of the 1,921 missed beams entering the hull needed more than 256 cells, none more than 512;
# there the beams cut by the surface went from 20 % to 2 % (of 2,044 near the strikes); on noisy
# generated satellites none needed more than 256.
MISS_STEPS = 8
# Crossings buffered before they are summed per facet (bounds the walk's memory).
FLUSH_CROSSINGS = 4_000_000
_INT32_MAX = np.iinfo(np.int32).max


def ray_sigma(cloud: MethodInput, sigma: float | None) -> np.ndarray:
    """Soft-visibility scale of each strike's ray, metres (n,).

    ``sigma`` given: that many spacings for every ray. None: the recorded uncertainty along
    the normal over the cosine of the incidence (the distance along the beam over which the
    surface may lie), or the cloud's noise scale when no error model was recorded.
    """
    n = len(cloud.points)
    floor = MIN_SIGMA * cloud.spacing
    if sigma is not None:
        return np.full(n, max(sigma * cloud.spacing, floor))
    if cloud.sigma is None:
        return np.full(n, max(cloud.noise, floor))
    beam = cloud.points - cloud.view_points
    beam /= np.maximum(np.linalg.norm(beam, axis=1, keepdims=True), 1e-300)
    cos = np.clip(np.abs(np.einsum("ij,ij->i", beam, cloud.normals)), MIN_COS, 1.0)
    return np.maximum(cloud.sigma / cos, floor)


def denoise_neighbours(noise: float, spacing: float) -> int:
    """Strikes each denoising plane averages: enough to bring ``noise`` (metres, along the
    normal) down to ``DENOISE_RESIDUAL`` x ``spacing`` (metres), from ``DENOISE_K`` to
    ``DENOISE_K_MAX``."""
    wanted = (noise / (DENOISE_RESIDUAL * spacing)) ** 2 if spacing > 0 else np.inf
    return int(np.clip(np.round(wanted), DENOISE_K, DENOISE_K_MAX))


@dataclass(frozen=True)
class Cells:
    """A Delaunay tetrahedralisation as the walk needs it.

    Attributes
    ----------
    points : (n, 3) float64, metres
    simplices, neighbors : (m, 4) int64
        Cells and, across the facet opposite each vertex, the neighbour (-1: outside the hull).
    inverse : (m, 3, 3) float64
        Barycentric transform: ``inverse[c] @ (x - offset[c])`` gives the coordinates of ``x``
        for the first three vertices of ``c`` (the fourth: one minus their sum); NaN for a flat
        cell. scipy's ``Delaunay.transform`` holds the same, computed cell by cell through
        LAPACK (minutes on a million cells when BLAS threads compete); here vectorised.
    offset : (m, 3) float64
        The fourth vertex of each cell.
    on_hull : (n,) bool
        Vertices on the convex hull.
    """

    points: np.ndarray
    simplices: np.ndarray
    neighbors: np.ndarray
    inverse: np.ndarray
    offset: np.ndarray
    on_hull: np.ndarray

    @classmethod
    def of(cls, tri) -> Cells:
        """From a ``scipy.spatial.Delaunay``."""
        points = np.asarray(tri.points, dtype=np.float64)
        simplices = tri.simplices.astype(np.int64)
        offset = points[simplices[:, 3]]
        e0, e1, e2 = (points[simplices[:, i]] - offset for i in range(3))
        rows = np.stack([np.cross(e1, e2), np.cross(e2, e0), np.cross(e0, e1)], axis=1)
        det = np.einsum("mi,mi->m", e0, rows[:, 0])
        with np.errstate(divide="ignore", invalid="ignore"):
            inverse = rows / det[:, None, None]                 # rows of A^-1, A = [e0 e1 e2]
        inverse[~np.isfinite(inverse).all(axis=(1, 2))] = np.nan
        on_hull = np.zeros(len(points), dtype=bool)
        on_hull[tri.convex_hull.ravel()] = True
        return cls(points, simplices, tri.neighbors.astype(np.int64), inverse, offset, on_hull)


def first_cells(tri: Cells, vertex: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """The cell each ray enters when it leaves its vertex, all rays at once.

    Among the cells around the ray's vertex (its star), the one in which the barycentric
    coordinates of the three other vertices all grow along the ray; the best of them when
    rounding leaves none.

    Parameters
    ----------
    tri : Cells
    vertex : (r,) int64
        Vertex each ray starts at.
    direction : (r, 3) float64
        Unit direction of each ray.

    Returns
    -------
    (r,) int64
        The cell; -1 when the ray leaves the convex hull at once (a hull vertex looking out) or
        its point is not a vertex of the triangulation (qhull drops exact coplanar copies).
    """
    inverse, on_hull = tri.inverse, tri.on_hull
    incident = tri.simplices.ravel()
    order = np.argsort(incident, kind="stable")                  # corners grouped by vertex
    bounds = np.searchsorted(incident[order], np.arange(len(tri.points) + 1))
    out = np.full(len(vertex), -1, dtype=np.int64)
    for lo in range(0, len(vertex), STAR_BLOCK):
        rays = np.arange(lo, min(lo + STAR_BLOCK, len(vertex)))
        first, count = bounds[vertex[rays]], np.diff(bounds)[vertex[rays]]
        has = count > 0
        rays, first, count = rays[has], first[has], count[has]
        if len(rays) == 0:
            continue
        owner = np.repeat(np.arange(len(rays)), count)                 # (p,) ray of each corner
        segment = np.cumsum(count) - count
        corner = order[np.repeat(first, count) + np.arange(len(owner)) - segment[owner]]
        cell, own = corner // 4, corner % 4
        growth = np.einsum("pij,pj->pi", inverse[cell], direction[rays[owner]])
        growth = np.column_stack([growth, -growth.sum(axis=1)])        # (p, 4) per metre
        growth[np.arange(len(owner)), own] = np.inf
        worst = growth.min(axis=1)
        best = np.lexsort((-worst, owner))[segment]                    # per ray, largest worst
        leaves = on_hull[vertex[rays]] & (worst[best] < 0)
        out[rays] = np.where(leaves, -1, cell[best])
    return out


def walk_rays(tri: Cells, origin: np.ndarray, direction: np.ndarray, length: np.ndarray,
              start: np.ndarray, max_steps: int, scale: np.ndarray | None = None, *,
              weigh: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
              | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Advance every ray cell by cell through a Delaunay tetrahedralisation, all at once.

    Each step finds, for every ray still going, the facet through which it leaves its cell
    (the first barycentric coordinate to reach zero along the ray, never the facet it came in
    by) and moves it to the neighbour across. At most ``len(origin) x max_steps`` cell visits.

    Parameters
    ----------
    tri : Cells
        Of ``m`` cells.
    origin : (r, 3) float64, metres
        Where each ray starts.
    direction : (r, 3) float64
        Unit direction of each ray.
    length : (r,) float64, metres
        Where each ray ends, along ``direction``.
    start : (r,) int64
        Cell of each ray just after its origin (``first_cells``; -1: outside the hull).
    max_steps : int
        Cells visited per ray at most.
    scale : (r,) float64, metres, optional
        Soft-visibility scale: a facet crossed at distance ``d`` weighs
        ``1 - exp(-d^2 / (2 scale^2))``. None (and no ``weigh``): record no crossings.
    weigh : callable, optional
        Instead of ``scale``: ``weigh(ray, cell, facet, d)``, all (c,) arrays (the ray's index,
        the cell it leaves, the facet it leaves by, the distance from its origin [m]), returns
        the (c,) free-space weight of each crossing.

    Returns
    -------
    end : (r,) int64
        The cell holding each ray's end, or where it stopped after ``max_steps`` cells; -1 when
        it left the convex hull first.
    inflow : (m, 4) float64 or None
        With ``scale`` or ``weigh``: free-space weight entering each cell through each of its facets
        (facet ``j`` is opposite vertex ``j``), the capacity of the edge from
        ``tri.neighbors[c, j]`` (the outside when -1) into cell ``c``.
    """
    m = len(tri.simplices)
    inverse, offset, neighbors = tri.inverse, tri.offset, tri.neighbors
    inflow = None if scale is None and weigh is None else np.zeros(4 * m)
    keys, weights = [], []
    buffered = 0
    end = np.full(len(origin), -1, dtype=np.int64)
    ray = np.flatnonzero(start >= 0)
    cell = start[ray]
    entry = np.full(len(ray), -1)                     # facet of ``cell`` the ray came in by
    t_in = np.zeros(len(ray))                         # distance from the origin at ``entry``
    for _ in range(int(max_steps)):
        if len(ray) == 0:
            break
        rows = np.arange(len(ray))
        a = inverse[cell]                                                  # (r, 3, 3)
        b = np.einsum("rij,rj->ri", a, origin[ray] - offset[cell])
        b = np.column_stack([b, 1.0 - b.sum(axis=1)])                     # at the origin
        db = np.einsum("rij,rj->ri", a, direction[ray])
        db = np.column_stack([db, -db.sum(axis=1)])                       # per metre
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(db < 0, -b / db, np.inf)
        t[~np.isfinite(t)] = np.inf                   # parallel facets, flat cells
        came = entry >= 0
        t[rows[came], entry[came]] = np.inf
        facet = np.argmin(t, axis=1)
        exit_t = np.maximum(t[rows, facet], t_in)     # rounding never walks a ray backwards
        done = ~np.isfinite(exit_t) | (exit_t >= length[ray])  # its end (or a flat cell)
        end[ray[done]] = cell[done]
        crossing = ~done
        if inflow is not None:
            d = exit_t[crossing]
            keys.append(cell[crossing] * 4 + facet[crossing])
            weights.append(1.0 - np.exp(-0.5 * (d / scale[ray[crossing]]) ** 2)
                           if weigh is None else
                           weigh(ray[crossing], cell[crossing], facet[crossing], d))
            buffered += len(d)
        nxt = neighbors[cell, facet]
        going = crossing & (nxt >= 0)
        previous = cell[going]
        ray, cell, t_in = ray[going], nxt[going], exit_t[going]
        entry = np.argmax(neighbors[cell] == previous[:, None], axis=1)
        if buffered > FLUSH_CROSSINGS:
            inflow += np.bincount(np.concatenate(keys), np.concatenate(weights),
                                  minlength=4 * m)
            keys, weights, buffered = [], [], 0
    end[ray] = cell                                   # out of steps
    if keys:
        inflow += np.bincount(np.concatenate(keys), np.concatenate(weights), minlength=4 * m)
    return end, None if inflow is None else inflow.reshape(m, 4)


def hull_entries(tri: Cells, origin: np.ndarray, direction: np.ndarray, near: float,
                 far: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where rays from outside enter the convex hull of the cells, all at once.

    One Embree cast (``sim.raycast.EmbreeBackend``) against the hull's facets finds the facet
    each ray meets first; the distance is recomputed in float64 on that facet's plane. The
    cast starts where the ray reaches the cells' bounding sphere (or at ``near``), in
    coordinates about the cells' centre, so that float32 keeps the facets apart.

    Parameters
    ----------
    tri : Cells
    origin : (r, 3) float64, metres
    direction : (r, 3) float64, unit vectors
    near, far : float, metres
        The span of each ray that counts (a missed beam's free span).

    Returns
    -------
    ray : (e,) int64
        The rays that enter the hull from outside within ``near``..``far``; a ray whose span
        begins inside the hull (first meets a facet from within) is left out.
    cell : (e,) int64
        The cell each enters.
    t : (e,) float64, metres
        The distance along the ray of its entry.
    """
    from sim.raycast import EmbreeBackend

    points = tri.points
    cell, facet = np.nonzero(tri.neighbors < 0)
    triangles = tri.simplices[cell[:, None], CELL_FACETS[facet]]
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    radius = float(np.linalg.norm(points - centre, axis=1).max())
    closest = np.einsum("ij,ij->i", centre - origin, direction)
    start = np.maximum(near, closest - 1.01 * radius)
    begin = origin + start[:, None] * direction
    caster = EmbreeBackend(points - centre, triangles)
    first = caster.first_hit((begin - centre).astype(np.float32),
                             direction.astype(np.float32)).astype(np.int64)
    ray = np.flatnonzero(first >= 0)
    hit = first[ray]
    a, b, c = (points[triangles[hit, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    apex = points[tri.simplices[cell[hit], facet[hit]]]
    normal *= np.sign(np.einsum("ij,ij->i", apex - a, normal))[:, None]   # into the hull
    towards = np.einsum("ij,ij->i", direction[ray], normal)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = start[ray] + np.einsum("ij,ij->i", a - begin[ray], normal) / towards
    entering = (towards > 0) & np.isfinite(t) & (t <= far)
    return ray[entering], cell[hit[entering]], np.maximum(t[entering], start[ray[entering]])


def miss_inflow(tri: Cells, misses, vertex_sigma: np.ndarray, max_steps: int) -> np.ndarray:
    """Free-space weight of the missed beams on the facets they cross (module docstring).

    Each missed beam enters the hull (``hull_entries``) and is walked cell by cell
    (``walk_rays``) to the end of its free span or out of the hull. A facet it crosses at
    distance ``r`` from the facet's nearest vertex weighs ``1 - exp(-r^2 / (2 s^2))``, ``s``
    that vertex's soft-visibility scale: where a beam grazes a strike, the evidence is only as
    sure as the strike's position. The weight goes on the edge from the far side (along the
    beam) into the near side: both ends of a missed beam's free span are free space, so every
    cell along it that the cut leaves inside costs at least the weight of one facet where the
    beam leaves the inside.

    Parameters
    ----------
    tri : Cells
        Of ``m`` cells.
    misses : recon.registration.misses.MissedBeams
        In the body frame.
    vertex_sigma : (n,) float64, metres
        Soft-visibility scale of each vertex of ``tri``.
    max_steps : int
        Cells each beam visits at most (the caller's ``MISS_STEPS`` x ``max_steps``).

    Returns
    -------
    (m, 4) float64
        As ``walk_rays``' ``inflow``.
    """
    direction = np.asarray(misses.direction, dtype=np.float64)
    origin = np.asarray(misses.origin, dtype=np.float64)
    ray, cell, t = hull_entries(tri, origin, direction, misses.range_min, misses.range_max)
    entry = origin[ray] + t[:, None] * direction[ray]       # within the free span
    direction = direction[ray]
    points, simplices = tri.points, tri.simplices

    def weigh(beam, cells, facets, d):
        at = entry[beam] + d[:, None] * direction[beam]
        corners = simplices[cells[:, None], CELL_FACETS[facets]]                   # (c, 3)
        gap = np.linalg.norm(points[corners] - at[:, None, :], axis=2)
        nearest = np.argmin(gap, axis=1)
        rows = np.arange(len(d))
        scale = vertex_sigma[corners[rows, nearest]]
        return 1.0 - np.exp(-0.5 * (gap[rows, nearest] / scale) ** 2)

    _, inflow = walk_rays(tri, entry, direction, misses.range_max - t, cell, max_steps,
                          weigh=weigh)
    return inflow


def facet_quality(points: np.ndarray, simplices: np.ndarray, neighbors: np.ndarray
                  ) -> np.ndarray:
    """Labatut et al.'s surface-quality cost ``1 - min(cos phi, cos psi)`` of every facet.

    Parameters
    ----------
    points : (n, 3) float64
    simplices, neighbors : (m, 4) int
        The Delaunay cells and their neighbours (facet ``j`` opposite vertex ``j``; -1 beyond
        the convex hull, whose infinite cell's "sphere" is the half-space: cosine 1).

    Returns
    -------
    (m, 4) float64 in [0, 1]
        Per cell and facet; equal from both sides.
    """
    from recon.surfaces.methods.delaunay_balls import circumspheres

    centre, radius = circumspheres(points, simplices)
    triples = simplices[:, CELL_FACETS]                                          # (m, 4, 3)
    a, b, c = (points[triples[..., i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.maximum(np.linalg.norm(normal, axis=2, keepdims=True), 1e-300)
    apex = points[simplices]                                                 # (m, 4, 3)
    side = np.sign(np.einsum("mki,mki->mk", apex - a, normal))     # towards the cell
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = side * np.einsum("mki,mki->mk", centre[:, None, :] - a, normal) / radius[:, None]
    cos = np.clip(np.nan_to_num(cos, nan=-1.0, posinf=-1.0, neginf=-1.0), -1.0, 1.0)
    other = np.where(neighbors >= 0, np.maximum(neighbors, 0), 0)
    # The neighbour's cosine for the same facet: its facet that faces this cell.
    back = np.argmax(neighbors[other] == np.arange(len(simplices))[:, None, None], axis=2)
    across = np.where(neighbors >= 0, cos[other, back], 1.0)
    return 1.0 - np.minimum(cos, across)


def min_cut_outside(neighbors: np.ndarray, capacity: np.ndarray, source: np.ndarray,
                    sink: np.ndarray) -> np.ndarray:
    """The cells on the source (outside) side of a minimum s-t cut.

    Parameters
    ----------
    neighbors : (m, 4) int64
        -1 for the source (the infinite cells).
    capacity : (m, 4) int64
        Capacity of the edge from ``neighbors[c, j]`` into cell ``c``.
    source, sink : (m,) int64
        Capacities of the edges from the source to each cell and from each cell to the sink.

    Returns
    -------
    (m,) bool
        True outside.
    """
    m = len(neighbors)
    s, t = m, m + 1
    cells = np.repeat(np.arange(m), 4)
    tail = np.where(neighbors.ravel() >= 0, neighbors.ravel(), s)
    rows = np.concatenate([tail, np.full(m, s), np.arange(m)])
    cols = np.concatenate([cells, np.arange(m), np.full(m, t)])
    caps = np.concatenate([capacity.ravel(), source, sink])
    used = caps > 0
    return source_side(m + 2, rows[used], cols[used], caps[used], s, t)[:m]


def drop_small_parts(tri: Cells, inside: np.ndarray, min_volume: float) -> np.ndarray:
    """``inside`` without its parts (cells joined by facets) of less than ``min_volume`` m^3."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    cell, facet = np.nonzero(inside[:, None] & (tri.neighbors >= 0))
    other = tri.neighbors[cell, facet]
    joined = inside[other]
    m = len(inside)
    graph = coo_matrix((np.ones(joined.sum()), (cell[joined], other[joined])), shape=(m, m))
    _, part = connected_components(graph, directed=False)
    with np.errstate(invalid="ignore"):
        volume = np.nan_to_num(np.abs(1.0 / (6.0 * np.linalg.det(tri.inverse))))
    size = np.bincount(part[inside], volume[inside], minlength=m)
    return inside & (size[part] >= min_volume)


def run(cloud: MethodInput, *, beta: float, sigma: float | None, behind: float,
        denoise: bool | None, weighted: bool, max_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Closed surface of Delaunay triangles between the cells the rays say are outside and
    those behind the strikes.

    Parameters
    ----------
    cloud : MethodInput
        With ``view_points``; its ``misses``, when given, vote the cells they cross outside.
    beta : float
        Weight of the surface-quality cost of a facet against one ray's free-space weight.
    sigma : float or None
        Soft-visibility scale, spacings; None: each strike's recorded uncertainty along its
        beam (``ray_sigma``).
    behind : float
        The cell tied to the inside lies this many ``sigma`` behind each strike.
    denoise : bool or None
        Project the strikes onto robust local planes first; None: when the recorded noise along
        the normals (else the cloud's noise scale) exceeds ``DENOISE_NOISE`` spacings.
    weighted : bool
        Weight the denoising by the recorded uncertainty when known.
    max_steps : int
        Cells each ray visits at most.

    Returns
    -------
    vertices : (v, 3) float64, metres, body frame
    faces : (f, 3) int64, counter-clockwise seen from outside

    Raises
    ------
    MethodFailed
        The cloud has no view points.
    MethodFailed
        qhull failed, or no cell ended inside.
    """
    from scipy.spatial import Delaunay, QhullError

    if cloud.view_points is None:
        raise MethodFailed("visibility: the cloud has no view points (view_x/y/z, the sensor "
                           "position of each strike); ingest a strike log to get them")
    points, normals, view = cloud.points, cloud.normals, cloud.view_points
    if not np.all(np.isfinite(view)):
        raise MethodFailed("visibility: the cloud's view points contain NaN or Inf")
    if len(points) < 5:
        raise MethodFailed(f"visibility: need at least 5 points, got {len(points)}")
    scale = ray_sigma(cloud, sigma)
    raw_scale = scale
    noise = cloud.noise if cloud.sigma is None else float(np.median(cloud.sigma))
    if denoise is None:
        denoise = noise > DENOISE_NOISE * cloud.spacing
    if denoise:
        k = denoise_neighbours(noise, cloud.spacing)
        points, normals = project_to_planes(
            points, normals, k=k, iterations=DENOISE_ITERATIONS,
            neighbours=cloud.neighbours, order=DENOISE_ORDER,
            weights=uncertainty.weights(cloud.sigma if weighted else None, len(points)))
        if sigma is None:  # a plane's offset is the mean of k strikes' offsets
            scale = np.maximum(scale / np.sqrt(k), MIN_SIGMA * cloud.spacing)
    vertices, strike_vertex = np.unique(points, axis=0, return_inverse=True)
    strike_vertex = strike_vertex.ravel()
    rng = np.random.default_rng(cloud.seed)
    jittered = vertices + rng.uniform(-1.0, 1.0, vertices.shape) * (JITTER * cloud.spacing)
    try:
        tri = Cells.of(Delaunay(jittered))
    except QhullError as exc:
        raise MethodFailed(f"visibility: qhull failed ({str(exc).strip().splitlines()[0]})"
                           ) from None
    origin = jittered[strike_vertex]
    direction = view - origin
    length = np.linalg.norm(direction, axis=1)
    direction /= np.maximum(length, 1e-300)[:, None]
    m = len(tri.simplices)
    # Towards the sensor: free space, soft near the strike; the sensor's cell (or the last one
    # a ray reached) is outside.
    end, inflow = walk_rays(tri, origin, direction, length,
                            first_cells(tri, strike_vertex, direction), max_steps, scale)
    free = np.bincount(end[end >= 0], minlength=m)
    # Away from the sensor, ``behind`` sigmas: the cell there is inside.
    end, _ = walk_rays(tri, origin, -direction, behind * scale,
                       first_cells(tri, strike_vertex, -direction), max_steps)
    held = np.bincount(end[end >= 0], minlength=m)
    if not held.any():
        raise MethodFailed("visibility: no strike has a Delaunay cell behind it")

    if cloud.misses is not None and len(cloud.misses):
        # Each vertex's scale: the smallest of its strikes' before denoising (a missed beam's
        # own position is as uncertain as a single strike's).
        vertex_sigma = np.full(len(vertices), np.inf)
        np.minimum.at(vertex_sigma, strike_vertex, raw_scale)
        inflow += miss_inflow(tri, cloud.misses, vertex_sigma, MISS_STEPS * max_steps)
    simplices, neighbors = tri.simplices, tri.neighbors
    weight = inflow + beta * facet_quality(jittered, simplices, neighbors)
    capacity = np.maximum(1, np.round(CAPACITY_UNITS * weight)).astype(np.int64)
    outside = min_cut_outside(neighbors, np.minimum(capacity, _INT32_MAX),
                              CAPACITY_UNITS * free, CAPACITY_UNITS * held)
    resolved = max(cloud.spacing, float(np.median(scale)))
    inside = drop_small_parts(tri, ~outside, MIN_PART_VOLUME * resolved**3)
    if not inside.any():
        hint = f" (the surface-quality cost outweighs the rays: lower beta={beta:g})" if beta \
            else ""
        raise MethodFailed(f"visibility: the minimum cut left no cell inside{hint}")

    return vertices, boundary_faces(jittered, simplices, neighbors, inside)


METHOD = register(Method(
    name="visibility", run=run, kind="interpolating",
    summary="Delaunay cells labelled by the sensor-to-strike rays and a strike log's missed "
            "beams (Labatut et al. 2009, soft visibility), a minimum cut; needs view points",
    params={
        # 0 (the visibility terms alone, every facet costing one capacity unit) by
        # measurement: on a 2 m x 2 m x 2 cm plate of 4000 strikes with 2 mm range noise,
        # beta 0 keeps 399 of 400 mid-plane probes inside (volume +6 %), beta 0.1 pinches the
        # plate at 39 of them (volume -12 %), beta 1 bulges it (volume +36 %); on the RSO-A
        # cross LRF cloud of one rotation (7,494 strikes) Chamfer 0.53 m, 0.55 m, 0.65 m. On
        # 3000 strikes of a unit sphere with 2 cm noise beta 0.1 is smoother (mean accuracy
        # 6.5 mm against 9.5 mm).
        "beta": Param(0.0, float, "weight of the surface-quality cost per facet, in rays",
                      minimum=0.0, maximum=100.0),
        "sigma": Param(None, float, "soft-visibility scale in spacings; auto: each strike's "
                       "recorded uncertainty along its beam, else the noise scale", minimum=0.0,
                       maximum=100.0),
        "behind": Param(1.0, float, "the cell held inside lies this many sigma behind each "
                        "strike", minimum=0.0, maximum=100.0),
        "denoise": Param(None, bool, "project onto robust local planes first (default: when "
                         "the noise exceeds a quarter of the spacing)"),
        "weighted": Param(True, bool, "weight the denoising by the recorded error model"),
        # 256: on the RSO-A LRF clouds (7,494 and 77,400 strikes) no ray needs more than 128
        # cells to leave the hull (at 32, 24 % and 15 % would stop early); twice that for
        # deeper concavities.
        "max_steps": Param(256, int, "cells each ray walks through at most, eight times that "
                           "for a missed beam (bounds the cost: (points + 8 x missed beams) x "
                           "max_steps)", minimum=1, maximum=4096),
    },
    grid=({"beta": 0.1}, {"beta": 1.0})))
