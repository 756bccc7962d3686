"""Carving by missed beams, cheaply: the recast of only the beams whose first hit was removed
(and the stop without a scene build) removes exactly the faces the full recast of every beam
against a scene of the faces left removes; the ladder fitted and judged in one go gives the
candidates level by level gives; ``closed`` counts edges as the row-wise count does."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from recon.registration.misses import MissedBeams
from recon.surfaces import auto, judge


def full_recast(vertices, faces, misses, strikes, reach) -> np.ndarray:
    """The reference: every pass builds the scene of the faces left and casts every beam."""
    faces = np.asarray(faces, dtype=np.int64)
    carved = np.zeros(len(faces), dtype=bool)
    for _ in range(judge.CARVE_PASSES):
        left = np.flatnonzero(~carved)
        if not len(left):
            break
        caster = judge.Caster(vertices, faces[left])
        cut = judge.cut_misses(misses, caster, strikes, reach)
        rays = np.hstack([misses.origin - caster.centre, misses.direction]).astype(np.float32)
        triangle = caster.scene.cast_rays(caster._o3d.core.Tensor(rays))["primitive_ids"]
        if not cut.any():
            break
        carved[left[triangle.numpy().astype(np.int64)[cut]]] = True
    return carved


def sphere(radius: float, subdivisions: int = 2, offset=(0.0, 0.0, 0.0)):
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(mesh.vertices) + offset, np.asarray(mesh.faces, dtype=np.int64)


def nested(seed: int):
    """Three nested, slightly jittered spheres (a beam through the middle crosses six
    layers: several passes), their strikes on a cap of the outer one."""
    rng = np.random.default_rng(seed)
    parts = [sphere(r) for r in (1.0, 1.6, 2.2)]
    vertices, faces, start = [], [], 0
    for v, f in parts:
        vertices.append(v + rng.normal(0.0, 0.01, v.shape))
        faces.append(f + start)
        start += len(v)
    vertices, faces = np.vstack(vertices), np.vstack(faces)
    cap = rng.normal(size=(300, 3))
    cap[:, 2] = np.abs(cap[:, 2]) + 2.0
    strikes = 2.2 * cap / np.linalg.norm(cap, axis=1, keepdims=True)
    return vertices, faces, strikes


def beams(seed: int, n: int = 400, spread: float = 1.5):
    """Missed beams from far along +x towards the origin's neighbourhood."""
    rng = np.random.default_rng(seed)
    target = rng.uniform(-spread, spread, (n, 3))
    origin = np.column_stack([np.full(n, 20.0), rng.uniform(-3.0, 3.0, (n, 2))])
    direction = target - origin
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return MissedBeams(origin, direction, 1.0, 100.0, np.arange(n),
                       np.zeros(n, dtype=np.int64), n)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("reach", [0.05, 0.6])
def test_carving_removes_exactly_the_faces_of_the_full_recast(seed, reach):
    vertices, faces, strikes = nested(seed)
    misses = beams(seed)
    expected = full_recast(vertices, faces, misses, strikes, reach)
    assert expected.sum() > 20    # the reference carved something, over several layers
    carved = judge.carved_faces(vertices, faces, misses, strikes, reach)
    np.testing.assert_array_equal(carved, expected)
    # The same with the caller's scene of the whole surface.
    caster = judge.Caster(vertices, faces)
    np.testing.assert_array_equal(
        judge.carved_faces(vertices, faces, misses, strikes, reach, caster=caster), expected)
    kept_v, kept_f = judge.carve(vertices, faces, misses, strikes, reach, caster=caster)
    assert len(kept_f) == len(faces) - expected.sum()
    np.testing.assert_allclose(kept_v[kept_f], vertices[faces[~expected]])


def test_the_passes_run_out_as_the_full_recast_does():
    """With more layers than passes both stop at ``CARVE_PASSES``, with the same faces."""
    parts = [sphere(0.5 + 0.2 * i, subdivisions=1) for i in range(judge.CARVE_PASSES)]
    vertices = np.vstack([v for v, _ in parts])
    faces = np.vstack([f + 42 * i for i, (_, f) in enumerate(parts)])
    strikes = np.array([[0.0, 0.0, 50.0]])
    misses = beams(3, n=200, spread=0.3)
    expected = full_recast(vertices, faces, misses, strikes, 0.1)
    carved = judge.carved_faces(vertices, faces, misses, strikes, 0.1)
    np.testing.assert_array_equal(carved, expected)
    # the innermost layer is still crossed: the passes ran out
    assert judge.cut_misses(misses, judge.Caster(vertices, faces[~carved]), strikes, 0.1).any()


