"""Sweeps: results stream to disk as they finish, an interrupted sweep resumes where it stopped."""

from __future__ import annotations

import json
import os
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from formats.errors import ParameterError
from recon.experiments.sweep import QUEUED_PER_WORKER, iterate, read_results, run_sweep, to_jsonable

CALLS_ENV = "RECON_TEST_SWEEP_CALLS"


def square(*, x: int, offset: int = 0, calls: str, stop_at: int | None = None) -> dict:
    """A case that records that it ran (in the ``calls`` file) and optionally interrupts."""
    with open(calls, "a") as out:
        out.write(f"{x}\n")
    if stop_at is not None and x == stop_at:
        raise KeyboardInterrupt  # what Ctrl-C does in the middle of a sweep
    return {"status": "ok", "value": x * x + offset}


def timed(*, x: int, calls: str) -> dict:
    """A short case that records when it started (in the ``calls`` file)."""
    with open(calls, "a") as out:
        out.write(f"{x} {time.monotonic()}\n")
    time.sleep(0.005)
    return {"status": "ok"}


def broken(*, x: int) -> dict:
    raise RuntimeError(f"case {x} is broken")


def _cases(n: int) -> dict:
    return {f"x={i}": {"x": i} for i in range(n)}


def _ran(calls) -> list[int]:
    if not os.path.exists(calls):
        return []
    with open(calls) as text:
        return [int(v) for v in text.read().split()]


@pytest.mark.parametrize("scheduler", ["serial", "threads"])
def test_results_stream_and_come_back_in_case_order(tmp_path, scheduler):
    calls = str(tmp_path / "calls")
    done = run_sweep(square, _cases(6), tmp_path / "out", shared={"offset": 1, "calls": calls},
                     scheduler=scheduler, n_workers=2)
    assert list(done) == [f"x={i}" for i in range(6)]
    assert [r["value"] for r in done.values()] == [i * i + 1 for i in range(6)]
    lines = (tmp_path / "out" / "results.jsonl").read_text().splitlines()
    assert sorted(json.loads(line)["key"] for line in lines) == sorted(done)


def test_interrupted_sweep_keeps_its_results_and_resume_skips_them(tmp_path):
    calls = str(tmp_path / "calls")
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        run_sweep(square, _cases(6), out, shared={"calls": calls, "stop_at": 3},
                  scheduler="serial")
    assert sorted(read_results(out / "results.jsonl")) == ["x=0", "x=1", "x=2"]
    # A torn last line (killed mid-write) is dropped, not fatal.
    with open(out / "results.jsonl", "a") as stream:
        stream.write('{"key": "x=4", "val')
    done = run_sweep(square, _cases(6), out, shared={"calls": calls}, scheduler="serial",
                     resume=True)
    assert [r["value"] for r in done.values()] == [i * i for i in range(6)]
    assert _ran(calls) == [0, 1, 2, 3, 3, 4, 5]  # 0-2 were not run again
    lines = (out / "results.jsonl").read_text().splitlines()
    assert len(lines) == 6 and all(json.loads(line) for line in lines)


def _counting_submissions(monkeypatch, *, interrupt_at: int | None = None) -> list:
    """Count the cases submitted to thread pools; raise KeyboardInterrupt from submission
    number ``interrupt_at`` (where a Ctrl-C may land), recording when in the list."""
    submit, submitted = ThreadPoolExecutor.submit, []

    def counting(self, *args, **kwargs):
        submitted.append(time.monotonic())
        if len(submitted) == interrupt_at:
            raise KeyboardInterrupt
        return submit(self, *args, **kwargs)

    monkeypatch.setattr(ThreadPoolExecutor, "submit", counting)
    return submitted


def test_a_thread_pool_takes_the_cases_a_few_at_a_time(tmp_path, monkeypatch):
    submitted = _counting_submissions(monkeypatch)
    cases = {f"x={i}": {"x": i} for i in range(5000)}
    results = iterate(timed, cases, shared={"calls": str(tmp_path / "calls")},
                      scheduler="threads", n_workers=2)
    next(results)
    assert len(submitted) <= 2 * QUEUED_PER_WORKER + 2
    results.close()


