"""The gap-seeking attitude law: scene keys, limits, closed loop from the log alone, coverage."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import sim
from formats import StrikeLog
from formats.strike_log import StrikeChunk
from sim.gap_seeking import (
    GapSeeker,
    body_points,
    turn_from_boresight,
)
from sim.pipeline import make_plan, poses

SMALL = ["target.subdivisions=3", "orbit.inclination_deg=60", "attitude.mode=gaps"]


def test_turns():
    b = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, -0.6, 0.8]])
    m = turn_from_boresight(b)
    np.testing.assert_allclose(m[:, :, 2], b, atol=1e-15)        # +z goes onto the boresight
    np.testing.assert_allclose(np.linalg.det(m), 1.0)
    np.testing.assert_allclose(m[0], np.eye(3))                  # no turn: identity


def test_scene_keys_of_the_attitude_law():
    scene = sim.load_scene("asteroid-lrf-60deg-slew", ["attitude.mode=gaps"])
    assert scene.values["slew"] == {}                # the preset's slew gives way to the law
    assert scene["attitude.max_rate_deg_s"] == 1.0 and scene["attitude.replan_s"] == 300.0
    with pytest.raises(sim.SceneError, match=r'slew\.amplitude_deg is only used when '
                                             r'attitude\.mode is "fixed"'):
        sim.load_scene("asteroid-lrf", ["attitude.mode=gaps", "slew.amplitude_deg=2"])
    with pytest.raises(sim.SceneError, match=r'attitude\.max_rate_deg_s is only used when '
                                             r'attitude\.mode is "gaps"'):
        sim.load_scene("asteroid-lrf", ["attitude.max_rate_deg_s=2"])
    with pytest.raises(sim.SceneError, match=r"attitude\.max_offset_deg must be above 0 and "
                                             r"below 90 deg, got 95"):
        sim.load_scene("asteroid-lrf", ["attitude.mode=gaps", "attitude.max_offset_deg=95"])
    with pytest.raises(sim.SceneError, match=r"attitude\.mode must be one of fixed, gaps"):
        sim.load_scene("asteroid-lrf", ["attitude.mode=gap"])


def _commanded_boresight(scene, log_path):
    """Time (n,) and the commanded boresight (n, 3) in the nominal sensor frame, from the log."""
    from scipy.spatial.transform import Rotation

    with StrikeLog(log_path) as log:
        shots = log.shots()
    _, _, nominal = poses(make_plan(scene, seed=0), shots.time)
    recorded = Rotation.from_quat(shots.sensor_attitude).as_matrix()
    return shots.time, np.einsum("nji,nj->ni", nominal, recorded[:, :, 2])


def test_closed_loop_keeps_its_limits_and_is_replayed_from_the_log_alone(tmp_path):
    scene = sim.load_scene("asteroid-lrf", [*SMALL, "time.duration=10800",
                                            "attitude.max_rate_deg_s=0.5",
                                            "attitude.max_offset_deg=20"])
    log_path = tmp_path / "gaps.h5"
    sim.simulate(scene, log_path, seed=0, progress=False)
    t, boresight = _commanded_boresight(scene, log_path)
    off = np.degrees(np.arccos(np.clip(boresight[:, 2], -1, 1)))
    step = np.degrees(np.arccos(np.clip(np.einsum("ni,ni->n", boresight[1:], boresight[:-1]),
                                        -1, 1)))
    assert off.max() <= 20.0 + 1e-6 and step.max() <= 0.5 * 10.0 + 1e-6
    assert off.max() > 10.0                       # the law does leave nadir
    # Replay: a fresh law fed only what the log holds commands the same attitudes.
    plan = make_plan(scene, seed=0)
    law = GapSeeker(step=10.0, max_rate=math.radians(0.5), max_offset=math.radians(20),
                    poses=lambda times: poses(plan, times), beams=plan.pattern.directions)
    with StrikeLog(log_path) as log:
        shot, beam, rng = log.strikes()
        direction = log.directions(beam, 0, log.n_strikes)
        shots = log.shots()
        for first in range(0, log.n_shots, 30):
            stop = min(first + 30, log.n_shots)
            command = law.command(t[first:stop])
            np.testing.assert_allclose(command[:, :, 2], boresight[first:stop], atol=1e-9)
            rows = (shot >= first) & (shot < stop)
            law.observe(StrikeChunk(start=0, shot=shot[rows], beam=beam[rows], range=rng[rows],
                                    direction=direction[rows],
                                    shots=log.shots(first, stop), shot_offset=first))
        # Registration from the recorded values puts every strike on its true point.
        truth = log.truth_strikes().point
        chunk = StrikeChunk(start=0, shot=shot, beam=beam, range=rng, direction=direction,
                            shots=shots, shot_offset=0)
        np.testing.assert_allclose(body_points(chunk), truth, atol=1e-6)


def test_gap_seeking_covers_far_more_than_nadir_in_the_same_time(tmp_path):
    from metrics.score import score
    from recon.registration.ingest import ingest

    coverage = {}
    for mode in ("gaps", "fixed"):
        scene = sim.load_scene("asteroid-lrf", [*SMALL[:2], f"attitude.mode={mode}",
                                                "time.duration=14400"])
        sim.simulate(scene, tmp_path / f"{mode}.h5", seed=0, progress=False)
        cloud = ingest(tmp_path / f"{mode}.h5")
        coverage[mode] = score(cloud.points, (scene.vertices, scene.faces), seed=0,
                               n_truth_samples=20_000, coverage_points=40_000).coverage
    # Measured: 0.15 against 0.03 after 4 h at 60 deg (one sixth of the 25 h orbit).
    assert coverage["gaps"] > 3 * coverage["fixed"], coverage


def test_closed_loop_on_a_generated_satellite_gives_the_same_bytes_for_the_same_seed(tmp_path):
    from tests.sim.conftest import read_all

    scene = sim.load_scene("rso-a-lrf", ["target.kind=satellite", "target.seed=1",
                                         "attitude.mode=gaps", "time.duration=2400"])
    for name in ("a.h5", "b.h5"):
        sim.simulate(scene, tmp_path / name, seed=3, progress=False)
    a, b = read_all(tmp_path / "a.h5"), read_all(tmp_path / "b.h5")
    assert a.keys() == b.keys()
    for key in a:
        assert np.asarray(a[key]).tobytes() == np.asarray(b[key]).tobytes(), key
    boresight = _commanded_boresight(scene, tmp_path / "a.h5")[1]
    assert np.degrees(np.arccos(np.clip(boresight[:, 2], -1, 1))).max() > 0.5   # off nadir


def _law_over_a_struck_plate(hits_per_voxel, side=4):
    """A gap-seeking law whose map holds a ``side`` x ``side`` plate in layer z = 0, struck
    from above ``hits_per_voxel(x)`` times at voxel column x; the space above it carved, the
    layer below unknown (frontier)."""
    from sim.surface_map import SurfaceMap

    law = GapSeeker(step=10.0, max_rate=math.radians(1), max_offset=math.radians(30),
                    poses=None, beams=np.array([[0.0, 0.0, 1.0]]))
    law.map = SurfaceMap(1.0)
    x, y = np.meshgrid(np.arange(side) + 0.5, np.arange(side) + 0.5)
    points = np.column_stack([x.ravel(), y.ravel(), np.full(side * side, 0.5)])
    hits = np.repeat(points, hits_per_voxel(points[:, 0]), axis=0)
    law.map.add(hits + np.array([0.0, 0.0, 20.0]), np.tile([0.0, 0.0, -1.0], (len(hits), 1)),
                np.full(len(hits), 19.5), margin=2.0)
    return law


def _pool(law: GapSeeker) -> np.ndarray:
    """The law's candidates before the plan keeps one per cube (cubes of one voxel)."""
    return law._candidates(block=1)[0]


