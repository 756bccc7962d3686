"""The closed-loop study's measures: slew effort from attitudes, hours to a coverage level, the
target's verdict; and that its cases load."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import sim
from recon.experiments.studies import closed_loop


def test_slew_effort_adds_the_angles_between_consecutive_attitudes():
    angles = np.radians([0.0, 2.0, -1.0, -1.0, 4.0])      # about x: 2, 3, 0, 5 deg turned
    q = (Rotation.from_euler("z", 30, degrees=True)
         * Rotation.from_rotvec(angles[:, None] * [1.0, 0.0, 0.0])).as_quat()
    np.testing.assert_allclose(closed_loop.slew_effort(q), [0, 2, 5, 5, 10], atol=1e-9)
    assert closed_loop.slew_effort(q[:1]).tolist() == [0.0]


def _record(hours, coverage, slew, law="gaps"):
    return {"status": "ok", "tags": {"target": "asteroid-60", "law": law},
            "prefixes": [{"time_s": h * 3600.0, "hours": h, "scored": True, "coverage": c,
                          "slew_deg": e, "edge_score": 0.1}
                         for h, c, e in zip(hours, coverage, slew, strict=True)]}


def test_hours_to_a_level_interpolates_and_the_verdict_follows_the_target():
    records = {"asteroid-60 gaps": _record([10, 20, 30], [0.5, 0.9, 1.0], [100, 200, 300]),
               "asteroid-60 slew-2": _record([50, 100], [0.6, 0.8], [1000, 2000], law="slew-2"),
               "asteroid-60 slew-5": _record([50, 100], [0.5, 0.7], [3000, 6000], law="slew-5")}
    assert closed_loop.hours_to(records, "asteroid-60 gaps", 0.95) == pytest.approx(25.0)
    assert closed_loop.hours_to(records, "asteroid-60 gaps", 0.4) == 10.0
    assert closed_loop.hours_to(records, "asteroid-60 slew-2", 0.95) is None
    assert closed_loop.effort_at(records, "asteroid-60 gaps", 25.0) == pytest.approx(250.0)
    # Neither slew reaches 95 %: the better is the one of higher final coverage, counted at its
    # last time, 100 h and 2000 deg.
    assert closed_loop.best_slew(records, "asteroid-60") == "asteroid-60 slew-2"
    result = closed_loop._claim_target(records, "asteroid-60", 1.0)
    assert result["verdict"] == "reproduced"
    assert ">= 4.0x sooner" in result["ours"] and "2 deg slew" in result["ours"]
    # A slew reaching 95 % first is the better one; 2x sooner fails here.
    records["asteroid-60 slew-5"] = _record([10, 20], [0.9, 0.96], [10, 20], law="slew-5")
    assert closed_loop.best_slew(records, "asteroid-60") == "asteroid-60 slew-5"
    assert closed_loop._claim_target(records, "asteroid-60", 1.0)["verdict"] == "partly"
    # Equal at 30 h is not below; below at a common time after 24 h, and 1.5x sooner only:
    # not reproduced.
    records["asteroid-60 slew-5"] = _record([10, 30], [0.9, 1.0], [10, 20], law="slew-5")
    assert closed_loop.shortfalls(records, "asteroid-60 gaps", "asteroid-60 slew-5") == []
    records["asteroid-60 gaps"] = _record([10, 20, 30], [0.5, 0.96, 0.97], [100, 200, 300])
    records["asteroid-60 slew-5"] = _record([10, 30], [0.5, 0.99], [10, 20], law="slew-5")
    assert closed_loop.shortfalls(records, "asteroid-60 gaps", "asteroid-60 slew-5") == [
        (30.0, 0.97, 0.99)]
    result = closed_loop._claim_target(records, "asteroid-60", 1.0)
    assert result["verdict"] == "not reproduced" and "below it at 30 h" in result["ours"]
    # A ceiling below 95 %: the claim times 95 % of the ceiling (88.7 %) and says so; 1.5x
    # sooner and never below: partly.
    records["asteroid-60 gaps"] = _record([10, 20, 30], [0.5, 0.92, 0.93], [100, 200, 300])
    records["asteroid-60 slew-5"] = _record([10, 30], [0.5, 0.92], [10, 20], law="slew-5")
    result = closed_loop._claim_target(records, "asteroid-60", 0.934)
    assert "88.7% coverage (95% of 0.934, the most any law can reach here)" in result["claim"]
    assert result["ours"].startswith("88.7% after 19.2 h (gap-seeking) against 28.4 h")
    assert result["verdict"] == "partly"
    # Not even that level, but never below the slew: partly, and the ceiling is stated.
    records["asteroid-60 gaps"] = _record([10, 20, 30], [0.5, 0.85, 0.88], [100, 200, 300])
    records["asteroid-60 slew-5"] = _record([10, 30], [0.5, 0.87], [10, 20], law="slew-5")
    result = closed_loop._claim_target(records, "asteroid-60", 0.934)
    assert result["verdict"] == "partly" and "any law can reach here is 0.934" in result["ours"]
    assert "never reached 88.7%" in result["rule"]
    # A run that ends before 24 h cannot tell: not tested.
    records["asteroid-60 gaps"] = _record([4, 8], [0.5, 0.7], [100, 200])
    assert closed_loop._claim_target(records, "asteroid-60", 1.0)["verdict"] == "not tested"


def test_the_coverage_ceiling_leaves_out_a_box_shut_inside_another():
    from sim.targets import box, combine

    outer, inner = box([-5, -5, -5], [5, 5, 5]), box([-1, -1, -1], [1, 1, 1])
    options = {"n_truth_samples": 4000, "coverage_points": 8000}
    assert closed_loop.coverage_ceiling(*outer, seed=0, score_options=options) == 1.0
    # 24 m^2 of 624 m^2 is shut in, 4 m from any surface seen from outside.
    both = closed_loop.coverage_ceiling(*combine(outer, inner), seed=0, score_options=options)
    assert both == pytest.approx(600 / 624, abs=0.01)


@pytest.mark.parametrize("size", ["tiny", "quick", "full"])
def test_cases_load_and_cover_every_target_and_law(size):
    cases = closed_loop.cases(size)
    assert {(c["tags"]["target"], c["tags"]["law"]) for c in cases.values()} == {
        (t, law) for t in closed_loop.TARGETS for law in closed_loop.LAWS}
    for key, case in cases.items():
        scene = sim.load_scene(case["scene"], case["overrides"])
        assert max(case["prefixes_s"]) <= scene.duration + 1e-6, key
        assert scene["attitude.mode"] == ("gaps" if key.endswith("gaps") else "fixed"), key
