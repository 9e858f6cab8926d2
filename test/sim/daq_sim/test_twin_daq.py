"""The twin as a simulated PCI-6221: the driver loop end to end on simulated time, no ROS.

Every test but the last runs the real :class:`DriverLoop` on a fake monotonic
clock shared by the loop and the card (each clock read costs 1 µs, a sleep
lasts what it asks plus 50 µs), so the 1 kHz sample clock, stalls and late
cycles are exact and repeatable. The last test kills a real process.
"""

import itertools
import math
import os
import signal
import subprocess
import sys
import time

import pytest
from pneu_driver.daq.backends import make_backend
from pneu_driver.daq.rig import RigParams
from pneu_driver.loop.driver_loop import DriverLoop
from pneu_driver.safety import SafetyParams, SafetySupervisor
from pneu_msgs_py.params.core import ParamError, with_updates
from pneu_sim.daq_sim.backend import TwinDaq
from pneu_sim.daq_sim.card import CardRegister, read_card_state
from pneu_sim.physics.plant import Plant
from pneu_sim.physics.plant_file import load_plant

T = 1_000_000


class FakeClock:
    def __init__(self):
        self.t = 10**9

    def __call__(self):
        self.t += 1_000
        return self.t

    def sleep(self, s):
        self.t += round(s * 1e9) + 50_000


def rig_for(**over):
    return with_updates(
        RigParams(), {"loop.rt_priority": 0, "loop.switch_interval_us": 0.0, **over}
    )


def make(rig=None, stalls=(), card=None, seed=0):
    rig = rig or rig_for()
    clock = FakeClock()
    plant = Plant(load_plant(), seed=seed)
    daq = TwinDaq(rig, plant, card=card, stalls=stalls, clock_ns=clock, sleep=clock.sleep)
    return rig, daq, clock


def run_loop(rig, daq, clock, n, controller, safety=None, **kw):
    sup = SafetySupervisor(safety or SafetyParams(), rig.period_s)
    loop = DriverLoop(daq, rig, sup, clock_ns=clock, sleep=clock.sleep, **kw)
    loop._on_sample = lambda s: controller(loop, s)
    stats = loop.run(n)
    return loop, stats


def hold_centre(loop, s):
    loop.put_command("linear", 5.0 + 50.0 * (0.0 - s.x), s.stamp_ns)
    loop.put_command("rotary", 6.0, s.stamp_ns)


def test_volts_in_volts_and_counts_out_one_clock_one_sample_delay():
    rig, daq, clock = make()
    seen = []

    def controller(loop, s):
        seen.append((s, daq.card.state(), daq.plant.state, daq.plant.k, daq._sample))
        hold_centre(loop, s)

    _loop, stats = run_loop(rig, daq, clock, 400, controller)
    assert stats.cycles == 400 and stats.late_cycles == 0 and stats.missed_ticks == 0
    assert stats.daq_late_errors == 0
    # one sample per clock: sample k is the twin's step k + 1, read at its clock
    assert [e[3] for e in seen] == list(range(1, 401))
    # through volts and back: the driver's scaling (rig.yaml) inverts the twin's sensor
    # model (plant.yaml), so the driver's sample is the twin's, to rounding
    for s, *_, twin in seen:
        for f in ("p_c1", "p_c2", "p_m1"):
            assert getattr(s, f) == pytest.approx(getattr(twin, f), abs=1e-6)
        assert s.x == pytest.approx(twin.x, abs=1e-12) and s.counts == twin.counts
    # the value decided at sample k-1 is on the DACs while the twin runs from k to k+1
    for (s_prev, *_), (_s, card, *_rest) in itertools.pairwise(seen[10:]):
        u_prev = 5.0 + 50.0 * (0.0 - s_prev.x)
        assert card.ao0_v == pytest.approx(u_prev) and card.ao1_v == 6.0
    assert math.isclose(seen[-1][2].u_rotary, 6.0, abs_tol=1e-3)  # the twin's spool saw it
    # stopped: 5 V on both valves, heartbeat low; the twin no longer steps
    end = daq.card.state()
    assert (end.ao0_v, end.ao1_v, end.do_level) == (5.0, 5.0, False)
    assert end.tick == 400 and daq.plant.k == 400


def test_heartbeat_on_the_card_toggles_every_cycle_and_stops_on_trip_and_stop():
    rig, daq, clock = make()
    edges = []

    def controller(loop, s):
        edges.append(daq.card.state().do_edges)
        hold_centre(loop, s)
        if s.k == 100:
            loop.estop("test")
        if s.k == 150:
            assert loop.reset()[0]

    _loop, stats = run_loop(rig, daq, clock, 200, controller)
    # one edge per cycle up to the e-stop, none while latched, again after the reset
    steps = [b - a for a, b in itertools.pairwise(edges)]
    assert set(steps[:100]) == {1}
    assert set(steps[101:150]) == {0}
    assert set(steps[151:]) == {1}
    assert stats.heartbeats == 100 + 50
    assert daq.card.state().do_level is False


