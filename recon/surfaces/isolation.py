"""Run one reconstruction in a fresh process with a time limit and a memory limit.

Surface methods fail in ways a ``try`` cannot catch: Open3D's ball pivoting can run for hours,
qhull can abort or segfault the process, Poisson can allocate without bound (failure modes
reported upstream for each). ``run_isolated`` therefore starts ``python -m
recon.surfaces.isolation JOBDIR`` for every run and waits for it from outside:

- the child limits its own address space (``RLIMIT_AS``, so allocations fail inside it) and
  writes no core files, then runs the method, checks the mesh and optionally scores it;
- the parent kills the child's whole process group at the wall-clock limit, and reads the
  child's exit status and peak memory with ``os.wait4`` even when it died;
- every outcome becomes a result dict: ``status`` "ok" or "failed", and for a failure its
  ``failure`` kind and a one-line ``reason``.

Failure kinds: ``timeout``, ``crash`` (killed by a signal), ``memory`` (an allocation failed
under the limit), ``error`` (the method raised, e.g. ``MethodFailed``), ``empty`` (no
triangles), ``degenerate`` (zero area, collapsed or far larger than the points), ``score``
(the mesh was fine but scoring it failed).

The job carries one ``Run`` (``recon.surfaces.methods``: method name, resolved parameters, the
registering module): the child imports ``Run.module`` on the parent's ``sys.path`` and looks the
method up by name once, so methods registered by test modules run too.
"""

from __future__ import annotations

import os
import pickle
import resource
import signal
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from formats.errors import ReconError
from recon.surfaces.checks import SurfaceRejected, check_surface, watertight
from recon.surfaces.methods import MethodFailed, MethodInput, Run, bind

# Defaults of every isolated run, also the CLI's.
# 600 s: several times the slowest method's default run on 2e5 points (pymeshlab ball pivoting
# with automatic radius took 155 s, measured on a 2-core, 24 GiB machine with pymeshlab 2025.7),
# so a limit hit means a runaway.
DEFAULT_TIMEOUT_S = 600.0
# 8 GiB of address space: the child reserves ~1.8 GB of virtual memory just importing Open3D
# and pymeshlab and running a small Poisson (measured with open3d 0.20), and two children (one
# per core) must fit a 2-core, 24 GiB machine with room for the Dask workers.
DEFAULT_MEMORY_MB = 8192
# Time allowed for checking and scoring a finished mesh, seconds (the method's own limit does
# not include it): metrics.score of a 2e5-face mesh with its default 2e5 samples per side takes
# ~10-30 s here; a limit hit means a runaway.
DEFAULT_SCORE_TIMEOUT_S = 600.0
# How often the parent polls the child, seconds (start, growing to the maximum).
POLL_START_S, POLL_MAX_S = 0.02, 0.25
# Lines of the child's output kept in a failure's reason.
OUTPUT_TAIL_LINES = 3

FAILURE_KINDS = ("timeout", "crash", "memory", "error", "empty", "degenerate", "score")
# Linux prctl option asking the kernel to signal a process when its parent thread dies.
_PR_SET_PDEATHSIG = 1

# Process ids of the children running now (``kill_running`` ends them on an interrupt).
_RUNNING: set[int] = set()
_RUNNING_LOCK = threading.Lock()


class LimitError(ReconError, ValueError):
    """A time or memory limit that is not a valid limit."""


@dataclass(frozen=True)
class Limits:
    """Time and memory limits of one isolated run.

    Attributes
    ----------
    timeout_s : float, seconds
        Wall-clock limit of the child up to the end of the method; must be positive.
    memory_mb : int or None, MiB
        Address-space limit of the child; None: unlimited.
    """

    timeout_s: float = DEFAULT_TIMEOUT_S
    memory_mb: int | None = DEFAULT_MEMORY_MB

    def __post_init__(self):
        _check_limits(self.timeout_s, self.memory_mb, "timeout_s", "memory_mb")

    @classmethod
    def from_options(cls, timeout: float | None = None, memory_limit: int | None = None
                     ) -> Limits:
        """The limits of the command line's ``--timeout`` and ``--memory-limit``.

        None takes the default (``DEFAULT_TIMEOUT_S``, ``DEFAULT_MEMORY_MB``); a memory limit of
        0 means none. Errors name the options.
        """
        timeout = DEFAULT_TIMEOUT_S if timeout is None else timeout
        memory = DEFAULT_MEMORY_MB if memory_limit is None else memory_limit
        _check_limits(timeout, memory, "--timeout", "--memory-limit")
        return cls(timeout, memory or None)

    def kwargs(self) -> dict[str, Any]:
        """``{"timeout_s": ..., "memory_mb": ...}``, the keyword arguments of ``run_isolated``."""
        return {"timeout_s": self.timeout_s, "memory_mb": self.memory_mb}


