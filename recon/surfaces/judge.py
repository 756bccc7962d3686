"""Judge a surface without the truth: held-out passes, the recorded noise, and the sensor rays.

A strike log knows more than its points. Each strike was taken at a time, by one beam of one
shot, from a recorded sensor position, with a recorded 1-sigma error model
(``recon.surfaces.uncertainty``). This module turns that into three truth-free judgements of a
surface mesh:

**K-fold hold-out over time blocks** (``pass_folds``). Along a track consecutive strikes can be
closer than the range noise, so a random held-out strike has a training neighbour with nearly
the same noise offset, and a surface that follows the noise predicts it well. Here the log's
time line is cut into blocks of ``block_shots`` contiguous shots, and the blocks are dealt to
``k`` folds; a surface fitted on the other folds is tested on each fold's blocks, only in
their interiors, ``margin`` shots in from both ends, where ``margin`` is the number of shots
the track takes to move ``NOISE_LENGTHS`` recorded noise lengths. No tested strike then has a
training strike of its own track within that distance; other passes over the same ground
carry independent noise. Every strike is held out once; the blocks, not the strikes, are the
independent units of the standard errors (``block_mean_se``). A cloud without
``time``/``shot`` attributes is cut in its stored order (one strike a shot).

**Per-strike check against a mesh** (``check``). Each strike's beam, from its view point
through the strike, is cast against the mesh (Open3D's Embree ray caster, batched):

- ``distance``: closest-point distance of the strike to the surface;
- the **residual along the beam**: from the strike to where its beam meets the surface (the
  closest-point distance without view points or where the beam misses). This, not the
  closest-point distance, is what the range noise moves: a surface that follows the noise of
  a track is a saw-tooth whose facets hold the beams, and the closest point of such a sheet is
  near any strike, while the beam still meets it at the training strikes' noise. A surface
  error ``e`` along the normal reads ``e / cos`` along a grazing beam (capped, below);
- ``sigma``: the strike's recorded 1-sigma error along its beam (range and pose knowledge),
  with a floor of ``FLOOR_FRACTION`` tau so that a noise-free log still divides by a length.
  It does not depend on the surface judged, so every candidate is measured on one scale (the
  error along a candidate's own normal would favour a crumpled surface, whose random facets
  make the beam graze); it is the normal error of a strike met head-on, so the true surface
  reads about 1 where the beams meet it head-on, below 1 at oblique incidence for a range-only
  sensor and above it for a sensor with large angle errors;
- ``tolerance``: ``max(tau, SIGMAS sigma)``, tau being ``TAU_FRACTION`` (1%) of the cloud's
  bounding-box diagonal (the F-score threshold of ``metrics``, here of the cloud);
- ``violated``: the surface cuts the beam before the strike by more than the tolerance (the
  segment from the sensor to the strike crossed empty space: a surface there is wrong);
- ``missed``: the beam meets no surface at all (the closest-point distance alone cannot see
  this: a strip of surface along a track holds the beam, and a strike off its end along the
  beam is near it);
- ``hole``: no surface within the tolerance of the strike (the beam stopped where the surface
  has nothing);
- ``crack``: the beam missed through a crack, an opening narrower than ``crack`` metres (when
  given: the reach of a supported surface point, ``recon.surfaces.auto.miss_reach``): around
  it, at a radius of ``CRACK_SCALES`` times that width, at least ``RING_SHARE`` of
  ``RING_RAYS`` parallel beams meet the surface within the strike's tolerance plus the radius
  of its range (a face tilted up to 45 degrees to the beam). A straight crack lets the two
  ring beams along it through, a junction of cells the four along both cracks, a hole wider
  than the radius all eight. A surface of local cells (a fine local-plane grid) has such
  cracks between its cells; the strikes cannot resolve them, and the surface refitted on all
  strikes keeps them without losing recall, where a hole loses it;
- ``cost``: ``(min(residual, tolerance) / sigma)^2``, and the full ``(tolerance / sigma)^2``
  for a violated beam and, on strikes the surface was not fitted on, a missed one, except a
  beam missed through a crack, whose residual is the strike's closest-point distance. Its mean is
  a chi-square per strike: about 1 for the true surface judged on independent strikes, above
  1 for a surface that follows the noise of other strikes (its error adds to theirs). On the
  strikes it was fitted on (``fitted=True``) the residual is the closest-point distance, and a
  surface that follows their noise reads well below 1 (``chi_fit``; an interpolant reads 0).

The truth-free accuracy estimate of a surface, built on these checks, is
``recon.surfaces.estimate``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from formats.geometry import Cloud
from recon.surfaces._arrays import unique_sorted
from recon.surfaces.uncertainty import COLUMNS as SIGMA_COLUMNS
from recon.surfaces.uncertainty import sigma_at_incidence

# The F-score threshold of the truth scores (metrics/defaults.py TAU_FRACTION): 1% of the
# bounding-box diagonal, here of the cloud's (the truth's is unknown).
TAU_FRACTION = 0.01
# Strike tolerance in recorded sigmas: 3 sigma, the paper's unit of error.
SIGMAS = 3.0
# Least sigma, as a fraction of tau: a noise-free log (all sigmas 0) still gives finite
# chi-squares, all scaled by the same length, so their ranking is that of the squared distances.
FLOOR_FRACTION = 1e-3
# The distance, in recorded 1-sigma noise lengths, that a track must move between a tested strike
# and the nearest training strike of the same track: at 2 sigma the surface's noise-following
# wiggle under the training strike no longer predicts the tested strike's offset.
NOISE_LENGTHS = 2.0
# The crack test (``through_cracks``): rings of RING_RAYS parallel beams around a missed beam, at
# CRACK_SCALES times the crack's width; a crack where at least RING_SHARE of one ring meets the
# surface near the strike. 8 rays: a straight crack lets 2 through, a junction of cells 4. The
# scales and the width (auto.miss_reach) were fixed before the crack test was first replayed on
# the suite's clouds (docs/decisions.md).
RING_RAYS, RING_SHARE = 8, 0.5
CRACK_SCALES = (0.25, 0.5, 1.0)
# A held-out block is at least this many margins long, so that half of it is tested.
BLOCK_MARGINS = 4
# Strikes checked for the per-surface fractions and the estimate (a seeded subsample): the
# standard error of a fraction is below 0.5 / sqrt(n) = 0.4%.
MAX_CHECKED = 20_000
# Surface samples of the coverage and of the estimate's unsupported parts.
SURFACE_SAMPLES = 20_000
# A surface point is supported when a strike lies within max(tau, SIGMAS noise,
# COVERAGE_SPACINGS spacing): between the strikes of a uniformly sampled patch no point is
# farther than about one spacing.
COVERAGE_SPACINGS = 2.0
# Passes of ``carve``: each removes the first layer a cut missed beam meets; the membranes of a
# graph cut across a satellite's gaps are one or two layers deep (6 passes left none on the
# suite's spacecraft, docs/decisions.md).
CARVE_PASSES = 8
# Relative slack of ``carved_faces``'s test whether a beam may still be cut: the distances of a
# listing and of a cast of the same face agree (one Embree intersector), float32 rounding aside.
CROSSING_SLACK = 1e-6


@dataclass(frozen=True)
class Strikes:
    """Strikes to judge a surface with, in the body frame.

    Attributes
    ----------
    points : (n, 3) float64, metres
    view : (n, 3) float64, metres, or None
        Sensor positions (the beams run from each through its strike).
    columns : dict of str to (n,) float64, or None
        The recorded uncertainty columns (``recon.surfaces.uncertainty.COLUMNS``); None, or all
        zero, for a log without an error model.
    """

    points: np.ndarray
    view: np.ndarray | None = None
    columns: dict[str, np.ndarray] | None = None

    @classmethod
    def of(cls, cloud: Cloud) -> Strikes:
        """A ``Cloud``'s points, view points and uncertainty columns (when it has all four)."""
        attributes = cloud.attributes
        columns = None
        if all(key in attributes for key in SIGMA_COLUMNS):
            columns = {key: np.asarray(attributes[key], dtype=np.float64)
                       for key in SIGMA_COLUMNS}
        return cls(np.asarray(cloud.points, dtype=np.float64), cloud.view_points, columns)

    def __len__(self) -> int:
        return len(self.points)

    def take(self, index: np.ndarray) -> Strikes:
        """The strikes at ``index`` (integer indices or a mask)."""
        return Strikes(self.points[index], None if self.view is None else self.view[index],
                       None if self.columns is None else
                       {k: v[index] for k, v in self.columns.items()})

    def recorded(self) -> bool:
        """Whether the strikes carry a non-zero recorded error model."""
        return self.columns is not None and any(v.any() for v in self.columns.values())

    def noise(self) -> float | None:
        """The recorded noise length [m]: the median 1-sigma error along the beam (range and
        pose knowledge), or None without a recorded error model."""
        if not self.recorded():
            return None
        return float(np.median(self.columns["sigma_along"]))


