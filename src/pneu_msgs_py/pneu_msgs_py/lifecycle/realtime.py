"""What a 1 kHz process asks of the OS (Linux), and one line when it cannot get it.

Two levels, both best effort (without the privilege a loop still runs, with the normal
scheduler, and says why):

- :func:`enable_realtime` -- the calling thread (the 1 kHz loop): SCHED_FIFO, timer slack,
  the GIL switch interval, ``gc.freeze``;
- :func:`realtime_process` -- every thread of the process (the executor that takes the
  commands, the DDS threads that deliver them, any publishing thread) at SCHED_FIFO one
  below the loop, and its memory locked (DESIGN §14). A thread at normal priority that holds
  the GIL, or delivers a sample, is preempted by whatever else runs on the cores: the loop
  then waits for it -- priority inversion through the GIL, measured as 5.8 ms stalls and
  0.1 % skipped ticks with two busy processes beside the hosted graph.

:func:`privilege` says what this account may set (CAP_SYS_NICE or an rtprio limit for
SCHED_FIFO; CAP_IPC_LOCK or an unlimited memlock limit for ``mlockall``) and
:func:`missing_line` what it could not set, what that costs and how to grant it, in one line.
"""

from __future__ import annotations

import ctypes
import gc
import os
import resource
import sys
from collections.abc import Callable
from dataclasses import dataclass

__all__ = [
    "Privilege",
    "enable_realtime",
    "exec_at",
    "missing_line",
    "privilege",
    "realtime_process",
]

_PR_SET_TIMERSLACK = 29
_PR_GET_TIMERSLACK = 30
_CAP_IPC_LOCK = 14  # linux/capability.h
_CAP_SYS_NICE = 23
_MCL_CURRENT, _MCL_FUTURE, _MCL_ONFAULT = 1, 2, 4  # sys/mman.h (MCL_ONFAULT: Linux >= 4.4)


def _prctl() -> Callable[..., int] | None:
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl
    except (OSError, AttributeError):
        return None


def enable_realtime(
    priority: int, timerslack_ns: int = 1, switch_interval_s: float = 0.0, freeze_gc: bool = True
) -> tuple[list[str], Callable[[], None]]:
    """Apply SCHED_FIFO at ``priority`` (0: leave the policy) and the timer slack to this thread,
    and the GIL switch interval to the process (``switch_interval_s`` > 0).

    Returns (what was applied or why not, one line each; an undo function
    restoring the previous settings). Linux's default timer slack (50 µs) is
    added to every sleep; 1 ns makes ``time.sleep`` wake when asked. A thread
    waiting for the GIL asks its holder to drop it only after the switch
    interval (Python's default 5 ms), so a busy executor thread can hold the
    loop off a whole sample clock or five. ``freeze_gc``: every object alive now
    (modules, rclpy, numpy) leaves the cyclic collector (:func:`gc.freeze`),
    so a full collection -- which walks them all, milliseconds -- cannot stall a tick.
    """
    notes: list[str] = []
    undo: list[Callable[[], None]] = []
    if freeze_gc:
        gc.collect()
        gc.freeze()
        notes.append(f"gc.freeze: {gc.get_freeze_count()} objects out of the cyclic collector")
        undo.append(gc.unfreeze)
    if switch_interval_s > 0.0:
        old_si = sys.getswitchinterval()
        sys.setswitchinterval(switch_interval_s)
        notes.append(
            f"GIL switch interval {switch_interval_s * 1e6:g} us (was {old_si * 1e6:g} us)"
        )
        undo.append(lambda: sys.setswitchinterval(old_si))
    prctl = _prctl()
    if timerslack_ns > 0 and prctl is not None:
        old = prctl(_PR_GET_TIMERSLACK, 0, 0, 0, 0)
        if prctl(_PR_SET_TIMERSLACK, int(timerslack_ns), 0, 0, 0) == 0:
            notes.append(f"timer slack {timerslack_ns} ns (was {old} ns)")
            if old > 0:
                undo.append(lambda: prctl(_PR_SET_TIMERSLACK, old, 0, 0, 0))
        else:
            notes.append(f"timer slack not set (errno {ctypes.get_errno()})")
    if priority > 0:
        if not hasattr(os, "sched_setscheduler"):
            notes.append("SCHED_FIFO not available on this platform")
        else:
            try:
                old_policy = os.sched_getscheduler(0)
                old_param = os.sched_getparam(0)
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(priority)))
                notes.append(f"SCHED_FIFO priority {priority}")
                undo.append(lambda: os.sched_setscheduler(0, old_policy, old_param))
            except (OSError, ValueError) as err:
                notes.append(f"SCHED_FIFO {priority} refused ({err}); normal scheduling")

    def restore() -> None:
        for fn in reversed(undo):
            try:
                fn()
            except OSError:
                pass

    return notes, restore


@dataclass(frozen=True)
class Privilege:
    """What this process may set: its effective capabilities and its rlimits."""

    sys_nice: bool  # CAP_SYS_NICE: any SCHED_FIFO priority
    ipc_lock: bool  # CAP_IPC_LOCK: mlockall whatever the memlock limit
    rtprio_limit: int  # RLIMIT_RTPRIO (soft): the highest SCHED_FIFO priority without the cap
    memlock_limit: int  # RLIMIT_MEMLOCK (soft), bytes; resource.RLIM_INFINITY when unlimited

    def fifo(self, priority: int) -> bool:
        """May this process run a thread at SCHED_FIFO ``priority``?"""
        return (
            self.sys_nice
            or self.rtprio_limit == resource.RLIM_INFINITY
            or (self.rtprio_limit >= priority)
        )

    @property
    def lock(self) -> bool:
        """May it lock all its memory (the memlock limit is no bound)?"""
        return self.ipc_lock or self.memlock_limit == resource.RLIM_INFINITY