def test_a_3ms_stall_is_counted_late_on_the_simulated_daq():
    rig, daq, clock = make(stalls=[(0.2, 0.003)])
    ks = []
    loop, stats = run_loop(rig, daq, clock, 300, lambda lp, s: (ks.append(s.k), hold_centre(lp, s)))
    # the write after the stall missed its clock; the next read found two clocks gone
    assert stats.late_codes == {-209801: 1, -209800: 1}
    assert stats.daq_late_errors == 2 and stats.late_cycles == 2
    assert stats.missed_ticks == 2
    # sample indices follow the card's clock across the gap (the late cycle has no sample)
    gap = [b - a for a, b in itertools.pairwise(ks) if b - a != 1]
    assert gap == [4]
    assert ks[-1] + 1 == daq.plant.k  # the twin stepped every clock, read or not
    assert loop.diagnostics()["daq_late_codes"] == "-209801:1 -209800:1"
    assert loop.status()["linear"].state == "OK"  # 4 ms without a sample: within the watchdog


def test_without_missed_sample_reporting_the_stall_goes_unreported():
    rig, daq, clock = make(
        rig=rig_for(**{"loop.report_missed_samples": False}), stalls=[(0.2, 0.003)]
    )
    ks = []
    _loop, stats = run_loop(
        rig, daq, clock, 300, lambda lp, s: (ks.append(s.k), hold_centre(lp, s))
    )
    assert -209800 not in stats.late_codes and stats.missed_ticks == 0
    assert ks == list(range(300))  # one index per read: from the stall on, 2 clocks behind
    assert daq.plant.k == 300 + 2


def test_the_card_file_holds_the_outputs_across_processes(tmp_path):
    path = tmp_path / "card"
    reg = CardRegister(path)
    assert reg.state().ao0_v == 0.0  # a new card powers up at 0 V
    reg.set_ao(7.5, 3.25)
    reg.set_do(True)
    reg.close()
    again = read_card_state(path)
    assert (again.ao0_v, again.ao1_v, again.do_level, again.do_edges) == (7.5, 3.25, True, 1)
    _rig, daq, _clock = make(card=CardRegister(path))
    daq.open()  # the driver's first act: 5 V on demand
    assert (daq.card.state().ao0_v, daq.card.state().ao1_v) == (5.0, 5.0)
    daq.card.reset_device()  # a device reset: M Series AO to 0 V -- an MPYE fully open
    assert (daq.card.state().ao0_v, daq.card.state().ao1_v) == (0.0, 0.0)


_POWER_UPS = """
import os, sys
from pneu_sim.daq_sim.card import CardRegister
path, n = sys.argv[1], int(sys.argv[2])
for _ in range(n):
    if os.path.exists(path):
        os.unlink(path)
    CardRegister(path).close()
print("done", flush=True)
"""


def test_a_card_being_powered_up_is_never_read_half_made(tmp_path):
    """Another process polls the card file while the driver powers it up (the killed-driver
    test below, on a loaded machine): it reads no card or a whole one, never a file that its
    foreign-file check refuses. A process powers up a new card 2000 times while this one reads."""
    card = tmp_path / "card"
    proc = subprocess.Popen(
        [sys.executable, "-c", _POWER_UPS, str(card), "2000"], stdout=subprocess.PIPE, text=True
    )
    reads = 0
    while proc.poll() is None:
        try:
            st = read_card_state(card)
        except FileNotFoundError:
            continue
        assert (st.ao0_v, st.ao1_v, st.pid) == (0.0, 0.0, proc.pid)
        reads += 1
    assert proc.wait() == 0 and proc.stdout.read().strip() == "done"
    assert reads > 0 and not list(tmp_path.glob(".card.*"))  # no temporary file left behind


