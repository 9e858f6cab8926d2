"""The driver loop core on simulated time: ordering, one-sample delay, pacing, safety, shutdown."""

import math
import threading

import pytest
from pneu_driver.bench.loop import TrivialPlant, loop_pacing
from pneu_driver.daq.backend import SimBackend
from pneu_driver.daq.errors import DriverError, LateCycleError
from pneu_driver.daq.rig import RigParams
from pneu_driver.daq.scaling import RawSample
from pneu_driver.loop.driver_loop import CommandSlot, DriverLoop, LoopStats
from pneu_driver.safety import SafetyParams, SafetySupervisor
from pneu_msgs_py.params.core import with_updates

T = 1_000_000


def software_rig(**over):
    return with_updates(RigParams(), {"loop.timing": "software", **over})


class FakeClock:
    """Monotonic ns; each read costs 1 µs, sleep overshoots by ``overshoot_ns``."""

    def __init__(self, overshoot_ns=50_000):
        self.t = 10**9
        self.overshoot_ns = overshoot_ns
        self.sleeps = []

    def __call__(self):
        self.t += 1_000
        return self.t

    def sleep(self, s):
        assert s >= 0
        self.sleeps.append(s)
        self.t += round(s * 1e9) + self.overshoot_ns


class RecordingPlant(TrivialPlant):
    """Remembers the valve voltages each step integrated over, and when it was stepped."""

    def __init__(self, clock):
        super().__init__()
        self.clock = clock
        self.u = []
        self.t = []

    def step(self, u_lin, u_rot):
        self.u.append((u_lin, u_rot))
        self.t.append(self.clock.t)
        return super().step(u_lin, u_rot)


def make_loop(rig=None, clock=None, plant=None, safety=None, **kw):
    rig = rig or software_rig()
    clock = clock or FakeClock()
    plant = plant or RecordingPlant(clock)
    sup = SafetySupervisor(safety or SafetyParams(), rig.period_s)
    backend = SimBackend(plant, rig)
    loop = DriverLoop(backend, rig, sup, clock_ns=clock, sleep=clock.sleep, **kw)
    return loop, plant, backend, clock


def test_one_sample_delay_matches_the_runner():
    """Step j (producing sample j) integrates under the command computed from sample j-2."""
    samples = []

    def controller(s):
        samples.append(s)
        loop.put_command("linear", 1.0 + 0.01 * s.k, s.stamp_ns)
        loop.put_command("rotary", 9.0 - 0.01 * s.k, s.stamp_ns)

    loop, plant, backend, _ = make_loop(on_sample=controller)
    loop.run(20)
    assert [s.k for s in samples] == list(range(20))
    assert [s.stamp_ns for s in samples] == [k * T for k in range(20)]
    assert plant.u[0] == plant.u[1] == (5.0, 5.0)
    for j in range(2, 20):
        assert plant.u[j] == pytest.approx((1.0 + 0.01 * (j - 2), 9.0 - 0.01 * (j - 2)))
    # the last command was never written: shutdown wrote the safe value
    assert backend.last_written == (5.0, 5.0) and not backend.is_open


def test_absolute_deadlines_do_not_accumulate_error():
    clock = FakeClock(overshoot_ns=80_000)  # every sleep wakes 80 µs late: the spin absorbs it
    work = [0]

    def busy(s):  # variable work per cycle, up to 0.6 ms
        clock.t += (s.k * 37_000) % 600_000
        loop.put_command("linear", 5.0, s.stamp_ns)
        loop.put_command("rotary", 5.0, s.stamp_ns)
        work[0] += 1

    loop, plant, _, _ = make_loop(clock=clock, on_sample=busy)
    stats = loop.run(200)
    t0 = plant.t[0]
    for k, t in enumerate(plant.t):
        assert abs(t - t0 - k * T) <= 10_000, k  # read k within 10 µs of t0 + k·T
    assert stats.cycles == 200 and stats.on_time == 200 and stats.missed_ticks == 0
    assert stats.on_time_ratio == 1.0
    assert stats.jitter_us(99.0) < 10.0
    assert all(s > 0 for s in clock.sleeps)  # it slept, then spun


