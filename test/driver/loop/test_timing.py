"""The timing ring of the realtime loops: percentiles over the whole ring or the last ticks."""

from __future__ import annotations

import numpy as np
import pytest
from pneu_driver.loop.pacer import Timing


@pytest.mark.parametrize("n", [4, 10, 25, 37])
@pytest.mark.parametrize("last", [1, 3, 7, 10, 50, None])
def test_last_ticks_are_the_newest_whether_or_not_the_ring_wrapped(n, last):
    t = Timing(window=10)
    for v in range(n):
        t.add(v)
    kept = list(range(max(0, n - 10), n))  # what a ring of 10 holds
    want = kept if last is None else kept[-last:]
    assert sorted(t.values(last).tolist()) == want


def test_summary_over_the_last_second_reports_the_recent_ticks_and_the_run_max():
    t = Timing(window=5000)
    for _ in range(4000):
        t.add(100_000)  # 100 µs
    for _ in range(1000):
        t.add(300_000)  # the last second: 300 µs
    recent, whole = t.summary("x", last=1000), t.summary("x")
    assert recent["x_p50_us"] == "300.0" and whole["x_p50_us"] == "100.0"
    assert recent["x_max_us"] == whole["x_max_us"] == "300.0" and recent["x_n"] == "5000"
    assert float(whole["x_p99_us"]) == pytest.approx(np.percentile([100] * 4000 + [300] * 1000, 99))