def test_an_interrupt_while_cases_are_submitted_starts_no_more_of_them(tmp_path, monkeypatch):
    calls = tmp_path / "calls"
    submitted = _counting_submissions(monkeypatch, interrupt_at=200)
    cases = {f"x={i}": {"x": i} for i in range(5000)}
    with pytest.raises(KeyboardInterrupt):
        for _ in iterate(timed, cases, shared={"calls": str(calls)}, scheduler="threads",
                         n_workers=2):
            pass
    interrupted = submitted[-1]
    time.sleep(0.5)   # what still ran after the interrupt has started by now
    starts = [float(line.split()[1]) for line in calls.read_text().splitlines()]
    # at most the cases queued when it came (a race: one may start as it is cancelled)
    assert sum(start > interrupted for start in starts) <= 2 * QUEUED_PER_WORKER


def test_without_resume_a_sweep_starts_afresh(tmp_path):
    calls = str(tmp_path / "calls")
    run_sweep(square, _cases(2), tmp_path, shared={"calls": calls}, scheduler="serial")
    run_sweep(square, _cases(2), tmp_path, shared={"calls": calls}, scheduler="serial")
    assert _ran(calls) == [0, 1, 0, 1]
    assert len((tmp_path / "results.jsonl").read_text().splitlines()) == 2


def test_resume_refuses_results_of_another_input(tmp_path):
    calls = str(tmp_path / "calls")
    run_sweep(square, _cases(2), tmp_path, shared={"calls": calls}, scheduler="serial",
              fingerprint={"input": "a.ply"})
    with pytest.raises(ParameterError, match="different input; use a new output directory"):
        run_sweep(square, _cases(2), tmp_path, shared={"calls": calls}, scheduler="serial",
                  fingerprint={"input": "b.ply"}, resume=True)


def test_a_raising_case_is_a_recorded_failure(tmp_path):
    done = run_sweep(broken, _cases(2), tmp_path, scheduler="threads")
    assert all(r["status"] == "failed" and r["failure"] == "task" for r in done.values())
    assert "RuntimeError: case 1 is broken" in done["x=1"]["reason"]


def test_local_dask_cluster_runs_the_cases(tmp_path):
    calls = str(tmp_path / "calls")
    done = run_sweep(square, _cases(4), tmp_path, shared={"calls": calls}, n_workers=2)
    assert [r["value"] for r in done.values()] == [0, 1, 4, 9]


def test_unreachable_scheduler_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setattr("recon.experiments.sweep.CONNECT_TIMEOUT_S", 1.0)
    with pytest.raises(ParameterError, match=r"^scheduler tcp://127\.0\.0\.1:9: cannot connect"):
        run_sweep(square, _cases(1), tmp_path, shared={"calls": str(tmp_path / "c")},
                  scheduler="tcp://127.0.0.1:9")


def test_workers_must_be_positive(tmp_path):
    with pytest.raises(ParameterError, match=r"^n_workers must be >= 1"):
        run_sweep(square, _cases(1), tmp_path, n_workers=0)


def test_to_jsonable_handles_numpy_and_non_finite():
    value = {"a": np.float32(1.5), "b": np.arange(3), "c": (1, float("inf")), "d": np.bool_(1)}
    assert to_jsonable(value) == {"a": 1.5, "b": [0, 1, 2], "c": [1, None], "d": True}


def seeded(*, x: int, seed: int) -> dict:
    """A case whose value is drawn from its own seed."""
    return {"status": "ok", "value": float(np.random.default_rng([seed, x]).normal())}


def signalled(*, x: int, at: int) -> dict:
    """A case; case ``at`` records a SIGINT whose exception a library swallowed (what
    ``formats.interrupt``'s handler leaves for ``check``). The in-process cluster's worker
    threads share this process's record."""
    import signal

    from formats import interrupt

    if x == at:
        interrupt._received.append(signal.SIGINT)
    time.sleep(0.01)
    return {"status": "ok", "value": x}


@pytest.fixture
def dask_address():
    """The address of an in-process Dask cluster of 2 single-threaded workers."""
    import logging

    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp",
                      host="127.0.0.1", dashboard_address="127.0.0.1:0",
                      silence_logs=logging.ERROR) as cluster:
        yield cluster.scheduler_address