def _check_limits(timeout: float, memory: int | None, timeout_name: str, memory_name: str):
    if not timeout > 0:
        raise LimitError(f"{timeout_name} must be positive, got {timeout:g}")
    if memory is not None and memory < 0:
        raise LimitError(f"{memory_name} must be >= 0, got {memory}")


class _Failure(Exception):
    """Raised in the child: a failure of a known kind with its reason."""

    def __init__(self, kind: str, reason: str):
        super().__init__(reason)
        self.kind = kind


def _maxrss_mb() -> float:
    """This process's peak resident memory [MB].

    Linux keeps ``ru_maxrss`` across fork and exec, so a child started by a large parent would
    report the parent's peak; the ``VmHWM`` line of /proc/self/status is this image's own.
    """
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0  # kB
    except OSError:  # not Linux
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _die_with_parent(parent: int) -> None:
    """Ask Linux to SIGKILL this process when the thread that started it dies (an interrupted
    sweep must not leave orphans running for hours); elsewhere a no-op."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the parent died before the request took effect
        os._exit(1)


def _child(jobdir: Path) -> int:
    """Body of ``python -m recon.surfaces.isolation JOBDIR``: run the job, write result.pkl."""
    job = pickle.loads((jobdir / "job.pkl").read_bytes())
    if job.get("parent_pid"):
        _die_with_parent(job["parent_pid"])
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    if job["memory_mb"]:   # the soft limit only: lifted again once the method has returned
        limit = int(job["memory_mb"]) * 1024 * 1024
        resource.setrlimit(resource.RLIMIT_AS, (limit, resource.getrlimit(
            resource.RLIMIT_AS)[1]))
    for entry in reversed(job["sys_path"]):
        if entry not in sys.path:
            sys.path.insert(0, entry)
    stage = jobdir / "stage"
    result: dict[str, Any] = {}
    try:
        stage.write_text("loading")
        import importlib

        run: Run = job["run"]
        method = run.method_spec()
        for name in method.preload:
            importlib.import_module(name)
        cloud: MethodInput = job["cloud"]
        result["baseline_memory_mb"] = _maxrss_mb()
        stage.write_text("running")
        start = time.perf_counter()
        try:
            vertices, faces = method.run(cloud, **run.params)
        except MemoryError:
            raise _Failure("memory", f"{run.method}: out of memory (limit "
                                     f"{job['memory_mb']} MB)") from None
        except MethodFailed as exc:
            raise _Failure("error", str(exc)) from None
        except Exception as exc:  # a library error is a recorded failure, with its type
            last = str(exc).strip().splitlines()[-1] if str(exc).strip() else ""
            raise _Failure("error", f"{run.method}: {type(exc).__name__}: {last}") from None
        result["wall_time_s"] = time.perf_counter() - start
        result["peak_memory_mb"] = _maxrss_mb()
        # The memory limit is the method's: checking and scoring the mesh (ours) run without it.
        hard = resource.getrlimit(resource.RLIMIT_AS)[1]
        resource.setrlimit(resource.RLIMIT_AS, (hard, hard))
        stage.write_text("checking")
        try:
            vertices, faces = check_surface(vertices, faces, cloud.points, method=run.method)
        except SurfaceRejected as exc:
            raise _Failure(exc.kind, str(exc)) from None
        except MethodFailed as exc:
            raise _Failure("error", str(exc)) from None
        result.update(vertices=vertices, faces=faces, n_vertices=len(vertices),
                      n_faces=len(faces), watertight=watertight(faces))
        if job.get("truth") is not None:
            stage.write_text("scoring")
            try:
                result["scores"] = _score(vertices, faces, job["truth"], job["score_options"])
            except Exception as exc:
                raise _Failure("score", f"scoring failed: {type(exc).__name__}: {exc}") from None
        result.update(status="ok", failure=None, reason="")
    except _Failure as failure:
        result.update(status="failed", failure=failure.kind, reason=str(failure))
    except MemoryError:
        result.update(status="failed", failure="memory",
                      reason=f"out of memory while {stage.read_text()} "
                             f"(limit {job['memory_mb']} MB)")
    except Exception as exc:
        traceback.print_exc()
        result.update(status="failed", failure="error",
                      reason=f"{type(exc).__name__} while {stage.read_text()}: {exc}")
    tmp = jobdir / "result.pkl.partial"
    tmp.write_bytes(pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL))
    tmp.rename(jobdir / "result.pkl")
    return 0


def _score(vertices, faces, truth, options) -> dict:
    """Score a mesh against the truth with ``metrics.score``; a flat dict of numbers."""
    from metrics.score import score

    report = score((vertices, faces), truth, **(options or {}))
    return {k: v for k, v in report.to_dict().items() if isinstance(v, (int, float, bool))
            or v is None}


def _tail(path: Path) -> str:
    try:
        lines = [ln.strip() for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return " | ".join(lines[-OUTPUT_TAIL_LINES:])


def run_isolated(run: Run | str, cloud: MethodInput, params: dict | None = None, *,
                 truth: tuple[np.ndarray, np.ndarray] | None = None,
                 score_options: dict | None = None, timeout_s: float = DEFAULT_TIMEOUT_S,
                 memory_mb: int | None = DEFAULT_MEMORY_MB, threads: int | None = None,
                 score_timeout_s: float = DEFAULT_SCORE_TIMEOUT_S,
                 on_wait: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run one method on one cloud in a fresh, limited process and report what happened.

    Parameters
    ----------
    run : Run or str
        The method and its resolved parameters (``recon.surfaces.methods.bind``), or a
        registered name (hidden test methods included), then resolved here once with ``params``.
    cloud : MethodInput
    params : dict, optional
        With a name only: overrides of the method's defaults (checked before any process starts).
    truth : (vertices, faces), optional
        Truth mesh, metres, same frame: when given, the mesh is scored with ``metrics.score``.
    score_options : dict, optional
        Keyword arguments of ``metrics.score``.
    timeout_s : float
        Wall-clock limit of the child up to the end of the method (start-up and imports
        included), seconds.
    memory_mb : int or None
        Address-space limit of the child, MiB (None: unlimited).
    threads : int, optional
        ``OMP_NUM_THREADS`` and friends of the child (sweeps set 1 so parallel runs do not
        compete for the cores).
    score_timeout_s : float
        Further limit for checking and scoring the mesh, counted from the method's end.
    on_wait : callable, optional
        Called with the child's current stage (e.g. "running") each time the parent polls it,
        at least every ``POLL_MAX_S``: drives a progress display.

    Returns
    -------
    dict
        ``method``, ``params`` (resolved), ``status`` ("ok" or "failed"), ``failure`` (kind or
        None), ``reason``, ``wall_time_s`` (the method alone), ``process_time_s`` (the whole
        child), ``peak_memory_mb`` (the child's peak resident set after the method, or at its
        death), and when ok ``vertices``, ``faces``, ``n_vertices``, ``n_faces``,
        ``watertight`` and (with a truth) ``scores``.
    """
    run = bind(run, params)
    limits = Limits(timeout_s, memory_mb)
    job = {"run": run, "cloud": cloud, "truth": truth, "score_options": score_options,
           "memory_mb": limits.memory_mb, "sys_path": [p for p in sys.path if p],
           "parent_pid": os.getpid()}
    env = dict(os.environ)
    if threads:
        for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            env[name] = str(int(threads))
    base = {"method": run.method, "params": run.params}
    with tempfile.TemporaryDirectory(prefix="recon-run-") as tmp:
        jobdir = Path(tmp)
        (jobdir / "job.pkl").write_bytes(pickle.dumps(job, protocol=pickle.HIGHEST_PROTOCOL))
        log = jobdir / "output.log"
        start = time.perf_counter()
        with open(log, "wb") as out:
            proc = subprocess.Popen([sys.executable, "-m", "recon.surfaces.isolation", str(jobdir)],
                                    stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                    env=env, start_new_session=True)
        with _RUNNING_LOCK:
            _RUNNING.add(proc.pid)
        try:
            status, usage, timed_out = _wait(proc, timeout_s, jobdir / "stage", score_timeout_s,
                                             on_wait)
        finally:
            with _RUNNING_LOCK:
                _RUNNING.discard(proc.pid)
        elapsed = time.perf_counter() - start
        peak = usage.ru_maxrss / 1024.0
        result_file = jobdir / "result.pkl"
        stage_file = jobdir / "stage"
        stage = stage_file.read_text() if stage_file.exists() else "starting"
        if timed_out:
            limit = score_timeout_s if stage in ("checking", "scoring") else timeout_s
            return base | {"status": "failed", "failure": "timeout",
                           "reason": f"timed out after {limit:g} s while {stage}",
                           "process_time_s": elapsed, "peak_memory_mb": peak}
        if result_file.exists():
            result = pickle.loads(result_file.read_bytes())
            result.setdefault("peak_memory_mb", peak)
            return base | result | {"process_time_s": elapsed}
        if os.WIFSIGNALED(status):
            number = os.WTERMSIG(status)
            name = signal.Signals(number).name if number in signal.valid_signals() else number
            kind = "crash"
            hint = ""
            if memory_mb and peak > 0.9 * memory_mb:
                kind, hint = "memory", f" near the {memory_mb} MB memory limit"
            elif number == signal.SIGKILL:
                hint = " (by the system: out of memory?)"
            reason = f"crashed with {name} while {stage}{hint}"
        else:
            kind = "crash"
            reason = f"exited with status {os.WEXITSTATUS(status)} while {stage}"
        tail = _tail(log)
        if tail:
            reason += f": {tail}"
        return base | {"status": "failed", "failure": kind, "reason": reason,
                       "process_time_s": elapsed, "peak_memory_mb": peak}


