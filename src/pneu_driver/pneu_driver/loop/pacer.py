"""Absolute-deadline pacing of a software loop at 1/T, and its timing record.

Tick k is due at t0 + k·T (so errors never accumulate): :meth:`Pacer.wait`
sleeps until ``spin_us`` before the deadline, then spins on the clock. A
tick that starts a whole period or more late skips the missed ticks (the
caller counts them). Used by the sim node's realtime loop and the one-process
controller manager; the driver loop paces the same way when the DAQ does
not (software pacing).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

__all__ = ["Pacer", "Timing"]


class Timing:
    """A ring of per-tick durations in ns (e.g. lateness, or sample -> command turnaround)."""

    def __init__(self, window: int = 60_000) -> None:
        self._ring = np.zeros(int(window), dtype=np.int64)
        self.n = 0
        self.max_ns = 0

    def add(self, ns: int) -> None:
        self._ring[self.n % self._ring.shape[0]] = ns
        self.n += 1
        if ns > self.max_ns:
            self.max_ns = ns

    def values(self, last: int | None = None) -> np.ndarray:
        """The recorded durations (the whole ring, or the ``last`` ones), in no particular order."""
        n, w = self.n, self._ring.shape[0]
        if last is None or last >= min(n, w):
            return self._ring[: min(n, w)].copy()
        i = n % w  # the next slot: the newest ``last`` end just before it
        return np.concatenate(
            (self._ring[max(0, i - last) : i], self._ring[w - max(0, last - i) :])
        )

    def percentile_us(self, q: float, last: int | None = None) -> float:
        v = self.values(last)
        return float(np.percentile(v, q)) * 1e-3 if v.size else float("nan")

    def summary(self, prefix: str, last: int | None = None) -> dict[str, str]:
        """``{prefix_p50_us, prefix_p99_us, prefix_max_us, prefix_n}`` as strings (diagnostics).

        Percentiles over the ``last`` ticks (None: the whole ring). Over a full ring they cost
        milliseconds: a 1 Hz diagnostics callback on the executor thread that also takes the
        commands can hold them up past the supervisor's command watchdog, so periodic reports
        use the last second (the benchmarks in ``bench/`` measure the costs).
        """
        v = self.values(last)
        p50, p99 = (np.percentile(v, (50, 99)) * 1e-3) if v.size else (float("nan"),) * 2
        return {
            f"{prefix}_p50_us": f"{p50:.1f}",
            f"{prefix}_p99_us": f"{p99:.1f}",
            f"{prefix}_max_us": f"{self.max_ns * 1e-3:.1f}",
            f"{prefix}_n": str(self.n),
        }


class Pacer:
    """Waits for tick k at t0 + k·T (see the module docstring)."""

    def __init__(
        self,
        period_ns: int,
        spin_us: float = 200.0,
        clock_ns: Callable[[], int] = time.perf_counter_ns,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if period_ns <= 0:
            raise ValueError(f"period_ns: {period_ns!r} refused; allowed: > 0")
        self.T = int(period_ns)
        self._spin_ns = round(spin_us * 1e3)
        self._clock = clock_ns
        self._sleep = sleep
        self.t0 = clock_ns() + self.T
        self.lateness = Timing()
        self.skipped = 0

    def start(self) -> None:
        """Tick 0 is one period from now."""
        self.t0 = self._clock() + self.T

    def wait(self, k: int) -> int:
        """Block until tick k is due; returns the tick actually started (k, or later if late)."""
        deadline = self.t0 + k * self.T
        clock = self._clock
        remaining = deadline - clock()
        if remaining > self._spin_ns:
            self._sleep((remaining - self._spin_ns) * 1e-9)
        while clock() < deadline:
            pass
        late = clock() - deadline
        if late >= self.T:  # whole ticks missed: skip to the current one
            skip = late // self.T
            self.skipped += skip
            k += skip
            late -= skip * self.T
        self.lateness.add(late)
        return k
