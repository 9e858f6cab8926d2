"""What a 1 kHz process asks of the OS (pneu_msgs_py.lifecycle.realtime): the loop thread's settings,
the whole process's, and the one line when the account lacks the privilege."""

from __future__ import annotations

import gc
import sys
import threading

import pytest
from pneu_msgs_py.lifecycle.realtime import enable_realtime


def _in_thread(fn):
    """Run ``fn`` in a fresh thread (the settings are per thread) and return its result."""
    out = []
    th = threading.Thread(target=lambda: out.append(fn()))
    th.start()
    th.join()
    return out[0]


def test_gc_freeze_moves_live_objects_out_of_the_collector_and_restore_undoes_it():
    gc.unfreeze()  # a node's main run earlier in this process (run_node) froze the heap too

    def body():
        before = gc.get_freeze_count()
        notes, restore = enable_realtime(0, timerslack_ns=0, freeze_gc=True)
        frozen = gc.get_freeze_count()
        restore()
        return before, notes, frozen, gc.get_freeze_count()

    before, notes, frozen, after = _in_thread(body)
    assert before == 0
    assert frozen > 1000  # every module, function and class alive now
    said = [int(n.split()[1]) for n in notes if n.startswith("gc.freeze: ")]
    assert said and said[0] > 1000, notes
    assert after == 0


def test_switch_interval_is_set_and_restored_and_nothing_else_without_asking():
    old = sys.getswitchinterval()

    def body():
        notes, restore = enable_realtime(
            0, timerslack_ns=0, switch_interval_s=2e-4, freeze_gc=False
        )
        during = sys.getswitchinterval()
        restore()
        return notes, during

    notes, during = _in_thread(body)
    assert abs(during - 2e-4) < 1e-9
    assert sys.getswitchinterval() == old
    assert gc.get_freeze_count() == 0
    assert not any("SCHED_FIFO" in n or "gc.freeze" in n for n in notes), notes


# -- the whole process ----------------------------------------------------------------
_PROBE = r"""
import json, os, threading
from pneu_msgs_py.lifecycle.realtime import realtime_process
ready, stop = threading.Event(), threading.Event()
th = threading.Thread(target=lambda: (ready.set(), stop.wait()), daemon=True)  # exists before
th.start(); ready.wait()
notes, line = realtime_process(20)
late = {}
t2 = threading.Thread(target=lambda: late.update(p=os.sched_getscheduler(0)))  # and one after
t2.start(); t2.join()
def policy(tid):
    try:
        return os.sched_getscheduler(tid)
    except ProcessLookupError:  # t2, joined, may still be listed for a moment
        return None
policies = [p for p in map(policy, map(int, os.listdir("/proc/self/task"))) if p is not None]
locked = [l for l in open("/proc/self/status") if l.startswith("VmLck")][0].split()[1]
stop.set(); th.join()
print(json.dumps({"notes": notes, "line": line, "policies": policies, "late": late["p"],
                  "locked_kb": int(locked), "fifo": os.SCHED_FIFO}))
"""


def _probe(prefix: list[str] | None = None, limits: bool = False) -> dict:
    """Run the probe in a fresh process (SCHED_FIFO must not reach the test's own)."""
    import json
    import resource
    import subprocess

    def drop() -> None:  # an unprivileged account's limits: no rtprio, 64 KiB of memlock
        resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))
        resource.setrlimit(resource.RLIMIT_MEMLOCK, (64 << 10, 64 << 10))

    out = subprocess.run(
        [*(prefix or []), sys.executable, "-c", _PROBE],
        capture_output=True, text=True, timeout=120, preexec_fn=drop if limits else None,
        check=True,
    )  # fmt: skip
    return json.loads(out.stdout)


def test_privilege_reads_the_effective_capabilities_and_the_limits():
    import resource

    from pneu_msgs_py.lifecycle.realtime import Privilege, _effective_caps

    assert _effective_caps("Name:\tx\nCapEff:\t0000000000800000\n") == 1 << 23
    nice_only = Privilege(sys_nice=True, ipc_lock=False, rtprio_limit=0, memlock_limit=8 << 20)
    assert nice_only.fifo(98) and not nice_only.lock
    limited = Privilege(False, False, rtprio_limit=40, memlock_limit=resource.RLIM_INFINITY)
    assert limited.fifo(40) and not limited.fifo(41) and limited.lock