def test_overrun_skips_ticks_and_counts_them():
    ks = []

    def slow(s):
        ks.append(s.k)
        if s.k == 3:
            clock.t += 2_500_000  # this cycle overruns by 2.5 periods
        loop.put_command("linear", 6.0, s.stamp_ns)
        loop.put_command("rotary", 6.0, s.stamp_ns)

    clock = FakeClock()
    loop, _plant, _, _ = make_loop(clock=clock, on_sample=slow)
    stats = loop.run(8)
    assert ks == [0, 1, 2, 3, 5, 6, 7, 8]  # tick 4 is gone; 5 started late but within the period
    assert stats.missed_ticks == 1
    assert stats.late_cycles == 1  # tick 5 started ~0.5 ms late
    assert stats.on_time_ratio == pytest.approx(7 / 9)  # 7 on time of 8 cycles + 1 skipped tick
    # the sample after the gap carries its true tick and a speed over the real elapsed time
    assert loop.last_sample.stamp_ns == 8 * T


def test_late_commands_held_then_closed_then_the_watchdog_through_the_loop():
    """The controllers answer samples 0..2, then fall silent: the loop writes their last
    commands held for late_hold_ms (the default policy), then 5 V, and the watchdog latches
    watchdog_ms after the last fresh tick; every late and held tick counted."""
    p = SafetyParams()
    hold, wd = round(p.late_hold_ms), round(p.watchdog_ms)  # in 1 ms periods
    events = []
    written = []
    states = []

    def controller(s):
        states.append(loop.status()["linear"].state)
        if s.k < 3:
            loop.put_command("linear", 7.0, s.stamp_ns)
            loop.put_command("rotary", 6.0, s.stamp_ns)

    loop, _plant, backend, _ = make_loop(
        on_sample=controller, on_events=events.extend, expected_axes=()
    )
    orig = backend.write
    backend.write = lambda a, b: (written.append((a, b)), orig(a, b))
    n = wd + 10
    loop.run(n)
    # writes at ticks 0..n-1: safe, the commands from samples 0..2 at ticks 1..3 (fresh), the
    # last one held at ticks 4..3+hold (late by 1..hold ms), then 5 V; the final write is the
    # shutdown's
    assert written[0] == (5.0, 5.0)
    assert written[1 : 4 + hold] == [(7.0, 6.0)] * (3 + hold)
    assert written[4 + hold : n] == [(5.0, 5.0)] * (n - 4 - hold)
    # not latched until the command is older than the watchdog: the wd-th late tick
    trips = [e for e in events if e.rule == "watchdog" and e.level == "ERROR"]
    assert {e.axis for e in trips} == {"linear", "rotary"}
    assert all(e.stamp_ns == (3 + wd) * T for e in trips)
    assert states[: 3 + wd] == ["SAFE"] + ["OK"] * (2 + wd) and states[3 + wd] == "SAFE"
    assert not [e for e in events if e.level == "ERROR" and e.stamp_ns < (3 + wd) * T]
    st = loop.status()
    assert st["linear"].state == "SAFE" and "watchdog" in st["linear"].causes
    diag = loop.diagnostics()
    assert diag["cycles"] == str(n) and diag["pacing"] == "software"
    assert diag["linear.state"] == "SAFE" and diag["linear.causes"] == "watchdog"
    for axis in ("linear", "rotary"):  # late by 1 .. wd-1 ms, of them 1 .. hold held
        assert diag[f"{axis}.late_ticks"] == str(wd - 1)
        assert diag[f"{axis}.held_ticks"] == str(hold)
        assert diag[f"{axis}.ramped_ticks"] == "0"


