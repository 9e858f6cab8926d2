"""Best-effort real-time settings for the calling thread (Linux): SCHED_FIFO, timer slack, GIL switch interval.

Used by the driver loop when ``loop.rt_priority`` > 0. Nothing here is
required: without the privilege (root, CAP_SYS_NICE or an rtprio limit) the
loop runs with the normal scheduler and the report says why.
"""

from __future__ import annotations

import ctypes
import gc
import os
import sys
from collections.abc import Callable

__all__ = ["enable_realtime"]

_PR_SET_TIMERSLACK = 29
_PR_GET_TIMERSLACK = 30


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
