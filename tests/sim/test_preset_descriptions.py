"""Every preset's one-line description (``recon simulate --list``) agrees with what it runs.

Each number a description states is matched by one of the claims below and checked against the
scene's resolved values; a number no claim covers fails the test, so a new description cannot
state an unchecked value.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import sim

HOUR = 3600.0


def _beams(s) -> int:
    sensor = s.values["sensor"]
    return {"single": 1, "cross": 5}.get(sensor["pattern"], sensor.get("beams"))


# (pattern, check(scene, *groups as float)) in the order they are tried.
CLAIMS = (
    (r"(\d+)-beam", lambda s, n: _beams(s) == n),
    (r"(\d+) x (\d+) scanning-LIDAR grid over ([\d.]+) x ([\d.]+) deg",
     lambda s, a, b, fa, fb: list(s.values["sensor"]["resolution"]) == [a, b]
     and list(s.values["sensor"]["field_of_view_deg"]) == [fa, fb]),
    (r"([\d.]+) x ([\d.]+) deg field of view",
     lambda s, a, b: list(s.values["sensor"]["field_of_view_deg"]) == [a, b]),
    (r"(\d+) h at (\d+) deg, then (\d+) h at (\d+) deg",
     lambda s, h1, i1, h2, i2: round(s.values["orbit"]["change_time"] / HOUR) == h1
     and round((s.duration - s.values["orbit"]["change_time"]) / HOUR) == h2
     and (s.values["orbit"]["inclination_deg"], s.values["orbit"]["change_inclination_deg"])
     == (i1, i2)),
    (r"(\d+) rotations",
     lambda s, n: np.isclose(s.duration, n * s.values["target"]["spin_period"])),
    (r"\((\d+) h\)", lambda s, h: round(s.duration / HOUR) == h),
    (r"every ([\d.]+) h", lambda s, h: round(s.values["target"]["spin_period"] / HOUR, 1) == h),
    (r"at (\d+) m, (\d+) deg", lambda s, r, i: (s.values["orbit"]["radius"],
                                                s.values["orbit"]["inclination_deg"]) == (r, i)),
    (r"at (\d+) m\b", lambda s, r: s.values["orbit"]["radius"] == r),
    (r"at (?:the suboptimal )?(\d+) deg", lambda s, i: s.values["orbit"]["inclination_deg"] == i),
    (r"a ([\d.]+) deg slew", lambda s, a: s.values["slew"]["amplitude_deg"] == a),
    (r"alpha ([\d.]+), (\d+) sub-rays in ([\d.]+) mrad",
     lambda s, a, n, h: (s.values["errors"]["dilation_alpha"],
                         s.values["errors"]["dilation_subrays"],
                         s.values["errors"]["dilation_half_angle_mrad"]) == (a, n, h)),
    (r"([\d.]+) m range error, ([\d.]+) m pose",
     lambda s, r, p: (s.values["errors"]["range_sigma3"],
                      s.values["errors"]["position_sigma3"]) == (r, p)),
    (r"errors \(([\d.]+) deg, ([\d.]+) m\) and ([\d.]+) m pose",
     lambda s, a, r, p: (s.values["errors"]["azimuth_sigma3_deg"],
                         s.values["errors"]["elevation_sigma3_deg"],
                         s.values["errors"]["range_sigma3"],
                         s.values["errors"]["position_sigma3"]) == (a, a, r, p)),
)


@pytest.mark.parametrize(("name", "description"), sim.list_presets())
def test_description_states_what_the_preset_runs(name, description):
    scene = sim.load_scene(name)
    text = re.sub(r"\(paper[^)]*\)", "", description)  # the paper's figure numbers
    for pattern, check in CLAIMS:
        for match in list(re.finditer(pattern, text)):
            values = [float(g) for g in match.groups()]
            assert check(scene, *values), f"{name}: '{match.group(0)}' is not what it runs"
        text = re.sub(pattern, "", text)
    assert not re.search(r"\d", text), f"{name}: unchecked number in {text!r}"


def test_a_wrong_description_is_caught():
    """The rso presets said 129 h while running 774,000 s (215 h)."""
    scene = sim.load_scene("rso-a-lrf")
    hours = next(check for pattern, check in CLAIMS if pattern == r"\((\d+) h\)")
    assert not hours(scene, 129.0) and hours(scene, 215.0)
