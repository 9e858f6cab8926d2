"""The driver loop's cycle statistics: lateness, missed clocks, DAQmx late codes, per-cycle cost.

Kept by :class:`~pneu_driver.loop.driver_loop.DriverLoop` (loop thread only),
read by ``diagnostics()`` and the benchmarks.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

__all__ = ["LoopStats"]


class LoopStats:
    """Cycle timing of one run. ``lateness`` = cycle start − deadline [ns].

    Software pacing: the start against the absolute deadline t0 + k·T.
    Hardware pacing: the read's return against the previous one + T (the
    clock itself is exact; this is the software's jitter around it).
    A cycle is on time when |lateness| ≤ ``tol_ns``; skipped ticks count as
    not on time.
    """

    def __init__(self, window: int, tol_ns: int):
        self.tol_ns = int(tol_ns)
        self.cycles = 0
        self.on_time = 0
        self.late_cycles = 0  # started beyond tol, or a DAQmx late error
        self.missed_ticks = 0  # ticks skipped entirely
        self.daq_late_errors = 0
        self.late_codes: dict[int, int] = {}  # DAQmx status code -> count
        self.max_lateness_ns = 0
        self.heartbeats = 0  # heartbeat edges written
        self._ring = np.zeros(int(window), dtype=np.int64)
        self._cost = np.zeros(int(window), dtype=np.int64)
        self._n = 0
        self._n_cost = 0
        self._last_on_time = False

    def daq_late(self, codes: Iterable[int]) -> None:
        """A DAQmx late-cycle error (one per read or write that reported it)."""
        self.daq_late_errors += 1
        for c in codes:
            self.late_codes[c] = self.late_codes.get(c, 0) + 1

    def record_cost(self, cost_ns: int) -> None:
        """One cycle's work [ns]: sample in → outputs written and heartbeat toggled."""
        self._cost[self._n_cost % self._cost.shape[0]] = cost_ns
        self._n_cost += 1

    def cost_ns(self) -> np.ndarray:
        """The most recent per-cycle costs (up to the window), oldest first."""
        return self._window(self._cost, self._n_cost)

    def cost_us(self, q: float = 50.0, last: int | None = None) -> float:
        """The q-th percentile of the per-cycle cost over the window (or the ``last`` cycles) [µs]."""
        c = self.cost_ns()
        c = c[-last:] if last else c
        return float(np.percentile(c, q)) * 1e-3 if c.size else math.nan

    def record(self, lateness_ns: int, late: bool = False) -> None:
        """One cycle's start lateness; ``late`` forces it late (a DAQmx late error)."""
        ring = self._ring
        ring[self._n % ring.shape[0]] = lateness_ns
        self._n += 1
        self.cycles += 1
        mag = abs(lateness_ns)
        self._last_on_time = mag <= self.tol_ns and not late
        if self._last_on_time:
            self.on_time += 1
        else:
            self.late_cycles += 1
        if mag > self.max_lateness_ns:
            self.max_lateness_ns = mag

    def mark_late(self) -> None:
        """The last recorded cycle turned out late (a DAQmx late error on its write)."""
        if self._last_on_time:
            self._last_on_time = False
            self.on_time -= 1
            self.late_cycles += 1

    def lateness_ns(self) -> np.ndarray:
        """The most recent lateness values (up to the window), oldest first."""
        return self._window(self._ring, self._n)

    @staticmethod
    def _window(ring: np.ndarray, n: int) -> np.ndarray:
        w = ring.shape[0]
        if n <= w:
            return ring[:n].copy()
        i = n % w
        return np.concatenate((ring[i:], ring[:i]))

    @property
    def on_time_ratio(self) -> float:
        total = self.cycles + self.missed_ticks
        return self.on_time / total if total else math.nan

    def jitter_us(self, q: float = 99.0, last: int | None = None) -> float:
        """The q-th percentile of |lateness| over the window (or the ``last`` cycles) [µs]."""
        lat = self.lateness_ns()
        lat = lat[-last:] if last else lat
        if lat.size == 0:
            return math.nan
        return float(np.percentile(np.abs(lat), q)) * 1e-3

    def as_dict(self, last: int | None = None) -> dict[str, Any]:
        """Counters, and percentiles over the window or the ``last`` cycles (a 1 Hz report takes
        the last second: over a full 60,000-cycle window they cost milliseconds on the thread
        that also takes the commands, see :meth:`pneu_driver.loop.pacer.Timing.summary`)."""
        return {
            "cycles": self.cycles,
            "on_time": self.on_time,
            "late_cycles": self.late_cycles,
            "missed_ticks": self.missed_ticks,
            "daq_late_errors": self.daq_late_errors,
            "daq_late_codes": " ".join(f"{c}:{n}" for c, n in sorted(self.late_codes.items())),
            "on_time_ratio": self.on_time_ratio,
            "jitter_us_p99": self.jitter_us(99.0, last),
            "max_lateness_us": self.max_lateness_ns * 1e-3,
            "cost_us_p50": self.cost_us(50.0, last),
            "cost_us_p99": self.cost_us(99.0, last),
            "heartbeats": self.heartbeats,
        }
