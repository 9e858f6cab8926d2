"""The loop's hand-off to its publishing thread (pneu_msgs_py.nodes.handoff) and the hosted
tick (pneu_msgs_py.nodes.hosted): no tick waits on a slow consumer, nothing is reordered."""

from __future__ import annotations

import threading

import pytest
from pneu_msgs_py.nodes.handoff import Handoff
from pneu_msgs_py.nodes.hosted import answer_hosts

WAIT_S = 60.0  # an event's longest wait on a loaded machine (never reached when it works)


def test_batches_are_published_in_order_and_close_publishes_what_is_queued():
    got: list[tuple[str, int]] = []
    h = Handoff(depth=10_000)
    h.start()
    for k in range(2000):
        h.put([(lambda x: got.append(("sample", x)), k), (lambda x: got.append(("cmd", x)), k)])
    h.close(timeout_s=WAIT_S)
    assert got == [(kind, k) for k in range(2000) for kind in ("sample", "cmd")]
    assert h.published == 2000 and h.dropped == 0 and h.pending() == 0


def test_put_never_waits_on_a_stuck_publisher_and_drops_the_oldest_batches():
    entered, release = threading.Event(), threading.Event()
    got: list[int] = []

    def stuck(x: int) -> None:  # the middleware stuck in a write: the first publish never returns
        entered.set()
        assert release.wait(WAIT_S)
        got.append(x)

    h = Handoff(depth=50)
    h.start()
    h.put([(stuck, 0)])
    assert entered.wait(WAIT_S)  # the publishing thread holds batch 0 and is stuck in it
    for k in range(1, 1001):  # 1000 ticks while it is stuck: every put returns
        h.put([(got.append, k)])
    assert not release.is_set() and got == []  # the consumer is still stuck, the loop went on
    assert h.pending() == 50 and h.dropped == 1000 - 50  # bounded: only the newest 50 wait
    release.set()
    h.close(timeout_s=WAIT_S)
    assert got == [0, *range(951, 1001)]  # the batch in hand, then the newest, in order
    assert h.published == 51


def test_a_raising_publish_is_counted_and_the_thread_goes_on():
    errors: list[BaseException] = []
    got: list[int] = []

    def gone(x: int) -> None:
        raise RuntimeError("publisher destroyed")

    h = Handoff(on_error=errors.append)
    h.start()
    h.put([(gone, 0), (got.append, 1)])
    h.put([(got.append, 2)])
    h.close(timeout_s=WAIT_S)
    assert got == [1, 2] and h.errors == 1 and len(errors) == 1
    assert h.counters() == {"published_batches": "2", "dropped_batches": "0", "publish_errors": "1"}


def test_close_twice_and_put_after_close_are_harmless():
    h = Handoff(depth=2)
    h.start()
    h.close(timeout_s=WAIT_S)
    h.close(timeout_s=WAIT_S)
    h.put([(print, "never")])  # the loop's last tick after the node closed it: no error
    assert h.pending() == 1


def test_depth_below_one_is_refused_in_one_line():
    with pytest.raises(ValueError, match=r"^depth: 0 refused; allowed: an integer >= 1$"):
        Handoff(depth=0)


class _Host:
    def __init__(self, axis: str, u: float, fail_at: int | None = None):
        self.axis, self.u, self.fail_at = axis, u, fail_at

    def compute(self, s: int):
        if s == self.fail_at:
            raise ZeroDivisionError("division by zero")
        return self.u + s, [(print, f"{self.axis} cmd {s}")]


def test_hosted_answers_are_offered_before_any_message_and_a_crashed_controller_falls_silent():
    offered: list[tuple[str, float]] = []
    errors: list[str] = []
    crashed: dict[str, str] = {}
    hosts = (_Host("linear", 5.0, fail_at=2), _Host("rotary", 6.0))
    for s in range(4):
        msgs = answer_hosts(s, hosts, crashed, lambda a, u: offered.append((a, u)), errors.append)
        axes = [m[1].split()[0] for m in msgs]
        assert axes == (["linear", "rotary"] if s < 2 else ["rotary"])
    assert offered == [
        ("linear", 5.0), ("rotary", 6.0), ("linear", 6.0), ("rotary", 7.0),
        ("rotary", 8.0), ("rotary", 9.0),
    ]  # fmt: skip
    assert crashed == {"linear": "ZeroDivisionError: division by zero"}
    assert len(errors) == 1 and errors[0].startswith("linear controller raised ZeroDivisionError")
