"""The refinement's time, estimated before it starts: the model's arithmetic, the refusal beyond
``MAX_REFINE_S`` (naming the interval that would do), the announcement and the progress
(``recon.registration.refine``)."""

from __future__ import annotations

import re

import pytest

from formats.errors import InputError, ParameterError
from recon.registration import refine as refine_module
from recon.registration.refine import (
    _instead,
    _knot_count,
    duration_text,
    refine,
    refine_seconds,
    step_seconds,
)
from tests.conftest import write_sphere_log

# Whole refinements measured on the suite's logs (docs/decisions.md, "the refinement's time
# estimate"): (fitted strikes, knots) -> median seconds of three runs. The model beside
# STEP_POINT_S was fitted to them; these catch a constant mistyped or a term dropped.
MEASURED_S = {(30_000, 1): 11.6, (30_000, 5): 16.3, (30_000, 20): 33.6, (30_000, 50): 57.2,
              (30_000, 100): 123.7, (10_000, 1): 5.0, (10_000, 5): 7.1, (10_000, 20): 15.0,
              (10_000, 50): 30.8, (10_000, 100): 79.4, (2606, 1): 2.0, (2606, 5): 3.4,
              (2606, 20): 5.7, (2606, 50): 17.1}
# How far the model may stray from a measured median (it stays within 0.49 to 1.36 of them).
MODEL_FACTOR = 2.5


@pytest.fixture
def sphere(tmp_path):
    """400 strikes over 1,990 s of a sphere that does not spin (no coarse stage): 200 fitted,
    at most 4 knots."""
    path = tmp_path / "sphere.h5"
    write_sphere_log(path, n_shots=200)
    return path


def _never_sampled(monkeypatch):
    """Fail the test if the strikes are sampled: a refusal comes before."""
    def sampled(*args):
        raise AssertionError("the strikes were sampled")
    monkeypatch.setattr(refine_module, "_samples", sampled)


def test_the_model_counts_every_step_of_both_stages(monkeypatch):
    """Hand arithmetic of the model's form: 15 fine steps of n strikes, 25 coarse starts of 6
    steps of n / 10 (rounded up) each."""
    for name, value in (("STEP_POINT_S", 1e-5), ("STEP_KNOT_S", 1e-7), ("STEP_PAIR_S", 1e-9),
                        ("STEP_SQUARE_S", 1e-6), ("STEP_CUBE_S", 1e-8)):
        monkeypatch.setattr(refine_module, name, value)
    n, k = 30_001, 100
    p = 601

    def step(m):
        return m * (1e-5 + 1e-7 * k + 1e-9 * p * p) + 1e-6 * p * p + 1e-8 * p ** 3

    assert step_seconds(n, k) == pytest.approx(step(n), rel=1e-12)
    assert refine_seconds(n, k, coarse=False) == pytest.approx(15 * step(n), rel=1e-12)
    assert refine_seconds(n, k) == pytest.approx(15 * step(n) + 25 * 6 * step(3001),
                                                 rel=1e-12)


@pytest.mark.parametrize(("n_points", "knots"), sorted(MEASURED_S))
def test_the_model_reproduces_the_measured_refinements(n_points, knots):
    measured = MEASURED_S[n_points, knots]
    assert measured / MODEL_FACTOR < refine_seconds(n_points, knots) < measured * MODEL_FACTOR


def test_the_estimate_grows_with_knots_and_strikes():
    times = [refine_seconds(n, k) for n in (2_000, 30_000) for k in (1, 5, 20, 100, 600)]
    assert times[:5] == sorted(times[:5]) and times[5:] == sorted(times[5:])
    assert all(small < big for small, big in zip(times[:5], times[5:], strict=True))
    assert refine_seconds(30_000, 20, coarse=False) < refine_seconds(30_000, 20)


def test_at_the_most_knots_the_default_strikes_can_estimate_hours_are_allowed():
    """30,000 strikes estimate at most 600 knots (MIN_ROWS a knot): within the day allowed, so
    the time limit refuses only what more strikes (``max_points``) would ask for."""
    most = refine_module.MAX_POINTS // refine_module.MIN_ROWS
    assert refine_seconds(refine_module.MAX_POINTS, most) <= refine_module.MAX_REFINE_S


def test_a_refinement_estimated_beyond_the_limit_is_refused_before_the_strikes_are_read(
        sphere, monkeypatch):
    limit = 0.5 * (refine_seconds(200, 2, coarse=False) + refine_seconds(200, 3, coarse=False))
    monkeypatch.setattr(refine_module, "MAX_REFINE_S", limit)
    _never_sampled(monkeypatch)
    with pytest.raises(ParameterError, match=r"^interval 1000 s makes 3 knots over the log's "
                                             r"1990 s; refining them with 200 sampled strikes "
                                             r"would take about \d+ s, more than the \d+ s a "
                                             r"refinement may take \(at most 2 knots\); give at "
                                             r"least 1990 s$") as error:
        refine(sphere, interval=1000.0)
    assert error.value.argument == "interval"
    assert _knot_count(1990.0, 1990.0) == 2


def test_constant_errors_beyond_the_limit_name_the_sampled_strikes(sphere, monkeypatch):
    monkeypatch.setattr(refine_module, "MAX_REFINE_S",
                        0.5 * refine_seconds(200, 1, coarse=False))
    _never_sampled(monkeypatch)
    for interval in (None, 1000.0):
        with pytest.raises(ParameterError, match=rf"^max_points 30,000 samples 200 strikes of "
                                                 rf"{sphere}; refining them would take about "
                                                 r".*; sample fewer$") as error:
            refine(sphere, interval=interval)
        assert error.value.argument == "max_points"


@pytest.mark.parametrize("span", [1990.0, 15_420.0, 30_950.0, 386_990.0, 7.0])
@pytest.mark.parametrize("most", [2, 3, 4, 7, 52, 101, 599, 600])
def test_the_interval_named_makes_no_more_knots_than_accepted(span, most):
    """Rounded to 4 digits, the shortest interval would make one knot too many (1990 s for 4
    knots is 663.33 s: "663.3 s" made 5): it is rounded up."""
    named = float(re.fullmatch(r"give at least (\S+) s", _instead(span, most)).group(1))
    assert _knot_count(span, named) <= most
    assert named <= span / (most - 1) * (1 + 1e-3)
    assert _instead(span, 1) == "refine constant errors only (no interval)"


def test_a_long_refinement_is_announced_before_it_starts(sphere, monkeypatch):
    """The 80-strike sphere is too few to refine: the announcement comes first all the same."""
    said = []
    with pytest.raises(InputError, match="too few to refine the poses"):
        refine(sphere, interval=1000.0, announce=said.append)
    assert said == []    # a fraction of a second: nothing to say
    monkeypatch.setattr(refine_module, "ANNOUNCE_S", 0.0)
    with pytest.raises(InputError, match="too few to refine the poses"):
        refine(sphere, interval=1000.0, announce=said.append)
    seconds = refine_seconds(200, 3, coarse=False)
    assert said == [f"refining 3 knots over 1,990 s: about {duration_text(seconds)}"]


@pytest.mark.parametrize(("seconds", "text"), [
    (0.4, "0 s"), (40, "40 s"), (89, "89 s"), (90, "2 min"), (25 * 60, "25 min"),
    (89 * 60, "89 min"), (90 * 60, "1.5 h"), (3.2 * 3600, "3.2 h"), (86400, "24 h"),
    (2.5 * 86400, "2.5 days")])
def test_duration_text(seconds, text):
    assert duration_text(seconds) == text
