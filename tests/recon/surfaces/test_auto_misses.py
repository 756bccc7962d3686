"""Missed beams as free space: registered as strikes are, cut by a membrane across a gap and
not by the open surface at the truth, carved away, and absent without a strike log."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from formats import SensorInfo, StrikeLogWriter
from recon.registration.ingest import ingest
from recon.registration.misses import MissedBeams, beam_rays, missed_beams
from recon.surfaces import judge
from recon.surfaces.auto import choose, format_choice

SPHERE_M, ORBIT_M = 50.0, 250.0
# Beam 2 points 0.5 rad off the boresight: the 50 m sphere seen from 250 m subtends
# asin(0.2) = 0.2 rad, so every shot's beam 2 misses.
BEAMS = np.array([[0.0, 0.0, 1.0], [np.sin(0.05), 0.0, np.cos(0.05)],
                  [np.sin(0.5), 0.0, np.cos(0.5)]])


def write_spinning_log(path, n_shots: int = 30) -> None:
    """A sensor circling a sphere that spins about z (so the body frame is not the inertial
    one); beams 0 and 1 strike it, beam 2 misses."""
    t = np.arange(n_shots) * 10.0
    phase = 2 * np.pi * t / (n_shots * 10.0)
    position = ORBIT_M * np.stack([np.cos(phase), np.sin(phase), np.zeros(n_shots)], 1)
    boresight = -position / ORBIT_M
    y_axis = np.tile([0.0, 0.0, 1.0], (n_shots, 1))
    sensor_q = Rotation.from_matrix(np.stack([np.cross(y_axis, boresight), y_axis, boresight],
                                             axis=2)).as_quat()
    target_q = Rotation.from_rotvec(np.outer(0.01 * t, [0.2, 0.1, 1.0])).as_quat()
    sensor = SensorInfo("custom", BEAMS, range_min=1.0, range_max=1000.0,
                        field_of_view=(0.0, 0.5, 0.0, 0.0))
    shot, beam = np.repeat(np.arange(n_shots), 2), np.tile([0, 1], n_shots)
    d_i = Rotation.from_quat(sensor_q[shot]).apply(BEAMS[beam])
    b = np.einsum("ij,ij->i", position[shot], d_i)
    c = np.einsum("ij,ij->i", position[shot], position[shot]) - SPHERE_M**2
    with StrikeLogWriter(path, sensor=sensor, target="sphere", scene="# test", seed=0) as log:
        log.write_shots(t, position, sensor_q, target_q)
        log.write_strikes(shot, beam, -b - np.sqrt(b * b - c))


def test_missed_beams_are_registered_as_the_strikes_are(tmp_path):
    path = tmp_path / "spin.h5"
    write_spinning_log(path)
    cloud = ingest(path)
    from formats import StrikeLog

    with StrikeLog(path) as log:
        shots, (shot, beam, rng) = log.shots(), log.strikes()
    origin, direction = beam_rays(shots, BEAMS, shot, beam)
    np.testing.assert_allclose(origin + rng[:, None] * direction, cloud.points, atol=1e-9)
    np.testing.assert_allclose(origin, cloud.view_points, atol=1e-9)

    misses = missed_beams(path, low=np.full(3, -1e4), high=np.full(3, 1e4))
    assert len(misses) == misses.n_missed == 30 and set(misses.beam) == {2}
    np.testing.assert_array_equal(misses.shot, np.arange(30))
    # Same rotations: 0.5 rad from the same shot's beam 0, from the same sensor position.
    first = beam == 0
    assert np.allclose(np.einsum("ij,ij->i", misses.direction, direction[first]), np.cos(0.5))
    np.testing.assert_allclose(misses.origin, origin[first], atol=1e-9)
    # In the body frame no missed beam meets the sphere; a box far from it keeps none.
    closest = np.einsum("ij,ij->i", -misses.origin, misses.direction)
    gap = np.linalg.norm(misses.origin + closest[:, None] * misses.direction, axis=1)
    assert np.all(gap > SPHERE_M)
    assert len(missed_beams(path, low=np.full(3, 5e3), high=np.full(3, 6e3))) == 0


def plates(n: int = 1500, seed: int = 0):
    """Two parallel 4 x 4 m plates at x = -1 and x = +1 m, each seen from its own side, and
    missed beams falling along -z through the gap between them."""
    rng = np.random.default_rng(seed)
    yz = rng.uniform(-2.0, 2.0, (2 * n, 2))
    x = np.repeat([-1.0, 1.0], n) + rng.normal(0.0, 0.002, 2 * n)
    points = np.column_stack([x, yz])
    view = np.column_stack([np.sign(x) * 10.0, yz])
    ends = rng.uniform([-0.6, -1.8], [0.6, 1.8], (400, 2))
    misses = MissedBeams(np.column_stack([ends, np.full(400, 10.0)]),
                         np.tile([0.0, 0.0, -1.0], (400, 1)), 1.0, 100.0,
                         np.arange(400), np.zeros(400, dtype=np.int64), 400)
    return points, view, misses


def box(low, high) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    mesh = trimesh.creation.box(bounds=[low, high])
    return np.asarray(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64)


def grid(x: float, n: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """A 4 x 4 m plate at ``x``, n x n cells."""
    u = np.linspace(-2.0, 2.0, n + 1)
    yy, zz = np.meshgrid(u, u, indexing="ij")
    vertices = np.column_stack([np.full(yy.size, x), yy.ravel(), zz.ravel()])
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    faces = np.concatenate([np.column_stack([a, a + n + 1, a + 1]),
                            np.column_stack([a + 1, a + n + 1, a + n + 2])])
    return vertices, faces


def test_a_membrane_across_the_gap_is_cut_and_carved_the_open_plates_are_not():
    points, _, misses = plates()
    reach = 0.2
    # The closed hull of the two plates spans the gap at z = +-2: its top cuts every beam.
    hull = box([-1.0, -2.0, -2.0], [1.0, 2.0, 2.0])
    cut = judge.cut_misses(misses, judge.Caster(*hull), points, reach)
    assert cut.mean() == 1.0
    # The plates themselves, open like the truth, are crossed by none.
    a, b = grid(-1.0), grid(1.0)
    open_plates = (np.vstack([a[0], b[0]]), np.vstack([a[1], b[1] + len(a[0])]))
    assert not judge.cut_misses(misses, judge.Caster(*open_plates), points, reach).any()
    # Carving takes the top and the bottom (both layers a beam crosses) and keeps the sides.
    vertices, faces = judge.carve(*hull, misses, points, reach)
    assert not judge.cut_misses(misses, judge.Caster(vertices, faces), points, reach).any()
    centre = vertices[faces].mean(axis=1)
    assert not np.any(np.abs(centre[:, 2]) > 1.99)   # top and bottom gone
    assert np.sum(np.abs(centre[:, 0]) > 0.99) == 4    # the two side walls kept
    # A crossing within reach of a strike is no evidence: a beam grazing past a plate's edge.
    edge = MissedBeams(np.array([[0.9, 0.0, 10.0]]), np.array([[0.0, 0.0, -1.0]]), 1.0, 100.0,
                       np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), 1)
    assert not judge.cut_misses(edge, judge.Caster(*hull), points, reach).any()


def test_auto_carves_a_closed_candidate_that_fills_the_gap_and_not_without_misses():
    points, view, misses = plates()
    candidates = [("convex-hull", {}), ("ball-pivoting", {})]
    choice = choose(points, view_points=view, candidates=candidates, seed=0, misses=misses)
    table = {c.label: c for c in choice.candidates}
    assert table["convex-hull"].misses_cut > 0.9, format_choice(choice)
    carved = table["convex-hull carved"]
    assert carved.carved and carved.misses_cut < 0.05 and not carved.closed
    assert table["ball-pivoting"].misses_cut < 0.05
    assert "ball-pivoting carved" not in table
    assert choice.n_misses == 400 and "free" in format_choice(choice)
    # A cloud without a log: no misses, no carved candidates, the same choice as before.
    plain = choose(points, view_points=view, candidates=candidates, seed=0)
    assert plain.n_misses == 0 and not plain.carved
    assert [c.label for c in plain.candidates] == ["convex-hull", "ball-pivoting"]
    assert all(c.misses_cut is None for c in plain.candidates)
    before = {c.label: c.chi2 for c in plain.candidates}
    assert before == pytest.approx({k: table[k].chi2 for k in before})
    if not choice.carved:
        assert plain.label == choice.label


def test_only_a_strike_log_hands_auto_its_misses(tmp_path):
    from recon.api import _misses

    path = tmp_path / "spin.h5"
    write_spinning_log(path)
    cloud = ingest(path, output=tmp_path / "spin.ply")
    from_log = _misses(path, cloud, 0)
    assert isinstance(from_log, MissedBeams) and set(from_log.beam) <= {2}
    assert _misses(tmp_path / "spin.ply", cloud, 0) is None
    assert _misses(cloud, cloud, 0) is None


def test_the_refitted_choice_is_carved_only_when_a_carved_candidate_was_chosen():
    points, view, misses = plates()
    hull = box([-1.0, -2.0, -2.0], [1.0, 2.0, 2.0])
    choice = choose(points, view_points=view, candidates=[("convex-hull", {})], seed=0,
                    misses=misses)
    assert choice.carved and choice.label == "convex-hull carved", format_choice(choice)
    assert "carved: the uncarved surface cuts" in choice.reason
    vertices, faces = choice.carve(*hull, points)
    assert len(faces) == 8 and len(vertices) == 8   # the four walls; top and bottom gone
    assert np.all(np.abs(vertices[faces].mean(axis=1)[:, 2]) < 1.99)
    plain = choose(points, view_points=view, candidates=[("convex-hull", {})], seed=0)
    assert not plain.carved
    same = plain.carve(*hull, points)
    assert same[0] is hull[0] and same[1] is hull[1]


def test_missed_beams_are_a_seeded_bounded_draw(tmp_path):
    path = tmp_path / "spin.h5"
    write_spinning_log(path)
    box = {"low": np.full(3, -1e4), "high": np.full(3, 1e4)}
    # 90 pairs fired, 40 drawn (20 a miss kept): about a third of them missed.
    a = missed_beams(path, limit=2, seed=3, **box)
    b = missed_beams(path, limit=2, seed=3, **box)
    assert len(a) == 2 and set(a.beam) == {2}
    np.testing.assert_array_equal(a.origin, b.origin)
    np.testing.assert_array_equal(a.shot, b.shot)
    assert 10 <= a.n_missed <= 60
    assert not np.array_equal(missed_beams(path, limit=2, seed=4, **box).shot, a.shot) or \
        not np.array_equal(missed_beams(path, limit=2, seed=5, **box).shot, a.shot)


def test_compare_ranks_a_carved_choice_as_the_surface_reconstruct_makes():
    from formats.geometry import Cloud
    from recon.api import _auto_agreement
    from recon.surfaces.isolation import Limits
    from recon.surfaces.prepare import Preparation, load_prepared

    points, view, misses = plates()
    cloud = Cloud(points, dict(zip(("view_x", "view_y", "view_z"), view.T, strict=True)))
    _, prepared = load_prepared(cloud, Preparation())
    a, b = grid(-1.0, 20), grid(1.0, 20)
    truth = (np.vstack([a[0], b[0]]), np.vstack([a[1], b[1] + len(a[0])]))
    # The compared runs: the closed hull far from the open truth, and one open run close to it.
    records = [{"status": "ok", "key": "hull", "label": "convex-hull", "method": "convex-hull",
                "chamfer_m": 0.9, "fscore": 0.5},
               {"status": "ok", "key": "near", "label": "near", "method": "plane",
                "chamfer_m": 0.05, "fscore": 0.97}]
    result, text = _auto_agreement(cloud, records, ["convex-hull"], Preparation(),
                                   Limits.from_options(), "unknown", misses=misses,
                                   prepared=prepared, truth=truth,
                                   score_options={"n_truth_samples": 20_000,
                                                  "n_test_samples": 20_000,
                                                  "coverage_points": 40_000})
    verdict = result["agreement"]
    assert result["choice"]["label"] == "convex-hull carved", text
    # The carved walls are the plates: scored, it ranks among the runs, ahead of the hull.
    assert verdict["label"] == "convex-hull carved" and verdict["n_ranked"] == 3
    assert verdict["rank"] <= 2


def test_the_estimate_does_not_count_free_space_the_misses_show_as_unseen_truth():
    from formats.geometry import Cloud
    from recon.surfaces.estimate import estimate

    points, view, misses = plates()
    cloud = Cloud(points, dict(zip(("view_x", "view_y", "view_z"), view.T, strict=True)))
    a, b = grid(-1.0, 20), grid(1.0, 20)
    open_plates = (np.vstack([a[0], b[0]]), np.vstack([a[1], b[1] + len(a[0])]))
    # The truth is the two plates: their Chamfer distance to it is ~0. Without the misses the
    # strikes' hull stands for unseen truth across the gap (its top, bottom and ends); the
    # misses cross about half of the top and the bottom, which are then free space.
    blind = estimate(open_plates, cloud)
    seen = estimate(open_plates, cloud, misses=misses)
    assert seen.chamfer_m < 0.8 * blind.chamfer_m, (seen.describe(), blind.describe())
    assert seen.unseen < blind.unseen


def test_the_missed_beams_reach_the_methods_input(tmp_path, monkeypatch):
    """Every fold auto fits on carries the log's misses (``MethodInput.misses``, which the
    visibility method uses), and so does the fit of ``recon.api.reconstruct`` on a strike log;
    a cloud file's fit carries none."""
    from formats.geometry import Cloud
    from recon import api
    from recon.surfaces import auto
    from recon.surfaces import reconstruct as reconstruct_module

    points, view, misses = plates()
    cloud = Cloud(points, dict(zip(("view_x", "view_y", "view_z"), view.T, strict=True)))
    folds = judge.pass_folds(cloud, 3, seed=0)
    context = auto._context(cloud, folds, k=30, fallback="centroid", seed=0, misses=misses)
    assert all(fold.prepared.misses is misses for fold in context.folds)

    path = tmp_path / "spin.h5"
    write_spinning_log(path)
    received = []
    fit = reconstruct_module.reconstruct

    def spy(prepared, **kwargs):
        received.append(prepared.misses)
        return fit(prepared, **kwargs)

    monkeypatch.setattr(reconstruct_module, "reconstruct", spy)
    api.reconstruct(path, method="convex-hull", isolate=False)
    ingest(path, output=tmp_path / "spin.ply")
    api.reconstruct(tmp_path / "spin.ply", method="convex-hull", isolate=False)
    # (the log's 30 misses pass 0.3 rad beside the sphere: none near the strikes is kept)
    assert isinstance(received[0], MissedBeams) and received[0].n_missed == 30
    assert received[1] is None
