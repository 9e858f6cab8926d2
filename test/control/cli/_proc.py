"""Helpers for tests that run ``pneu`` as a real process and signal it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

PNEU = [sys.executable, "-m", "pneu_control.cli.main"]
DOCUMENTED = {0, 1, 2, 3, 129, 130, 143}


def start(*argv: str) -> subprocess.Popen:
    return subprocess.Popen(
        [*PNEU, *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )


def handlers_installed(pid: int) -> bool:
    """Has the process installed pneu's handlers (SIGTERM caught: Python alone never catches it)?"""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("SigCgt:"):
                return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    except OSError:
        pass
    return False


def wait_for(cond, timeout: float = 120.0, poll: float = 0.002) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(poll)
    return False


def finish(proc: subprocess.Popen, timeout: float = 300.0) -> tuple[int, str, str]:
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err
