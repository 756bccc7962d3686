"""The voxel map of the gap-seeking law: keys, free space, frontier, predicted visibility."""

from __future__ import annotations

import numpy as np
import pytest

from sim.raycast import EmbreeBackend, ExactHits
from sim.surface_map import (
    FACE_STEPS,
    SurfaceMap,
    member,
    pack,
    unpack,
)
from sim.targets import box, combine


def test_keys_round_trip_and_membership():
    index = np.array([[0, 0, 0], [-5, 7, 1_000_000], [-1_000_000, -1, 3]])
    np.testing.assert_array_equal(unpack(pack(index)), index)
    table = np.sort(pack(index[:2]))
    np.testing.assert_array_equal(member(pack(index), table), [True, True, False])
    with pytest.raises(ValueError, match="size must be positive, got 0"):
        SurfaceMap(0)


def _plate_beams(side: float, n: int = 9):
    """Beams from 30 m above (side +1) or below (-1) onto a grid of the plate z = 0.1, |x|, |y|
    <= 1: origins, directions, ranges."""
    x, y = np.meshgrid(np.linspace(-0.95, 0.95, n), np.linspace(-0.95, 0.95, n))
    targets = np.column_stack([x.ravel(), y.ravel(), np.full(n * n, 0.1)])
    origins = targets + np.array([0.3, -0.2, 30.0 * side])
    line = targets - origins
    ranges = np.linalg.norm(line, axis=1)
    return origins, line / ranges[:, None], ranges


def test_a_plate_seen_from_one_side_is_a_frontier_until_its_other_side_is_struck():
    plate = SurfaceMap(0.25)
    plate.add(*_plate_beams(+1), margin=2.0)
    struck = plate.occupied
    assert set(unpack(struck)[:, 2]) == {0}              # z = 0.1 lies in voxel layer 0
    assert (plate.view[:, 2] > 0).all() and plate.count.sum() == 81     # seen from above
    # Every struck voxel of the plate is still a frontier: the layer below it is unknown.
    np.testing.assert_array_equal(plate.surface_frontier(), struck)
    below = pack(unpack(struck) - np.array([0, 0, 1]))
    assert member(below, plate.frontier()).all()
    assert not member(pack(unpack(struck) + np.array([0, 0, 1])), plate.frontier()).any()   # carved
    # Struck from below too: no voxel of the plate keeps unknown space under it.
    plate.add(*_plate_beams(-1), margin=2.0)
    np.testing.assert_array_equal(plate.occupied, struck)
    assert plate.count.sum() == 162 and np.allclose(plate.view[:, 2], 0)   # from both sides
    assert not member(below, plate.frontier()).any()
    inner = np.abs(unpack(struck)[:, :2] + 0.5).max(axis=1) < 3      # away from the plate's rim
    assert not member(struck[inner], plate.surface_frontier()).any()