def _wait(proc: subprocess.Popen, timeout_s: float, stage: Path, score_timeout_s: float,
          on_wait: Callable[[str], None] | None = None):
    """Wait for ``proc`` with ``os.wait4``; kill its process group at the limit.

    The limit is ``timeout_s`` from the start until the child reports (in the ``stage`` file)
    that the method has returned, then ``score_timeout_s`` from that moment. ``on_wait`` gets
    the child's stage at every poll.

    Returns ``(status, rusage, timed_out)``.
    """
    deadline = time.monotonic() + timeout_s
    scoring = False
    delay = POLL_START_S
    try:
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            current = stage.read_text() if stage.exists() else "starting"
            if on_wait is not None:
                on_wait(current)
            if not scoring and current in ("checking", "scoring"):
                scoring = True
                deadline = time.monotonic() + score_timeout_s
            if time.monotonic() >= deadline:
                _kill_group(proc.pid)
                _, status, usage = os.wait4(proc.pid, 0)
                proc.returncode = -signal.SIGKILL
                return status, usage, True
            time.sleep(delay)
            delay = min(delay * 1.5, POLL_MAX_S)
    except BaseException:  # interrupted while waiting: never leave the child behind
        _kill_group(proc.pid)
        try:
            os.wait4(proc.pid, 0)
        except ChildProcessError:
            pass
        proc.returncode = -signal.SIGKILL
        raise
    proc.returncode = os.waitstatus_to_exitcode(status)
    return status, usage, False


def kill_running() -> int:
    """SIGKILL every child this process is waiting on (from any thread); returns how many.

    Their waiting threads then report them as crashed; a sweep calls this when interrupted.
    """
    with _RUNNING_LOCK:
        pids = list(_RUNNING)
    for pid in pids:
        _kill_group(pid)
    return len(pids)


def _kill_group(pid: int) -> None:
    """SIGKILL the process group ``pid`` leads (the child and anything it started)."""
    try:
        os.killpg(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


if __name__ == "__main__":
    sys.exit(_child(Path(sys.argv[1])))