def test_an_exhausted_frontier_turns_the_law_to_the_least_struck_surface():
    # Struck once on the left half of the plate, three times on the right.
    law = _law_over_a_struck_plate(lambda x: np.where(x > 2, 3, 1))
    frontier = law.map.frontier()
    np.testing.assert_array_equal(_pool(law), frontier)
    law._after_interval(False)
    law._after_interval(True)                     # something to aim at: the count starts again
    law._after_interval(False)
    assert not law.residual
    law._after_interval(False)                    # two intervals in a row with nothing
    assert law.residual
    once = law.map.occupied[law.map.count == 1]
    np.testing.assert_array_equal(_pool(law), np.union1d(frontier, once))
    assert len(once) == 8 and not np.isin(law.map.occupied[law.map.count == 3],
                                          _pool(law)).any()


def test_candidates_found_hidden_are_set_aside_and_readmitted():
    from sim import planner_kernels as kernels
    from sim.defaults import GAP_ASIDE_INTERVALS, GAP_ASIDE_WALKS

    # The plate struck once per voxel; the layer below it is the frontier.
    law = _law_over_a_struck_plate(lambda x: np.ones(len(x), dtype=int))
    frontier = law.map.frontier()
    grid = law.map.grid()
    # While the frontier lasts nothing is set aside, whatever the counts.
    kernels.store_hidden(frontier, np.full(len(frontier), GAP_ASIDE_WALKS), *grid)
    np.testing.assert_array_equal(_pool(law), frontier)
    kernels.store_hidden(frontier, np.zeros(len(frontier), dtype=np.int64), *grid)
    # The least-struck phase: every voxel struck once, so all of them are candidates.
    law.residual = True
    pool = np.union1d(frontier, law.map.occupied)
    law._plan()
    planned = law._keys.copy()
    assert len(planned) > 4 and np.isin(planned, pool).all()
    # The sweeps found half of them hidden often enough: the next plan leaves them aside.
    law._hidden[::2] = GAP_ASIDE_WALKS
    aside = planned[::2]
    law._plan()
    assert len(law._keys) and not np.isin(aside, law._keys).any()
    np.testing.assert_array_equal(_pool(law), np.setdiff1d(pool, aside))
    # Once GAP_ASIDE_INTERVALS intervals have passed, a plan takes them again, counts cleared.
    law._interval += GAP_ASIDE_INTERVALS
    law._plan()
    assert np.isin(aside, law._keys).all()
    assert not kernels.hidden_counts(pool, *grid).any()
    np.testing.assert_array_equal(_pool(law), pool)


