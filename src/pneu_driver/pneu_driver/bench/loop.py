"""Loop pacing benchmark: the software-timed loop over a simulated backend, no ROS, no DAQ.

Not a test: it measures, it asserts nothing. Figures (DESIGN "speed"):

- ``loop_on_time_ratio``: fraction of cycles starting within ``on_time_tol_us``
  (200 µs) of their absolute deadline (skipped ticks count as not on time);
- ``loop_jitter_us_p99``: 99th percentile of |start − deadline| [µs].

Every cycle does the real work: scaling, the safety supervisor, a publish
callback that runs a small controller and puts both commands, the watchdog,
the write. The machine's load average is reported beside the figures.
"""

from __future__ import annotations

import math
import os
import threading
import time
from typing import Any

import numpy as np
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.params.core import with_updates

from pneu_driver.daq.backend import SimBackend, SteppablePlant
from pneu_driver.daq.rig import RigParams
from pneu_driver.loop.driver_loop import DriverLoop
from pneu_driver.safety import SafetyParams, SafetySupervisor

__all__ = ["TrivialPlant", "gil_contention", "loop_pacing"]


class TrivialPlant:
    """A deterministic stand-in with live-looking signals (seeded noise), for pacing only.

    Chamber pressures around 0.25 MPa abs, a 20 mm / 0.25 Hz position sine,
    the motor turning at 500 rpm (4000 counts/rev). It ignores the commands.
    """

    def __init__(self, seed: int = 0, period_s: float = 1e-3, counts_per_rev: int = 4000):
        self._rng = np.random.Generator(np.random.PCG64(seed))
        self._T = period_s
        self._T_ns = round(period_s * 1e9)
        self._cpr = counts_per_rev
        self._noise = self._rng.normal(0.0, 1.0, (4096, 4))
        self.k = 0

    def step(self, u_lin: float, u_rot: float) -> SensorSample:
        self.k += 1
        k = self.k
        t = k * self._T
        n = self._noise[k % 4096]
        counts = int(500.0 / 60.0 * self._cpr * t)
        return SensorSample(
            k=k,
            stamp_ns=k * self._T_ns,
            p_c1=2.5e5 + 300.0 * n[0],
            p_c2=2.4e5 + 300.0 * n[1],
            p_m1=3.0e5 + 300.0 * n[2],
            x=0.02 * math.sin(2.0 * math.pi * 0.25 * t) + 2e-5 * n[3],
            theta=2.0 * math.pi * counts / self._cpr,
            omega=2.0 * math.pi * 500.0 / 60.0,
            counts=counts,
        )


def loop_pacing(
    duration_s: float = 10.0,
    plant: SteppablePlant | None = None,
    rig: RigParams | None = None,
    safety: SafetyParams | None = None,
    rt_priority: int = 50,
) -> dict[str, Any]:
    """Run the software-timed loop for ``duration_s`` over ``plant`` (default :class:`TrivialPlant`).

    ``rt_priority`` > 0 runs the loop thread SCHED_FIFO as config/rig.yaml
    does on the rig (if permitted; ``loop_realtime`` says what was applied);
    0 measures the normal scheduler.
    """
    if not (duration_s > 0 and math.isfinite(duration_s)):
        raise ValueError(f"duration_s: {duration_s!r} refused; allowed: a time > 0 s")
    rig = with_updates(
        rig or RigParams(), {"loop.timing": "software", "loop.rt_priority": rt_priority}
    )
    sup = SafetySupervisor(
        safety or SafetyParams(counts_per_rev=rig.encoder.counts_per_rev), rig.period_s
    )
    backend = SimBackend(
        plant
        if plant is not None
        else TrivialPlant(period_s=rig.period_s, counts_per_rev=rig.encoder.counts_per_rev),
        rig,
    )
    loop: DriverLoop

    def controller(s: SensorSample) -> None:  # a P controller in the publish callback
        x_ref = 0.0
        u_lin = min(max(5.0 + 200.0 * (x_ref - s.x), 0.0), 10.0)
        u_rot = min(max(5.0 + 0.01 * (52.36 - s.omega), 0.0), 10.0)
        loop.put_command("linear", u_lin, s.stamp_ns)
        loop.put_command("rotary", u_rot, s.stamp_ns)

    loop = DriverLoop(backend, rig, sup, on_sample=controller)
    n = max(1, round(duration_s * rig.loop.rate_hz))
    load_before = os.getloadavg()[0]
    cpu0, wall0 = time.process_time(), time.perf_counter()
    stats = loop.run(n)
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    return {
        "loop_on_time_ratio": stats.on_time_ratio,
        "loop_jitter_us_p99": stats.jitter_us(99.0),
        "loop_jitter_us_p50": stats.jitter_us(50.0),
        "loop_max_lateness_us": stats.max_lateness_ns * 1e-3,
        "loop_cycles": stats.cycles,
        "loop_late_cycles": stats.late_cycles,
        "loop_missed_ticks": stats.missed_ticks,
        "loop_cpu_fraction": cpu / wall if wall > 0 else math.nan,
        "loop_safety_trips": sup.counters["trips"],
        "loop_load_avg_1min": max(load_before, os.getloadavg()[0]),
        "loop_duration_s": wall,
        "loop_realtime": "; ".join(loop.realtime_notes) or "normal scheduling",
    }


