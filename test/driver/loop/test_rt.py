"""Best-effort real-time settings of the loop thread (pneu_driver.loop.rt)."""

from __future__ import annotations

import gc
import sys
import threading

from pneu_driver.loop.rt import enable_realtime


def _in_thread(fn):
    """Run ``fn`` in a fresh thread (the settings are per thread) and return its result."""
    out = []
    th = threading.Thread(target=lambda: out.append(fn()))
    th.start()
    th.join()
    return out[0]


def test_gc_freeze_moves_live_objects_out_of_the_collector_and_restore_undoes_it():
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