def test_nothing_to_carve():
    vertices, faces, strikes = nested(0)
    none = MissedBeams(np.zeros((0, 3)), np.zeros((0, 3)), 1.0, 100.0,
                       np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), 0)
    assert not judge.carved_faces(vertices, faces, none, strikes, 0.1).any()
    # beams that pass beside the surface
    far = beams(0)
    far = MissedBeams(far.origin + np.array([0.0, 50.0, 0.0]), far.direction, 1.0, 100.0, far.shot,
                      far.beam, len(far))
    assert not judge.carved_faces(vertices, faces, far, strikes, 0.1).any()


def rows_closed(faces: np.ndarray) -> bool:
    """The reference: edges counted as rows."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]),
                    axis=1)
    _, count = np.unique(edges, axis=0, return_counts=True)
    return bool(len(faces)) and not np.any(count == 1)


def test_closed_counts_edges_as_rows_do():
    _, ball = sphere(1.0)
    _, faces, _ = nested(0)
    cases = [ball, ball[1:], faces, faces[::2], np.vstack([ball, ball[:5]]),
             np.zeros((0, 3), dtype=np.int64)]
    for f in cases:
        assert auto.closed(f) == rows_closed(f)
    assert auto.closed(ball) and not auto.closed(ball[1:])


def test_the_ladder_fitted_at_once_judges_as_level_by_level(monkeypatch):
    """``climb`` fits the always-fitted levels together and judges each run as its folds come
    in: the same candidates, in the same order, with the same figures as one level at a
    time (without the race, which a level alone runs against fewer runs)."""
    monkeypatch.setattr(auto, "RACE_STAGES", ())
    from formats.geometry import Cloud
    from recon.surfaces.isolation import Limits
    from recon.surfaces.methods import bind

    rng = np.random.default_rng(0)
    points = rng.normal(size=(1500, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    points += rng.normal(0.0, 0.01, points.shape)
    view = 5.0 * points
    attributes = dict(zip(("view_x", "view_y", "view_z"), view.T, strict=True))
    cloud = Cloud(points, attributes | {"shot": np.arange(1500), "beam": np.zeros(1500)})
    folds = judge.pass_folds(cloud, 4, seed=0)
    misses = beams(0, n=200)
    context = auto._context(cloud, folds, k=10, fallback="centroid", seed=0, misses=misses)
    levels = [[bind("convex-hull"), bind("ellipsoid")], [bind("planes")]]
    limits = Limits()
    together, _ = auto.climb(levels, context, limits=limits, n_workers=2)
    apart = [c for depth, level in enumerate(levels)
             for judged in auto._fit_and_judge([(depth, level)], context, limits=limits,
                                               n_workers=1)[depth] for c in judged]
    assert [c.label for c in together] == [c.label for c in apart]
    assert [c.level for c in together] == sorted(c.level for c in together)
    for before, c in itertools.pairwise(together):   # a carved twin follows its run
        assert not c.carved or (before.run.key == c.run.key and not before.carved)
    for a, b in zip(together, apart, strict=True):
        assert (a.chi2, a.chi2_se, a.holes, a.violated, a.misses_cut, a.n_faces) == \
            (b.chi2, b.chi2_se, b.holes, b.violated, b.misses_cut, b.n_faces)


def hemisphere():
    """The upper half of a unit sphere (1 cm of noise, seeded), each strike seen from 5 m out
    along its normal, dealt to 4 pass folds, with 200 missed beams: its closures (a hull, an
    ellipsoid) fill space the beams cross. Returns auto's context (its folds in context.folds)."""
    from formats.geometry import Cloud

    rng = np.random.default_rng(1)
    points = rng.normal(size=(3000, 3))
    points = points[points[:, 2] > 0.0] / np.linalg.norm(points[points[:, 2] > 0.0], axis=1,
                                                         keepdims=True)
    points += rng.normal(0.0, 0.01, points.shape)
    n = len(points)
    attributes = dict(zip(("view_x", "view_y", "view_z"), (5.0 * points).T, strict=True))
    cloud = Cloud(points, attributes | {"shot": np.arange(n), "beam": np.zeros(n)})
    folds = judge.pass_folds(cloud, 4, seed=0)
    context = auto._context(cloud, folds, k=10, fallback="centroid", seed=0,
                            misses=beams(0, n=200))
    return context


