"""Run one reconstruction in a warm, isolated worker process with a time and a memory limit.

Surface methods fail in ways a ``try`` cannot catch: Open3D's ball pivoting can run for hours,
qhull can abort or segfault the process, Poisson can allocate without bound (failure modes
reported upstream for each). ``run_isolated`` therefore runs every method in a child process
and watches it from outside. The children are a pool of warm workers (``python -m
recon.surfaces.isolation``, started with numpy, scipy, Open3D, pymeshlab and the metrics
already imported, then reading one job after another), so a run pays neither a fresh
interpreter nor fresh imports:

- for each job the worker limits its own address space (``RLIMIT_AS``, the run's limit on top
  of what the warm worker already holds, so allocations fail inside it) while the method runs,
  resets its peak-memory mark (``/proc/self/clear_refs``) so the peak it reports is the run's
  own, checks the mesh and optionally scores it against a truth it keeps between jobs
  (``metrics.Truth``: built once per worker and truth);
- the parent kills the worker's whole process group at the limit, and otherwise reads the
  worker's exit status when it died; the time limit counts from the moment the method starts
  (a worker's start-up and a job's loading have their own, generous limit,
  ``START_TIMEOUT_S``), so a loaded machine cannot make a fast method time out while
  importing Open3D;
- ``warm_truth`` has idle workers build a truth's ``metrics.Truth`` ahead of the runs, while
  the caller still reads and prepares the cloud;
- a worker is replaced after a crash, a hang, a memory failure, or ``WORKER_RUNS`` runs (Open3D's
  Poisson is known to crash after hundreds of calls in one process); in the last case its
  replacement is started ``WARM_AHEAD`` runs ahead, so that no run waits for its imports;
- every outcome becomes a result dict: ``status`` "ok" or "failed", and for a failure its
  ``failure`` kind and a one-line ``reason``.

Failure kinds: ``timeout``, ``crash`` (killed by a signal), ``memory`` (an allocation failed
under the limit), ``error`` (the method raised, e.g. ``MethodFailed``), ``empty`` (no
triangles), ``degenerate`` (zero area, collapsed or far larger than the points), ``score``
(the mesh was fine but scoring it failed).

The job carries one ``Run`` (``recon.surfaces.methods``: method name, resolved parameters, the
registering module): the worker imports ``Run.module`` on the parent's ``sys.path`` and looks the
method up by name, so methods registered by test modules run too.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import pickle
import resource
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import traceback
import types
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from formats import scratch
from formats.errors import MethodFailed, ParameterError
from recon.surfaces.checks import SurfaceRejected, check_surface
from recon.surfaces.methods import MethodInput, Run, bind, predicted_fit_s, watertight

# Defaults of every isolated run, also the CLI's.
# 600 s: several times the slowest method's default run on 2e5 points (pymeshlab ball pivoting
# with automatic radius took 155 s; docs/decisions.md, "Measurements behind the defaults"), so a
# limit hit means a runaway.
DEFAULT_TIMEOUT_S = 600.0
# 8 GiB of address space on top of the warm worker's own (~1.4 GB of virtual memory after
# importing Open3D and pymeshlab): two runs at once (one per core of the development
# workstation, docs/decisions.md) must leave room for the Dask workers.
DEFAULT_MEMORY_MB = 8192
# Time allowed for checking and scoring a finished mesh, seconds (the method's own limit does
# not include it): metrics.score of a 2e5-face mesh with its default 2e5 samples per side takes
# a few seconds; a limit hit means a runaway.
DEFAULT_SCORE_TIMEOUT_S = 600.0
# Time a worker may take to start (interpreter and imports: 3 to 8 s, docs/decisions.md) plus
# a job's loading, seconds; a limit hit means a broken installation, not a slow method.
START_TIMEOUT_S = 300.0
# Runs a worker does before it is replaced (Open3D's Poisson crashes after hundreds of calls in
# one process, reported upstream; 50 keeps far from that and costs one start-up per 50 runs).
WORKER_RUNS = 50
# Runs before a worker's last at which its replacement is started, so that the replacement has
# imported its modules (3 to 8 s) by the time the worker ends instead of delaying the next run.
WARM_AHEAD = 3
# Modules a worker imports before its first job (the methods' and scoring's heavy imports; the
# minimum cut's compiled kernels, loaded from numba's cache).
WORKER_PRELOAD = ("numpy", "scipy.spatial", "open3d", "pymeshlab", "metrics.score",
                  "recon.surfaces.methods._min_cut")
# Modules a fit worker never uses that a preloaded one imports: Open3D's plotly drawing, which
# imports dash, plotly, IPython and werkzeug (half of Open3D's import time, a third of a
# worker's start-up CPU; docs/decisions.md). A worker gets stand-ins (``leave_out_unused``), and
# so does the ``recon reconstruct`` command's own process (``recon.api``'s ``own_process``).
UNUSED_MODULES = ("open3d.visualization.draw_plotly",)
# How often the parent polls the worker, seconds (start, growing to the maximum): for the stage
# and the limits. A finished run does not wait for the next poll: the worker wakes its parent
# (``_Worker.wake``; polling alone left a finished run waiting half the maximum on average,
# a twentieth of auto's fits of a second or less, docs/decisions.md); a poll reads two small
# files, a few tens of microseconds.
POLL_START_S, POLL_MAX_S = 0.02, 0.05
# Lines of the worker's output kept in a failure's reason.
OUTPUT_TAIL_LINES = 3

FAILURE_KINDS = ("timeout", "crash", "memory", "error", "empty", "degenerate", "score")
# Job directories named so are warm-ups (``warm_truth``), not runs.
_WARM_PREFIX = "warm-"
# About this many of the truth's vertices are scored by a warm-up (the truth's own structure,
# samples and lattice are the work; the probe only has to exist).
_WARM_PROBE = 64
# Linux prctl option asking the kernel to signal a process when its parent thread dies.
_PR_SET_PDEATHSIG = 1
# Stages a job goes through, as the worker writes them to the job's ``stage`` file.
_LOADING, _RUNNING, _CHECKING, _SCORING = "loading", "running", "checking", "scoring"


@dataclass(frozen=True)
class Limits:
    """Time and memory limits of one isolated run.

    Attributes
    ----------
    timeout_s : float, seconds
        Wall-clock limit of the method's own run; must be positive.
    memory_mb : int or None, MiB
        Address space the method may add to its worker's; None: unlimited.
    """

    timeout_s: float = DEFAULT_TIMEOUT_S
    memory_mb: int | None = DEFAULT_MEMORY_MB

    def __post_init__(self):
        _check_limits(self.timeout_s, self.memory_mb, ("timeout_s", "memory_mb"))

    @classmethod
    def from_options(cls, timeout: float | None = None, memory_limit: int | None = None
                     ) -> Limits:
        """The limits of the API's ``timeout`` and ``memory_limit`` arguments.

        None takes the default (``DEFAULT_TIMEOUT_S``, ``DEFAULT_MEMORY_MB``); a memory limit of
        0 means none. Errors name these arguments.
        """
        timeout = DEFAULT_TIMEOUT_S if timeout is None else timeout
        memory = DEFAULT_MEMORY_MB if memory_limit is None else memory_limit
        _check_limits(timeout, memory, ("timeout", "memory_limit"))
        return cls(timeout, memory or None)

    def kwargs(self) -> dict[str, Any]:
        """``{"timeout_s": ..., "memory_mb": ...}``, the keyword arguments of ``run_isolated``."""
        return {"timeout_s": self.timeout_s, "memory_mb": self.memory_mb}


# The largest memory limit [MB] the operating system's limit takes (a signed 64-bit byte count).
MAX_MEMORY_MB = (2**63 - 1) // 2**20


def _check_limits(timeout: float, memory: int | None, names: tuple[str, str]):
    """Refuse a time limit that is not positive or a memory limit that is negative or beyond
    what the operating system takes, naming the argument (``names``: of the time and of the
    memory limit)."""
    if not timeout > 0:
        raise ParameterError(f"{names[0]} must be positive, got {timeout:g}", argument=names[0])
    if memory is not None and not 0 <= memory <= MAX_MEMORY_MB:
        raise ParameterError(f"{names[1]} must be from 0 to {MAX_MEMORY_MB} MB, got {memory}",
                             argument=names[1])


class _Failure(Exception):
    """Raised in the worker: a failure of a known kind with its reason."""

    def __init__(self, kind: str, reason: str):
        super().__init__(reason)
        self.kind = kind


def _status_mb(field: str, pid: int | str = "self") -> float | None:
    """A ``/proc/PID/status`` memory line (``VmHWM``, ``VmRSS``, ``VmSize``) in MB; None when
    unreadable (the process is gone, or not Linux)."""
    from formats.memory import proc_bytes

    n_bytes = proc_bytes(f"/proc/{pid}/status", field)
    return None if n_bytes is None else n_bytes / 2**20


def _maxrss_mb() -> float:
    """This process's peak resident memory [MB] since start or since ``_reset_peak``.

    Linux keeps ``ru_maxrss`` across fork and exec, so a child started by a large parent would
    report the parent's peak; the ``VmHWM`` line of /proc/self/status is this image's own.
    """
    peak = _status_mb("VmHWM")
    if peak is None:  # not Linux
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return peak


def _reset_peak() -> None:
    """Reset this process's ``VmHWM`` to its current resident size (Linux: writing 5 to
    /proc/self/clear_refs), so a reused worker reports each run's own peak."""
    try:
        with open("/proc/self/clear_refs", "w") as refs:
            refs.write("5")
    except OSError:  # not Linux: the peak then covers the worker's earlier runs too
        pass


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


