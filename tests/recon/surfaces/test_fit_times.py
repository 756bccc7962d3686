"""The fit-time table: read from the benchmark's results, stated in --help without the machine."""

from __future__ import annotations

import math

import pytest

from recon.surfaces import fit_times, methods


def test_the_registry_reads_the_table():
    assert methods.DEFAULT_FIT_S == fit_times.fit_s()
    assert methods.COST_POINTS == (336_333, 77_400)
    assert methods.COST_SOURCE == "benchmarks/bench_methods.py"


def test_cost_help_states_the_slowest_default_on_each_cloud():
    times = fit_times.fit_s()
    slowest = max(times, key=lambda name: times[name][0])
    text = fit_times.cost_help()
    assert f"336k-point asteroid LIDAR cloud in at most {math.ceil(times[slowest][0])} s each " \
           f"({slowest}; Open3D Poisson {times['poisson'][0]:.2g} s)" in text
    assert f"LRF cloud in at most {math.ceil(max(t for _, t in times.values()))} s" in text
    assert "core" not in text and "load" not in text


def _summary(cloud: str, n_points: int, fits: dict) -> dict:
    runs = [{"method": m, "fit_s": t} if t is not None else
            {"method": m, "failure": "timeout", "reason": "over 600 s"} for m, t in fits.items()]
    return {"cloud": cloud, "n_points": n_points, "runs": runs}


def test_table_of_a_benchmark_run():
    table = fit_times.table_of([
        _summary("lidar", 120_400, {"poisson": 2.0, "plane": 10.12345, "rimls": None}),
        _summary("rso-a", 77_400, {"poisson": 1.0, "plane": 5.0, "rimls": 3.0}),
        _summary("asteroid", 77_400, {"poisson": 1.5})])
    assert table["fit_s"] == {"poisson": [2.0, 1.0], "plane": [10.123, 5.0]}  # rimls: no LIDAR
    assert table["clouds"]["lidar"] == {"points": 120_400, "label": "120k-point asteroid LIDAR"}
    with pytest.raises(ValueError, match="needs a run over the clouds rso-a"):
        fit_times.table_of([_summary("lidar", 1000, {"poisson": 1.0})])
