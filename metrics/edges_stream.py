"""The edge metric of a cloud given block by block: exact, in memory that does not grow with it.

``edges.edge_report`` holds the whole cloud because a point's edge test (its surface variation)
needs its k nearest neighbours among every point. Everything else in the metric adds up over
any partition of the cloud: a truth-edge sample is found when some part has a point (an edge
point, on a feature edge) within t of it; "near a feature edge" is a query of each point
against the truth's samples; the counts are sums. So the cloud is cut into slabs along the
truth's longest axis, each holding at most ``defaults.EDGE_SLAB_POINTS`` points:

1. The first pass (the one ``score_stream`` makes anyway) counts the points in
   ``defaults.EDGE_STREAM_BINS`` bins along that axis; slabs are runs of bins holding at most
   the budget (a single fuller bin is a slab of its own), the outer two open-ended. A cloud
   within the budget is kept from this pass and is its own single slab.
2. One pass per slab keeps the points of the slab (its core, ``lo <= x < hi``) and of a halo h
   either side, and finds every core point's k nearest among them (``edges.nearest_k``:
   canonical order, so ties are broken as in the whole cloud). A point whose k-th distance is
   below its distance to the halo's outer faces (by a 1e-9 relative margin, far above the
   rounding of either) has its whole-cloud neighbourhood among the kept points: its sigma and
   drop are the whole cloud's, bit for bit. h is ``defaults.EDGE_HALO_RADII`` neighbourhood
   radii: estimated from the truth's area for the first slab, then the 99th percentile of the
   radii found so far; shrunk where the bin counts say the halo would hold more than the
   budget.
3. The other core points (near a slab face, or with a neighbourhood wider than the halo:
   outliers) are set aside with their coordinates and, once there are
   ``EDGE_SLAB_POINTS / k`` of them (or at the end), resolved by one more pass that keeps
   each one's k nearest over the blocks (the canonical k nearest of each block, merged).

Cost: one pass over the blocks per slab (``n / EDGE_SLAB_POINTS`` and up) plus one per batch
of set-aside points, each re-reading the input; memory: a slab and its halo (24 bytes a point,
its KD-tree and the k-nearest temporaries of ``defaults.EDGE_BLOCK`` points), or a batch of
set-aside points with their neighbours (32 k bytes each). The report is ``edge_report``'s:
score, rates and counts exactly; only its per-point arrays are left out (None).

With a ``precision`` (a score sized to one, ``metrics.precision``), the edge test runs on the
core points near a feature edge and on the far ones whose key falls below the fraction sized
from the share of far points among the ``far_share_points`` smallest keys (kept in the first
pass): the same points as ``edge_report`` with that precision tests, so the same report.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from functools import partial
from itertools import pairwise

import numpy as np

from formats import interrupt
from formats.errors import InputError
from metrics import defaults
from metrics.edges import (
    EdgeReport,
    EdgeRule,
    EdgeVariant,
    TruthEdges,
    _check_angle,
    _check_k,
    _check_rule,
    _check_variant,
    _tree,
    copy_tree,
    nearest_k,
    neighbour_offsets,
    neighbourhood_variation,
    resolve_length,
)
from metrics.inputs import Mesh, bbox_diagonal, face_areas
from metrics.precision import (
    EDGE_SALT,
    KeySample,
    far_sample_fraction,
    far_share_points,
    point_keys,
)
from metrics.spatial import PointIndex, morton_order, nearest_distance, within

Blocks = Callable[[], Iterable[np.ndarray]]


class EdgeStream:
    """``edge_report`` of a cloud given block by block (module docstring).

    Feed every block of the first pass to ``add``, then call ``report`` with a callable that
    gives the same blocks again (once per further pass).

    Parameters
    ----------
    mesh : Mesh
        The truth, validated (``inputs.as_mesh``).
    k, rule, threshold, feature_angle_deg, tolerance, tolerance_fraction, variant
        As ``edges.edge_score``; checked here (k against the point count in ``report``).
    """

    def __init__(self, mesh: Mesh, *, k: int = defaults.EDGE_K,
                 rule: EdgeRule = "leave_one_out", threshold: float | None = None,
                 feature_angle_deg: float = defaults.FEATURE_ANGLE_DEG,
                 tolerance: float | None = None, tolerance_fraction: float | None = None,
                 variant: EdgeVariant = "weighted", precision: float | None = None,
                 seed: int = 0):
        t = resolve_length(tolerance, tolerance_fraction, defaults.EDGE_TOLERANCE_FRACTION,
                           bbox_diagonal(mesh.vertices), "tolerance")
        self.k = _check_k(k, k)
        self.rule, self.threshold = _check_rule(rule, threshold, self.k)
        self.side = TruthEdges.of(mesh, t, _check_angle(feature_angle_deg),
                                  _check_variant(variant))
        low, high = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
        self.axis = int(np.argmax(high - low))
        self.cuts = np.linspace(low[self.axis], high[self.axis], defaults.EDGE_STREAM_BINS + 1)
        self.counts = np.zeros(len(self.cuts) + 1, dtype=np.int64)  # below, bins, above
        self.area = float(face_areas(mesh.vertices, mesh.faces).sum())
        self.n = 0
        self.kept: list[np.ndarray] | None = []   # the blocks, while they fit in one slab
        self.precision, self.seed = precision, seed
        self.far_fraction = 1.0
        # The points whose share far from feature edges sizes the far sample (edge_report).
        self.share = (None if precision is None
                      else KeySample(far_share_points(precision), seed, EDGE_SALT))

    def add(self, points: np.ndarray) -> None:
        """Count a block of the first pass: points (b, 3) float64, metres, truth frame."""
        self.counts += np.bincount(self._bin(points[:, self.axis]), minlength=len(self.counts))
        self.n += len(points)
        if self.share is not None:
            self.share.add(points, None)
        if self.kept is not None:
            self.kept.append(points)
            if self.n > defaults.EDGE_SLAB_POINTS:
                self.kept = None

    def report(self, blocks: Blocks) -> EdgeReport:
        """The edge report of the points counted, re-reading them with ``blocks()``.

        Raises
        ------
        InputError
            Fewer points than k, or a pass that gives another number of points.
        """
        k = _check_k(self.k, self.n)
        side = self.side
        if self.precision is not None:
            probe = self.share.sample()[0]
            near = np.zeros(len(probe), dtype=bool)
            if side.on_sharp.any():
                t = side.tolerance_m
                near = within(side.sharp_tree(), probe, t)
            self.far_fraction = far_sample_fraction(self.n, float(np.mean(~near)),
                                                    self.precision)
        if self.kept is not None:   # one slab, held since the first pass: no further pass
            kept, self.kept = self.kept, None
            blocks = partial(iter, kept)
        tally = _Tally(side, self)
        budget = max(defaults.EDGE_SLAB_POINTS, 1)
        radius = np.sqrt(k * self.area / (np.pi * self.n))   # uniform cover of the truth
        aside: list[np.ndarray] = []   # rows (x, y, z, far) of points not yet resolved
        for lo, hi in self._slabs(budget):
            h = self._halo(lo, hi, defaults.EDGE_HALO_RADII * radius, budget)
            radii = self._slab(blocks, tally, lo, hi, h, aside)
            if len(radii):
                radius = float(np.quantile(radii, 0.99))
            if sum(map(len, aside)) >= max(1, budget // k):
                self._resolve(blocks, tally, aside)
        self._resolve(blocks, tally, aside)
        return side.report(tally.found, n_points=self.n, n_edge_points=tally.n_edge,
                           n_far=tally.n_far, n_false_edges=tally.n_false, k=k, rule=self.rule,
                           threshold=self.threshold, n_far_tested=tally.n_far_tested)

    def _bin(self, x: np.ndarray) -> np.ndarray:
        """Bin of coordinates: 0 below the truth, j for [cuts[j-1], cuts[j]), last above."""
        return np.searchsorted(self.cuts, x, side="right")

    def _slabs(self, budget: int) -> list[tuple[float, float]]:
        """(lo, hi) of slabs holding at most ``budget`` points each (a fuller bin alone)."""
        bounds, filled = [-np.inf], 0
        for j, count in enumerate(self.counts):
            if filled and filled + count > budget:
                bounds.append(float(self.cuts[j - 1]))
                filled = 0
            filled += int(count)
        bounds.append(np.inf)
        return list(pairwise(bounds))

    def _held(self, a: float, b: float) -> int:
        """Points counted in the bins meeting [a, b) (an upper bound of those inside)."""
        return int(self.counts[self._bin(np.array([a]))[0]:self._bin(np.array([b]))[0] + 1]
                   .sum())

    def _halo(self, lo: float, hi: float, h: float, budget: int) -> float:
        """``h``, halved while the bin counts say the halo would hold more than ``budget``."""
        core = self._held(lo, hi)
        for _ in range(64):
            if self._held(lo - h, hi + h) <= core + budget:
                break
            h /= 2
        return h

    def _points(self, blocks: Blocks):
        """The blocks of a further pass, checked against the first pass's count."""
        seen = 0
        for points in blocks():
            seen += len(points)
            yield points
            interrupt.check()
        if seen != self.n:
            raise InputError(f"the test gave {seen} points on a second pass, {self.n} on "
                                    "the first: it changed while it was scored")

    def _slab(self, blocks: Blocks, tally: _Tally, lo: float, hi: float, h: float,
              aside: list[np.ndarray]) -> np.ndarray:
        """One pass: the edge results of the slab's core points whose neighbourhood lies in
        the halo; the others set aside. Returns the k-th distances found (halo estimate)."""
        a, b, axis, k = lo - h, hi + h, self.axis, self.k
        held = [p[(p[:, axis] >= a) & (p[:, axis] < b)] for p in self._points(blocks)]
        held = np.concatenate(held) if held else np.zeros((0, 3))
        held = held[morton_order(held)] if len(held) else held
        inside = (held[:, axis] >= lo) & (held[:, axis] < hi)
        core = held[inside]
        if len(core) == 0:
            return np.zeros(0)
        far = tally.far(core)
        if len(held) < k:
            tally.found_by(core, lo, hi, edge=False)
            aside.append(self._tested(tally, core, far))
            return np.zeros(0)
        tree, copies = copy_tree(held)
        # The held points (core and halo, all of them the cloud's) look for the gentle samples
        # near the core: over all slabs the same samples are found as by the cores alone.
        tally.found_by(core, lo, hi, edge=False, index=tree)
        rows = self._tested(tally, core, far)
        core, far = np.ascontiguousarray(rows[:, :3]), rows[:, 3].astype(bool)
        columns = np.ascontiguousarray(tree.data.T)
        queries = np.ascontiguousarray(core.T)  # C layout: the offsets' bits (edges.py)
        radii = np.empty(len(core))
        sure = np.empty(len(core), dtype=bool)
        is_edge = np.zeros(len(core), dtype=bool)
        step = max(1, defaults.EDGE_BLOCK)
        for start in range(0, len(core), step):
            sl = slice(start, start + step)
            dist, idx = nearest_k(tree, core[sl], k, copies)
            x = core[sl, axis]
            ok = dist[:, -1] < np.minimum(x - a, b - x) * (1 - 1e-9)
            radii[sl], sure[sl] = dist[:, -1], ok
            value = neighbourhood_variation(neighbour_offsets(columns, idx[ok],
                                                              queries[:, sl][:, ok]))
            is_edge[sl][ok] = self._edge(value)
        tally.add(core[sure], is_edge[sure], far[sure], lo, hi)
        aside.append(np.column_stack([core[~sure], far[~sure]]))
        return radii

    def _tested(self, tally: _Tally, core: np.ndarray, far: np.ndarray) -> np.ndarray:
        """Rows (x, y, z, far) of the core points whose edge test runs: all, or those near a
        feature edge and the far ones whose key falls below ``far_fraction``
        (``edges.edge_report``); the far ones counted in ``tally.n_far_tested``."""
        if self.far_fraction < 1:
            keep = ~far | (point_keys(core, self.seed, EDGE_SALT) < self.far_fraction)
            core, far = core[keep], far[keep]
        tally.n_far_tested += int(far.sum())
        return np.column_stack([core, far])

    def _edge(self, value: np.ndarray) -> np.ndarray:
        """Edge points from ``neighbourhood_variation``'s (2, b) sigma and drop."""
        sigma, drop = value
        return (drop if self.rule == "leave_one_out" else sigma) > self.threshold

    def _resolve(self, blocks: Blocks, tally: _Tally, aside: list[np.ndarray]) -> None:
        """One pass: the exact k nearest of the set-aside points over every block, merged in
        canonical order (distance, then x, y, z), then their edge results; ``aside`` emptied."""
        rows = np.concatenate(aside) if aside else np.zeros((0, 4))
        aside.clear()
        if len(rows) == 0:
            return
        points, far = np.ascontiguousarray(rows[:, :3]), rows[:, 3].astype(bool)
        k = self.k
        best = np.full((len(points), k), np.inf)
        near = np.zeros((len(points), k, 3))
        for block in self._points(blocks):
            if len(block) == 0:
                continue
            tree, copies = copy_tree(block)
            dist, idx = nearest_k(tree, points, min(k, len(block)), copies)
            best = np.concatenate([best, dist], axis=1)
            near = np.concatenate([near, tree.data[idx]], axis=1)
            pick = np.lexsort((near[..., 2], near[..., 1], near[..., 0], best), axis=-1)[:, :k]
            best = np.take_along_axis(best, pick, axis=1)
            near = np.take_along_axis(near, pick[..., None], axis=1)
        offset = np.ascontiguousarray(near.transpose(2, 0, 1)) - points.T[:, :, None]
        is_edge = self._edge(neighbourhood_variation(offset))
        tally.add(points, is_edge, far, -np.inf, np.inf)


