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
_PNEU_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # lifecycle.signals.SIGNALS


def start(*argv: str, new_session: bool = False) -> subprocess.Popen:
    """``pneu ARGV`` as a process; ``new_session``: in its own process group (a terminal's
    Ctrl-C reaches the whole group: ``os.killpg``)."""
    return subprocess.Popen(
        [*PNEU, *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
        start_new_session=new_session,
    )


def handlers_installed(pid: int) -> bool:
    """Has the process installed pneu's handlers? All of SIGINT, SIGTERM and SIGHUP caught
    (Python alone catches SIGINT only; pneu installs the three one after the other, so a
    process seen between two of them would still die of the third's default action)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("SigCgt:"):
                caught = int(line.split()[1], 16)
                return all(caught >> (s - 1) & 1 for s in _PNEU_SIGNALS)
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


def children(pid: int) -> list[int]:
    """The live child processes of ``pid`` (from /proc)."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()  # after "(comm)": state, ppid, ...
        if int(fields[1]) == pid and fields[0] != "Z":
            out.append(int(d.name))
    return out


def alive(pid: int) -> bool:
    """Is ``pid`` a live process (not gone, not a zombie)?"""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def ignores(pid: int, sig: int) -> bool:
    """Does the process ignore ``sig`` (SIG_IGN: its SigIgn mask in /proc)?"""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("SigIgn:"):
                return bool(int(line.split()[1], 16) >> (sig - 1) & 1)
    except OSError:
        pass
    return False


def maps(pid: int, name: str) -> bool:
    """Has the process mapped a file whose path contains ``name`` (a loaded shared library)?"""
    try:
        return name in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


def cpu_s(pid: int) -> float:
    """CPU time (user + system) the process has used so far, s (0 when it is gone)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return 0.0
    fields = stat.rsplit(")", 1)[1].split()  # state is field 3; utime, stime are 14, 15
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
