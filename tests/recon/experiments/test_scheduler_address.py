"""A ``--scheduler`` address where no Dask scheduler answers is one line, within seconds: a
closed port, a plain HTTP server (which waits for a request, so Dask would wait forever), a
server sending garbage (which Dask would read as a frame length of exabytes). The servers run
in the test, on the loopback interface."""

from __future__ import annotations

import contextlib
import http.server
import logging
import os
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from cli.main import main
from formats.errors import ParameterError
from recon.experiments.sweep import probe_scheduler

REPO = Path(__file__).resolve().parents[3]


@contextlib.contextmanager
def _http_server():
    server = http.server.HTTPServer(("127.0.0.1", 0), http.server.BaseHTTPRequestHandler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{server.server_port}"
    finally:
        server.shutdown()
        server.server_close()


@contextlib.contextmanager
def _garbage_server():
    """Sends 4 KB of bytes that are not Dask's to each connection, then closes it."""
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen()
    listener.settimeout(0.2)
    stop = threading.Event()

    def serve():
        while not stop.is_set():
            try:
                conn, _ = listener.accept()
            except TimeoutError:
                continue
            with conn:
                conn.sendall(bytes(range(256)) * 16)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{listener.getsockname()[1]}"
    finally:
        stop.set()
        thread.join()
        listener.close()


@contextlib.contextmanager
def _closed_port():
    probe = socket.socket()
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    yield f"tcp://127.0.0.1:{port}"


SERVERS = {"http": (_http_server, "not a Dask scheduler"),
           "garbage": (_garbage_server, "not a Dask scheduler"),
           "closed": (_closed_port, "cannot connect")}


@pytest.mark.parametrize("kind", sorted(SERVERS))
def test_an_address_without_a_dask_scheduler_is_one_line(kind):
    server, message = SERVERS[kind]
    with server() as address, pytest.raises(ParameterError, match=rf"^scheduler {address}: "
                                                               f"{message}"):
        probe_scheduler(address)


@pytest.mark.parametrize("kind", sorted(SERVERS))
def test_study_with_a_non_dask_scheduler_is_a_usage_error(kind, tmp_path, capsys):
    server, message = SERVERS[kind]
    with server() as address, pytest.raises(SystemExit) as done:
        main(["study", "duration", "-o", str(tmp_path / "out"), "--scheduler", address])
    assert done.value.code == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"recon study: error: argument --scheduler: {address}: ")
    assert message in err[-1] and "Traceback" not in "".join(err)
    assert not (tmp_path / "out").exists()


def test_compare_with_an_http_scheduler_ends_in_one_line_through_a_process(tmp_path):
    """A real ``recon`` process: it exits with one line (the probe's bound, not Dask's own
    wait, which never ends on an HTTP server; the limit here only keeps a failure from
    hanging the suite)."""
    with _http_server() as address:
        done = subprocess.run([sys.executable, "-m", "cli", "compare", "in.ply", "--truth",
                               "t.ply", "-o", str(tmp_path / "out"), "--scheduler", address],
                              capture_output=True, text=True, cwd=tmp_path, timeout=120,
                              env=dict(os.environ, PYTHONPATH=str(REPO)))
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 1, done.stderr
    assert "not a Dask scheduler" in lines[-1] and "Traceback" not in done.stderr


def test_a_dask_scheduler_passes_the_probe():
    from distributed import LocalCluster

    with LocalCluster(n_workers=1, processes=False, protocol="tcp", host="127.0.0.1",
                      dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR) as cluster:
        probe_scheduler(cluster.scheduler_address)   # no error
