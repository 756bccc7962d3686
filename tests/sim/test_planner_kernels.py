"""The planner's compiled kernels (sim/planner_kernels.py) against the numpy code they replaced.

Each reference below is the numpy implementation the kernel replaced, kept here written the
numpy way (sorted-key merges with np.unique/np.insert, batched slab clipping, np.lexsort, scipy
rotations), or for the visibility walk a brute-force test of every beam against every occupied
voxel; run on small maps beside the kernel.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from formats.strike_log import StrikeChunk
from formats.strike_log.schema import Shots
from sim import planner_kernels as kernels
from sim.gap_seeking import recorded_beams, turn_from_boresight
from sim.surface_map import (
    BLOCK_RADIUS,
    BLOCK_SLACK,
    CROSSED,
    ENCLOSED,
    FACE_STEPS,
    FRONTIER,
    HIDDEN_MAX,
    HIDDEN_STEP,
    OCCUPIED,
    TRAVERSAL_STEP,
    SurfaceMap,
    member,
    pack,
    unpack,
)

# ---------------------------------------------------------------------- numpy references


def clip_to_box(origins: np.ndarray, directions: np.ndarray, lo: np.ndarray, hi: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Where each ray enters and leaves the box ``lo``..``hi`` (slab method).

    Parameters
    ----------
    origins, directions : (n, 3) float64, B; directions unit vectors
    lo, hi : (3,) float64, metres, B

    Returns
    -------
    enter, leave : (n,) float64, metres along each ray (``enter >= leave`` when it misses)
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = 1.0 / directions
        a = (lo - origins) * inverse
        b = (hi - origins) * inverse
    near = np.where(np.isnan(a), -np.inf, np.minimum(a, b))
    far = np.where(np.isnan(b), np.inf, np.maximum(a, b))
    return np.maximum(near.max(axis=1), 0.0), far.min(axis=1)


def ref_strike(m: SurfaceMap, origins, directions, ranges) -> None:
    """The numpy strike: unique keys, merged into the sorted occupied keys by np.insert, the
    new voxels' unknown face neighbours marked frontier. Updates ``m`` (grid grown by
    ``m._cover``) like the strikes of :meth:`SurfaceMap.add`."""
    hit = np.isfinite(ranges)
    end = origins[hit] + ranges[hit, None] * directions[hit]
    keys, inverse = np.unique(m.keys_of(end), return_inverse=True)
    count = np.bincount(inverse, minlength=len(keys))
    view = np.stack([np.bincount(inverse, weights=-directions[hit, i], minlength=len(keys))
                     for i in range(3)], axis=1)
    known = member(keys, m.occupied)
    row = np.searchsorted(m.occupied, keys[known])
    m.count[row] += count[known]
    m.view[row] += view[known]
    new = keys[~known]
    at = np.searchsorted(m.occupied, new)
    m.occupied = np.insert(m.occupied, at, new)
    m.count = np.insert(m.count, at, count[~known])
    m.view = np.insert(m.view, at, view[~known], axis=0)
    if not len(new):
        return
    index = unpack(new)
    m._cover(index.min(axis=0) - 1, index.max(axis=0) + 1)
    lo, hi = unpack(m.occupied).min(axis=0), unpack(m.occupied).max(axis=0)
    m._index_lo, m._index_hi = lo, hi
    state = m._state.reshape(-1)
    cell = m._cells(index)[0]
    state[cell] = (state[cell] | OCCUPIED) & ~FRONTIER
    around = m._cells((index[:, None, :] + FACE_STEPS[None]).reshape(-1, 3))[0]
    fresh = np.unique(around[(state[around] & (OCCUPIED | CROSSED | FRONTIER)) == 0])
    state[fresh] |= FRONTIER
    fresh = m._keys_of_cells(fresh)
    m._frontier = np.insert(m._frontier, np.searchsorted(m._frontier, fresh), fresh)


def ref_carve(m: SurfaceMap, origins, directions, ranges, *, margin: float) -> None:
    """The numpy carve: every beam's samples at once (np.repeat), as the paths of
    :meth:`SurfaceMap.add`."""
    hit = np.isfinite(ranges)
    lo, hi = m.bounds(margin)
    m._cover(np.floor(lo / m.size).astype(np.int64), np.floor(hi / m.size).astype(np.int64))
    enter, leave = clip_to_box(origins, directions, lo, hi)
    leave = np.where(hit, np.minimum(leave, ranges - m.size), leave)
    samples = np.ceil(np.maximum(leave - enter, 0.0) * (TRAVERSAL_STEP / m.size)).astype(np.int64)
    total = int(samples.sum())
    ray = np.repeat(np.arange(len(origins)), samples)
    first = np.cumsum(samples) - samples
    along = enter[ray] / m.size + (np.arange(total) - first[ray] + 0.5) / TRAVERSAL_STEP
    start = origins / m.size - m._corner
    shape = m._state.shape
    cell = np.zeros(total, dtype=np.int64)
    for axis, stride in enumerate((shape[1] * shape[2], shape[2], 1)):
        cell += stride * np.clip((start[ray, axis] + along * directions[ray, axis]
                                  ).astype(np.int64), 0, shape[axis] - 1)
    state = m._state.reshape(-1)
    state[cell] = (state[cell] | CROSSED) & ~FRONTIER


def ref_hidden(positions, occupied, targets, size):
    """Brute force: every beam from each position to each target against every occupied voxel
    centre (o, 3) at once: hidden when the beam crosses the voxel's box, passes within
    ``BLOCK_RADIUS`` edges of its centre and the centre is nearer than the target by more than
    ``BLOCK_SLACK`` edges. (p, n) bool."""
    out = np.zeros((len(positions), len(targets)), dtype=bool)
    for q, position in enumerate(positions):
        line = targets - position                                   # (n, 3)
        length = np.linalg.norm(line, axis=1)
        d = line / length[:, None]
        c = occupied[None] - position                               # (1, o, 3)
        along = np.einsum("noi,ni->no", np.broadcast_to(c, (len(targets), *c.shape[1:])), d)
        far = (c * c).sum(axis=2)                                   # (1, o)
        near = far < np.maximum(length - BLOCK_SLACK * size, 0.0)[:, None] ** 2
        close = far - along**2 < (BLOCK_RADIUS * size) ** 2
        with np.errstate(divide="ignore", invalid="ignore"):        # the slabs of each box
            a = (c - 0.5 * size)[:, :, :] / d[:, None, :]
            b = (c + 0.5 * size)[:, :, :] / d[:, None, :]
        enter = np.nanmax(np.minimum(a, b), axis=2)
        leave = np.nanmin(np.maximum(a, b), axis=2)
        crossed = (enter < leave) & (leave > 0) & (enter < length[:, None])
        out[q] = (near & close & crossed).any(axis=1)
    return out


def ref_turn_toward(b, goal, angle):
    cos = min(max(float(b @ goal), -1.0), 1.0)
    if math.acos(cos) <= angle:
        return goal
    s = goal - cos * b
    return math.cos(angle) * b + math.sin(angle) / np.linalg.norm(s) * s


def ref_sweep(n, centres, used, occupied, size, position, target, nominal, boresight,
              max_offset, reach, block):
    """The numpy interval: visibility from the middle shot, np.lexsort of the sweep, the goals
    by masks and np.maximum.accumulate, the rate limit from the first goal out of reach.
    Returns pick, goal, the used mask after."""
    used = used.copy()
    open_ = np.flatnonzero(~used)
    centres = centres[open_]
    m_ib = target.transpose(0, 2, 1)
    chaser = np.einsum("nij,nj->ni", m_ib, position)
    to_nominal = np.matmul(m_ib, nominal).transpose(0, 2, 1)
    middle = n // 2
    seen = ~ref_hidden(chaser[[middle]], occupied, centres, size)[0]
    aim = (centres - chaser[middle]) @ to_nominal[middle].T
    aim /= np.linalg.norm(aim, axis=1)[:, None]
    ok = np.flatnonzero(seen & (aim[:, 2] >= math.cos(max_offset)))
    band = block * size / np.linalg.norm(chaser[middle])
    row = np.floor(aim[ok, 1] / band).astype(np.int64)
    across = np.where(row % 2 == 0, aim[ok, 0], -aim[ok, 0])
    later = row >= math.floor(float(boresight[1]) / band)
    chosen = ok[np.lexsort((across, row, ~later))][:n]
    used[open_[chosen]] = True
    pick = np.full(n, -1)
    pick[:len(chosen)] = chosen
    aimed = pick >= 0
    g = np.einsum("nij,nj->ni", to_nominal[:n][aimed], centres[pick[aimed]] - chaser[:n][aimed])
    g /= np.linalg.norm(g, axis=1)[:, None]
    cos = math.cos(max_offset)
    beyond = g[:, 2] < cos
    side = g[beyond, :2] / np.linalg.norm(g[beyond, :2], axis=1)[:, None]
    g[beyond] = np.column_stack([math.sin(max_offset) * side, np.full(len(side), cos)])
    goal = np.empty((n, 3))
    goal[aimed] = g
    last = np.maximum.accumulate(np.where(aimed, np.arange(n), -1))
    goal = np.where((last >= 0)[:, None], goal[np.maximum(last, 0)], boresight)
    before = np.vstack([boresight, goal[:-1]])
    turn = np.arccos(np.clip(np.einsum("ni,ni->n", goal, before), -1.0, 1.0))
    late = np.flatnonzero(turn > reach)
    if len(late):
        b = goal[late[0] - 1] if late[0] else boresight
        for k in range(late[0], n):
            b = goal[k] = ref_turn_toward(b, goal[k], reach)
    return pick, goal, used


# ---------------------------------------------------------------------- small maps


def _beams(rng, n, scale, spread=40.0):
    """Beams from around the origin's box onto points of a flattened cloud: origins,
    directions, ranges (one in seven a miss)."""
    points = rng.normal(size=(n, 3)) * scale
    origins = points + rng.normal(size=(n, 3)) * spread
    directions = points - origins
    ranges = np.linalg.norm(directions, axis=1)
    directions /= ranges[:, None]
    ranges[::7] = np.inf
    return origins, directions, ranges


def _maps(seed=0, blocks=5):
    """A map grown block by block by the kernels and one by the numpy references."""
    rng = np.random.default_rng(seed)
    compiled, reference = SurfaceMap(0.5), SurfaceMap(0.5)
    previous = None
    for block in range(blocks):
        origins, directions, ranges = _beams(rng, 60, np.array([5.0, 3.0, 1.0]) * (1 + block))
        # Strike some voxels again (a second strike merges into the known voxel).
        if previous is not None:
            again = rng.choice(len(origins), 20, replace=False)
            ranges[again] = np.inf
            hit = np.isfinite(previous[2])
            origins = np.concatenate([origins, previous[0][hit][:20]])
            directions = np.concatenate([directions, previous[1][hit][:20]])
            ranges = np.concatenate([ranges, previous[2][hit][:20]])
        previous = origins, directions, ranges
        compiled.add(origins, directions, ranges, margin=2.0)
        ref_strike(reference, origins, directions, ranges)
        ref_carve(reference, origins, directions, ranges, margin=2.0)
        yield compiled, reference


def test_map_update_kernels_match_the_numpy_reference():
    for compiled, reference in _maps():
        np.testing.assert_array_equal(compiled.occupied, reference.occupied)
        np.testing.assert_array_equal(compiled.count, reference.count)
        np.testing.assert_array_equal(compiled.view, reference.view)
        np.testing.assert_array_equal(compiled._corner, reference._corner)
        np.testing.assert_array_equal(compiled._state, reference._state)
        np.testing.assert_array_equal(compiled._index_lo, reference._index_lo)
        np.testing.assert_array_equal(compiled._index_hi, reference._index_hi)
        np.testing.assert_array_equal(compiled.occupied_centres,
                                      compiled.centres(compiled.occupied))
        # The frontier list, read (stale keys dropped) the numpy way and by the kernel.
        state = reference._state.reshape(-1)
        cell = reference._cells(unpack(reference._frontier))[0]
        expected = reference._frontier[(state[cell] & FRONTIER) > 0]
        np.testing.assert_array_equal(compiled.frontier(), expected)
    assert compiled.count.max() > 1 and len(expected) > 100     # re-struck voxels, a frontier


def test_strikes_on_known_voxels_only_match_the_numpy_reference():
    # No voxel struck for the first time: the kernel updates the counts and views in place.
    rng = np.random.default_rng(2)
    *_, (compiled, reference) = _maps(seed=2)
    occupied, frontier = compiled.occupied.copy(), compiled.frontier().copy()
    pick = rng.choice(len(occupied), 40)                   # some voxels twice
    directions = rng.normal(size=(40, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    ranges = np.full(40, 3.0)
    ranges[::9] = np.inf                                   # misses are ignored
    origins = compiled.centres(occupied[pick]) - 3.0 * directions
    compiled.add(origins, directions, ranges, margin=2.0)
    ref_strike(reference, origins, directions, ranges)
    ref_carve(reference, origins, directions, ranges, margin=2.0)
    np.testing.assert_array_equal(compiled.occupied, occupied)
    np.testing.assert_array_equal(compiled.count, reference.count)
    np.testing.assert_array_equal(compiled.view, reference.view)
    np.testing.assert_array_equal(compiled._state, reference._state)
    state = reference._state.reshape(-1)
    cell = reference._cells(unpack(frontier))[0]
    np.testing.assert_array_equal(compiled.frontier(), frontier[(state[cell] & FRONTIER) > 0])


def test_occupancy_grid_matches_numpy_packbits_as_the_map_grows():
    for m, _ in _maps(seed=4):
        solid, lo, hi = m.occupancy()
        dense = np.zeros(hi - lo + 1, dtype=bool)
        dense[tuple((unpack(m.occupied) - lo).T)] = True
        np.testing.assert_array_equal(solid, np.packbits(dense.ravel(), bitorder="little"))
        state, shape, corner = m.grid()
        first, last = lo - corner, hi - corner + 1
        box = state.reshape(shape)[first[0]:last[0], first[1]:last[1], first[2]:last[2]]
        np.testing.assert_array_equal(dense, (box & OCCUPIED).astype(bool))
        assert m.occupancy()[0] is solid                 # kept until a voxel is new
    # A voxel struck for the first time inside the box: its bit set in place.
    solid, lo, hi = m.occupancy()
    inside = pack((lo + hi)[None] // 2)
    for key in (inside - 1, inside, inside + 1):
        if not member(key, m.occupied)[0]:
            break
    assert not member(key, m.occupied)[0]
    above = m.centres(key) + np.array([0.0, 0.0, 0.1])       # struck from 0.1 m above
    m.add(above, np.array([[0.0, 0.0, -1.0]]), np.array([0.1]), margin=2.0)
    assert member(key, m.occupied)[0] and m.occupancy()[0] is solid
    dense = np.zeros(hi - lo + 1, dtype=bool)
    dense[tuple((unpack(m.occupied) - lo).T)] = True
    np.testing.assert_array_equal(solid, np.packbits(dense.ravel(), bitorder="little"))


def test_visibility_walk_matches_the_brute_force_reference():
    rng = np.random.default_rng(1)
    *_, (m, _) = _maps(seed=1)
    positions = rng.normal(size=(6, 3)) * 60.0
    positions[0] = m.occupied_centres.mean(axis=0) + np.array([0.0, 0.0, 0.2])   # inside
    targets = m.centres(np.concatenate([m.frontier(), m.occupied]))
    hidden = kernels.hidden(positions, targets, m.size, *m.occupancy())
    expected = ref_hidden(positions, m.occupied_centres, targets, m.size)
    np.testing.assert_array_equal(hidden, expected)
    assert 0.1 < expected.mean() < 0.9
    np.testing.assert_array_equal(m.visible(positions, targets), ~expected)


def test_spread_kernel_matches_the_numpy_reference():
    *_, (m, _) = _maps(seed=2)
    keys = np.union1d(m.frontier(), m.occupied)
    for block in (1, 2, 3):
        chosen, centres = kernels.spread(keys, block, m.size)
        cube = pack(np.floor_divide(unpack(keys), block))
        expected = keys[np.sort(np.unique(cube, return_index=True)[1])]
        np.testing.assert_array_equal(chosen, expected)
        np.testing.assert_array_equal(centres, m.centres(expected))
    assert len(expected) < len(keys)
    chosen, centres = kernels.spread(keys[:0], 2, m.size)
    assert chosen.shape == (0,) and centres.shape == (0, 3)


def test_recorded_beams_kernel_matches_scipy_rotations():
    rng = np.random.default_rng(3)
    n, b = 12, 3
    beams = rng.normal(size=(b, 3))
    beams /= np.linalg.norm(beams, axis=1)[:, None]
    struck = np.sort(rng.choice(n * b, 20, replace=False))
    row, beam = struck // b, struck % b
    direction = beams[beam] + 1e-3 * rng.normal(size=(len(struck), 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    shots = Shots(np.arange(n) * 10.0, rng.normal(size=(n, 3)) * 100.0,
                  Rotation.random(n, random_state=4).as_quat(),
                  Rotation.random(n, random_state=5).as_quat())
    chunk = StrikeChunk(start=0, shot=row + 40, beam=beam, range=rng.uniform(50, 90, len(row)),
                        direction=direction, shots=shots, shot_offset=40)
    origins, directions, ranges, stats = recorded_beams([chunk], beams)
    # scipy: strikes along their measured directions, then the misses along their beams.
    to_body, sensor = (Rotation.from_quat(shots.target_attitude).inv(),
                       Rotation.from_quat(shots.sensor_attitude))
    missed = np.setdiff1d(np.arange(n * b), struck)
    every_row = np.concatenate([row, missed // b])
    every_direction = np.concatenate([direction, beams[missed % b]])
    np.testing.assert_allclose(
        directions, to_body[every_row].apply(sensor[every_row].apply(every_direction)),
        atol=1e-14)
    np.testing.assert_allclose(origins, to_body.apply(shots.sensor_position)[every_row],
                               rtol=1e-14, atol=1e-12)
    np.testing.assert_array_equal(ranges[:len(row)], chunk.range)
    assert np.isinf(ranges[len(row):]).all() and len(ranges) == n * b
    end = origins[:len(row)] + ranges[:len(row), None] * directions[:len(row)]
    np.testing.assert_allclose(stats[:3], end.min(axis=0), rtol=1e-14)
    np.testing.assert_allclose(stats[3:6], end.max(axis=0), rtol=1e-14)
    np.testing.assert_allclose(stats[6:], [len(row), chunk.range.sum(),
                                           np.linalg.norm(end, axis=1).max()], rtol=1e-14)


def test_sweep_kernel_matches_the_numpy_reference():
    rng = np.random.default_rng(6)
    *_, (m, _) = _maps(seed=6)
    n = 30
    keys = m.frontier()
    centres = m.centres(keys)
    # The chaser circles the map 80 m out; the target turns slowly; nominal looks at the centre.
    angle = np.linspace(0.0, 0.3, n + 1)
    position = 80.0 * np.column_stack([np.cos(angle), np.sin(angle), 0.2 * np.ones(n + 1)])
    target = Rotation.from_rotvec(np.outer(np.linspace(0, 0.05, n + 1), [0.1, 0.3, 1.0]))
    z = -position / np.linalg.norm(position, axis=1)[:, None]
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x, axis=1)[:, None]
    nominal = np.stack([x, np.cross(z, x), z], axis=2)          # columns: sensor axes in I
    for max_offset, reach in ((math.radians(30), math.radians(10)),
                              (math.radians(3), math.radians(0.2))):
        used = rng.random(len(keys)) < 0.3
        boresight = np.array([0.05, -0.02, math.sqrt(1 - 0.05**2 - 0.02**2)])
        expected = ref_sweep(n, centres, used, m.occupied_centres, m.size, position,
                             target.as_matrix(), nominal, boresight, max_offset, reach, 2)
        now = used.copy()
        pick, goal, turn, left = kernels.sweep(
            n, centres, now, m.size, *m.occupancy(), position[:n], target.as_matrix()[:n],
            nominal[:n], boresight, max_offset, reach, 2, np.zeros(len(keys), dtype=np.int64), 2)
        assert left == (~expected[2]).sum()
        np.testing.assert_array_equal(pick, expected[0])
        np.testing.assert_allclose(goal, expected[1], atol=1e-13)
        np.testing.assert_array_equal(now, expected[2])
        np.testing.assert_allclose(turn, turn_from_boresight(goal), atol=1e-15)
        assert (pick >= 0).sum() >= 5


def test_turn_toward_stays_within_the_angle():
    b = (0.0, 0.0, 1.0)
    turned = kernels._turn_toward(*b, 1.0, 0.0, 0.0, math.radians(10))
    np.testing.assert_allclose(turned, [math.sin(math.radians(10)), 0, math.cos(math.radians(10))])
    np.testing.assert_array_equal(kernels._turn_toward(*b, 0.0, 0.1, 0.99, 1.0), [0, 0.1, 0.99])


def test_least_struck_kernel_matches_the_numpy_quantile():
    rng = np.random.default_rng(7)
    for n in (1, 2, 5, 40, 333):
        occupied = np.sort(rng.choice(10_000, n, replace=False)).astype(np.int64)
        count = rng.integers(1, 6, n)
        frontier = np.sort(rng.choice(10_000, 50, replace=False)).astype(np.int64)
        for q in (0.0, 0.25, 0.5, 0.9):
            expected = np.union1d(frontier, occupied[count <= np.quantile(count, q)])
            got = kernels.least_struck(frontier, occupied, count, math.floor((n - 1) * q))
            np.testing.assert_array_equal(got, expected)


def test_kth_smallest_count_matches_the_partition():
    # Counts below the histogram's reach, above it (the partition's fallback) and across it.
    rng = np.random.default_rng(8)
    top = kernels._HISTOGRAM_COUNTS
    for low, high in ((1, 6), (top - 3, top + 3), (top, 10 * top), (0, 3 * top)):
        for n in (1, 7, 500):
            count = rng.integers(low, high, n)
            for rank in {0, n // 4, n // 2, n - 1}:
                assert kernels._kth_smallest(count, rank) == np.partition(count, rank)[rank]


def test_hidden_counts_live_in_the_state_s_upper_bits():
    *_, (m, _) = _maps(seed=3)
    keys = np.union1d(m.frontier(), m.occupied)[::3]
    state = m._state.reshape(-1)
    before = state.copy()
    counts = np.arange(len(keys)) % (HIDDEN_MAX + 5)             # some beyond the largest
    kernels.store_hidden(keys, counts, *m.grid())
    np.testing.assert_array_equal(kernels.hidden_counts(keys, *m.grid()),
                                  np.minimum(counts, HIDDEN_MAX))
    np.testing.assert_array_equal(state & (HIDDEN_STEP - 1), before & (HIDDEN_STEP - 1))
    aside = 4
    kept = kernels.not_aside(keys, *m.grid(), aside, False)
    np.testing.assert_array_equal(kept, keys[np.minimum(counts, HIDDEN_MAX) < aside])
    # Re-admitted: every key back, its count cleared, the map's own bits as they were.
    np.testing.assert_array_equal(kernels.not_aside(keys, *m.grid(), aside, True), keys)
    assert not kernels.hidden_counts(keys, *m.grid()).any()
    np.testing.assert_array_equal(state, before & (HIDDEN_STEP - 1))


def test_the_sweep_sets_aside_candidates_found_hidden_and_keeps_its_picks():
    rng = np.random.default_rng(6)
    *_, (m, _) = _maps(seed=6)
    n = 30
    keys = np.union1d(m.frontier(), m.occupied)
    centres = m.centres(keys)
    position = np.tile([80.0, 10.0, 16.0], (n, 1))
    target = np.tile(np.eye(3), (n, 1, 1))
    z = -position[0] / np.linalg.norm(position[0])
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    nominal = np.tile(np.stack([x, np.cross(z, x), z], axis=1), (n, 1, 1))
    boresight = np.array([0.0, 0.0, 1.0])
    args = (m.size, *m.occupancy(), position, target, nominal, boresight, math.radians(30),
            math.radians(10), 2)
    seen = m.visible(position[n // 2], centres)
    used = rng.random(len(keys)) < 0.3
    # Hidden counts one short of being set aside: those walked and found hidden are set aside
    # (marked used); the picks are those of the sweep without counts.
    hidden = np.full(len(keys), 2, dtype=np.int64)
    free, aside = used.copy(), used.copy()
    pick_free = kernels.sweep(n, centres, free, *args, np.zeros(len(keys), dtype=np.int64),
                              HIDDEN_MAX + 1)[0]
    pick, _, _, left = kernels.sweep(n, centres, aside, *args, hidden, 3)
    np.testing.assert_array_equal(pick, pick_free)
    assert left == (~aside).sum()              # the open count: the picks and those set aside
    walked_hidden = hidden == 3
    assert walked_hidden.any() and not seen[walked_hidden].any()
    np.testing.assert_array_equal(aside, free | walked_hidden)
    np.testing.assert_array_equal(hidden[~walked_hidden], 2)
    # Set aside, they are not walked again: a second sweep leaves their counts alone.
    again = hidden.copy()
    open_before = (~aside).sum()
    *_, left = kernels.sweep(n, centres, aside, *args, again, 3)
    np.testing.assert_array_equal(again[walked_hidden], 3)
    assert left == (~aside).sum() < open_before


def test_enclose_kernel_matches_an_opening_by_scipy():
    """The kernel against scipy's morphology and connected components: the occupied voxels
    grown by the 3 x 3 x 3 cube are walls; the components (face neighbours) of the rest that
    touch the faces of the occupied box grown by two, grown back by the cube, are near the
    outside; unknown voxels neither near it nor next to (a face) a voxel near it and not
    occupied are the enclosed ones. A second call marks nothing more."""
    from scipy import ndimage

    cube = np.ones((3, 3, 3), dtype=bool)
    rng = np.random.default_rng(3)
    marked = []
    for density in (0.02, 0.08, 0.15):
        shape, corner = np.array([15, 13, 14]), np.array([-4, 7, -30])
        state = np.zeros(tuple(shape), dtype=np.uint8)
        inner = state[3:12, 2:11, 4:11]                     # holds the occupied box
        inner[...] = np.where(rng.random(inner.shape) < density, OCCUPIED, 0)
        inner |= np.where(rng.random(inner.shape) < 0.05, CROSSED | FRONTIER, 0).astype(np.uint8)
        inner[inner & OCCUPIED > 0] &= ~FRONTIER
        occupied = np.argwhere(state & OCCUPIED)
        lo, hi = occupied.min(axis=0) + corner, occupied.max(axis=0) + corner
        box = tuple(slice(a - c - 2, b - c + 3) for a, b, c in zip(lo, hi, corner, strict=True))
        region = state[box]
        walls = ndimage.binary_dilation(region & OCCUPIED > 0, structure=cube)
        labels, _ = ndimage.label(~walls)
        faces = np.unique(np.concatenate([labels[0].ravel(), labels[-1].ravel(),
                                          labels[:, 0].ravel(), labels[:, -1].ravel(),
                                          labels[:, :, 0].ravel(), labels[:, :, -1].ravel()]))
        near = ndimage.binary_dilation(np.isin(labels, faces[faces > 0]), structure=cube)
        outside = near | ndimage.binary_dilation(near & (region & OCCUPIED == 0),
                                                 structure=ndimage.generate_binary_structure(3, 1))
        expected = ~outside & (region & (OCCUPIED | CROSSED) == 0)
        before = state.copy()
        flat = state.reshape(-1)
        marked.append(kernels.enclose(flat, shape, corner, lo, hi))
        assert marked[-1] == expected.sum()
        np.testing.assert_array_equal(state[box] & ENCLOSED > 0, expected)
        want = before.copy()
        want[box][expected] = (want[box][expected] | ENCLOSED) & ~FRONTIER
        np.testing.assert_array_equal(state, want)
        assert kernels.enclose(flat, shape, corner, lo, hi) == 0
        np.testing.assert_array_equal(state, want)
    assert marked[0] == 0 < marked[1] < marked[2]     # none (the free space percolates), pockets


def test_reach_matches_the_components_joined_to_the_faces():
    """The raster sweeps of the enclose's fill stop at the first sweep after the first that
    adds nothing: the cells they reach are, on winding open space (walls on about half the
    cells, so reach turns back and forth), those a path of face neighbours through cells not
    walls joins to the box's faces (scipy's connected components; face cells count as open)."""
    from scipy import ndimage

    rng = np.random.default_rng(5)
    for seed in range(6):
        extent = tuple(int(e) for e in rng.integers(6, 14, 3))
        wall = rng.random(extent) < 0.45
        face = np.ones(extent, dtype=bool)
        face[1:-1, 1:-1, 1:-1] = False
        labels, _ = ndimage.label(~wall | face)
        expected = np.isin(labels, np.unique(labels[face]))
        reached = kernels._reach(wall.ravel(), extent)
        np.testing.assert_array_equal(reached.reshape(extent), expected, err_msg=f"case {seed}")


def test_candidates_kernel_matches_its_steps_done_the_numpy_way():
    rng = np.random.default_rng(9)
    *_, (m, _) = _maps(seed=9)
    frontier = m._frontier.copy()
    state = m._state.reshape(-1)
    stored = np.union1d(frontier, m.occupied)[::2]
    counts = rng.integers(0, 5, len(stored))
    for rank, readmit, most in ((-1, False, 10_000), (len(m.count) // 4, False, 10_000),
                                (len(m.count) // 4, False, 50), (len(m.count) // 2, True, 10_000)):
        m._frontier = frontier.copy()
        before = state.copy()
        keys, centres, hidden = m.candidates(rank=rank, aside=3, readmit=readmit, most=most,
                                             block=2, stored=stored, stored_hidden=counts)
        # The numpy way: the counts stored, the frontier read, the least-struck joined (the
        # rank-th smallest count as the threshold), the set-aside left out, every k-th kept,
        # the first per cube of two voxels, the counts read.
        grid = before.copy()
        cell = m._cells(unpack(stored))[0]
        grid[cell] = (grid[cell] & (HIDDEN_STEP - 1)) + np.minimum(counts, HIDDEN_MAX) * HIDDEN_STEP
        pool = frontier[grid[m._cells(unpack(frontier))[0]] & FRONTIER > 0]
        if rank >= 0:
            least = m.occupied[m.count <= np.sort(m.count)[rank]]
            pool = np.union1d(pool, least)
            at = m._cells(unpack(pool))[0]
            if readmit:
                grid[at] &= HIDDEN_STEP - 1
            pool = pool[grid[at] < 3 * HIDDEN_STEP]
        if len(pool) > most:
            pool = pool[::-(-len(pool) // most)]
        cube = pack(np.floor_divide(unpack(pool), 2))
        expected = pool[np.sort(np.unique(cube, return_index=True)[1])]
        np.testing.assert_array_equal(keys, expected)
        np.testing.assert_array_equal(centres, m.centres(expected))
        np.testing.assert_array_equal(hidden, grid[m._cells(unpack(expected))[0]] // HIDDEN_STEP)
        np.testing.assert_array_equal(state, grid)
        assert len(expected) > 5
        state[:] = before


def test_sweep_aims_match_the_aim_point_by_point():
    rng = np.random.default_rng(10)
    points = rng.normal(size=(300, 3)) * 20.0
    origin = np.array([150.0, -40.0, 30.0])
    turn = Rotation.random(random_state=11).as_matrix()
    x, y, z = kernels._aims(points, origin, turn)
    for q in range(len(points)):
        assert (x[q], y[q], z[q]) == kernels._toward(points[q], origin, turn)
    aim = (points - origin) @ turn.T
    np.testing.assert_allclose(np.column_stack([x, y, z]),
                               aim / np.linalg.norm(aim, axis=1)[:, None], rtol=0, atol=1e-15)
