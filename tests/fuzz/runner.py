"""Run a fuzz case through a real ``recon`` process, as the fuzzer and its CI form both do.

Each run is bounded: a memory limit (``RLIMIT_AS``: a run that would take the machine's memory
fails inside itself instead of waking the kernel's OOM killer) and a hang limit (the process
group is killed). Where strace is installed, the run is traced (``openat`` and friends, the
successful ones) so that the judge can see every file it opened: an escape is a file opened
under the ``secrets`` directory, through any link. A case with ``user`` runs under that user
(``setpriv``), so that file modes apply as they do not to root.

``servers()`` starts, on the loopback interface, what a ``--scheduler`` address of the
``scheduler`` kind points at: a plain HTTP server, a server that sends garbage, a closed port.
"""

from __future__ import annotations

import contextlib
import http.server
import os
import re
import resource
import shutil
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

from tests.fuzz.fuzzing import Case

REPO = Path(__file__).resolve().parents[2]
# Address space of a case's process (and its children): 6 GiB, far above any case's needs on
# its small inputs, far below the machine's memory.
MEMORY_LIMIT_BYTES = 6 << 30
STRACE = shutil.which("strace")
SETPRIV = shutil.which("setpriv")
# A successful open in strace's output: pid, call, its path argument.
_OPEN = re.compile(r'^(?:\[pid\s+)?(\d+)\]?\s+(open|openat|openat2|creat)\((?:AT_FDCWD, |'
                   r'(\d+)<[^>]*>, )?"((?:[^"\\]|\\.)*)"')


def can_drop_privileges() -> bool:
    """Whether cases with a ``user`` can run (root with setpriv)."""
    return SETPRIV is not None and os.geteuid() == 0


def _limits() -> None:   # in the child, before exec
    # The soft limit only: recon's isolated workers set their own (lower) limits.
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT_BYTES, hard))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def _unescape(text: str) -> str:
    return text.encode("latin-1", "backslashreplace").decode("unicode_escape",
                                                             errors="replace")


def opened_files(trace: Path, cwd: Path) -> list[str]:
    """The paths that the traced run opened successfully (relative ones made absolute)."""
    paths = []
    try:
        lines = trace.read_text(errors="replace").splitlines()
    except OSError:
        return paths
    for line in lines:
        match = _OPEN.match(line)
        if match and not re.search(r"= -1 ", line):
            path = _unescape(match.group(4))
            paths.append(path if os.path.isabs(path) else str(cwd / path))
    return paths


def _open_to(directory: Path, user: str | None) -> None:
    """Let ``user`` reach and write ``directory`` (the fuzzer's files belong to root)."""
    if user is None:
        return
    for parent in [directory, *directory.parents]:
        if parent == Path(parent.anchor):
            break
        with contextlib.suppress(OSError):
            mode = parent.stat().st_mode & 0o7777
            os.chmod(parent, mode | 0o755)
    os.chmod(directory, 0o777)


def run_case(case: Case, directory: Path, *, limit: float, trace: bool = True
             ) -> tuple[int | None, str, list[str]]:
    """Run ``recon CASE.ARGS`` in ``directory``; ``(status, stderr, opened files)``.

    ``status`` is None after the hang ``limit`` (seconds), negative when a signal killed it.
    """
    env = dict(os.environ, PYTHONPATH=str(REPO), HOME=str(directory),
               MPLCONFIGDIR=str(directory / ".matplotlib"))
    command = [sys.executable, "-c", "import sys; from cli.main import main; sys.exit(main())",
               *case.args]
    if case.user is not None:
        if not can_drop_privileges():
            raise RuntimeError("cases run as another user need root and setpriv")
        _open_to(directory, case.user)
        command = [SETPRIV, f"--reuid={case.user}", "--regid=nogroup", "--clear-groups",
                   *command]
    log = directory / ".strace"
    if trace and STRACE:
        command = [STRACE, "-f", "-qq", "--seccomp-bpf", "-e", "trace=open,openat,openat2,creat",
                   "-e", "status=successful", "-s", "4096", "-o", str(log), *command]
    proc = subprocess.Popen(command, cwd=directory, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, start_new_session=True,
                            preexec_fn=_limits)
    try:
        _, err = proc.communicate(timeout=limit)
        status = proc.returncode
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        _, err = proc.communicate()
        status = None
    with contextlib.suppress(ProcessLookupError):   # whatever the case left running
        os.killpg(proc.pid, signal.SIGKILL)
    text = err.decode(errors="replace")
    opened = opened_files(log, directory) if trace and STRACE else []
    log.unlink(missing_ok=True)   # (strace ends as its traced process does: same status)
    return status, text, opened


# --------------------------------------------------------------------------- servers


class _Silent(http.server.BaseHTTPRequestHandler):
    def log_message(self, *args):   # no request lines on the fuzzer's stderr
        pass


@contextlib.contextmanager
def servers():
    """``{"http", "garbage", "closed"}`` -> ``tcp://127.0.0.1:PORT`` for the block."""
    http_server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Silent)
    garbage = socket.socket()
    garbage.bind(("127.0.0.1", 0))
    garbage.listen()
    garbage.settimeout(0.2)
    closed = socket.socket()
    closed.bind(("127.0.0.1", 0))
    closed_port = closed.getsockname()[1]
    closed.close()
    stop = threading.Event()

    def send_garbage():
        noise = bytes(range(256)) * 64
        while not stop.is_set():
            try:
                conn, _ = garbage.accept()
            except OSError:
                continue
            with conn, contextlib.suppress(OSError):
                conn.sendall(noise)

    threads = [threading.Thread(target=http_server.serve_forever, daemon=True),
               threading.Thread(target=send_garbage, daemon=True)]
    for thread in threads:
        thread.start()
    try:
        yield {"http": f"tcp://127.0.0.1:{http_server.server_port}",
               "garbage": f"tcp://127.0.0.1:{garbage.getsockname()[1]}",
               "closed": f"tcp://127.0.0.1:{closed_port}"}
    finally:
        stop.set()
        http_server.shutdown()
        http_server.server_close()
        threads[1].join()
        garbage.close()
