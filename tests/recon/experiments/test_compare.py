"""The comparison's ranking, Pareto fronts, files and the auto-versus-truth agreement."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from formats.errors import ParameterError
from recon.experiments.cases import pareto_front, rank, variants
from recon.experiments.compare import agreement, finish
from recon.surfaces.methods import run_key as case_key


def _brute_front(time, value):
    """Runs no other run beats on both time and value (ties kept by the earliest)."""
    keep = []
    for i in range(len(time)):
        dominated = any((time[j] <= time[i] and value[j] <= value[i])
                        and (time[j] < time[i] or value[j] < value[i]) for j in range(len(time)))
        if not dominated:
            keep.append(i)
    return sorted(keep, key=lambda i: time[i])


@pytest.mark.parametrize("seed", range(5))
def test_pareto_front_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    time, value = rng.uniform(0.1, 10, 40), rng.uniform(0.01, 1, 40)
    assert list(pareto_front(time, value)) == _brute_front(time, value)
    assert list(pareto_front(time, -value, minimize=False)) == _brute_front(time, value)


def _record(label, method, time, chamfer, fscore, status="ok", params=None):
    params = params or {}
    return {"key": case_key(method, params), "label": label, "method": method, "params": params,
            "kind": "smooth", "status": status, "failure": None if status == "ok" else "crash",
            "reason": "" if status == "ok" else "crashed with SIGSEGV while running",
            "wall_time_s": time, "process_time_s": 1.0, "peak_memory_mb": 100.0,
            "n_vertices": 10, "n_faces": 20, "watertight": True, "mesh": None,
            "chamfer_m": chamfer, "fscore": fscore}


RECORDS = [
    _record("slow-good", "poisson", 10.0, 0.01, 0.99),
    _record("fast-bad", "convex-hull", 0.1, 0.5, 0.40),
    _record("dominated", "plane", 20.0, 0.2, 0.50),
    _record("crashed", "alpha-shape", None, None, None, status="failed"),
    _record("middle", "planes", 1.0, 0.05, 0.95),
]


def test_rank_orders_by_chamfer_with_failures_last():
    assert [r["label"] for r in rank(RECORDS)] == ["slow-good", "middle", "dominated",
                                                   "fast-bad", "crashed"]


def test_finish_writes_csv_json_png_and_fronts(tmp_path):
    report = finish(RECORDS, tmp_path, title="test")
    assert [r["label"] for r in report["pareto_chamfer"]] == ["fast-bad", "middle", "slow-good"]
    assert [r["label"] for r in report["pareto_fscore"]] == ["fast-bad", "middle", "slow-good"]
    with open(tmp_path / "results.csv") as text:
        rows = list(csv.DictReader(text))
    assert rows[0]["label"] == "slow-good" and len(rows) == 5
    assert {"wall_time_s", "peak_memory_mb", "chamfer_m", "fscore", "n_faces", "watertight",
            "reason"} <= set(rows[0])
    saved = json.loads((tmp_path / "results.json").read_text())
    assert saved["pareto_chamfer"][0]["label"] == "fast-bad"
    assert (tmp_path / "speed_accuracy.png").stat().st_size > 20_000
    assert "FAILED (crash)" in report["table"] and "slow-good" in report["table"]


def test_agreement_reports_rank_and_ratio():
    verdict = agreement(RECORDS, case_key("planes", {}))
    assert verdict["rank"] == 2 and verdict["n_ranked"] == 4
    assert verdict["best_label"] == "slow-good" and not verdict["same_run"]
    assert verdict["chamfer_ratio"] == pytest.approx(5.0)
    assert agreement(RECORDS, case_key("poisson", {}))["same_run"]
    assert agreement(RECORDS, case_key("alpha-shape", {}))["rank"] is None


def test_variants_and_labels():
    runs = variants(["poisson", "convex-hull"])
    assert runs[0].method == "poisson" and runs[-1].method == "convex-hull"
    assert len(runs) == 1 + 4 + 1
    assert runs[1].label == "poisson depth=6"
    assert runs[0].label == "poisson"
    assert len(variants(["poisson"], grid=False)) == 1
    assert variants(["poisson"], grid="defaults") == variants(["poisson"], grid=False)
    assert variants(["poisson"], grid="full") == variants(["poisson"])


def test_bad_grid_is_named():

    with pytest.raises(ParameterError, match="grid must be one of defaults, full, got 'big'"):
        variants(["poisson"], grid="big")


def test_full_grid_estimate_times_each_variant_as_its_methods_defaults():
    from recon.experiments.cases import full_grid_estimate
    from recon.experiments.compare import format_full_grid
    from recon.surfaces import methods

    defaults = methods.get("poisson").defaults
    records = [_record("poisson", "poisson", 4.0, 0.1, 0.9, params=dict(defaults)),
               _record("convex-hull", "convex-hull", 1.0, 0.5, 0.5, status="crash")]
    records[0]["process_time_s"] = 6.0  # the fit (4 s) checked and scored
    estimate = full_grid_estimate(records, ["poisson", "convex-hull"], workers=2)
    # Poisson's 4 grid variants at 6 s each, on 2 workers; the hull's only run is done.
    assert estimate == {"runs": 4, "estimate_s": 12.0, "unknown": []}
    assert "4 more runs, about 0.2 min" in format_full_grid(estimate)
    del records[0]["process_time_s"]  # an older record: the fit alone
    assert full_grid_estimate(records, ["poisson"], workers=2)["estimate_s"] == 8.0
    failed = full_grid_estimate(records[1:], ["poisson"], workers=2)
    assert failed["estimate_s"] is None and failed["unknown"] == ["poisson"]
    assert "no default run succeeded" in format_full_grid(failed)


def test_agreement_on_another_truth_metric():
    records = [dict(r, accuracy_mean_m=a) for r, a in zip(RECORDS, (0.3, 0.2, 0.1, None, 0.4),
                                                           strict=True)]
    verdict = agreement(records, case_key("plane", {}), metric="accuracy_mean_m")
    assert verdict["rank"] == 1 and verdict["same_run"] and verdict["ratio"] == 1.0
    assert "chamfer_ratio" not in verdict


def test_score_options_sample_coverage_on_twice_the_samples():
    from recon.experiments.cases import score_options

    assert score_options() is None
    assert score_options(4000) == {"n_truth_samples": 4000, "n_test_samples": 4000,
                                   "coverage_points": 8000}
    with pytest.raises(ParameterError, match=r"^samples must be at least 100, got 99$"):
        score_options(99)


def test_score_options_refuse_samples_whose_scoring_cannot_fit_in_memory():
    from recon.experiments.cases import SCORE_BYTES_PER_SAMPLE, score_options

    most = 8192 * 2**20 // SCORE_BYTES_PER_SAMPLE
    assert score_options(most, memory_mb=8192)["n_test_samples"] == most
    with pytest.raises(ParameterError, match=rf"^samples must be at most {most:,}, got "
                                             r"100,000,000,000: scoring them would need about "
                                             r"[\d,.]+ GiB, more than a run's memory limit "
                                             r"\(8,192 MiB\)$") as info:
        score_options(10**11, memory_mb=8192)
    assert info.value.argument == "samples"
    with pytest.raises(ParameterError, match="more than this machine's memory"):
        score_options(10**15)   # no limit: the machine's memory bounds them


def test_compare_walks_its_hdf5_files_before_starting_workers(tmp_path, monkeypatch):
    """A strike log's structure is walked before it is read (formats.hdf5_check): in a forked
    child while recon has one thread, else in a fresh interpreter (0.6 s of CPU). compare walks
    its files before the worker pool's launcher thread starts (the walk is kept)."""
    import recon.surfaces.isolation as isolation
    from formats import hdf5_check
    from recon import api
    from tests.conftest import write_sphere_log

    log = tmp_path / "log.h5"
    write_sphere_log(log)
    monkeypatch.setattr(hdf5_check, "_VERDICTS", {})  # forget that recon wrote it (trust)
    events = []

    class Started(Exception):
        pass

    def start_workers(*args, **kwargs):
        events.append("start workers")
        raise Started

    def verdict(path, cpu_s, live=False):
        events.append(f"walk {path.name}")
        return ""

    monkeypatch.setattr(isolation, "start_workers", start_workers)
    monkeypatch.setattr(hdf5_check, "_verdict", verdict)
    with pytest.raises(Started):
        api.compare(log, truth=log, output=tmp_path / "out", methods=["convex-hull"])
    assert events == ["walk log.h5", "start workers"]


