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
               "asteroid-60 slew": _record([50, 100], [0.6, 0.8], [1000, 2000], law="slew")}
    assert closed_loop.hours_to(records, "asteroid-60 gaps", 0.95) == pytest.approx(25.0)
    assert closed_loop.hours_to(records, "asteroid-60 gaps", 0.4) == 10.0
    assert closed_loop.hours_to(records, "asteroid-60 slew", 0.95) is None
    assert closed_loop.effort_at(records, "asteroid-60 gaps", 25.0) == pytest.approx(250.0)
    result = closed_loop._claim_target(records, "asteroid-60")
    # never reached by the slew: counted at its last time, 100 h and 2000 deg
    assert result["verdict"] == "reproduced"
    assert ">= 4.0x sooner" in result["ours"] and "(0.12x at most)" in result["ours"]
    records["asteroid-60 slew"] = _record([10, 20], [0.9, 0.96], [10, 20], law="slew")
    assert closed_loop._claim_target(records, "asteroid-60")["verdict"] == "not reproduced"


@pytest.mark.parametrize("size", ["tiny", "quick", "full"])
def test_cases_load_and_cover_every_target_and_law(size):
    cases = closed_loop.cases(size)
    assert {(c["tags"]["target"], c["tags"]["law"]) for c in cases.values()} == {
        (t, law) for t in closed_loop.TARGETS for law in closed_loop.LAWS}
    for key, case in cases.items():
        scene = sim.load_scene(case["scene"], case["overrides"])
        assert max(case["prefixes_s"]) <= scene.duration + 1e-6, key
        assert scene["attitude.mode"] == ("gaps" if key.endswith("gaps") else "fixed"), key
