"""Run many independent cases on Dask, streaming each result to disk as it finishes.

A sweep is one function applied to many cases (``{key: keyword arguments}``) plus shared inputs
(a cloud, a truth mesh) sent to the workers once. Results stream to ``results.jsonl``, one JSON
object per line, appended and flushed as each case finishes, so an interrupted sweep keeps what it
finished; ``resume=True`` skips the keys already there. A ``sweep.json`` beside it records the
sweep's fingerprint (input and settings); resuming with a different one is refused, so results
of different inputs never mix. The progress bar counts finished cases plus the fractions the
running ones report (``recon.experiments.progress``) and redraws every second.

Schedulers
----------
``None``
    A ``dask.distributed.LocalCluster`` of single-threaded worker processes, started for the
    sweep and closed after it.
``"tcp://host:port"`` (any address)
    An existing Dask cluster (``dask scheduler`` + ``dask worker`` on several machines). The
    workers must be able to import recon; inputs travel through Dask, outputs come back to this
    process, so no shared filesystem is needed.
``"threads"``
    A local thread pool, no Dask: for cases that spend their time waiting on a child process
    (every ``recon.surfaces.isolation`` run does), it is as parallel as processes and starts
    instantly.
``"serial"``
    One case after another in this process (debugging).

Whatever the scheduler, ``QUEUED_PER_WORKER`` cases per worker (thread of the local pool, or
worker thread of the Dask cluster) are submitted at a time and the next ones as those finish:
starting and interrupting a sweep take the same time whatever its size, and a Ctrl-C cancels
only the cases in flight.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import logging
import math
import os
import re
import socket
import struct
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from formats import scratch
from formats.atomic import write_text_atomically
from formats.errors import ParameterError
from formats.paths import check_destination, output_directory
from recon.experiments import progress

RESULTS_NAME = "results.jsonl"
FINGERPRINT_NAME = "sweep.json"
# What to do when the output directory cannot be resumed, in words a caller of the API and a
# user of the command line both act on.
START_AFRESH = "use a new output directory, or run again without resuming"
# Seconds to wait for an existing Dask scheduler before giving up.
CONNECT_TIMEOUT_S = 10.0
# Seconds to open a TCP connection to a scheduler address, and then to receive its greeting: a
# Dask server sends its handshake as soon as it accepts a connection (distributed/comm/core.py,
# ``Listener.on_connection``), in well under a second on a network that can run a sweep.
PROBE_CONNECT_S = 5.0
PROBE_GREETING_S = 5.0
# Largest handshake accepted: Dask's is about 100 bytes (a small msgpack mapping).
PROBE_MAX_BYTES = 1 << 16
# A Dask scheduler address: ``host:port`` or ``protocol://host:port`` with one of Dask's comms.
SCHEDULER_ADDRESS = re.compile(r"^((tcp|tls|ws|wss|ucx)://)?[A-Za-z0-9_.\-\[\]:]+:\d{1,5}$")
# Cases submitted ahead per thread of a local pool (``_execute_threads``) or per worker thread
# of a Dask cluster (``_execute_dask``): one running, one ready to start as it ends.
QUEUED_PER_WORKER = 2
# Longest wait of a local pool for a case to finish before looking for a signal, in seconds.
WAIT_S = 0.5
# Step of a Dask sweep's wait for a case to finish, between looks for a signal, in seconds: the
# step of ``distributed.as_completed``'s own wait (a case takes seconds; a result waits at most
# this long to be written).
DASK_POLL_S = 0.1
# Where a local cluster listens: this machine only. Its scheduler and dashboard (HTTP, no
# authentication) would otherwise be open on every interface on random ports.
LOCAL_HOST = "127.0.0.1"


def check_scheduler(scheduler, error: type[Exception] = ParameterError):
    """A ``scheduler`` value: None, ``threads``, ``serial`` or a Dask address; returned as it
    is, or ``error`` (one line, about the argument ``scheduler``) when it is none of them."""
    if scheduler is None or scheduler in ("threads", "serial"):
        return scheduler
    if not isinstance(scheduler, str) or not SCHEDULER_ADDRESS.match(scheduler):
        shown = repr(scheduler)[:80]
        raise error(f"scheduler must be a Dask scheduler address (tcp://host:port), "
                    f"'threads' or 'serial', got {shown}", argument="scheduler")
    return scheduler


def _host_port(address: str) -> tuple[str, int]:
    rest = address.split("://", 1)[-1]
    host, _, port = rest.rpartition(":")
    return host.strip("[]"), int(port)


def probe_scheduler(scheduler: str, error: type[Exception] = ParameterError) -> None:
    """Refuse, in one line and within seconds, a ``tcp://`` address where no Dask scheduler
    answers: a closed port, a server of another protocol (HTTP waits for a request and sends
    nothing; Dask would wait for its greeting forever), or one that sends something else (Dask
    would read its first 8 bytes as a frame length and try to allocate exabytes).

    Reads the greeting a Dask server sends on accepting a connection: an 8-byte little-endian
    length, then that many bytes of msgpack with the keys of Dask's handshake. Other comms
    (``tls://``, ``ws://``, ``ucx://``) are left to Dask.
    """
    if "://" in scheduler and not scheduler.startswith("tcp://"):
        return
    host, port = _host_port(scheduler)
    where = f"scheduler {scheduler}"
    try:
        conn = socket.create_connection((host, port), timeout=PROBE_CONNECT_S)
    except TimeoutError:
        raise error(f"{where}: cannot connect (no answer in {PROBE_CONNECT_S:g} s)",
                    argument="scheduler") from None
    except OSError as exc:
        raise error(f"{where}: cannot connect ({exc.strerror or exc})",
                    argument="scheduler") from None
    with conn:
        conn.settimeout(PROBE_GREETING_S)
        try:
            head = _receive(conn, 8)
            size = struct.unpack("<Q", head)[0] if len(head) == 8 else 0
            body = _receive(conn, size) if 0 < size <= PROBE_MAX_BYTES else b""
        except TimeoutError:
            raise error(f"{where}: not a Dask scheduler (it sent no Dask greeting in "
                        f"{PROBE_GREETING_S:g} s)", argument="scheduler") from None
        except OSError as exc:
            raise error(f"{where}: cannot connect ({exc.strerror or exc})",
                        argument="scheduler") from None
    if len(body) != size or b"pickle-protocol" not in body:
        raise error(f"{where}: not a Dask scheduler (it answered with something other than "
                    "Dask's protocol)", argument="scheduler")


def _receive(conn: socket.socket, n: int) -> bytes:
    """Up to ``n`` bytes from ``conn`` (fewer when it closes)."""
    data = b""
    while len(data) < n:
        chunk = conn.recv(min(n - len(data), 65536))
        if not chunk:
            break
        data += chunk
    return data


def connect(scheduler: str, error: type[Exception] = ParameterError):
    """A ``distributed.Client`` of the existing scheduler at ``scheduler``.

    Raises
    ------
    error
        One line, within seconds, when no Dask scheduler answers there (``probe_scheduler``)
        or Dask cannot connect in ``CONNECT_TIMEOUT_S``.
    """
    from distributed import Client

    probe_scheduler(scheduler, error)
    try:
        with quiet_dask():
            return Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s")
    except Exception as exc:  # Dask raises many types on a peer that is not a scheduler
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise error(f"scheduler {scheduler}: cannot connect ({text})",
                    argument="scheduler") from None


@contextlib.contextmanager
def quiet_dask():
    """Within the block, every log message is dropped: while a cluster connects or shuts down,
    Dask logs what is noise to the user (a worker closing its comm as the cluster stops logs a
    CommClosedError with its traceback); what matters reaches the caller as an exception or a
    failed case's record."""
    previous = logging.root.manager.disable
    logging.disable(logging.CRITICAL)
    try:
        yield
    finally:
        logging.disable(previous)


# Loggers of a local cluster's worker processes kept to critical messages (``local_cluster``).
_WORKER_LOGGERS = ("distributed", "asyncio", "tornado")


def local_cluster(n_workers: int):
    """A ``LocalCluster`` of single-threaded worker processes on the loopback interface, its
    dashboard on a free loopback port (the default 8787 may be taken by another cluster).

    Its worker processes log only what is critical: as the cluster stops, a worker whose comm
    the scheduler closed logs a CommClosedError with its traceback (seen once in six quick
    studies), noise on a run that succeeded. Their logging is set up from Dask's configuration
    when they start, which they read from the environment (``DASK_LOGGING__NAME``); a value the
    user set is kept.
    """
    import logging

    from distributed import LocalCluster

    for name in _WORKER_LOGGERS:
        os.environ.setdefault(f"DASK_LOGGING__{name.upper()}", "critical")

    return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                        host=LOCAL_HOST, dashboard_address=f"{LOCAL_HOST}:0",
                        silence_logs=logging.CRITICAL)