def test_compare_records_carry_the_truth_free_prediction(tmp_path, monkeypatch):
    """Every successful run's record holds the estimate of its mesh, named by the estimate's
    version (results.csv too); an estimate that cannot judge the strikes leaves the run
    standing and says why."""
    import csv
    from types import SimpleNamespace

    from recon import api
    from recon.experiments.compare import estimate_version
    from recon.surfaces import estimate as module
    from tests.conftest import write_sphere_log

    seen = []

    def estimate(surface, cloud, misses=None):
        seen.append(len(cloud.points))
        if len(seen) > 1:
            raise RuntimeError("QH6154 the strikes are flat")
        return SimpleNamespace(chamfer_m=0.2, chamfer_low_m=0.1, chamfer_high_m=0.4,
                               fscore=0.8)

    monkeypatch.setattr(module, "estimate", estimate)
    log = tmp_path / "log.h5"
    write_sphere_log(log)
    report = api.compare(log, truth=log, output=tmp_path / "out", methods=["plane"], n_workers=1)
    (record,) = report.records
    assert seen == [80]      # the strikes of the log, once per successful run
    assert record["status"] == "ok" and record["predicted_by"] == estimate_version()
    assert (record["predicted_chamfer_low_m"], record["predicted_chamfer_m"],
            record["predicted_chamfer_high_m"], record["predicted_fscore"]) == (0.1, 0.2, 0.4,
                                                                                 0.8)
    with open(report.csv, newline="") as f:
        (row,) = csv.DictReader(f)
    assert float(row["predicted_chamfer_m"]) == pytest.approx(0.2)
    report = api.compare(log, truth=log, output=tmp_path / "again", methods=["plane"], n_workers=1)
    (record,) = report.records
    assert record["status"] == "ok" and "flat" in record["prediction_failed"]
    assert record.get("predicted_chamfer_m") is None
