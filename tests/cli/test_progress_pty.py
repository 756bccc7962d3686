"""Progress bars show on a pseudo-terminal that reports a size of 0 x 0 (CI runners, ``script``),
where tqdm on its own draws nothing."""

from __future__ import annotations

import fcntl
import os
import pty
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
# As ``recon`` does it: cli.main sizes the bars before anything imports tqdm (which reads its
# TQDM_* defaults at import).
BAR = """
import sys, time
import cli.main
assert "tqdm" not in sys.modules
if sys.argv[1] == "sized":
    cli.main.size_progress_bars()
from tqdm import tqdm
for _ in tqdm(range(3), desc="work", disable=None, mininterval=0):
    time.sleep(0.05)
"""


def run_on_zero_size_pty(mode: str) -> str:
    """Run BAR with stderr on a pseudo-terminal of 0 rows and 0 columns; what it drew."""
    main, child = pty.openpty()
    fcntl.ioctl(child, termios.TIOCSWINSZ, struct.pack("HHHH", 0, 0, 0, 0))
    env = {k: v for k, v in os.environ.items()
           if k not in ("LINES", "COLUMNS", "TQDM_NROWS", "TQDM_NCOLS")}
    env["PYTHONPATH"] = str(ROOT)
    proc = subprocess.Popen([sys.executable, "-c", BAR, mode], stderr=child,
                            stdout=subprocess.DEVNULL, env=env)
    os.close(child)
    chunks = []
    while True:
        try:
            data = os.read(main, 4096)
        except OSError:  # the child closed its end
            break
        if not data:
            break
        chunks.append(data)
    os.close(main)
    assert proc.wait(timeout=120) == 0
    return b"".join(chunks).decode(errors="replace")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux pseudo-terminals")
def test_bars_show_on_a_zero_size_pseudo_terminal():
    assert "work" not in run_on_zero_size_pty("plain")  # tqdm alone: silent
    drawn = run_on_zero_size_pty("sized")
    assert "work: 100%" in drawn and "3/3" in drawn