def _counting_dask_submissions(monkeypatch, consumed: list, *, interrupt_at: int | None = None
                               ) -> tuple[list, list]:
    """Record, at each case submitted to a Dask client, the cases submitted (this one
    included) and not yet handed to the caller (``consumed[0]``); raise KeyboardInterrupt at
    submission number ``interrupt_at``. Returns (those counts, the clients used)."""
    from distributed import Client

    submit, in_flight, clients = Client.submit, [], []

    def counting(self, *args, **kwargs):
        if self not in clients:
            clients.append(self)
        in_flight.append(len(in_flight) + 1 - consumed[0])
        if len(in_flight) == interrupt_at:
            raise KeyboardInterrupt
        return submit(self, *args, **kwargs)

    monkeypatch.setattr(Client, "submit", counting)
    return in_flight, clients


def test_a_dask_cluster_takes_the_cases_a_few_per_worker_at_a_time(tmp_path, monkeypatch,
                                                                   dask_address):
    """At most QUEUED_PER_WORKER cases per worker thread of the cluster are submitted and not
    yet returned (plus the one being returned), whatever n_workers says: the cluster's workers
    run them."""
    consumed = [0]
    in_flight, _ = _counting_dask_submissions(monkeypatch, consumed)
    calls = str(tmp_path / "calls")
    got = {}
    for key, result in iterate(square, _cases(40), shared={"calls": calls},
                               scheduler=dask_address, n_workers=50):
        got[key] = result["value"]
        consumed[0] += 1
    assert got == {f"x={i}": i * i for i in range(40)}
    assert len(in_flight) == 40 and sorted(_ran(calls)) == list(range(40))
    assert max(in_flight) <= 2 * QUEUED_PER_WORKER + 1


def test_a_dask_sweep_gives_the_serial_sweep_s_results(tmp_path, dask_address):
    cases = {f"x={i}": {"x": i} for i in range(12)}
    serial = run_sweep(seeded, cases, tmp_path / "serial", shared={"seed": 5},
                       scheduler="serial")
    dask = run_sweep(seeded, cases, tmp_path / "dask", shared={"seed": 5},
                     scheduler=dask_address)
    assert list(dask) == list(serial) and dask == serial


def test_an_interrupt_during_a_dask_sweep_cancels_the_few_cases_in_flight(tmp_path,
                                                                         monkeypatch,
                                                                         dask_address):
    """Ctrl-C landing as a case is submitted, mid-sweep: the cases in flight (a few per
    worker) are cancelled, and no other is submitted."""
    from distributed import Client

    consumed = [0]
    in_flight, clients = _counting_dask_submissions(monkeypatch, consumed, interrupt_at=20)
    cancel, cancelled = Client.cancel, []

    def counting_cancel(self, futures, *args, **kwargs):
        cancelled.append(len(futures))
        return cancel(self, futures, *args, **kwargs)

    monkeypatch.setattr(Client, "cancel", counting_cancel)
    try:
        with pytest.raises(KeyboardInterrupt):
            for _ in iterate(square, _cases(40), shared={"calls": str(tmp_path / "calls")},
                             scheduler=dask_address):
                consumed[0] += 1
    finally:
        for client in clients:   # left open on Ctrl-C, as a command ends at once
            client.close()
    assert len(in_flight) == 20 and consumed[0] >= 20 - 2 * QUEUED_PER_WORKER - 1
    assert len(cancelled) == 1 and cancelled[0] <= 2 * QUEUED_PER_WORKER


def test_a_swallowed_interrupt_stops_a_dask_sweep(monkeypatch, dask_address):
    """A signal whose exception a library swallowed stops the sweep at the next look, with the
    cases submitted by then at most, not at its end."""
    from formats import interrupt

    monkeypatch.setattr(interrupt, "_received", [])
    consumed = [0]
    in_flight, clients = _counting_dask_submissions(monkeypatch, consumed)
    cases = {f"x={i}": {"x": i} for i in range(200)}
    try:
        with pytest.raises(interrupt.Interrupted, match="SIGINT"):
            for _ in iterate(signalled, cases, shared={"at": 3}, scheduler=dask_address):
                consumed[0] += 1
    finally:
        for client in clients:
            client.close()
    assert consumed[0] < 3 + 2 * QUEUED_PER_WORKER + 2 and len(in_flight) < 20
