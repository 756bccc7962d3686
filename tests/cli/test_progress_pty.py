"""Progress bars show on a pseudo-terminal that reports a size of 0 x 0 (CI runners, ``script``),
where tqdm on its own draws nothing."""

from __future__ import annotations

import sys

import pytest

from tests.conftest import python_on_zero_size_pty

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
    return python_on_zero_size_pty(BAR, mode)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux pseudo-terminals")
def test_bars_show_on_a_zero_size_pseudo_terminal():
    assert "work" not in run_on_zero_size_pty("plain")  # tqdm alone: silent
    drawn = run_on_zero_size_pty("sized")
    assert "work: 100%" in drawn and "3/3" in drawn