def test_checks_made_ahead_while_the_workers_fit_judge_as_those_made_at_the_judging():
    """``_Race.make_next`` makes the judging's checks (training strikes, all strikes, missed
    beams, the carved twin's) fold by fold while the workers fit: every candidate, carved
    twins included, has the figures of the judging that makes them all itself."""
    from recon.surfaces.isolation import run_isolated
    from recon.surfaces.methods import bind

    context = hemisphere()
    runs = [bind("convex-hull"), bind("ellipsoid")]
    results = [[run_isolated(run, fold.prepared) for fold in context.folds] for run in runs]
    state = auto._Race([(0, runs)], context)
    for j, fitted in enumerate(results):
        for f, result in enumerate(fitted):
            state.arrived((0, j), f, result)
    steps = 0
    while state.make_next():
        steps += 1
    assert steps > 0 and all(state.made[0, j].overall is not None for j in range(2))

    def figures(judged):
        return [(c.label, c.carved, c.chi2, c.chi2_se, c.chi_fit, c.holes, c.violated,
                 c.misses_cut, c.n_faces, c.heldout_mean_m) for c in judged]

    for j, (run, fitted) in enumerate(zip(runs, results, strict=True)):
        ahead = auto._judged(run, 0, fitted, context, state.made[0, j])
        at_judging = auto._judged(run, 0, fitted, context)
        assert figures(ahead) == figures(at_judging)
    assert any(c.carved for c in ahead + at_judging)
    assert state.made[0, 1].twin is not None or state.made[0, 0].twin is not None


def counting(monkeypatch, name: str) -> tuple[list, object]:
    """Count the calls of ``judge.<name>`` for the test's duration: the list it appends each
    call's arguments to, and the function it wraps."""
    calls = []
    original = getattr(judge, name)

    def counted(*args, **kwargs):
        calls.append(args)
        return original(*args, **kwargs)

    monkeypatch.setattr(judge, name, counted)
    return calls, original


def test_carving_given_the_first_cast_casts_it_not_again_and_carves_alike(monkeypatch):
    """``carve`` given the missed beams' cast against the whole surface (``cast_misses``, as
    the first fold's overall check makes it) starts from it: one cast fewer, the same faces."""
    vertices, faces, strikes = nested(0)
    misses = beams(0)
    caster = judge.Caster(vertices, faces)
    cast = judge.cast_misses(misses, caster, strikes, 0.1)
    np.testing.assert_array_equal(cast[2], judge.cut_misses(misses, caster, strikes, 0.1))
    casts, _ = counting(monkeypatch, "_cast_misses")
    given = judge.carve(vertices, faces, misses, strikes, 0.1, caster=caster, cast=cast)
    n_given = len(casts)
    plain = judge.carve(vertices, faces, misses, strikes, 0.1, caster=caster)
    assert n_given == len(casts) - n_given - 1 and n_given >= 1   # several passes: nested
    for a, b in zip(given, plain, strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_twin_fold_the_carving_left_whole_shares_the_uncarved_surface_and_its_checks(
        monkeypatch):
    """Where the missed beams cut nothing of a fold's surface, the carved twin's surface there
    is the uncarved one (``auto._carved`` gives the fold's result back): the twin takes its
    checks instead of casting the fold's strikes again, and its figures are those of the
    carved folds judged afresh."""
    from recon.surfaces.isolation import run_isolated
    from recon.surfaces.methods import bind

    context = hemisphere()
    run = bind("convex-hull")
    hull = run_isolated(run, context.folds[0].prepared)
    # the other folds' surface: a plate far above the beams, which none of them crosses
    plate = hull | {"vertices": np.array([[-1.0, -1.0, 50.0], [1.0, -1.0, 50.0],
                                          [1.0, 1.0, 50.0], [-1.0, 1.0, 50.0]]),
                    "faces": np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64)}
    results = [hull] + [dict(plate) for _ in range(3)]
    checks, original = counting(monkeypatch, "check")
    made = auto._Made.empty(4)
    candidate, twin = auto._judged(run, 0, results, context, made)
    assert twin.carved and twin.n_faces < candidate.n_faces
    # the uncarved run: 4 held-out, 4 training and 1 overall check; its twin only fold 0's 3
    assert len(checks) == 9 + 3
    assert all(made.twin.results[f] is results[f] for f in range(1, 4))
    assert made.twin.results[0] is not results[0]
    monkeypatch.setattr(judge, "check", original)
    afresh = auto.judge_candidate(run, 0, [dict(r) for r in made.twin.results], context,
                                  carved=True)

    def figures(c):
        return (c.chi2, c.chi2_se, c.chi_fit, c.heldout_mean_m, c.beam_misses, c.holes,
                c.violated, c.misses_cut, c.n_faces, c.n_params, c.span)

    assert figures(twin) == figures(afresh)
    np.testing.assert_array_equal(twin.cost, afresh.cost)
    np.testing.assert_array_equal(twin.heldout.sigma, afresh.heldout.sigma)