def test_the_missing_line_names_what_is_missing_its_cost_and_the_grant_in_one_line():
    from pneu_msgs_py.lifecycle.realtime import Privilege, missing_line

    none = Privilege(False, False, rtprio_limit=0, memlock_limit=8 << 20)
    line = missing_line(50, none, who="the graph")
    assert "\n" not in line
    assert line.startswith("realtime: the graph runs without SCHED_FIFO 50 (no CAP_SYS_NICE, ")
    assert "rtprio limit 0" in line and "memlock limit 8 MiB" in line
    assert "skipped samples" in line and "rtprio 98" in line and "memlock unlimited" in line
    half = missing_line(50, Privilege(False, False, rtprio_limit=60, memlock_limit=8 << 20))
    assert "SCHED_FIFO" not in half.split(":")[1] and "page fault" in half
    assert missing_line(50, Privilege(True, True, 0, 0)) is None
    assert missing_line(0, none) is None  # nothing asked, nothing missing


@pytest.mark.skipif(sys.platform != "linux", reason="Linux scheduling")
def test_granted_every_thread_runs_fifo_the_later_ones_too_and_memory_is_locked():
    from pneu_msgs_py.lifecycle.realtime import privilege

    priv = privilege()
    if not priv.fifo(20):
        pytest.skip("this account may not set SCHED_FIFO 20 (the refused case is tested below)")
    r = _probe()
    assert r["line"] is None, r
    assert set(r["policies"]) == {r["fifo"]} and r["late"] == r["fifo"], r
    assert any(n.endswith("threads at SCHED_FIFO 20") for n in r["notes"]), r
    if priv.lock:
        assert "memory locked (mlockall)" in r["notes"] and r["locked_kb"] > 0, r


@pytest.mark.skipif(sys.platform != "linux", reason="Linux scheduling")
def test_refused_nothing_changes_and_one_line_says_why():
    import os
    import shutil

    prefix = None
    if os.geteuid() == 0:  # root: drop the capabilities too, as an ordinary account has none
        if shutil.which("setpriv") is None:
            pytest.skip("root without setpriv: cannot drop CAP_SYS_NICE")
        caps = "-sys_nice,-ipc_lock"
        prefix = ["setpriv", "--inh-caps", caps, "--bounding-set", caps]
    r = _probe(prefix, limits=True)
    assert r["notes"] == [] and r["fifo"] not in r["policies"], r
    assert r["line"].startswith("realtime: this process runs without SCHED_FIFO 20"), r
    assert "locked memory" in r["line"] and r["locked_kb"] == 0, r


@pytest.mark.skipif(sys.platform != "linux", reason="Linux scheduling")
def test_exec_at_runs_the_command_at_the_priority_it_may_have_and_its_exit_status():
    import os
    import subprocess

    from pneu_msgs_py.lifecycle.realtime import privilege

    show = "import os, sys; print(os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)"
    wrap = [sys.executable, "-m", "pneu_msgs_py.lifecycle.realtime", "10", "--"]
    res = subprocess.run([*wrap, sys.executable, "-c", show + "; sys.exit(3)"],
                         capture_output=True, text=True, timeout=120)  # fmt: skip
    assert res.returncode == 3, res.stderr  # it became the command: its exit status
    policy, prio = map(int, res.stdout.split())
    if privilege().fifo(10):
        assert (policy, prio) == (os.SCHED_FIFO, 10)
    else:
        assert policy == os.SCHED_OTHER
    bad = subprocess.run([sys.executable, "-m", "pneu_msgs_py.lifecycle.realtime", "x", "true"],
                         capture_output=True, text=True, timeout=120)  # fmt: skip
    assert bad.returncode == 1 and bad.stderr.startswith("usage: python -m pneu_msgs_py")