def _serve(parent: int, wake: int | None = None) -> int:
    """Body of a worker (``python -m recon.surfaces.isolation PARENT_PID [WAKE_FD]``): import the
    heavy modules once, then run each job directory named on a line of stdin until stdin
    closes, writing a byte to the file descriptor ``wake`` (a pipe to the parent) after each."""
    import importlib

    _die_with_parent(parent)
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    leave_out_unused()
    for name in WORKER_PRELOAD:
        try:
            importlib.import_module(name)
        except ImportError:  # a method needing it fails at its own import, with the reason
            pass
    truths: dict[str, Any] = {}
    for line in sys.stdin:
        jobdir = Path(line.strip())
        if jobdir.name.startswith(_WARM_PREFIX):
            _warm(jobdir, truths)
        else:
            _run_job(jobdir, truths)
        sys.stdout.flush()
        if wake is not None:
            try:
                os.write(wake, b"\n")
            except OSError:  # the parent closed its end: it no longer waits
                pass
    return 0


def leave_out_unused() -> None:
    """Put a stand-in (``_stand_in``) for each of ``UNUSED_MODULES`` not imported yet into
    ``sys.modules``, so that importing the library that imports it skips it."""
    for name in UNUSED_MODULES:
        sys.modules.setdefault(name, _stand_in(name))