def default_workers() -> int:
    """Worker count of a local sweep: the usable cores."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def to_jsonable(value: Any) -> Any:
    """``value`` with numpy scalars and arrays, tuples and non-finite floats made JSON-safe."""
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def read_results(path) -> dict[str, dict]:
    """The finished results of a ``results.jsonl``, by key (a torn last line is ignored).

    Raises
    ------
    ParameterError
        The file cannot be read, or a line other than the last is not UTF-8 text (not a file
        a sweep wrote).
    """
    path = Path(path)
    done: dict[str, dict] = {}
    if not path.exists():
        return done
    try:
        lines = path.read_bytes().splitlines()
    except OSError as exc:
        raise ParameterError(f"resume: {path}: cannot be read ({exc.strerror})",
                             argument="resume") from None
    for number, raw in enumerate(lines, 1):
        try:
            line = raw.decode("utf-8")
        except UnicodeDecodeError:
            if number == len(lines):   # a torn last line may end inside a character
                continue
            raise ParameterError(f"resume: {path}: line {number} is not UTF-8 text (not a "
                                 f"results file of recon; {START_AFRESH})",
                                 argument="resume") from None
        try:
            record = json.loads(line)
        except (json.JSONDecodeError, RecursionError):
            continue
        if isinstance(record, dict) and isinstance(record.get("key"), str):
            done[record["key"]] = record
    return done


def _rewrite(path: Path, records: list[dict]) -> None:
    """Atomically replace ``path`` with ``records`` (drops a torn line before appending)."""
    tmp = path.with_name(path.name + ".partial")
    with open(tmp, "w") as out:
        for record in records:
            out.write(json.dumps(record) + "\n")
    tmp.replace(path)


def _check_fingerprint(out_dir: Path, fingerprint: Mapping | None, resume: bool) -> None:
    file = out_dir / FINGERPRINT_NAME
    current = to_jsonable(dict(fingerprint or {}))
    if resume and file.exists():
        try:
            previous = json.loads(file.read_bytes().decode("utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError):
            previous = None
        if not isinstance(previous, dict):
            raise ParameterError(f"resume: {file} is damaged (not a JSON object); "
                                 f"{START_AFRESH}", argument="resume")
        if previous != current:
            changed = sorted(k for k in set(previous) | set(current)
                             if previous.get(k) != current.get(k))
            raise ParameterError(f"resume: {out_dir} holds a sweep with different "
                                 f"{', '.join(changed)}; {START_AFRESH}", argument="resume")
    write_text_atomically(file, json.dumps(current, indent=2) + "\n", error=ParameterError)


def run_sweep(func: Callable[..., dict], cases: Mapping[str, Mapping[str, Any]], out_dir, *,
              shared: Mapping[str, Any] | None = None, fingerprint: Mapping | None = None,
              scheduler: str | None = None, n_workers: int | None = None, resume: bool = False,
              on_result: Callable[[str, dict], dict] | None = None, desc: str = "runs",
              outputs: Sequence[str] = ()) -> dict[str, dict]:
    """Run ``func(**shared, **case)`` for every case, streaming results to ``out_dir``.

    Parameters
    ----------
    func : callable
        Importable (module-level) function returning a dict. It should not raise: a raised
        exception (or a lost worker) is recorded as ``{"status": "failed", "failure": "task"}``.
    cases : dict of str to dict
        Keyword arguments per case, by unique key (the key is what ``resume`` matches).
    out_dir : str or Path
        Created if needed; receives ``results.jsonl`` and ``sweep.json``.
    shared : dict, optional
        Keyword arguments common to all cases (sent to each Dask worker once).
    fingerprint : dict, optional
        What makes results comparable (input, settings); checked on resume.
    scheduler : str, optional
        See the module docstring.
    n_workers : int, optional
        Local workers or threads (default: ``default_workers()``).
    resume : bool
        Keep the results already in ``results.jsonl`` and skip their keys; otherwise start
        the file afresh.
    on_result : callable, optional
        ``on_result(key, result) -> record`` runs in this process on each result before it is
        written (e.g. to save a mesh and drop its arrays); the record must be JSON-able.
    desc : str
        Progress-bar label.
    outputs : sequence of str
        Names of the files the caller writes into ``out_dir`` after the sweep: checked with
        the sweep's own before any work (one that is a directory is refused then, not after
        the runs).

    Returns
    -------
    dict of str to dict
        Every case's record, in ``cases`` order (resumed ones included).
    """
    from tqdm import tqdm

    check_scheduler(scheduler)
    if n_workers is not None and n_workers < 1:
        raise ParameterError(f"n_workers must be >= 1, got {n_workers}", argument="n_workers")
    out_dir = output_directory(out_dir, ParameterError)
    for name in (RESULTS_NAME, FINGERPRINT_NAME, *outputs):
        check_destination(out_dir / name, ParameterError)
    _check_fingerprint(out_dir, fingerprint, resume)
    path = out_dir / RESULTS_NAME
    done = {k: v for k, v in read_results(path).items() if k in cases} if resume else {}
    _rewrite(path, list(done.values()))
    pending = [key for key in cases if key not in done]
    shared = dict(shared or {})
    with open(path, "a") as stream, scratch.directory("recon-progress-") as channel, \
            tqdm(total=len(cases), initial=len(done), desc=desc, unit="runs", disable=None,
                 leave=False, bar_format=progress.BAR_FORMAT) as bar, \
            progress.Watcher(bar, channel, finished=len(done)) as watcher:

        def record(key: str, result: dict) -> None:
            result = dict(result)
            if on_result is not None:
                result = on_result(key, result)
            result = to_jsonable({"key": key, **result})
            stream.write(json.dumps(result) + "\n")
            stream.flush()
            os.fsync(stream.fileno())
            done[key] = result
            watcher.done(key)

        if pending:
            for key, result in iterate(func, cases, pending, shared=shared, scheduler=scheduler,
                                       n_workers=n_workers, channel=channel):
                record(key, result)
    return {key: done[key] for key in cases if key in done}


def _failed_task(exc: BaseException) -> dict:
    return {"status": "failed", "failure": "task",
            "reason": f"task failed: {type(exc).__name__}: {exc}"}


def _call(func, shared, case, report=(None, "")) -> dict:
    """``func(**shared, **case)``, its ``progress.step`` calls reported to ``report``
    (channel directory or None, case key)."""
    try:
        with progress.reporting(*report):
            return func(**shared, **case)
    except Exception as exc:  # the sweep goes on; the record says what went wrong
        return _failed_task(exc)


def iterate(func: Callable[..., dict], cases: Mapping[str, Mapping[str, Any]],
            keys: list[str] | None = None, *, shared: Mapping[str, Any] | None = None,
            scheduler: str | None = None, n_workers: int | None = None, channel=None):
    """Yield ``(key, func(**shared, **cases[key]))`` as cases finish, nothing written to disk.

    ``keys`` selects the cases (default: all); ``channel`` is the directory the cases report
    their progress into (``recon.experiments.progress``; None: nowhere); the other arguments
    are ``run_sweep``'s.
    """
    check_scheduler(scheduler)
    pending = list(cases) if keys is None else list(keys)
    shared = dict(shared or {})
    workers = n_workers or default_workers()
    if scheduler == "serial":
        for key in pending:
            yield key, _call(func, shared, cases[key], (channel, key))
        return
    if scheduler == "threads":
        yield from _execute_threads(func, cases, pending, shared, workers, channel)
        return
    yield from _execute_dask(func, cases, pending, shared, scheduler, workers, channel)


def _execute_threads(func, cases, pending, shared, workers, channel):
    """``iterate`` on a local thread pool: at most ``QUEUED_PER_WORKER`` cases per thread
    submitted at a time, the next ones as those finish, so that starting, interrupting and
    stopping a sweep take the same time whatever its size; waits of ``WAIT_S`` at most, so a
    signal whose exception a library swallowed is seen (``formats.interrupt.check``)."""
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    from formats import interrupt
    from recon.surfaces.isolation import kill_running, resume_runs

    keys = iter(pending)
    running: dict = {}
    pool = ThreadPoolExecutor(max_workers=workers)
    try:
        while True:
            for key in itertools.islice(keys, workers * QUEUED_PER_WORKER - len(running)):
                running[pool.submit(_call, func, shared, cases[key], (channel, key))] = key
            if not running:
                break
            finished, _ = wait(running, timeout=WAIT_S, return_when=FIRST_COMPLETED)
            interrupt.check()
            for future in finished:
                yield running.pop(future), future.result()
    except BaseException:  # Ctrl-C or a closed generator: stop the children, start no more
        for future in running:
            future.cancel()
        kill_running()
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    else:
        pool.shutdown(wait=True)
    finally:
        resume_runs()


def _execute_dask(func, cases, pending, shared, scheduler, workers, channel):
    """``iterate`` on Dask: a local cluster of ``workers`` processes (``scheduler`` None) or
    the cluster at the address ``scheduler`` (whose own workers run the cases).

    At most ``QUEUED_PER_WORKER`` cases per worker thread of the cluster (as its scheduler
    counts them whenever a case finishes: a cluster may grow or shrink) are submitted at a
    time, the next ones as those finish, so that neither the scheduler nor this process holds
    a future per case, and an interrupt has only those to cancel; waits of ``DASK_POLL_S`` at
    most between looks for a signal (``formats.interrupt.check``), as ``_execute_threads``.
    """
    import time

    from distributed import Client, as_completed

    from formats import interrupt

    cluster = client = None
    running: dict = {}   # future -> key: submitted, not yet yielded
    try:
        if scheduler is None:
            cluster = local_cluster(workers)
            client = Client(cluster)
        else:
            client = connect(scheduler)
        # A one-element list scatters the value whole (a tuple would be split).
        remote = {name: client.scatter([value], broadcast=True)[0]
                  for name, value in shared.items()}
        keys = iter(pending)

        def submit() -> list:
            """Submit the next cases, up to the bound; return their futures."""
            bound = QUEUED_PER_WORKER * max(1, sum(client.nthreads().values()))
            futures = []
            for key in itertools.islice(keys, max(0, bound - len(running))):
                future = client.submit(_call, func, remote, cases[key], (channel, key),
                                       pure=False)
                running[future] = key
                futures.append(future)
            return futures

        finished = as_completed(submit())
        try:
            while not finished.is_empty():
                interrupt.check()
                batch = finished.next_batch(block=False)
                if not batch:
                    time.sleep(DASK_POLL_S)
                    continue
                for future in batch:
                    key = running.pop(future)
                    try:
                        result = future.result()
                    except Exception as exc:  # a worker lost (KilledWorker) or a task error
                        result = _failed_task(exc)
                    finished.update(submit())   # the workers go on while the caller writes
                    yield key, result
        except BaseException:
            client.cancel(list(running))
            raise
    except KeyboardInterrupt:
        # No orderly shutdown on Ctrl-C: of a cluster still starting it fails with a traceback,
        # of a running one it takes seconds. The command line ends the workers at once
        # (cli/main.py); in a script they end with the interpreter.
        cluster = client = None
        raise
    finally:
        with quiet_dask():
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()