def _effective_caps(status: str) -> int:
    for line in status.splitlines():
        if line.startswith("CapEff:"):
            return int(line.split()[1], 16)
    return 0


def privilege() -> Privilege:
    """This process's :class:`Privilege` (``/proc/self/status``, ``getrlimit``)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            caps = _effective_caps(fh.read())
    except OSError:
        caps = 0
    return Privilege(
        sys_nice=bool(caps >> _CAP_SYS_NICE & 1),
        ipc_lock=bool(caps >> _CAP_IPC_LOCK & 1),
        rtprio_limit=resource.getrlimit(resource.RLIMIT_RTPRIO)[0],
        memlock_limit=resource.getrlimit(resource.RLIMIT_MEMLOCK)[0],
    )


def _limit(value: int, unit: str = "") -> str:
    if value == resource.RLIM_INFINITY:
        return "unlimited"
    return f"{value >> 20} MiB" if unit == "bytes" else str(value)


def missing_line(priority: int, priv: Privilege, who: str = "this process") -> str | None:
    """One line: what ``who`` cannot set for a loop at SCHED_FIFO ``priority`` (its other
    threads one below), what that costs and how to grant it; None when nothing is missing."""
    if priority <= 0:
        return None
    lacks = []
    if not priv.fifo(priority):
        lacks.append(
            f"SCHED_FIFO {priority} (no CAP_SYS_NICE, rtprio limit {_limit(priv.rtprio_limit)})"
        )
    if not priv.lock:
        lacks.append(
            f"locked memory (no CAP_IPC_LOCK, memlock limit {_limit(priv.memlock_limit, 'bytes')})"
        )
    if not lacks:
        return None
    cost = (
        "any busy program on the cores delays its ticks (skipped samples, held commands, "
        "watchdog trips under load)"
        if not priv.fifo(priority)
        else "a page fault can stall a tick"
    )
    return (
        f"realtime: {who} runs without {' and '.join(lacks)}: {cost}; grant it with "
        "'@pneu - rtprio 98' and '@pneu - memlock unlimited' in /etc/security/limits.d/pneu.conf "
        "for a group pneu you are in, then log in again (docs/ros2.md, real time)"
    )


def _threads() -> list[int]:
    try:
        return sorted(int(t) for t in os.listdir("/proc/self/task"))
    except OSError:
        return [0]


def realtime_process(priority: int, lock_memory: bool = True) -> tuple[list[str], str | None]:
    """Every thread of this process at SCHED_FIFO ``priority`` (threads started later inherit
    it from their creator) and its memory locked (``mlockall``, pages locked as they are first
    touched: a thread's unused stack is not made resident). Returns (what was applied or not,
    one note each; the :func:`missing_line` when SCHED_FIFO is refused, else None -- locked
    memory missing alone is a note: the launch files say it once for the graph).
    ``priority`` 0: nothing."""
    notes: list[str] = []
    if priority <= 0:
        return notes, None
    priv = privilege()
    if not priv.fifo(priority) or not hasattr(os, "sched_setscheduler"):
        return notes, missing_line(priority, priv)
    done = 0
    for tid in _threads():
        try:
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(int(priority)))
            done += 1
        except (OSError, ValueError):  # a thread that has just ended
            pass
    notes.append(f"{done} threads at SCHED_FIFO {priority}")
    if not lock_memory:
        return notes, None
    if not priv.lock:
        notes.append(
            f"memory not locked (no CAP_IPC_LOCK, memlock limit "
            f"{_limit(priv.memlock_limit, 'bytes')}): a page fault can stall a tick"
        )
        return notes, None
    libc = ctypes.CDLL(None, use_errno=True)
    flags = _MCL_CURRENT | _MCL_FUTURE
    if libc.mlockall(flags | _MCL_ONFAULT) == 0 or libc.mlockall(flags) == 0:
        notes.append("memory locked (mlockall)")
    else:
        notes.append(f"memory not locked (mlockall: errno {ctypes.get_errno()})")
    return notes, None


def exec_at(priority: int, argv: list[str]) -> None:
    """Become ``argv`` (``os.execvp``) at SCHED_FIFO ``priority``, which it keeps across the
    exec (0 or refused: normal scheduling, silently -- the launch has said it once). The
    launch files start ``ros2 bag record`` so, below the control path and above other work:
    a recorder at normal priority drops samples when the cores are busy."""
    if priority > 0 and privilege().fifo(priority):
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(priority)))
        except OSError:
            pass
    os.execvp(argv[0], argv)


if __name__ == "__main__":  # python -m pneu_msgs_py.lifecycle.realtime PRIORITY -- CMD ARGS...
    if len(sys.argv) < 4 or sys.argv[2] != "--" or not sys.argv[1].isdigit():
        sys.exit("usage: python -m pneu_msgs_py.lifecycle.realtime PRIORITY -- CMD [ARGS...]")
    exec_at(int(sys.argv[1]), sys.argv[3:])