def test_reading_a_card_file_never_creates_one(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_card_state(tmp_path / "card")
    assert not (tmp_path / "card").exists()
    (tmp_path / "card").write_bytes(b"")  # an empty file: a card that never powered up
    assert read_card_state(tmp_path / "card").ao0_v == 0.0
    assert (tmp_path / "card").stat().st_size == 0


def test_backend_by_name_and_its_options():
    rig = rig_for()
    daq = make_backend("sim:seed=3,stall_at_s=1,stall_ms=2", rig)
    assert isinstance(daq, TwinDaq) and daq.plant.seed == 3 and daq._stalls == [(1.0, 0.002)]
    with pytest.raises(ParamError, match=r"backend sim sede: 3 refused; allowed: one of seed"):
        make_backend("sim:sede=3", rig)
    with pytest.raises(ParamError, match=r"backend sim seed: 'x' refused; allowed: an integer"):
        make_backend("sim:seed=x", rig)
    # every option bounded by a true range: a seed numpy takes whole, a stall inside the cap
    with pytest.raises(ParamError, match=r"seed: 4294967296 refused; allowed: an integer in \["):
        make_backend("sim:seed=4294967296", rig)
    with pytest.raises(ParamError, match=r"stall_at_s: 1e\+300 refused; allowed: < 0 \(no stall\)"):
        make_backend("sim:stall_at_s=1e300", rig)
    with pytest.raises(ParamError, match=r"stall_ms: 1e\+300 refused; allowed: \(0, 600000\] ms"):
        make_backend("sim:stall_at_s=1,stall_ms=1e300", rig)


def test_a_card_file_never_overwrites_another_file(tmp_path):
    """``card=`` names the card's register file: a file that holds anything else (a bag, a
    config file) is refused and left byte for byte; an empty or new file becomes a card."""
    rig = rig_for()
    other = tmp_path / "plant.yaml"
    other.write_text("linear: {}\n" * 20)
    before = other.read_bytes()
    with pytest.raises(ParamError, match=r"backend sim card: .* refused; allowed: a new file or"):
        make_backend(f"sim:card={other}", rig)
    assert other.read_bytes() == before
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(ParamError, match=r"not a regular file"):
        make_backend(f"sim:card={fifo}", rig)
    card = tmp_path / "card"
    make_backend(f"sim:card={card}", rig).close()
    make_backend(f"sim:card={card}", rig).close()  # the card of an earlier run: taken again
    with pytest.raises(ParamError, match=r"backend: 'sum' refused; allowed: one of nidaqmx, sim"):
        make_backend("sum", rig)


# ----------------------------------------------------------------- process death

_DRIVER = """
import signal, sys
from pneu_driver.daq.backends import make_backend
from pneu_driver.daq.rig import load_rig_params
from pneu_driver.loop.driver_loop import DriverLoop
from pneu_driver.safety import SafetySupervisor, load_safety_params
from pneu_msgs_py.params.core import with_updates

rig = with_updates(load_rig_params(), {"loop.rt_priority": 0, "loop.max_consecutive_late": 100000})
# the shared test machine may pause this process for several ms: the watchdog is not under test
safety = with_updates(load_safety_params(), {"watchdog_ms": 1000.0})
daq = make_backend("sim:card=" + sys.argv[1], rig)
loop = None

def controller(s):
    loop.put_command("linear", 5.0, s.stamp_ns)
    loop.put_command("rotary", 6.0, s.stamp_ns)  # the motor turns (about 1200 rpm on the twin)

loop = DriverLoop(daq, rig, SafetySupervisor(safety, rig.period_s), on_sample=controller)
signal.signal(signal.SIGTERM, lambda *a: loop.stop())
loop.run()
"""


def _start_driver(card):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-c", _DRIVER, str(card)], env=env)


def _wait_running(proc, card, timeout_s=120.0):
    """Until the card shows the rotary valve at 6 V and 200 heartbeat edges (not a timing test)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        assert proc.poll() is None, "the driver process ended early"
        if card.exists():
            st = read_card_state(card)
            if st.pid == proc.pid and st.ao1_v == 6.0 and st.do_edges >= 200:
                return st
        time.sleep(0.05)
    proc.kill()
    pytest.fail("the driver on the simulated card did not start")


def test_a_killed_driver_leaves_the_valves_at_their_last_value(tmp_path):
    """SIGKILL: no finally, no close. The card keeps driving what it was last told (6 V: the
    motor valve open) and the heartbeat stops -- what a PCI-6221 does, and why the rig needs
    the external relay. A clean stop (SIGTERM) leaves 5 V."""
    card = tmp_path / "card"
    proc = _start_driver(card)
    _wait_running(proc, card)
    proc.send_signal(signal.SIGKILL)
    assert proc.wait(timeout=30) == -signal.SIGKILL
    dead = read_card_state(card)
    assert (dead.ao0_v, dead.ao1_v) == (5.0, 6.0)  # the last value, not the safe 5 V
    time.sleep(0.2)
    later = read_card_state(card)
    assert later.do_edges == dead.do_edges and later.ao_updates == dead.ao_updates  # still
    # a clean stop of a new driver on the same card: 5 V and the heartbeat low
    proc = _start_driver(card)
    _wait_running(proc, card)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=60) == 0
    done = read_card_state(card)
    assert (done.ao0_v, done.ao1_v, done.do_level) == (5.0, 5.0, False)


def test_a_second_driver_on_the_same_card_is_refused_before_it_touches_it(tmp_path):
    """Two graphs on one host (any ROS domain) never drive one card: the second driver is
    refused in one line naming the first's pid, and the first runs on undisturbed."""
    card = tmp_path / "card"
    first = _start_driver(card)
    try:
        before = _wait_running(first, card)
        second = subprocess.run(
            [sys.executable, "-c", _DRIVER, str(card)], capture_output=True, text=True, timeout=300
        )
        assert second.returncode != 0
        assert f"in use by another pneu driver (pid {first.pid})" in second.stderr
        after = read_card_state(card)
        assert after.pid == first.pid and after.ao1_v == 6.0  # still the first's card
        assert after.do_edges > before.do_edges  # and its loop still beating
    finally:
        first.send_signal(signal.SIGTERM)
        assert first.wait(timeout=60) == 0
    # released: a new driver takes the card
    again = _start_driver(card)
    _wait_running(again, card)
    again.send_signal(signal.SIGTERM)
    assert again.wait(timeout=60) == 0
