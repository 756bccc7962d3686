"""``benchmarks/judge_rules.py rules --holes-one-count``: the hole test's limit before it counted
the error of both fractions, replayed in place of ``auto.hole_limit``."""

from __future__ import annotations

import math

import pytest

from benchmarks import judge_rules
from recon.surfaces import auto


def test_the_one_count_limit_is_the_old_one_and_below_auto_s_above_the_band_s_fewest():
    # satellite F's band: 0.55 % and 1.00 % of 4,184 strikes in holes
    old = judge_rules.one_count_hole_limit([0.0100, 0.0055], 4_184)
    assert old == pytest.approx(0.0055 + 3 * math.sqrt(0.0055 * 0.9945 / 4_184))
    assert old < 0.0100 < auto.hole_limit([0.0100, 0.0055], 4_184)
    # where the noise's rate is the reference, both limits are one count's error above it
    assert judge_rules.one_count_hole_limit([0.001, 0.02], 16_000) == pytest.approx(
        auto.hole_limit([0.001, 0.02], 16_000))