def test_a_settled_plan_weighs_fewer_candidates_and_sets_aside_after_one_hidden_walk():
    from sim import planner_kernels as kernels
    from sim.defaults import (
        GAP_ASIDE_WALKS,
        GAP_MAX_CANDIDATES,
        GAP_SETTLED_ASIDE_WALKS,
        GAP_SETTLED_INTERVALS,
        GAP_SETTLED_MAX_CANDIDATES,
    )

    # A 24 x 24 plate struck once per voxel: in the least-struck phase every struck voxel and
    # the layer below are candidates, more than a settled plan weighs.
    law = _law_over_a_struck_plate(lambda x: np.ones(len(x), dtype=int), side=24)
    law.residual = True
    pool = _pool(law)
    assert GAP_SETTLED_MAX_CANDIDATES < len(pool) <= GAP_MAX_CANDIDATES
    # Every other candidate found hidden by one walk: not yet set aside early in the phase.
    assert GAP_SETTLED_ASIDE_WALKS < GAP_ASIDE_WALKS
    once = pool[::2]
    kernels.store_hidden(once, np.full(len(once), GAP_SETTLED_ASIDE_WALKS), *law.map.grid())
    np.testing.assert_array_equal(_pool(law), pool)
    # Once the phase has lasted GAP_SETTLED_INTERVALS (no re-admission due), they are set
    # aside, and the plan weighs at most GAP_SETTLED_MAX_CANDIDATES of the rest.
    law._interval = law._residual_from + GAP_SETTLED_INTERVALS
    law._readmitted = law._interval
    settled = _pool(law)
    assert 0 < len(settled) <= GAP_SETTLED_MAX_CANDIDATES
    assert np.isin(settled, pool).all() and not np.isin(once, settled).any()