def _busy_python(stop: threading.Event, counter: list[int]) -> None:
    """Pure-Python work in a second thread, as an rclpy executor deserialising messages."""
    while not stop.is_set():
        acc = 0
        for i in range(2000):
            acc += i * i
        counter[0] += 1


def gil_contention(
    switch_intervals_us: tuple[float, ...] = (5000.0, 1000.0, 200.0, 50.0),
    duration_s: float = 3.0,
    backend: str = "sim",
    busy: bool = True,
) -> dict[str, dict[str, Any]]:
    """The hardware-paced loop on ``backend`` (default: the twin as a simulated card, found by
    name) beside a busy pure-Python thread, per GIL switch interval.

    Per interval: the loop's lateness p50/p99/max after each sample clock [µs], late cycles,
    missed ticks, per-cycle cost p50/p99 [µs], and the other thread's work rate (what a short
    interval costs it). ``busy=False`` measures the loop alone.
    """
    from pneu_driver.daq.backends import make_backend
    from pneu_driver.daq.rig import load_rig_params

    out: dict[str, dict[str, Any]] = {}
    for si in switch_intervals_us:
        rig = with_updates(
            load_rig_params(),
            {"loop.rt_priority": 0, "loop.switch_interval_us": float(si)},
        )
        sup = SafetySupervisor(
            SafetyParams(counts_per_rev=rig.encoder.counts_per_rev, watchdog_ms=1000.0),
            rig.period_s,
        )
        loop = DriverLoop(make_backend(backend, rig), rig, sup, expected_axes=())
        stop = threading.Event()
        counter = [0]
        other = threading.Thread(target=_busy_python, args=(stop, counter), daemon=True)
        load = os.getloadavg()[0]
        t0 = time.perf_counter()
        if busy:
            other.start()
        try:
            stats = loop.run(max(1, round(duration_s * rig.loop.rate_hz)))
        finally:
            stop.set()
            if busy:
                other.join()
        wall = time.perf_counter() - t0
        lat = np.abs(stats.lateness_ns()) * 1e-3
        out[f"{si:g}us"] = {
            "lateness_us_p50": float(np.percentile(lat, 50)),
            "lateness_us_p99": float(np.percentile(lat, 99)),
            "lateness_us_max": float(lat.max()),
            "late_cycles": stats.late_cycles,
            "missed_ticks": stats.missed_ticks,
            "cost_us_p50": stats.cost_us(50.0),
            "cost_us_p99": stats.cost_us(99.0),
            "other_thread_work_per_s": counter[0] / wall,
            "load_avg_1min": max(load, os.getloadavg()[0]),
        }
    return out
