"""The graph's real-time settings as launched: what the nodes set themselves, and the one line
an account without the privilege gets (pneu_msgs_py.lifecycle.realtime, DESIGN §10).

Runs on a machine with ROS 2 Jazzy and this workspace built and sourced; skipped elsewhere.
Set ``ROS_DOMAIN_ID`` (and ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``).
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import threading
from pathlib import Path

import pytest
from pneu_msgs_py.lifecycle.realtime import privilege

pytest.importorskip("rclpy")  # rclpy-dependent: the rest (ros2, the workspace) in conftest
pytestmark = pytest.mark.ros

EVENT_S = 180.0  # the longest a launch may take to start and end on a busy machine
LAUNCH = ["ros2", "launch", "--noninteractive", "pneu_sim", "sim.launch.py", "mode:=realtime"]
NODES = ("sim_node", "linear_controller", "rotary_controller", "controller_manager")


def _unprivileged() -> list[str]:
    """A prefix that runs a command as an account without the privilege: no rtprio, 64 KiB of
    memlock (and, for root, without CAP_SYS_NICE / CAP_IPC_LOCK)."""
    prefix = ["prlimit", "--rtprio=0:0", "--memlock=65536:65536"]
    if os.geteuid() == 0:
        caps = "-sys_nice,-ipc_lock"
        prefix = ["setpriv", "--inh-caps", caps, "--bounding-set", caps, *prefix]
    return prefix


@pytest.mark.parametrize("deployment", ["hosted", "nodes"])
def test_an_unprivileged_launch_says_in_one_line_what_it_could_not_set_and_runs(
    deployment, tmp_path
):
    if shutil.which("prlimit") is None or (os.geteuid() == 0 and not shutil.which("setpriv")):
        pytest.skip("needs prlimit (and setpriv as root) to drop the privilege")
    out = tmp_path / "run"
    res = subprocess.run(
        [*_unprivileged(), *LAUNCH, f"deployment:={deployment}", "duration:=3", f"out:={out}"],
        capture_output=True, text=True, timeout=EVENT_S,
    )  # fmt: skip
    text = res.stdout + res.stderr
    assert res.returncode == 0, text[-4000:]
    said = [line for line in text.splitlines() if "realtime:" in line and "without" in line]
    assert len(said) == 1, said  # the launch says it once; no node repeats it
    assert "the graph runs without SCHED_FIFO 50" in said[0] and "locked memory" in said[0]
    assert "rtprio 98" in said[0]  # how to grant it
    # and the graph ran at normal priority to its end: the loop said so in its report
    report = re.search(r"finished after (\d+) samples; .*'realtime': '([^']*)'", text)
    assert report and int(report[1]) == 3000, text[-4000:]
    assert "SCHED_FIFO" not in report[2], report[2]
    assert (out / "bag" / "metadata.yaml").is_file()


def _policies(pid: int) -> list[tuple[int, int]]:
    """(policy, priority) of every thread of process ``pid``."""
    out = []
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            out.append(
                (os.sched_getscheduler(int(tid)), os.sched_getparam(int(tid)).sched_priority)
            )
        except OSError:  # a thread that just ended
            pass
    return out


def _children(root: int) -> dict[str, int]:
    """The graph's node processes under ``root``: executable name -> pid."""
    found = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            cmd = (d / "cmdline").read_bytes().split(b"\0")
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        names = {os.path.basename(c.decode(errors="replace")) for c in cmd}
        if {"bag", "record"} <= names:
            names.add("recorder")
        for n in (*NODES, "recorder"):
            if n in names and (ppid == root or _ancestor(root, int(d.name))):
                found[n] = int(d.name)
    return found


def _ancestor(root: int, pid: int) -> bool:
    while pid > 1:
        try:
            pid = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError):
            return False
        if pid == root:
            return True
    return False


@pytest.mark.parametrize("deployment", ["hosted", "nodes"])
def test_as_launched_every_thread_of_the_loop_and_controller_processes_runs_fifo(
    deployment, tmp_path
):
    if not privilege().fifo(50):
        pytest.skip("this account may not set SCHED_FIFO 50 (the refusal is tested above)")
    proc = subprocess.Popen(
        [*LAUNCH, f"deployment:={deployment}", "duration:=0", f"out:={tmp_path / 'run'}"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True,
    )  # fmt: skip
    killer = threading.Timer(EVENT_S, lambda: os.killpg(proc.pid, signal.SIGKILL))
    killer.start()
    lines: list[str] = []
    try:
        want = 1 if deployment == "hosted" else 3  # the loop's process (+ two controllers)
        for line in proc.stdout:  # the nodes say what they set, once each, before sample 0
            lines.append(line)
            if sum("realtime:" in ln and "threads at SCHED_FIFO 49" in ln for ln in lines) == want:
                break
        kids = _children(proc.pid)
        expected = {"controller_manager"} if deployment == "hosted" else set(NODES[:3])
        assert expected <= set(kids), (kids, "".join(lines)[-3000:])
        for name in expected:
            pol = _policies(kids[name])
            assert pol and all(p == os.SCHED_FIFO for p, _ in pol), (name, pol)
            assert {prio for _, prio in pol} <= {49, 50}, (name, pol)
        rec = _policies(kids["recorder"])  # ros2 bag record: below the control, above others
        assert rec and all(p == (os.SCHED_FIFO, 40) for p in rec), rec
        os.kill(proc.pid, signal.SIGINT)
        rest, _ = proc.communicate(timeout=EVENT_S)
    finally:
        killer.cancel()
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    text = "".join(lines) + rest
    assert proc.returncode == 0, text[-4000:]
    assert "memory locked (mlockall)" in text or not privilege().lock