def tau_of(points: np.ndarray) -> float:
    """``TAU_FRACTION`` of the bounding-box diagonal of ``points`` (n, 3) [m]."""
    return TAU_FRACTION * float(np.linalg.norm(np.ptp(points, axis=0)))


def _shot_order(cloud: Cloud) -> tuple[np.ndarray, np.ndarray]:
    """Each strike's shot rank in time order, and its beam (0 when not recorded)."""
    attributes = cloud.attributes
    n = len(cloud.points)
    beam = np.asarray(attributes.get("beam", np.zeros(n)), dtype=np.int64)
    if "shot" in attributes:
        shot = np.asarray(attributes["shot"], dtype=np.int64)
    elif "time" in attributes:
        shot = np.asarray(attributes["time"], dtype=np.float64)
    else:
        return np.arange(n), np.zeros(n, dtype=np.int64)
    time = np.asarray(attributes.get("time", shot), dtype=np.float64)
    keys, first = np.unique(shot, return_index=True)
    order = np.argsort(time[first], kind="stable")
    rank = np.empty(len(keys), dtype=np.int64)
    rank[order] = np.arange(len(keys))
    return rank[np.searchsorted(keys, shot)], beam


def _margin(points: np.ndarray, rank: np.ndarray, beam: np.ndarray, noise: float
            ) -> tuple[int, float]:
    """Shots a track takes to move ``NOISE_LENGTHS`` noise lengths, and its step [m] a shot.

    Consecutive strikes can differ more by their noise than by the track's motion, so the
    motion is measured at growing lags ``K`` (1, 2, 4, ... shots, strikes of one beam):
    ``mean |p(i + K) - p(i)|^2 = (K step)^2 + 2 noise^2``, read at the first lag whose motion
    reaches the distance sought. Returns (0, 0.0) without noise or without consecutive shots;
    the longest lag tried when no lag reaches it (tracks shorter than the distance).
    """
    order = np.lexsort((rank, beam))
    rank, beam, points = rank[order], beam[order], points[order]
    want = NOISE_LENGTHS * noise
    lag, step = 1, 0.0
    while lag < max(len(points) // 2, 2):
        same = (beam[lag:] == beam[:-lag]) & (rank[lag:] - rank[:-lag] == lag)
        if not same.any():
            break
        square = np.mean(np.sum((points[lag:] - points[:-lag])[same] ** 2, axis=1))
        motion = np.sqrt(max(square - 2.0 * noise**2, 0.0))
        step = motion / lag
        if want <= 0 or motion >= want:
            break
        lag *= 2
    if want <= 0 or step <= 0:
        return 0, step
    return int(np.ceil(want / step)), step


@dataclass(frozen=True)
class Folds:
    """A K-fold hold-out over time blocks (module docstring): every strike belongs to one block
    and every block to one fold; fitting on the other folds, a fold's tested strikes (its
    blocks' interiors) are predicted by a surface that never saw their track within a margin.

    Attributes
    ----------
    fold : (n,) int64
        Fold of each strike, 0 .. k - 1.
    block : (n,) int64
        Time block of each strike, 0 .. n_blocks - 1 (the units of the standard errors).
    tested : (n,) bool
        The strike lies in its block's interior, ``margin`` shots in from both ends.
    k : int
    n_blocks, block_shots, margin : int
        Blocks, shots a block, shots left untested at each end.
    step_m : float
        The track's motion a shot [m] (``_margin``).
    """

    fold: np.ndarray
    block: np.ndarray
    tested: np.ndarray
    k: int
    n_blocks: int
    block_shots: int
    margin: int
    step_m: float

    def train(self, f: int) -> np.ndarray:
        """Indices of the strikes fold ``f``'s surface is fitted on (every other fold)."""
        return np.flatnonzero(self.fold != f)

    def test(self, f: int) -> np.ndarray:
        """Indices of fold ``f``'s tested strikes."""
        return np.flatnonzero((self.fold == f) & self.tested)


def pass_folds(cloud: Cloud, k: int, *, noise: float | None = None, seed: int = 0) -> Folds:
    """Cut the time line into blocks and deal them to ``k`` folds (module docstring).

    A block is ``BLOCK_MARGINS`` margins of shots long (at least one shot, at most a
    ``k``-th of the log), a margin being the shots the track takes to move ``NOISE_LENGTHS``
    recorded noise lengths; consecutive groups of ``k`` blocks go one to each fold in a seeded
    order, so every fold samples the whole time line and every strike is held out once.

    Parameters
    ----------
    cloud : Cloud
        Metres; its ``shot`` (or ``time``) and ``beam`` attributes order the strikes.
    k : int
        Folds, at least 2.
    noise : float, metres, optional
        Noise length of the margin (default: the recorded ``Strikes.noise``; 0 without one).
    seed : int
        Seed of the deal.

    Returns
    -------
    Folds
    """
    rank, beam = _shot_order(cloud)
    n_shots = int(rank.max()) + 1 if len(rank) else 0
    if noise is None:
        noise = Strikes.of(cloud).noise() or 0.0
    margin, step = _margin(cloud.points, rank, beam, noise)
    block_shots = int(min(max(BLOCK_MARGINS * margin, 1), max(n_shots // k, 1)))
    margin = min(margin, (block_shots - 1) // 2)
    n_blocks = -(-n_shots // block_shots)
    groups = -(-n_blocks // k)
    rng = np.random.default_rng(seed)
    deal = np.concatenate([rng.permutation(k) for _ in range(groups)])[:n_blocks]
    block = rank // block_shots
    position = rank - block * block_shots
    length = np.minimum(block_shots, n_shots - block * block_shots)
    tested = (position >= margin) & (position < length - margin)
    return Folds(fold=deal[block].astype(np.int64), block=block.astype(np.int64), tested=tested,
                 k=int(k), n_blocks=int(n_blocks), block_shots=block_shots, margin=int(margin),
                 step_m=float(step))


@dataclass(frozen=True)
class Check:
    """Strikes against one surface (module docstring): per-strike arrays, (n,) each.

    Attributes
    ----------
    distance : float64, metres
    sigma : float64, metres
        Recorded 1-sigma error along the beam (with the floor): the scale of ``cost``, the
        same for every surface judged.
    sigma_normal : float64, metres
        Recorded 1-sigma error along the normal of the triangle the beam meets (with the
        floor; head-on where it misses): the noise in ``distance`` if this surface is right.
    tolerance : float64, metres
    violated, missed, hole, crack : bool
    cost : float64
        Capped chi-square of each strike.
    """

    distance: np.ndarray
    sigma: np.ndarray
    sigma_normal: np.ndarray
    tolerance: np.ndarray
    violated: np.ndarray
    missed: np.ndarray
    hole: np.ndarray
    crack: np.ndarray
    cost: np.ndarray

    def chi(self) -> float:
        """RMS of the capped residual over sigma: ``sqrt(mean(cost))``."""
        return float(np.sqrt(np.mean(self.cost))) if len(self.cost) else float("nan")


class Caster:
    """One surface, ready for distance queries and beam casts (Open3D ``RaycastingScene``,
    Embree inside, in float32 about the mesh's centre: ~1e-7 of the extent).

    Parameters
    ----------
    vertices : (v, 3) float64, metres
    faces : (f, 3) int64
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        import open3d as o3d

        self._o3d = o3d
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        # column by column: a reduction over the rows of an (n, 3) array is twenty times slower
        self.centre = 0.5 * (np.array([column.min() for column in self.vertices.T])
                             + np.array([column.max() for column in self.vertices.T]))
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(
            o3d.core.Tensor((self.vertices - self.centre).astype(np.float32)),
            o3d.core.Tensor(self.faces.astype(np.uint32)))

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Closest-point distance [m] of each of ``points`` (n, 3) to the surface."""
        query = self._o3d.core.Tensor((points - self.centre).astype(np.float32))
        return self.scene.compute_distance(query).numpy().astype(np.float64)

    def beams(self, view: np.ndarray, points: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Cast each beam from ``view`` (n, 3) through ``points`` (n, 3).

        Returns
        -------
        t_hit : (n,) float64, metres
            Distance from the view point to the first surface hit (inf for a miss).
        beam_range : (n,) float64, metres
            Distance from the view point to the strike.
        cos_incidence : (n,) float64
            |cos| between the beam and the normal of the triangle hit (1 for a miss).
        triangle : (n,) int64
            The face first hit (-1 for a miss).
        """
        ray = points - view
        beam_range = np.linalg.norm(ray, axis=1)
        direction = ray / np.maximum(beam_range, 1e-300)[:, None]
        rays = np.hstack([view - self.centre, direction]).astype(np.float32)
        cast = self.scene.cast_rays(self._o3d.core.Tensor(rays))
        t_hit = cast["t_hit"].numpy().astype(np.float64)
        triangle = cast["primitive_ids"].numpy().astype(np.int64)
        hit = np.isfinite(t_hit) & (triangle < len(self.faces))
        t_hit[~hit] = np.inf
        cos = np.ones(len(points))
        a, b, c = (self.vertices[self.faces[triangle[hit], i]] for i in range(3))
        normal = np.cross(b - a, c - a)
        cos[hit] = np.abs(np.einsum("ij,ij->i", normal, direction[hit])) / \
            np.maximum(np.linalg.norm(normal, axis=1), 1e-300)
        return t_hit, beam_range, cos, np.where(hit, triangle, -1)


def sigma_along(strikes: Strikes, *, tau: float, noise: float) -> np.ndarray:
    """Each strike's recorded 1-sigma error along its beam with the floor of
    ``FLOOR_FRACTION`` ``tau`` (module docstring; ``noise`` [m] without a recorded error
    model): the scale of ``check``'s cost, the same for every surface. Returns (n,) float64,
    metres."""
    along = strikes.columns["sigma_along"] if strikes.recorded() else \
        np.full(len(strikes), float(noise))
    return np.hypot(along, FLOOR_FRACTION * tau)


def check(strikes: Strikes, caster: Caster, *, tau: float, noise: float,
          fitted: bool = False, crack: float | None = None) -> Check:
    """Strikes against a surface (module docstring).

    Parameters
    ----------
    strikes : Strikes
    caster : Caster
        The surface.
    tau : float, metres
        Least tolerance (``tau_of`` the whole cloud).
    noise : float, metres
        1-sigma error of strikes without a recorded error model.
    fitted : bool
        The strikes are those the surface was fitted on: the cost then measures how closely
        the surface follows them, by the closest-point distance (an interpolant reads 0), and
        a missed beam is no error (a beam aimed at a vertex can slip between its triangles).
        Otherwise the residual is along the beam and a missed beam costs the full cap: where
        the beam meets no surface, the surface does not predict the strike, however close its
        edge is; unless it passed a crack (``crack``).
    crack : float, metres, optional
        The widest opening that counts as a crack (module docstring); None: none does.

    Returns
    -------
    Check
    """
    n = len(strikes)
    distance = caster.distance(strikes.points)
    residual = distance
    cos = np.ones(n)
    violated = np.zeros(n, dtype=bool)
    missed = np.zeros(n, dtype=bool)
    if strikes.view is not None:
        t_hit, beam_range, cos, _ = caster.beams(strikes.view, strikes.points)
        missed = ~np.isfinite(t_hit)
        if not fitted:
            residual = np.where(missed, distance, np.abs(t_hit - beam_range))
    normal = sigma_at_incidence(strikes.columns, cos) if strikes.recorded() else \
        np.full(n, float(noise))
    floor = FLOOR_FRACTION * tau
    sigma = sigma_along(strikes, tau=tau, noise=noise)
    tolerance = np.maximum(tau, SIGMAS * sigma)
    if strikes.view is not None:
        violated = ~missed & (t_hit < beam_range - tolerance)
    hole = distance > tolerance
    cracked = np.zeros(n, dtype=bool)
    if crack is not None and not fitted and strikes.view is not None:
        cracked[missed] = through_cracks(caster, strikes.view[missed], strikes.points[missed],
                                         tolerance[missed], crack)
    capped = np.where(violated | (missed & ~fitted & ~cracked), tolerance,
                      np.minimum(residual, tolerance))
    return Check(distance, sigma, np.hypot(normal, floor), tolerance, violated, missed, hole,
                 cracked, (capped / sigma) ** 2)


def ring_share(caster: Caster, view: np.ndarray, points: np.ndarray, radius: float,
               window: np.ndarray) -> np.ndarray:
    """Per beam from ``view`` (n, 3) through ``points`` (n, 3) [m]: the share of ``RING_RAYS``
    parallel beams offset ``radius`` [m] around it whose first hit on ``caster``'s surface lies
    within ``window`` (n,) [m] of the strike's range (one batched cast)."""
    ray = points - view
    direction = ray / np.linalg.norm(ray, axis=1)[:, None]
    helper = np.where(np.abs(direction[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(direction, helper)
    u /= np.linalg.norm(u, axis=1)[:, None]
    w = np.cross(direction, u)
    angle = 2.0 * np.pi * np.arange(RING_RAYS) / RING_RAYS
    offset = radius * (np.cos(angle)[None, :, None] * u[:, None, :]
                       + np.sin(angle)[None, :, None] * w[:, None, :])
    t_hit, beam_range, _, _ = caster.beams((view[:, None, :] + offset).reshape(-1, 3),
                                           (points[:, None, :] + offset).reshape(-1, 3))
    near = np.abs(t_hit - beam_range) <= np.repeat(window, RING_RAYS)
    return near.reshape(len(points), RING_RAYS).mean(axis=1)


def through_cracks(caster: Caster, view: np.ndarray, points: np.ndarray,
                   tolerance: np.ndarray, width: float) -> np.ndarray:
    """Which beams from ``view`` (m, 3) through ``points`` (m, 3) [m], that missed the surface,
    passed a crack no wider than ``width`` [m] (module docstring): (m,) bool, one batched cast
    per scale of ``CRACK_SCALES``."""
    cracked = np.zeros(len(points), dtype=bool)
    if not len(points):
        return cracked
    for scale in CRACK_SCALES:
        radius = scale * width
        cracked |= ring_share(caster, view, points, radius, tolerance + radius) >= RING_SHARE
    return cracked


def cut_misses(misses, caster: Caster, strikes: np.ndarray, reach: float) -> np.ndarray:
    """Which missed beams a surface cuts where no strike is (module docstring).

    A missed beam crossed free space from ``range_min`` to ``range_max``
    (``recon.registration.misses``). Each is cast against the surface (one batched Embree
    cast); it is cut when its first hit lies within that span and farther than ``reach`` from
    every strike: at a silhouette a beam that grazed past the body meets a surface at the
    truth near the strikes of its neighbours, within their spacing and the noise.

    Parameters
    ----------
    misses : recon.registration.misses.MissedBeams
    caster : Caster
        The surface.
    strikes : (n, 3) float64, metres, body frame
    reach : float, metres

    Returns
    -------
    (m,) bool
    """
    return cast_misses(misses, caster, strikes, reach)[2]


def cast_misses(misses, caster: Caster, strikes: np.ndarray, reach: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every missed beam cast against a surface (``cut_misses``, whose parameters these are):
    the distance of each's first hit [m] (m,) float64 (inf: none), its face (m,) int64 (-1:
    none) and whether the beam is cut there (m,) bool. ``carve`` given this answer
    (``cast``) does not cast its first pass again."""
    from scipy.spatial import cKDTree

    if len(misses) == 0:
        return np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool)
    return _cast_misses(misses, np.arange(len(misses)), caster, cKDTree(strikes), reach)


def carve(vertices: np.ndarray, faces: np.ndarray, misses, strikes: np.ndarray, reach: float,
          *, caster: Caster | None = None, cast: tuple | None = None
          ) -> tuple[np.ndarray, np.ndarray]:
    """A surface with the faces that missed beams cut removed (``cut_misses``): free space the
    surface filled, a membrane across a gap the beams went through.

    Pass after pass (at most ``CARVE_PASSES``), the face each cut beam first hits among the
    faces left is removed (``carved_faces``, whose parameters these are), until no beam cuts
    the rest (a beam may cross several layers). Vertices no face uses are dropped.

    Returns
    -------
    vertices : (v', 3) float64
    faces : (f', 3) int64
    """
    faces = np.asarray(faces, dtype=np.int64)[~carved_faces(
        vertices, faces, misses, strikes, reach, caster=caster, cast=cast)]
    used = unique_sorted(faces)
    index = np.full(len(vertices), -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    return np.asarray(vertices, dtype=np.float64)[used], index[faces]


def carved_faces(vertices: np.ndarray, faces: np.ndarray, misses, strikes: np.ndarray,
                 reach: float, *, caster: Caster | None = None, cast: tuple | None = None
                 ) -> np.ndarray:
    """Which faces ``carve`` removes: (f,) bool, pass after pass (at most ``CARVE_PASSES``) the
    face each cut missed beam first hits among the faces left (``cut_misses``).

    Removing faces never brings a hit nearer, so a beam whose first hit is left keeps it (and
    is not cut: a cut beam's face is removed). A pass therefore casts again only the beams
    whose first hit was removed, against the faces left (one Embree scene a pass). Before a
    pass is cast, the crossings of those beams with the whole surface, listed once
    (``RaycastingScene.list_intersections`` on the first scene), say whether any of them can
    still be cut beyond the face it lost; when none can, the carving is over without building
    the scene of the faces left.

    Parameters
    ----------
    vertices : (v, 3) float64, metres
    faces : (f, 3) int64
    misses : recon.registration.misses.MissedBeams
    strikes : (n, 3) float64, metres
    reach : float, metres
    caster : Caster, optional
        ``Caster(vertices, faces)``, when the caller has it (its scene is not built again).
    cast : tuple of three (m,) arrays, optional
        ``cast_misses(misses, caster, strikes, reach)``, when the caller has it: the first
        pass (every beam against the whole surface) is not cast again; the same answer.
    """
    from scipy.spatial import cKDTree

    faces = np.asarray(faces, dtype=np.int64)
    carved = np.zeros(len(faces), dtype=bool)
    if len(misses) == 0:
        return carved
    caster = caster or Caster(vertices, faces)
    tree = cKDTree(strikes)
    left = np.arange(len(faces))
    beams = np.arange(len(misses))          # the beams cast in this pass
    first = np.full(len(misses), -1)        # each beam's first hit among the faces left
    t_first = np.full(len(misses), np.inf)
    listed = None
    for done in range(CARVE_PASSES):
        if done:   # the scene of the faces left, built only for a pass that is cast
            caster = Caster(vertices, faces[left])
        t_hit, triangle, cut = (cast if done == 0 and cast is not None
                                else _cast_misses(misses, beams, caster, tree, reach))
        first[beams], t_first[beams] = np.where(triangle >= 0, left[triangle], -1), t_hit
        if not cut.any():
            break
        carved[first[beams[cut]]] = True
        left = np.flatnonzero(~carved)
        beams = np.flatnonzero((first >= 0) & carved[np.maximum(first, 0)])
        if listed is None:   # the first scene is still the whole surface's
            listed = _crossings(misses, caster, tree, reach)
        if not len(left) or not _may_cut(listed, beams, t_first):
            break
    return carved


def _cast_misses(misses, beams: np.ndarray, caster: Caster, tree, reach: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cast the missed beams ``beams`` (k,) against a surface: the distance of each's first
    hit [m] (inf: none), its face (-1: none) and whether the beam is cut there (``cut_misses``;
    ``tree``: a ``cKDTree`` of the strikes)."""
    origin, direction = misses.origin[beams], misses.direction[beams]
    rays = np.hstack([origin - caster.centre, direction]).astype(np.float32)
    cast = caster.scene.cast_rays(caster._o3d.core.Tensor(rays))
    t_hit = cast["t_hit"].numpy().astype(np.float64)
    triangle = cast["primitive_ids"].numpy().astype(np.int64)
    hit = np.isfinite(t_hit) & (triangle < len(caster.faces))
    t_hit[~hit], triangle[~hit] = np.inf, -1
    inside = hit & (t_hit >= misses.range_min) & (t_hit <= misses.range_max)
    cut = np.zeros(len(beams), dtype=bool)
    if inside.any():
        crossing = origin[inside] + t_hit[inside, None] * direction[inside]
        # one thread: a few thousand crossings, where threads started per query cost more
        # than they save beside the busy fit workers (the same answers)
        distance, _ = tree.query(crossing, distance_upper_bound=reach)
        cut[inside] = ~np.isfinite(distance)
    return t_hit, triangle, cut


def _crossings(misses, caster: Caster, tree, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Every crossing of the missed beams with a whole surface (``list_intersections``, which
    lists one of several faces met at the same distance): the beam (h,) int64, its distance
    along it [m] (h,) float64 and whether a first hit there would cut the beam (h,) bool."""
    rays = np.hstack([misses.origin - caster.centre, misses.direction]).astype(np.float32)
    listed = caster.scene.list_intersections(caster._o3d.core.Tensor(rays))
    beam = listed["ray_ids"].numpy().astype(np.int64)
    t_hit = listed["t_hit"].numpy().astype(np.float64)
    cuts = np.zeros(len(beam), dtype=bool)
    inside = (t_hit >= misses.range_min) & (t_hit <= misses.range_max)
    if inside.any():
        crossing = misses.origin[beam[inside]] + t_hit[inside, None] * \
            misses.direction[beam[inside]]
        # one thread: a few thousand crossings, where threads started per query cost more
        # than they save beside the busy fit workers (the same answers)
        distance, _ = tree.query(crossing, distance_upper_bound=reach)
        cuts[inside] = ~np.isfinite(distance)
    return beam, t_hit, cuts


def _may_cut(listed, beams: np.ndarray, t_first: np.ndarray) -> bool:
    """Whether any of ``beams`` (k,) may be cut once its first hit, at ``t_first`` [m] (m,),
    is removed: a crossing listed at or beyond that distance would cut it. A face met at the
    same distance as a listed one, left out of the list, crosses the beam at the same point,
    so it cuts exactly when the listed one does (``CROSSING_SLACK``: a crossing a hair nearer
    counts too, so the answer errs towards casting)."""
    beam, t_hit, cuts = listed
    wanted = np.zeros(len(t_first), dtype=bool)
    wanted[beams] = True
    mine = np.flatnonzero(cuts & wanted[beam])   # a removed first hit is finite
    start = t_first[beam[mine]]
    return bool(np.any(t_hit[mine] >= start - CROSSING_SLACK * np.maximum(start, 1.0)))


def subsample(n: int, limit: int, seed: int) -> np.ndarray:
    """Sorted indices of at most ``limit`` of ``n`` items (all of them when ``n <= limit``)."""
    if n <= limit:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, limit, replace=False))


def block_mean_se(values: np.ndarray, block: np.ndarray) -> tuple[float, float]:
    """Mean of ``values`` (n,) and its standard error from the spread of the block means
    (blocks weighted by their counts; 0 with fewer than two blocks)."""
    mean = float(np.mean(values))
    labels, inverse, count = np.unique(block, return_inverse=True, return_counts=True)
    if len(labels) < 2:
        return mean, 0.0
    means = np.bincount(inverse, weights=values) / count
    weight = count / count.sum()
    variance = np.sum(weight**2 * (means - mean) ** 2) * len(labels) / (len(labels) - 1)
    return mean, float(np.sqrt(variance))


@dataclass(frozen=True)
class HeldOut:
    """Residuals of strikes a surface was not fitted on (auto's held-out blocks), for
    ``recon.surfaces.estimate.estimate``: ``distance`` and ``sigma`` (k,) metres, ``block``
    (k,) int64."""

    distance: np.ndarray
    sigma: np.ndarray
    block: np.ndarray