def _stand_in(name: str) -> types.ModuleType:
    """A module ``name`` whose every public attribute is a function raising ``RuntimeError``:
    importing names from it succeeds (whatever names a library's version imports), calling
    them says that recon left the module out."""
    module = types.ModuleType(name, "left out of this process by recon (UNUSED_MODULES)")

    def absent(*args, **kwargs):
        raise RuntimeError(f"{name} is left out of this process by recon")

    def attribute(key: str):
        if key.startswith("__"):   # the import machinery's questions: a plain module
            raise AttributeError(key)
        return absent

    module.__getattr__ = attribute
    return module


def _warm(jobdir: Path, truths: dict[str, Any]) -> None:
    """Make a truth ready for scoring before any run needs it (``warm_truth``): its
    ``metrics.Truth`` with the distance structure, samples and coverage lattice the job's score
    options ask for, built by scoring a few of the truth's own vertices. A failure here is
    left for the runs' own scoring to report."""
    try:
        job = pickle.loads((jobdir / "job.pkl").read_bytes())
        vertices = np.asarray(job["truth"][0], dtype=np.float64)
        probe = vertices[:: max(1, len(vertices) // _WARM_PROBE)]
        options = dict(job["score_options"] or {}) | {"edges": False}
        _score(probe, None, job["truth"], job["truth_key"], options, truths)
    except Exception:  # reported, if it matters, by the run that needs it
        traceback.print_exc()
    finally:
        shutil.rmtree(jobdir, ignore_errors=True)


def _limit_memory(megabytes: int | None) -> None:
    """Limit this process's address space to its current size plus ``megabytes`` (None: lift
    the limit again)."""
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    soft = hard
    if megabytes:
        size = _status_mb("VmSize") or 0.0
        soft = int((size + megabytes) * 1024 * 1024)
        if hard != resource.RLIM_INFINITY:
            soft = min(soft, hard)
    resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def _run_job(jobdir: Path, truths: dict[str, Any]) -> None:
    """Run the job in ``jobdir``: the method, the checks, the score; write result.pkl."""
    import importlib

    stage = jobdir / "stage"
    result: dict[str, Any] = {}
    memory_mb = None
    loaded = time.perf_counter()
    try:
        stage.write_text(_LOADING)
        job = pickle.loads((jobdir / "job.pkl").read_bytes())
        memory_mb = job["memory_mb"]
        for entry in reversed(job["sys_path"]):
            if entry not in sys.path:
                sys.path.insert(0, entry)
        run: Run = job["run"]
        method = run.method_spec()
        for name in method.preload:
            importlib.import_module(name)
        cloud: MethodInput = job["cloud"]
        _reset_peak()
        result["baseline_memory_mb"] = _maxrss_mb()
        _limit_memory(memory_mb)
        stage.write_text(_RUNNING)
        start = time.perf_counter()
        result["load_time_s"] = start - loaded
        try:
            vertices, faces = method.run(cloud, **run.params)
        except MemoryError:
            raise _Failure("memory", f"{run.method}: out of memory (limit "
                                     f"{memory_mb} MB)") from None
        except MethodFailed as exc:
            raise _Failure("error", str(exc)) from None
        except Exception as exc:  # a library error is a recorded failure, with its type
            last = str(exc).strip().splitlines()[-1] if str(exc).strip() else ""
            raise _Failure("error", f"{run.method}: {type(exc).__name__}: {last}") from None
        finally:
            _limit_memory(None)  # the limit is the method's: checking and scoring are ours
        finished = time.perf_counter()
        result["wall_time_s"] = finished - start
        result["peak_memory_mb"] = _maxrss_mb()
        stage.write_text(_CHECKING)
        try:
            vertices, faces = check_surface(vertices, faces, cloud.points, method=run.method)
        except SurfaceRejected as exc:
            raise _Failure(exc.kind, str(exc)) from None
        except MethodFailed as exc:
            raise _Failure("error", str(exc)) from None
        result.update(vertices=vertices, faces=faces, n_vertices=len(vertices),
                      n_faces=len(faces), watertight=watertight(faces))
        if job.get("truth") is not None:
            stage.write_text(_SCORING)
            try:
                result["scores"] = _score(vertices, faces, job["truth"], job["truth_key"],
                                          job["score_options"], truths)
            except Exception as exc:
                raise _Failure("score", f"scoring failed: {type(exc).__name__}: {exc}") from None
        result["score_time_s"] = time.perf_counter() - finished
        result.update(status="ok", failure=None, reason="")
    except _Failure as failure:
        result.update(status="failed", failure=failure.kind, reason=str(failure))
    except MemoryError:
        _limit_memory(None)
        result.update(status="failed", failure="memory",
                      reason=f"out of memory while {stage.read_text()} (limit {memory_mb} MB)")
    except Exception as exc:
        traceback.print_exc()
        result.update(status="failed", failure="error",
                      reason=f"{type(exc).__name__} while {stage.read_text()}: {exc}")
    tmp = jobdir / "result.pkl.partial"
    tmp.write_bytes(pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL))
    tmp.rename(jobdir / "result.pkl")


def _score(vertices, faces, truth, key: str, options, truths: dict[str, Any]) -> dict:
    """Score a mesh (or, ``faces`` None, a cloud) against the truth with ``metrics.score``; a
    flat dict of numbers.

    The worker keeps the last truth it saw (``metrics.Truth``, by ``key``): a comparison's runs
    share its distance structure and samples.
    """
    from metrics.score import Truth, score

    if key not in truths:
        truths.clear()
        truths[key] = Truth(truth)
    test = vertices if faces is None else (vertices, faces)
    report = score(test, truths[key], **(options or {}))
    return {k: v for k, v in report.to_dict().items() if isinstance(v, (int, float, bool))
            or v is None}


def _truth_key(truth) -> str:
    """Identity of a truth mesh's arrays (the worker's cache key)."""
    digest = hashlib.sha1()
    for array in truth:
        array = np.ascontiguousarray(array)
        digest.update(str((array.dtype, array.shape)).encode())
        digest.update(array)
    return digest.hexdigest()


def _tail(path: Path, offset: int = 0) -> str:
    """The last lines of a worker's output after byte ``offset`` (this job's), joined."""
    try:
        with open(path, "rb") as log:
            log.seek(offset)
            text = log.read().decode(errors="replace")
    except OSError:
        return ""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return " | ".join(lines[-OUTPUT_TAIL_LINES:])


# --------------------------------------------------------------------------- the worker pool

class _Worker:
    """One warm worker process: its pipe, its output log, how many runs it did, and the read end
    of the pipe on which it wakes its parent after each job (``sleep``)."""

    def __init__(self, threads: int | None):
        env = dict(os.environ)
        if threads:
            for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
                env[name] = str(int(threads))
        self.dir = scratch.make("recon-worker-")
        self.log = self.dir / "output.log"
        self.threads = threads
        self.runs = 0
        self.wake, wake = os.pipe()
        os.set_blocking(self.wake, False)
        try:
            with open(self.log, "wb") as out:
                # Started from the pool's own long-lived thread: the worker's parent-death
                # signal follows the thread that started it (see _die_with_parent).
                self.proc = _LAUNCHER.submit(
                    subprocess.Popen,
                    [sys.executable, "-m", "recon.surfaces.isolation", str(os.getpid()),
                     str(wake)], stdin=subprocess.PIPE, stdout=out, stderr=subprocess.STDOUT,
                    env=env, start_new_session=True, pass_fds=(wake,)).result()
        finally:
            os.close(wake)   # the worker holds it: a dead worker reads as end of file

    def submit(self, jobdir: Path) -> int:
        """Hand the worker a job; returns the byte offset of its output where the job begins."""
        offset = self.log.stat().st_size if self.log.exists() else 0
        self.send(jobdir)
        self.runs += 1
        return offset

    def send(self, jobdir: Path) -> None:
        """Name a job directory on the worker's stdin."""
        self.proc.stdin.write(f"{jobdir}\n".encode())
        self.proc.stdin.flush()

    def alive(self) -> bool:
        return self.proc.poll() is None

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds``, or less when the worker finishes a job (or dies) meanwhile."""
        if self.wake < 0:   # stopped
            time.sleep(seconds)
        elif select.select([self.wake], [], [], seconds)[0]:
            try:
                if not os.read(self.wake, 4096):   # end of file: the worker is gone
                    time.sleep(seconds)
            except BlockingIOError:   # another thread read it
                pass

    def stop(self) -> None:
        """End the worker (its whole process group) and remove its files."""
        _kill_group(self.proc.pid)
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            pass
        for stream in (self.proc.stdin,):
            try:
                stream.close()
            except OSError:
                pass
        if self.wake >= 0:   # once: the number may be another file's after it is closed
            os.close(self.wake)
            self.wake = -1
        scratch.remove(self.dir)


_LAUNCHER = ThreadPoolExecutor(max_workers=1, thread_name_prefix="recon-isolation")
_IDLE: dict[int | None, list[_Worker]] = {}
_BUSY: set[_Worker] = set()
_POOL_LOCK = threading.Lock()
# Set by ``kill_running`` (an interrupted sweep): runs asked for until ``resume_runs`` start
# nothing, so a sweep's threads finish their cases at once instead of starting the next fit.
_STOPPED = threading.Event()


def _take(threads: int | None) -> _Worker:
    """An idle live worker for ``threads`` (OMP threads), or a new one."""
    with _POOL_LOCK:
        idle = _IDLE.setdefault(threads, [])
        while idle:
            worker = idle.pop()
            if worker.alive():
                _BUSY.add(worker)
                return worker
            worker.stop()
    worker = _Worker(threads)
    with _POOL_LOCK:
        _BUSY.add(worker)
    return worker


def start_workers(count: int, threads: int | None = None) -> None:
    """Start ``count`` workers for ``threads`` now, without waiting for their imports, so that
    they warm up while the caller prepares its runs (idle ones already there count)."""
    with _POOL_LOCK:
        missing = count - sum(w.alive() for w in _IDLE.get(threads, []))
    started = [_Worker(threads) for _ in range(max(0, missing))]
    with _POOL_LOCK:
        _IDLE.setdefault(threads, []).extend(started)


def warm_truth(truth: tuple[np.ndarray, np.ndarray], score_options: dict | None = None,
               threads: int | None = None) -> None:
    """Have every idle worker for ``threads`` make ``truth`` ready for scoring now.

    Each builds the truth's ``metrics.Truth`` (its distance structure, and the samples and
    coverage lattice of ``score_options``) while the caller prepares its runs, without waiting
    for it; a run later handed to the worker with this truth and these options finds them
    built (a run waits behind the warm-up, and its start-up limit covers both).
    """
    job = pickle.dumps({"truth": truth, "truth_key": _truth_key(truth),
                        "score_options": score_options}, protocol=pickle.HIGHEST_PROTOCOL)
    with _POOL_LOCK:
        workers = [w for w in _IDLE.get(threads, []) if w.alive()]
    for worker in workers:
        jobdir = Path(tempfile.mkdtemp(prefix=_WARM_PREFIX, dir=worker.dir))
        (jobdir / "job.pkl").write_bytes(job)
        try:
            worker.send(jobdir)
        except OSError:  # it died: the next run replaces it
            pass


def _give_back(worker: _Worker, healthy: bool) -> None:
    """Return a worker to the pool, or end it (after a failure that may have left it unwell,
    or after ``WORKER_RUNS`` runs); ``WARM_AHEAD`` runs before its end, start its replacement
    (idle behind the warm workers, ``_take`` takes the last)."""
    with _POOL_LOCK:
        _BUSY.discard(worker)
        kept = healthy and worker.alive() and worker.runs < WORKER_RUNS
        if kept:
            _IDLE.setdefault(worker.threads, []).append(worker)
    if not kept:
        worker.stop()
    elif worker.runs == WORKER_RUNS - WARM_AHEAD:
        spare = _Worker(worker.threads)
        with _POOL_LOCK:
            _IDLE.setdefault(worker.threads, []).insert(0, spare)


@atexit.register
def shutdown_workers() -> None:
    """End every worker of this process's pool (at exit; also for tests)."""
    with _POOL_LOCK:
        workers = [w for idle in _IDLE.values() for w in idle] + list(_BUSY)
        _IDLE.clear()
        _BUSY.clear()
    for worker in workers:
        worker.stop()