def _sphere(n: int) -> np.ndarray:
    """``n`` unit vectors (n, 3) spread over the sphere (Fibonacci lattice)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = np.pi * (3.0 - np.sqrt(5.0)) * k
    return np.column_stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z])


def _bus_and_boom():
    """A 2 m bus, a 0.2 m boom along +x and a 0.5 m box at its end (x 4 .. 4.5)."""
    return combine(box([-1, -1, -1], [1, 1, 1]), box([1, -0.1, -0.1], [4, 0.1, 0.1]),
                   box([4, -0.25, -0.25], [4.5, 0.25, 0.25]))


def _beams_at_bus_and_boom(n_sides: int, seed: int):
    """Beams from 60 m all around (20 from each of ``n_sides`` directions), each at a random
    point of the bounding box of :func:`_bus_and_boom`: origins, directions, ranges (inf for a
    miss)."""
    vertices, faces = _bus_and_boom()
    rng = np.random.default_rng(seed)
    sides = np.repeat(_sphere(n_sides), 20, axis=0)
    aim = rng.uniform([-1, -1, -1], [4.5, 1, 1], (len(sides), 3))
    origins = aim + 60.0 * sides
    directions = (aim - origins) / 60.0
    caster, exact = EmbreeBackend(vertices, faces), ExactHits(vertices, faces)
    face, u, v = caster.first_hit_uv(origins.astype(np.float32), directions.astype(np.float32))
    hit = face >= 0
    ranges = np.full(len(origins), np.inf)
    ranges[hit] = exact.refine(origins[hit], directions[hit], face[hit], u[hit], v[hit],
                               scale=70.0)[0]
    return origins, directions, ranges


def test_a_boom_behind_the_bus_is_predicted_hidden_from_the_far_side():
    origins, directions, ranges = _beams_at_bus_and_boom(400, seed=0)
    seen = SurfaceMap(0.2)
    seen.add(origins, directions, ranges, margin=1.0)
    end_box = seen.occupied[unpack(seen.occupied)[:, 0] >= 20]       # x >= 4 m
    assert len(end_box) > 20
    centres = seen.centres(end_box)
    # From the far side (-x, behind the bus) every voxel of the end box is predicted hidden;
    # from the +x side its near face is predicted struck, from the side (+y) its +y face.
    assert not seen.visible(np.array([-60.0, 0.0, 0.0]), centres).any()
    near = seen.visible(np.array([60.0, 0.0, 0.0]), centres)
    np.testing.assert_array_equal(near, unpack(end_box)[:, 0] == unpack(end_box)[:, 0].max())
    side = seen.visible(np.array([0.0, 60.0, 0.0]), centres)
    assert side.any() and not side[unpack(end_box)[:, 1] < unpack(end_box)[:, 1].max()].any()


def test_a_map_grown_block_by_block_keeps_its_frontier_as_defined():
    origins, directions, ranges = _beams_at_bus_and_boom(200, seed=1)
    grown, whole = SurfaceMap(0.2), SurfaceMap(0.2)
    whole.add(origins, directions, ranges, margin=1.0)
    for part in np.array_split(np.arange(len(origins)), 7):      # the grid grows between parts
        grown.add(origins[part], directions[part], ranges[part], margin=1.0)
    np.testing.assert_array_equal(grown.occupied, whole.occupied)
    np.testing.assert_array_equal(grown.count, whole.count)
    # (The crossed voxels differ a little: a beam is sampled within the occupied box of its
    # time, so from another first point.)
    steps = pack(FACE_STEPS) - pack(np.zeros((1, 3), dtype=np.int64))
    for kept in (grown, whole):            # the frontier kept up to date is the definition's
        around = np.unique((kept.occupied[:, None] + steps[None]).ravel())
        expected = around[~member(around, kept.occupied) & ~member(around, kept.free)]
        np.testing.assert_array_equal(kept.frontier(), expected)


def test_the_visibility_walk_agrees_with_beams_cast_against_the_voxels():
    # Reference: Embree casts from each view to each voxel centre against a mesh of every
    # occupied voxel as a box; hidden when a box is struck more than one edge short of the
    # voxel's centre (its own near face lies half an edge to sqrt(3) / 2 edges before it).
    origins, directions, ranges = _beams_at_bus_and_boom(200, seed=2)
    seen = SurfaceMap(0.2)
    seen.add(origins, directions, ranges, margin=1.0)
    corners = unpack(seen.occupied) * seen.size
    vertices, faces = combine(*(box(c, c + seen.size) for c in corners))
    caster = EmbreeBackend(vertices, faces)
    targets = seen.centres(np.concatenate([seen.frontier(), seen.occupied]))
    views = 60.0 * _sphere(12)
    predicted = seen.visible(views, targets)
    assert predicted.shape == (12, len(targets))
    agree = []
    for view, row in zip(views, predicted, strict=True):
        line = targets - view
        length = np.linalg.norm(line, axis=1)
        direction = (line / length[:, None]).astype(np.float32)
        face = caster.first_hit(np.broadcast_to(view, targets.shape).astype(np.float32),
                                direction)
        hit = np.where(face >= 0, face, 0)
        a, b, c = (vertices[faces[hit, i]] for i in range(3))
        normal = np.cross(b - a, c - a)
        t = np.einsum("ni,ni->n", normal, a - view) / np.einsum("ni,ni->n", normal, direction)
        reference = (face < 0) | (t >= length - seen.size)
        agree.append([(row & reference).sum(), (row & ~reference).sum(), reference.sum()])
        np.testing.assert_array_equal(seen.visible(view, targets), row)   # one view alone
    both, only_predicted, cast = np.sum(agree, axis=0)
    # Predicted visible: mostly what the beams reach, and most of that (measured 0.89 and 0.93).
    assert both / (both + only_predicted) > 0.85 and both / cast > 0.85, (both, only_predicted,
                                                                           cast)


def _shell(open_face: bool) -> SurfaceMap:
    """A map whose struck voxels are the shell of the cube of voxels 0 .. 7 (edge 0.5 m) seen
    from outside, without its +z face when ``open_face``: struck from 20 m out along the
    outward normal of each shell voxel's centre, the beams' paths carved."""
    index = np.stack(np.meshgrid(*[np.arange(8)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    shell = index[((index == 0) | (index == 7)).any(axis=1)]
    if open_face:
        shell = shell[shell[:, 2] < 7]
    centres = (shell + 0.5) * 0.5
    out = centres - 2.0
    out /= np.linalg.norm(out, axis=1)[:, None]
    surface = SurfaceMap(0.5)
    surface.add(centres + 20.0 * out, -out, np.full(len(out), 20.0), margin=1.0)
    return surface


def _inside(keys: np.ndarray) -> np.ndarray:
    """Which voxel ``keys`` lie strictly inside the cube of :func:`_shell`."""
    index = unpack(keys)
    return ((index >= 1) & (index <= 6)).all(axis=1)


def test_a_closed_shell_has_no_frontier_inside_once_enclosed():
    closed = _shell(open_face=False)
    assert _inside(closed.frontier()).sum() == 6 ** 3 - 4 ** 3     # the layer behind the shell
    assert closed.enclose() == 6 ** 3                              # the whole inside, now
    assert not _inside(closed.frontier()).any()
    outside = closed.frontier()
    assert len(outside) and closed.enclose() == 0                  # marked once, for good
    # A voxel struck next to the enclosed inside does not make it frontier again.
    closed.add(np.array([[1.75, 1.75, 30.0]]), np.array([[0.0, 0.0, -1.0]]),
               np.array([30.0 - 1.75]), margin=0.0)
    assert not _inside(closed.frontier()).any()


def test_a_shell_with_one_face_open_keeps_its_inside_frontier():
    open_ = _shell(open_face=True)
    before = open_.frontier().copy()
    assert _inside(before).any()
    assert open_.enclose() == 0
    np.testing.assert_array_equal(open_.frontier(), before)


def test_the_far_side_of_a_plate_stays_frontier_when_enclosed_voxels_are_marked():
    plate = SurfaceMap(0.25)
    plate.add(*_plate_beams(+1), margin=2.0)
    below = pack(unpack(plate.occupied) - np.array([0, 0, 1]))
    assert plate.enclose() == 0
    assert member(below, plate.frontier()).all()