class _Tally:
    """The sums of the edge metric over parts of the cloud (module docstring)."""

    def __init__(self, side: TruthEdges, stream: EdgeStream):
        self.side, self.axis = side, stream.axis
        self.found = np.zeros(len(side.samples), dtype=bool)
        self.sharp = np.flatnonzero(side.on_sharp)
        self.gentle = np.flatnonzero(~side.on_sharp)
        self.sharp_tree = side.sharp_tree() if len(self.sharp) else None
        self.n_edge = self.n_far = self.n_false = self.n_far_tested = 0

    def far(self, points: np.ndarray) -> np.ndarray:
        """(b,) bool: points not within t of a feature edge (counted here)."""
        if self.sharp_tree is None:
            far = np.ones(len(points), dtype=bool)
        else:
            t = self.side.tolerance_m
            far = ~within(self.sharp_tree, points, t)
        self.n_far += int(far.sum())
        return far

    def _within(self, which: np.ndarray, lo: float, hi: float) -> np.ndarray:
        """Samples of ``which`` that can be within t of a point with lo <= x < hi."""
        t = self.side.tolerance_m * (1 + 1e-9)
        x = self.side.samples[which, self.axis]
        return which[(x >= lo - t) & (x <= hi + t)]

    def found_by(self, points: np.ndarray, lo: float, hi: float, *, edge: bool,
                 index: PointIndex | None = None) -> None:
        """Mark the samples (feature-edge ones when ``edge``, else the others) within t of
        points (b, 3) lying in lo <= x < hi; ``index``, when given, holds the points (or more
        of the cloud's) for the gentle samples' search."""
        which = self._within(self.sharp if edge else self.gentle, lo, hi)
        if len(which) == 0 or len(points) == 0:
            return
        t = self.side.tolerance_m
        if edge:
            hit = nearest_distance(points, self.side.samples[which]) <= t
        else:
            index = _tree(points) if index is None else index
            hit = within(index, self.side.samples[which], t)
        self.found[which[hit]] = True

    def add(self, points: np.ndarray, is_edge: np.ndarray, far: np.ndarray, lo: float,
            hi: float) -> None:
        """Count resolved points (their ``far`` already counted) and mark the feature-edge
        samples their edge points reconstruct."""
        self.n_edge += int(is_edge.sum())
        self.n_false += int((is_edge & far).sum())
        self.found_by(points[is_edge], lo, hi, edge=True)