def test_estop_and_reset_from_another_thread():
    written = []

    def controller(s):
        if s.k == 4:
            th = threading.Thread(target=loop.estop, args=("operator button",))
            th.start()
            th.join()
        if s.k == 8:
            assert loop.reset()[0]
        loop.put_command("linear", 7.0, s.stamp_ns)
        loop.put_command("rotary", 6.0, s.stamp_ns)

    loop, _plant, backend, _ = make_loop(on_sample=controller)
    orig = backend.write
    backend.write = lambda a, b: (written.append((a, b)), orig(a, b))
    loop.run(12)
    assert written[4] == (7.0, 6.0)  # decided at sample 3
    assert written[5:9] == [(5.0, 5.0)] * 4  # decided at samples 4..7: e-stopped
    assert written[9] == (7.0, 6.0)  # after the reset at sample 8


def test_exception_in_a_callback_leaves_the_valves_safe():
    def broken(s):
        loop.put_command("linear", 9.0, s.stamp_ns)
        loop.put_command("rotary", 9.0, s.stamp_ns)
        if s.k == 5:
            raise RuntimeError("publisher died")

    loop, _plant, backend, _ = make_loop(on_sample=broken)
    with pytest.raises(RuntimeError, match="publisher died"):
        loop.run(20)
    assert backend.last_written == (5.0, 5.0) and not backend.is_open


def test_stop_from_the_callback_ends_the_loop():
    def stopper(s):
        if s.k == 6:
            loop.stop()

    loop, _plant, backend, _ = make_loop(on_sample=stopper, expected_axes=())
    stats = loop.run()
    assert stats.cycles == 7 and backend.last_written == (5.0, 5.0) and not backend.is_open


class PacedBackend:
    """A hardware-paced fake: each read advances the fake clock one period (or raises late)."""

    hardware_paced = True

    def __init__(self, clock, late_at=(), fail_at=None):
        self.clock = clock
        self.late_at = set(late_at)
        self.fail_at = fail_at
        self.n = 0
        self.writes = []
        self.closed = False

    def open(self):
        self.writes.append(("open", 5.0, 5.0))

    def read(self):
        self.n += 1
        self.clock.t += T
        if self.n in self.late_at:
            self.clock.t += T  # the read returns after the missed clock
            raise LateCycleError((-209802,))
        if self.n == self.fail_at:
            raise OSError("bus error")
        return RawSample(
            (2.0, 1.5, 3.0 + 1e-4 * (self.n % 2), 2.5 + 1e-4 * (self.n % 3)), 10 * self.n
        )

    def write(self, a, b):
        self.writes.append(("w", a, b))

    def heartbeat(self, level):
        self.writes.append(("hb", level))

    def close(self):
        self.closed = True


def test_hardware_pacing_counts_late_cycles_and_goes_on():
    clock = FakeClock()
    be = PacedBackend(clock, late_at={4, 5})
    rig = RigParams()
    sup = SafetySupervisor(SafetyParams(), rig.period_s)
    ks = []

    def controller(s):
        ks.append(s.k)
        loop.put_command("linear", 7.0, s.stamp_ns)
        loop.put_command("rotary", 6.0, s.stamp_ns)

    loop = DriverLoop(be, rig, sup, on_sample=controller, clock_ns=clock, sleep=clock.sleep)
    stats = loop.run(10)
    assert stats.daq_late_errors == 2 and stats.late_cycles == 2
    assert stats.missed_ticks == 2  # each late read lost one clock
    assert ks == [
        0,
        1,
        2,
        7,
        8,
        9,
        10,
        11,
    ]  # two late reads spanned 4 clocks: indices follow the clock
    assert be.n == 10  # one read per cycle
    assert len([w for w in be.writes if w[0] == "w"]) == 11  # one write per cycle + the shutdown's
    assert be.writes[-2:] == [("w", 5.0, 5.0), ("hb", False)] and be.closed


def test_hardware_pacing_stops_after_too_many_late_cycles():
    clock = FakeClock()
    be = PacedBackend(clock, late_at=set(range(3, 100)))
    rig = with_updates(RigParams(), {"loop.max_consecutive_late": 5})
    loop = DriverLoop(
        be,
        rig,
        SafetySupervisor(SafetyParams()),
        clock_ns=clock,
        sleep=clock.sleep,
        expected_axes=(),
    )
    with pytest.raises(DriverError, match="5 late cycles in a row"):
        loop.run(50)
    assert be.writes[-2:] == [("w", 5.0, 5.0), ("hb", False)] and be.closed