def test_a_fill_that_encloses_only_a_few_voxels_counts_as_enclosing_nothing():
    from sim.defaults import GAP_ENCLOSE_INTERVALS, GAP_ENCLOSE_MIN_FRACTION

    # A 24 x 24 plate (576 struck voxels) and, away from it, the shell of a cube of 3 x 3 x 3
    # voxels struck from outside: the first fill encloses the cube's one inside voxel.
    law = _law_over_a_struck_plate(lambda x: np.ones(len(x), dtype=int), side=24)
    index = np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    shell = index[(index != 1).any(axis=1)]
    out = shell - 1.0
    out /= np.linalg.norm(out, axis=1)[:, None]
    centres = shell + np.array([40.5, 40.5, 5.5])
    law.map.add(centres + 20.0 * out, -out, np.full(len(out), 20.0), margin=2.0)
    assert 1 <= GAP_ENCLOSE_MIN_FRACTION * len(law.map.count)
    marked, fill = [], law.map.enclose
    law.map.enclose = lambda: marked.append(fill()) or marked[-1]
    _pool(law)                                            # the plan's fill
    assert marked == [1]
    assert law._enclose_wait == 2 * GAP_ENCLOSE_INTERVALS  # one voxel: the wait doubles


def test_a_plan_leaves_out_what_the_struck_voxels_enclose_and_fills_less_often_when_idle():
    from sim.defaults import GAP_ENCLOSE_INTERVALS, GAP_ENCLOSE_MAX_INTERVALS
    from sim.surface_map import SurfaceMap, unpack

    law = GapSeeker(step=10.0, max_rate=math.radians(1), max_offset=math.radians(30),
                    poses=None, beams=np.array([[0.0, 0.0, 1.0]]))
    law.map = SurfaceMap(1.0)
    # The shell of a cube of 6 x 6 x 6 voxels, struck from outside along each voxel's normal.
    index = np.stack(np.meshgrid(*[np.arange(6)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    shell = index[((index == 0) | (index == 5)).any(axis=1)]
    centres = shell + 0.5
    out = centres - 3.0
    out /= np.linalg.norm(out, axis=1)[:, None]
    law.map.add(centres + 20.0 * out, -out, np.full(len(out), 20.0), margin=2.0)
    inside = ((unpack(law.map.frontier()) >= 1) & (unpack(law.map.frontier()) <= 4)).all(axis=1)
    assert inside.sum() == 4 ** 3 - 2 ** 3               # before the first fill
    keys = _pool(law)                            # the first plan fills
    assert len(keys) and not ((unpack(keys) >= 1) & (unpack(keys) <= 4)).all(axis=1).any()
    assert law._enclose_wait == GAP_ENCLOSE_INTERVALS   # it enclosed some: the wait stays
    waits = []
    for _ in range(6):                                 # nothing new to enclose: the wait doubles
        law._interval += law._enclose_wait
        _pool(law)
        waits.append(law._enclose_wait)
    assert waits == [min(GAP_ENCLOSE_INTERVALS * 2 ** k, GAP_ENCLOSE_MAX_INTERVALS)
                     for k in range(1, 7)]
    assert waits[-1] == GAP_ENCLOSE_MAX_INTERVALS        # up to its longest


def test_a_short_interval_calls_a_plan_at_once_only_while_the_frontier_lasts():
    from sim.defaults import (
        GAP_IDLE_INTERVALS,
        GAP_PLAN_INTERVALS,
        GAP_SETTLED_INTERVALS,
        GAP_SETTLED_PLAN_INTERVALS,
    )

    law = GapSeeker(step=10.0, max_rate=math.radians(1), max_offset=math.radians(30),
                    poses=None, beams=np.array([[0.0, 0.0, 1.0]]))
    plans = []

    def plan():                       # a plan that finds nothing to aim at: every interval
        plans.append(law._interval)   # runs short, and after GAP_IDLE_INTERVALS of them the
        law._age = 0                  # law is in the least-struck phase

    law._plan = plan
    settled = GAP_IDLE_INTERVALS + GAP_SETTLED_INTERVALS     # the first settled interval
    n = settled + 3 * GAP_SETTLED_PLAN_INTERVALS
    for _ in range(n):
        turn = law.command(np.arange(30.0))
        np.testing.assert_array_equal(turn, np.tile(np.eye(3), (30, 1, 1)))   # held on nadir
    assert law.residual
    # The frontier phase plans after every short interval, the least-struck phase every
    # GAP_PLAN_INTERVALS, and once it has lasted GAP_SETTLED_INTERVALS, every
    # GAP_SETTLED_PLAN_INTERVALS.
    last = GAP_IDLE_INTERVALS - 1
    early = list(range(last + GAP_PLAN_INTERVALS, settled, GAP_PLAN_INTERVALS))
    late = list(range(early[-1] + GAP_SETTLED_PLAN_INTERVALS, n, GAP_SETTLED_PLAN_INTERVALS))
    assert plans == [*range(GAP_IDLE_INTERVALS), *early, *late]
    assert len(late) >= 2


def test_an_interval_without_open_candidates_holds_every_shot_without_a_sweep():
    from sim.gap_seeking import turn_from_boresight

    law = _law_over_a_struck_plate(lambda x: np.ones(len(x), dtype=int))
    law._plan()
    assert len(law._keys)
    law._used[:] = True                       # every candidate aimed at or set aside
    law._open = 0                             # (as the sweep counts them)

    def sweep(*args):
        raise AssertionError("no sweep without an open candidate")

    law._sweep, law._age = sweep, 0
    law.residual = True                       # no plan at once after a held interval
    rng = np.random.default_rng(0)
    for _ in range(20):
        boresight = rng.normal(size=3)
        boresight[2] = abs(boresight[2]) + 0.5
        law.boresight = boresight / np.linalg.norm(boresight)
        turn = law.command(np.arange(30.0))
        # The same bytes as the rotation of the boresight, shot by shot.
        assert turn.tobytes() == turn_from_boresight(np.tile(law.boresight, (30, 1))).tobytes()
        law._age = 0                          # no plan due
    assert law._short


def test_the_law_s_open_count_follows_its_used_candidates(tmp_path, monkeypatch):
    # The sweep hands back how many candidates are left open, so that an interval need not pass
    # over the used mask to know whether to hold: after every interval the count must be the
    # mask's. A small closed loop, long enough to hold intervals with nothing open.
    command, checked = GapSeeker.command, []

    def checked_command(self, t, poses=None):
        turn = command(self, t, poses)
        checked.append((self._open, int((~self._used).sum())))
        return turn

    monkeypatch.setattr(GapSeeker, "command", checked_command)
    scene = sim.load_scene("asteroid-lrf", [*SMALL, "time.duration=10800"])
    sim.simulate(scene, tmp_path / "gaps.h5", seed=0, progress=False)
    assert [count for count, _ in checked] == [mask for _, mask in checked]
    assert any(count == 0 for count, _ in checked) and any(count > 0 for count, _ in checked)

def _law_over_a_struck_cube():
    """A gap-seeking law whose map holds the shell of a cube of 6 x 6 x 6 voxels, each voxel
    struck from outside along every face it lies on (the space outside carved): a closed
    surface, its inside unknown."""
    from sim.surface_map import SurfaceMap

    law = GapSeeker(step=10.0, max_rate=math.radians(1), max_offset=math.radians(30),
                    poses=None, beams=np.array([[0.0, 0.0, 1.0]]))
    law.map = SurfaceMap(1.0)
    index = np.stack(np.meshgrid(*[np.arange(6)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    centres, out = [], []
    for axis in range(3):
        for side, normal in ((0, -1.0), (5, 1.0)):
            face = index[index[:, axis] == side] + 0.5
            centres.append(face)
            out.append(np.tile(np.eye(3)[axis] * normal, (len(face), 1)))
    centres, out = np.concatenate(centres), np.concatenate(out)
    law.map.add(centres + 20.0 * out, -out, np.full(len(out), 20.0), margin=2.0)
    return law


def _plans_of_held_intervals(law: GapSeeker, n: int) -> list[int]:
    """The intervals at which ``law`` plans over ``n`` intervals whose plans find nothing to
    aim at (every shot held; the map kept as it is)."""
    plans = []

    def plan():
        plans.append(law._interval)
        law._age = 0

    law._plan = plan
    for _ in range(n):
        law.command(np.arange(30.0))
    return plans


def test_a_closed_frontier_settles_the_least_struck_phase_at_once_with_rarer_plans():
    from sim.defaults import (
        GAP_CLOSED_FRONTIER_FRACTION,
        GAP_CLOSED_PLAN_INTERVALS,
        GAP_IDLE_INTERVALS,
        GAP_PLAN_INTERVALS,
        GAP_SETTLED_INTERVALS,
    )

    # The closed cube, its inside enclosed by a plan's fill: almost no frontier is left.
    closed = _law_over_a_struck_cube()
    _pool(closed)
    assert len(closed.map.frontier()) <= GAP_CLOSED_FRONTIER_FRACTION * len(closed.map.occupied)
    # An open plate struck from above: its underside is frontier (one voxel per struck one).
    plate = _law_over_a_struck_plate(lambda x: np.ones(len(x), dtype=int))
    assert len(plate.map.frontier()) > GAP_CLOSED_FRONTIER_FRACTION * len(plate.map.occupied)
    n = 3 * GAP_CLOSED_PLAN_INTERVALS
    assert n < GAP_SETTLED_INTERVALS
    # Both turn to the least-struck surface after GAP_IDLE_INTERVALS short intervals; the
    # closed map's phase is settled from its start, a plan every GAP_CLOSED_PLAN_INTERVALS;
    # the plate's plans every GAP_PLAN_INTERVALS, not yet settled.
    last = GAP_IDLE_INTERVALS - 1
    assert _plans_of_held_intervals(closed, n) == [
        *range(GAP_IDLE_INTERVALS), *range(last + GAP_CLOSED_PLAN_INTERVALS, n,
                                           GAP_CLOSED_PLAN_INTERVALS)]
    assert closed.residual and closed._settled()
    assert _plans_of_held_intervals(plate, n) == [
        *range(GAP_IDLE_INTERVALS), *range(last + GAP_PLAN_INTERVALS, n, GAP_PLAN_INTERVALS)]
    assert plate.residual and not plate._settled()


def test_a_frontier_larger_than_a_plan_weighs_is_planned_less_often():
    from sim.defaults import GAP_LARGE_PLAN_INTERVALS, GAP_MAX_CANDIDATES, GAP_PLAN_INTERVALS

    def plans(side: int, n: int) -> tuple[list[int], bool]:
        """A plate of ``side`` x ``side`` voxels struck from above, its sweeps aiming every
        shot (no interval runs short): the intervals at which the law plans."""
        law = _law_over_a_struck_plate(lambda x: np.ones(len(x), dtype=int), side=side)
        real, planned = law._plan, []

        def plan():
            planned.append(law._interval)
            real()

        def sweep(n, *args):
            goal = np.tile(law.boresight, (n, 1))
            return (np.zeros(n, dtype=np.int64), goal, turn_from_boresight(goal),
                    int(np.count_nonzero(~law._used)))   # and the candidates left open

        law._plan, law._sweep = plan, sweep
        pose = (np.zeros((30, 3)), Rotation.identity(30), np.tile(np.eye(3), (30, 1, 1)))
        for _ in range(n):
            law.command(np.arange(30.0), pose)
        return planned, law._large

    n = 3 * GAP_LARGE_PLAN_INTERVALS
    # A 48 x 48 plate: its underside alone, 2,304 voxels, is more than a plan weighs.
    assert 48 * 48 > GAP_MAX_CANDIDATES >= 24 * 24 * 3
    assert plans(48, n) == (list(range(0, n, GAP_LARGE_PLAN_INTERVALS)), True)
    assert plans(24, n) == (list(range(0, n, GAP_PLAN_INTERVALS)), False)
