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