def test_fatal_read_error_writes_safe_and_propagates():
    clock = FakeClock()
    be = PacedBackend(clock, fail_at=3)
    loop = DriverLoop(
        be,
        RigParams(),
        SafetySupervisor(SafetyParams()),
        clock_ns=clock,
        sleep=clock.sleep,
        expected_axes=(),
    )
    with pytest.raises(OSError, match="bus error"):
        loop.run(10)
    assert be.writes[-2:] == [("w", 5.0, 5.0), ("hb", False)] and be.closed


def test_command_slot_across_threads():
    slot = CommandSlot()
    assert slot.put("linear", 3.0, 0) is False  # no sample taken yet: it answers none
    slot.taken(5)
    assert slot.wait_fresh(("linear",), 5, 0.001) is False
    th = threading.Thread(target=lambda: (slot.put("linear", 3.0, 5), slot.put("rotary", 4.0, 5)))
    th.start()
    assert slot.wait_fresh(("linear", "rotary"), 5, 10.0) is True
    th.join()
    assert slot.put("linear", 9.0, 4) is False  # older than the newest seen
    assert sorted(slot.take()) == [("linear", 3.0, 5), ("rotary", 4.0, 5)]
    assert slot.take() == []
    # a stamp after the newest sample is dropped, counted, and does not become the newest
    assert slot.put("linear", 10.0, 10**15) is False
    assert slot.future == {"linear": 2, "rotary": 0} and slot.take() == []
    slot.taken(6)
    slot.put("linear", math.nan, 6)  # the supervisor decides what a NaN means, not the slot
    assert math.isnan(slot.take()[0][1])
    with pytest.raises(ValueError, match="axis"):
        slot.put("z", 1.0, 7)


def test_loop_stats_window_and_ratio():
    st = LoopStats(window=4, tol_ns=200_000)
    for lat in (0, 100_000, 300_000, -250_000, 50_000, 10_000):
        st.record(lat)
    st.missed_ticks = 2
    assert st.cycles == 6 and st.on_time == 4 and st.late_cycles == 2
    assert st.on_time_ratio == pytest.approx(4 / 8)
    assert list(st.lateness_ns()) == [300_000, -250_000, 50_000, 10_000]
    assert st.max_lateness_ns == 300_000
    st.mark_late()
    assert st.on_time == 3 and st.late_cycles == 3


def test_construction_is_checked():
    plant = TrivialPlant()
    with pytest.raises(ValueError, match="loop.timing: 'hardware' refused"):
        DriverLoop(SimBackend(plant, RigParams()), RigParams(), SafetySupervisor(SafetyParams()))
    rig = software_rig()
    with pytest.raises(ValueError, match="counts_per_rev"):
        DriverLoop(SimBackend(plant, rig), rig, SafetySupervisor(SafetyParams(counts_per_rev=2000)))
    with pytest.raises(ValueError, match="sample_time_s"):
        DriverLoop(SimBackend(plant, rig), rig, SafetySupervisor(SafetyParams(), 2e-3))
    both = software_rig(rotary_plumbing="bidirectional")  # the stall rule must know it
    with pytest.raises(ValueError, match=r"^rotary_plumbing: 'paper' refused; allowed: "):
        DriverLoop(SimBackend(plant, both), both, SafetySupervisor(SafetyParams()))
    sup = SafetySupervisor(SafetyParams(rotary_plumbing="bidirectional"))
    DriverLoop(SimBackend(plant, both), both, sup)
    with pytest.raises(TypeError, match="step"):
        SimBackend(object(), rig)


def test_bench_returns_the_named_figures():
    r = loop_pacing(duration_s=0.05, rt_priority=0)
    assert r["loop_cycles"] == 50
    assert 0.0 <= r["loop_on_time_ratio"] <= 1.0 and r["loop_jitter_us_p99"] >= 0.0
    assert r["loop_safety_trips"] == 0  # the stand-in plant and controller are plausible throughout
