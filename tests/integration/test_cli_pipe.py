"""The command line under a reader that left: ``fcmaster check CONFIG | head -1``.

The pipe's read end is closed before fcmaster starts, so every write it makes meets a
closed pipe (EPIPE), whatever the timing: the command must end quietly, with the code of
a command that SIGPIPE ended, and no traceback on stderr.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys

from fcmaster.cli import DEMO_CONFIG


def test_check_into_a_closed_pipe_exits_quietly() -> None:
    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader (head -1) is gone before the first write
    try:
        done = subprocess.run(
            [sys.executable, "-m", "fcmaster", "check", "--config", str(DEMO_CONFIG)],
            stdout=write_end, stderr=subprocess.PIPE, text=True, timeout=60, check=False,
        )  # fmt: skip
    finally:
        os.close(write_end)
    assert done.stderr == ""  # no BrokenPipeError traceback, not even "Exception ignored"
    assert done.returncode == 128 + signal.SIGPIPE


def test_check_into_an_open_pipe_still_prints_everything() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "fcmaster", "check", "--config", str(DEMO_CONFIG)],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "line1" in done.stdout
    assert "line2" in done.stdout