# Failures after which a worker is replaced rather than reused.
_UNWELL = {"timeout", "crash", "memory", "score"}


def run_isolated(run: Run | str, cloud: MethodInput, params: dict | None = None, *,
                 truth: tuple[np.ndarray, np.ndarray] | None = None,
                 score_options: dict | None = None, timeout_s: float = DEFAULT_TIMEOUT_S,
                 memory_mb: int | None = DEFAULT_MEMORY_MB, threads: int | None = None,
                 score_timeout_s: float = DEFAULT_SCORE_TIMEOUT_S,
                 on_wait: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run one method on one cloud in a warm, limited worker process and report what happened.

    Parameters
    ----------
    run : Run or str
        The method and its resolved parameters (``recon.surfaces.methods.bind``), or a
        registered name (hidden test methods included), then resolved here once with ``params``.
    cloud : MethodInput
    params : dict, optional
        With a name only: overrides of the method's defaults (checked before any process starts).
    truth : (vertices, faces), optional
        Truth mesh, metres, same frame: when given, the mesh is scored with ``metrics.score``
        (in the worker, which keeps the truth's ``metrics.Truth`` for its next runs).
    score_options : dict, optional
        Keyword arguments of ``metrics.score``.
    timeout_s : float
        Wall-clock limit of the method's own run, seconds (a worker's start-up and the job's
        loading are limited separately by ``START_TIMEOUT_S``). A run whose predicted time
        (``recon.surfaces.methods.predicted_fit_s``) exceeds it is declined at once: a
        ``timeout`` failure whose reason starts with "declined", no process started.
    memory_mb : int or None
        Address space the method may add to its worker's, MiB (None: unlimited).
    threads : int, optional
        ``OMP_NUM_THREADS`` and friends of the worker (sweeps set 1 so parallel runs do not
        compete for the cores); workers are pooled per value.
    score_timeout_s : float
        Further limit for checking and scoring the mesh, counted from the method's end.
    on_wait : callable, optional
        Called with the job's current stage (e.g. "running") each time the parent polls it,
        at least every ``POLL_MAX_S``: drives a progress display.

    Returns
    -------
    dict
        ``method``, ``params`` (resolved), ``status`` ("ok" or "failed"), ``failure`` (kind or
        None), ``reason``, ``wall_time_s`` (the method alone; for a timeout, until it was
        stopped), ``process_time_s`` (the whole job in its worker, from hand-over to result,
        a new worker's start-up included), ``load_time_s`` (the worker reading the job and
        importing the method, before it runs), ``score_time_s`` (checking and scoring the mesh,
        after it ran; when ok), ``peak_memory_mb`` (the worker's peak resident set
        during this run: after the method, or at its death), ``baseline_memory_mb`` (resident
        just before the method), and when ok ``vertices``, ``faces``, ``n_vertices``,
        ``n_faces``, ``watertight`` and (with a truth) ``scores``.
    """
    run = bind(run, params)
    limits = Limits(timeout_s, memory_mb)
    base = {"method": run.method, "params": run.params}
    if _STOPPED.is_set():
        raise InterruptedError("the run was not started: the sweep is stopping")
    predicted = predicted_fit_s(run, len(cloud.points))
    if predicted is not None and predicted > timeout_s:
        return base | {"status": "failed", "failure": "timeout", "process_time_s": 0.0,
                       "predicted_s": predicted,
                       "reason": f"declined: predicted {predicted:.2g} s on "
                                 f"{len(cloud.points)} points, over the {timeout_s:g} s limit "
                                 "(raise the time limit to run it)"}
    job = {"run": run, "cloud": cloud, "truth": truth, "score_options": score_options,
           "truth_key": None if truth is None else _truth_key(truth),
           "memory_mb": limits.memory_mb, "sys_path": [p for p in sys.path if p]}
    with scratch.directory("recon-run-") as jobdir:
        (jobdir / "job.pkl").write_bytes(pickle.dumps(job, protocol=pickle.HIGHEST_PROTOCOL))
        start = time.perf_counter()
        worker = _take(threads)
        healthy = False
        try:
            try:
                offset = worker.submit(jobdir)
            except OSError:  # it died while idle: one fresh worker
                _give_back(worker, False)
                worker = _take(threads)
                offset = worker.submit(jobdir)
            outcome = _wait(worker, jobdir, timeout_s, score_timeout_s, on_wait)
            result = _outcome(outcome, worker, jobdir, offset, limits, timeout_s,
                              score_timeout_s)
            healthy = result.get("failure") not in _UNWELL
        finally:
            _give_back(worker, healthy)
        return base | result | {"process_time_s": time.perf_counter() - start}


def _outcome(outcome: dict, worker: _Worker, jobdir: Path, offset: int, limits: Limits,
             timeout_s: float, score_timeout_s: float) -> dict[str, Any]:
    """The result dict of a finished, dead or stopped job (``_wait``'s ``outcome``)."""
    stage = outcome["stage"]
    peak = outcome["peak_mb"] or 0.0
    if outcome["timed_out"]:
        limit = score_timeout_s if stage in (_CHECKING, _SCORING) else (
            timeout_s if stage == _RUNNING else START_TIMEOUT_S)
        out = {"status": "failed", "failure": "timeout",
               "reason": f"timed out after {limit:g} s while {stage}", "peak_memory_mb": peak}
        if outcome["running_s"] is not None:
            out["wall_time_s"] = outcome["running_s"]
        return out
    result_file = jobdir / "result.pkl"
    if result_file.exists():
        return pickle.loads(result_file.read_bytes())
    status = outcome["status"]
    memory_mb = limits.memory_mb
    if status is not None and os.WIFSIGNALED(status):
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
        code = "unknown" if status is None else os.WEXITSTATUS(status)
        kind, reason = "crash", f"exited with status {code} while {stage}"
    tail = _tail(worker.log, offset)
    if tail:
        reason += f": {tail}"
    return {"status": "failed", "failure": kind, "reason": reason, "peak_memory_mb": peak}


def _wait(worker: _Worker, jobdir: Path, timeout_s: float, score_timeout_s: float,
          on_wait: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Wait for the job in ``jobdir``; kill the worker's process group at the limit.

    The limit is ``START_TIMEOUT_S`` until the worker reports (in the ``stage`` file) that the
    method runs, then ``timeout_s`` from that moment, then ``score_timeout_s`` from the moment
    it reports checking. The worker's resident peak is read from /proc at every poll, so a
    worker killed by the system still has its run's peak. ``on_wait`` gets the stage at every
    poll.

    Returns
    -------
    dict
        ``stage`` (the last seen), ``timed_out``, ``status`` (the worker's wait status when it
        died, else None), ``peak_mb`` (last seen), ``running_s`` (time in the method so far, or
        None when it never started).
    """
    stage_file, result_file = jobdir / "stage", jobdir / "result.pkl"
    pid = worker.proc.pid
    deadline = time.monotonic() + START_TIMEOUT_S
    stage, running_since, peak = "starting", None, None
    delay = POLL_START_S
    try:
        while True:
            if result_file.exists():
                return {"stage": stage, "timed_out": False, "status": None, "peak_mb": peak,
                        "running_s": None}
            current = stage_file.read_text() if stage_file.exists() else "starting"
            now = time.monotonic()
            if current != stage:
                if current == _RUNNING:
                    running_since, deadline = now, now + timeout_s
                elif current in (_CHECKING, _SCORING) and stage not in (_CHECKING, _SCORING):
                    deadline = now + score_timeout_s
                stage = current
            if stage == _RUNNING:
                peak = _status_mb("VmHWM", pid) or peak
            if on_wait is not None:
                on_wait(stage)
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                worker.proc.returncode = os.waitstatus_to_exitcode(status)
                if result_file.exists():  # finished, then died (e.g. at exit)
                    continue
                return {"stage": stage, "timed_out": False, "status": status,
                        "peak_mb": peak, "running_s": None}
            if _STOPPED.is_set():   # a worker that was starting when ``kill_running`` ran
                raise InterruptedError("the run was stopped: the sweep is stopping")
            if now >= deadline:
                _kill_group(pid)
                worker.proc.wait()
                return {"stage": stage, "timed_out": True, "status": None, "peak_mb": peak,
                        "running_s": None if running_since is None else now - running_since}
            worker.sleep(delay)
            delay = min(delay * 1.5, POLL_MAX_S)
    except BaseException:  # interrupted while waiting: never leave the worker behind
        _kill_group(pid)
        raise


def kill_running() -> int:
    """SIGKILL every worker this process is waiting on (from any thread); returns how many.

    Their waiting threads then report them as crashed, and ``run_isolated`` starts nothing
    more (it raises ``InterruptedError``) until ``resume_runs``; a sweep calls this when
    interrupted.
    """
    _STOPPED.set()
    with _POOL_LOCK:
        pids = [worker.proc.pid for worker in _BUSY]
    for pid in pids:
        _kill_group(pid)
    return len(pids)


def resume_runs() -> None:
    """Let ``run_isolated`` start runs again after ``kill_running``."""
    _STOPPED.clear()


def _kill_group(pid: int) -> None:
    """SIGKILL the process group ``pid`` leads (the worker and anything it started)."""
    try:
        os.killpg(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


if __name__ == "__main__":
    sys.exit(_serve(int(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else None))
