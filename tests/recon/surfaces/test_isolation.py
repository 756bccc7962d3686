"""Isolation: crashes, hangs, memory blow-ups and bad meshes are recorded, never fatal.

``recon_fake_methods`` registers hidden methods that abort the process (``os.abort``), hang,
allocate past the memory limit, return nothing, return a zero-area mesh, or refuse. The
comparison runs them beside real methods on a Dask cluster and must keep everyone's results.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import recon_fake_methods  # noqa: F401  (registers the test-only methods)

from formats.errors import MethodFailed, ParameterError
from recon.experiments.compare import compare
from recon.surfaces import isolation
from recon.surfaces.isolation import run_isolated
from recon.surfaces.methods import watertight
from recon.surfaces.prepare import prepare
from recon.surfaces.reconstruct import reconstruct
from tests.recon.conftest import FAST_SCORE, sphere_mesh, sphere_points

# A hang must end at the limit, not after its hour-long sleep.
HANG_LIMIT_S = 4.0


@pytest.fixture(scope="module")
def cloud():
    points, view, _ = sphere_points(3000)
    return prepare(points, view_points=view)


@pytest.fixture(scope="module")
def cluster():
    """One local Dask cluster for the module (start-up costs a few seconds)."""
    import logging

    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0", silence_logs=logging.ERROR) as local:
        yield local.scheduler_address


@pytest.mark.parametrize("method, params, kind, reason", [
    ("test-abort", {}, "crash", "crashed with SIGABRT while running"),
    ("test-hang", {}, "timeout", f"timed out after {HANG_LIMIT_S:g} s while running"),
    ("test-hog", {"megabytes": 3000}, "memory", "out of memory"),
    ("test-empty", {}, "empty", "empty mesh"),
    ("test-flat", {}, "degenerate", "degenerate mesh"),
    ("test-refuse", {}, "error", "refused on purpose"),
])
def test_each_failure_is_recorded_with_its_kind_and_the_pool_goes_on(cloud, method, params,
                                                                    kind, reason):
    result = run_isolated(method, cloud, params, timeout_s=HANG_LIMIT_S, memory_mb=1536)
    assert result["status"] == "failed"
    assert result["failure"] == kind
    assert reason in result["reason"]
    if kind == "timeout":  # stopped at the limit of the method's own run
        assert HANG_LIMIT_S <= result["wall_time_s"] < HANG_LIMIT_S + 5
    after = run_isolated("convex-hull", cloud, memory_mb=1536)
    assert after["status"] == "ok", after["reason"]


def test_workers_are_reused_and_replaced_after_a_crash(cloud):
    from recon.surfaces import isolation

    def idle_pids():
        return {w.proc.pid for w in isolation._IDLE.get(None, [])}

    isolation.shutdown_workers()
    first = run_isolated("convex-hull", cloud)
    pids = idle_pids()
    second = run_isolated("convex-hull", cloud)
    assert first["status"] == second["status"] == "ok"
    assert idle_pids() == pids and len(pids) == 1  # the same warm worker did both runs
    assert second["process_time_s"] < first["process_time_s"]  # no start-up the second time
    crashed = run_isolated("test-abort", cloud)
    assert crashed["failure"] == "crash" and idle_pids() == set()  # the dead worker is gone
    assert run_isolated("convex-hull", cloud)["status"] == "ok"
    assert len(idle_pids()) == 1 and idle_pids() != pids


def test_a_finished_run_wakes_its_parent_before_the_next_poll(cloud, monkeypatch):
    """With a minute between polls, the parent still learns of a finished run at once: the
    worker wakes it on its pipe, and each run of a reused worker is the same fit."""
    import types

    from recon.surfaces import isolation

    monkeypatch.setattr(isolation, "POLL_START_S", 60.0)
    monkeypatch.setattr(isolation, "POLL_MAX_S", 60.0)
    woken = []

    def watched(read, write, error, timeout):
        ready = isolation_select(read, write, error, timeout)
        woken.append(bool(ready[0]))
        return ready

    isolation_select = isolation.select.select
    monkeypatch.setattr(isolation, "select", types.SimpleNamespace(select=watched))
    first = run_isolated("convex-hull", cloud)
    second = run_isolated("convex-hull", cloud)
    assert first["status"] == second["status"] == "ok"
    assert np.array_equal(first["faces"], second["faces"])
    # every wait that ended before the minute ended because the worker woke it
    assert woken.count(True) >= 2 and all(woken), woken


def test_each_runs_peak_memory_is_its_own_in_a_reused_worker(cloud):
    big = run_isolated("test-hog", cloud, {"megabytes": 600}, memory_mb=None)
    small = run_isolated("test-hog", cloud, {"megabytes": 10}, memory_mb=None)
    # test-hog returns a one-face mesh: rejected after the method, with its peak recorded.
    assert big["peak_memory_mb"] > big["baseline_memory_mb"] + 550
    assert small["peak_memory_mb"] < small["baseline_memory_mb"] + 100


def test_a_worker_imports_open3d_without_its_plotly_drawing(cloud):
    """A worker has Open3D loaded but not the plotly drawing Open3D imports (dash, plotly): its
    stand-in imports any name and says what it is when called."""
    result = run_isolated("test-modules", cloud)
    assert result["reason"] == "test-modules: loaded open3d", result
    stand_in = isolation._stand_in("some.module")
    from_import = stand_in.draw_anything   # what ``from some.module import ...`` reads
    with pytest.raises(RuntimeError, match=r"some\.module is left out of this process by recon"):
        from_import()
    assert not hasattr(stand_in, "__path__")   # a plain module to the import machinery


def test_a_good_run_returns_its_mesh_time_and_memory(cloud):
    result = run_isolated("convex-hull", cloud, truth=sphere_mesh(3), score_options=FAST_SCORE)
    assert result["status"] == "ok" and result["failure"] is None
    assert result["n_faces"] == len(result["faces"]) > 1000
    assert result["watertight"]
    assert 0 < result["wall_time_s"] < result["process_time_s"]
    assert result["peak_memory_mb"] > 10
    assert result["scores"]["chamfer_m"] < 0.01
    assert 0.9 < result["scores"]["fscore"] <= 1.0


def test_a_warm_up_builds_the_truth_a_run_then_scores_on(tmp_path):
    from metrics.score import Truth
    from recon.surfaces import isolation

    truth = sphere_mesh(3)
    jobdir = tmp_path / f"{isolation._WARM_PREFIX}job"
    jobdir.mkdir()
    key = isolation._truth_key(truth)
    (jobdir / "job.pkl").write_bytes(isolation.pickle.dumps(
        {"truth": truth, "truth_key": key, "score_options": FAST_SCORE}))
    truths = {}
    isolation._warm(jobdir, truths)  # what a worker does with a warm-up job
    assert list(truths) == [key] and isinstance(truths[key], Truth)
    built = truths[key]
    assert built._distance is not None and not jobdir.exists()
    assert list(built._lattices) == [FAST_SCORE["coverage_points"]]
    assert [n for n, _ in built._samples] == [FAST_SCORE["n_truth_samples"]]


def test_a_warmed_worker_scores_as_a_cold_one(cloud):
    from recon.surfaces import isolation

    truth = sphere_mesh(3)
    isolation.shutdown_workers()
    cold = run_isolated("convex-hull", cloud, truth=truth, score_options=FAST_SCORE)
    isolation.shutdown_workers()
    isolation.start_workers(1)
    isolation.warm_truth(truth, FAST_SCORE)
    warm = run_isolated("convex-hull", cloud, truth=truth, score_options=FAST_SCORE)
    assert warm["status"] == cold["status"] == "ok"
    assert warm["scores"] == cold["scores"]
    assert len(isolation._IDLE[None]) == 1  # the warmed worker did the run


def test_reconstruct_isolated_raises_method_failed(cloud):
    with pytest.raises(MethodFailed, match=r"test-abort failed \(crash\)"):
        reconstruct(cloud, method="test-abort", isolate=True)
    surface = reconstruct(cloud, method="convex-hull", isolate=True)
    assert surface.info["peak_memory_mb"] > 0 and len(surface.faces) > 1000


def test_comparison_survives_crashes_and_hangs(cloud, cluster, tmp_path):
    names = ["convex-hull", "test-abort", "planes", "test-hang", "ball-pivoting"]
    report = compare(cloud, sphere_mesh(4), tmp_path, names=names, grid=False,
                     timeout_s=HANG_LIMIT_S, scheduler=cluster, score_options=FAST_SCORE)
    by_method = {r["method"]: r for r in report["records"]}
    assert set(by_method) == set(names)
    assert by_method["test-abort"]["failure"] == "crash"
    assert by_method["test-hang"]["failure"] == "timeout"
    for name in ("convex-hull", "planes", "ball-pivoting"):
        record = by_method[name]
        assert record["status"] == "ok", record["reason"]
        assert record["chamfer_m"] > 0 and record["n_faces"] > 0
        assert (tmp_path / record["mesh"]).is_file()
    saved = json.loads((tmp_path / "results.json").read_text())
    assert {r["method"] for r in saved["runs"]} == set(names)
    assert "crashed with SIGABRT" in (tmp_path / "results.csv").read_text()
    assert (tmp_path / "speed_accuracy.png").stat().st_size > 10_000


def test_watertight_detects_holes_and_flips():
    from tests.recon.conftest import box_mesh

    _, faces = box_mesh()
    assert watertight(faces)
    assert not watertight(faces[1:])
    flipped = faces.copy()
    flipped[0] = flipped[0, ::-1]
    assert not watertight(flipped)
    assert not watertight(np.zeros((0, 3), dtype=np.int64))


def test_peak_memory_is_the_childs_own_not_the_parents():
    """ru_maxrss survives fork and exec on Linux; a large parent must not inflate the figure."""
    import subprocess
    import sys

    script = ("import numpy as np, subprocess, sys\n"
              "big = np.ones(300_000_000 // 8)\n"
              "print(subprocess.run([sys.executable, '-c', 'from recon.surfaces.isolation import "
              "_maxrss_mb; print(_maxrss_mb())'], capture_output=True, text=True, "
              "check=True).stdout)")
    child_mb = float(subprocess.run([sys.executable, "-c", script], capture_output=True,
                                    text=True, check=True).stdout)
    assert child_mb < 250  # the child imports numpy and scipy, far below the parent's 300 MB


def test_limits_take_the_defaults_and_name_the_arguments():
    from recon.surfaces.isolation import DEFAULT_MEMORY_MB, DEFAULT_TIMEOUT_S, Limits

    assert Limits.from_options() == Limits(DEFAULT_TIMEOUT_S, DEFAULT_MEMORY_MB)
    assert Limits.from_options(5, 0) == Limits(5.0, None)  # 0: no memory limit
    with pytest.raises(ParameterError, match=r"^timeout must be positive, got 0$") as info:
        Limits.from_options(0)
    assert info.value.argument == "timeout"
    with pytest.raises(ParameterError,
                       match=r"^memory_limit must be from 0 to 8796093022207 MB, got -1$") as info:
        Limits.from_options(memory_limit=-1)
    assert info.value.argument == "memory_limit"
    with pytest.raises(ParameterError, match=r"^timeout_s must be positive, got -1$"):
        Limits(-1.0)


def test_a_run_predicted_over_its_limit_is_declined_without_a_process(cloud):
    from recon.surfaces import isolation, methods

    run = methods.bind("alpha-shape")
    lidar_s, lrf_s = methods.DEFAULT_FIT_S["alpha-shape"]
    # The measured times at the measured sizes, a power law between them.
    assert methods.predicted_fit_s(run, methods.COST_POINTS[0]) == pytest.approx(lidar_s)
    assert methods.predicted_fit_s(run, methods.COST_POINTS[1]) == pytest.approx(lrf_s)
    predicted = methods.predicted_fit_s(run, len(cloud.points))
    exponent = np.log(lidar_s / lrf_s) / np.log(336_333 / 77_400)
    assert predicted == pytest.approx(lrf_s * (3000 / 77_400) ** max(1.0, exponent))
    assert methods.predicted_fit_s(methods.bind("alpha-shape", {"alpha": 1.5}), 10**9) is None
    isolation.shutdown_workers()
    result = run_isolated(run, cloud, timeout_s=predicted / 2)
    assert result["status"] == "failed" and result["failure"] == "timeout"
    assert result["reason"].startswith(f"declined: predicted {predicted:.2g} s on 3000 points")
    assert not isolation._IDLE.get(None) and not isolation._BUSY  # no worker was started


def test_a_stopped_sweep_kills_its_runs_and_starts_no_more_until_resumed(cloud):
    """Ctrl-C on a sweep: the running fit dies at once, and the sweep's other threads start no
    new fit (they would each run a whole case before the sweep could end)."""
    import threading

    from recon.surfaces.isolation import kill_running, resume_runs

    results = {}

    def hang():
        try:
            results["hang"] = run_isolated("test-hang", cloud, timeout_s=600)["failure"]
        except InterruptedError:   # its worker was still starting when the sweep stopped
            results["hang"] = "stopped"

    waiting = threading.Thread(target=hang)
    waiting.start()
    try:
        import time

        time.sleep(3.0)   # the hang is running (or its worker still starting)
        kill_running()
        waiting.join(60)
        assert not waiting.is_alive() and results["hang"] in ("crash", "stopped")
        with pytest.raises(InterruptedError):
            run_isolated("ball-pivoting", cloud)
    finally:
        resume_runs()
        waiting.join(60)
    assert run_isolated("convex-hull", cloud)["status"] == "ok"


def test_a_worker_s_replacement_is_started_before_it_ends(cloud, monkeypatch):
    """``WARM_AHEAD`` runs before a worker's last, its replacement starts and waits behind it;
    the worker does its remaining runs, and the run after its last goes to the replacement."""
    from recon.surfaces import isolation

    def idle_pids():
        return [w.proc.pid for w in isolation._IDLE.get(None, [])]

    monkeypatch.setattr(isolation, "WORKER_RUNS", 4)
    monkeypatch.setattr(isolation, "WARM_AHEAD", 2)
    isolation.shutdown_workers()
    assert run_isolated("convex-hull", cloud)["status"] == "ok"
    [old] = idle_pids()
    assert run_isolated("convex-hull", cloud)["status"] == "ok"   # run 2 of 4: a spare starts
    spare, again = idle_pids()
    assert again == old and spare != old
    for _ in range(2):   # runs 3 and 4 on the old worker, which then ends
        assert run_isolated("convex-hull", cloud)["status"] == "ok"
    assert idle_pids() == [spare]
    assert run_isolated("convex-hull", cloud)["status"] == "ok"
    assert idle_pids() == [spare]
    isolation.shutdown_workers()
