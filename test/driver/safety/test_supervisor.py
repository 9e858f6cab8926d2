"""The safety supervisor: every rule, at and just beyond its threshold; e-stop and reset."""

import dataclasses
import math
from pathlib import Path

import pytest
from pneu_driver.safety import (
    ERROR,
    OK,
    WARN,
    SafetyParams,
    SafetySupervisor,
    load_safety_params,
)
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.params.core import ParamError, from_dict

CONFIG = Path(__file__).resolve().parents[3] / "config"
T_NS = 1_000_000
WD = round(SafetyParams().watchdog_ms)  # the default watchdog in 1 ms periods
LIVE_VOLTS = (2.0, 1.5, 3.0, 2.5)


class Rig:
    """Feeds a supervisor plausible samples at 1 kHz; fields can be overridden per tick."""

    def __init__(self, params: SafetyParams | None = None, **over):
        self.sup = SafetySupervisor(params or SafetyParams(), sample_time_s=1e-3)
        self.k = -1
        self.counts = 0
        self.rate = over.pop("rate", 0)  # counts per tick
        self.x = 0.0

    def tick(self, raw_volts=None, u=(7.0, 6.0), command=("linear", "rotary"), **fields):
        self.k += 1
        stamp = self.k * T_NS
        self.counts += fields.pop("dcounts", self.rate)
        wiggle = 10.0 * (self.k % 3)  # live sensors never repeat bit-exactly
        values = dict(
            k=self.k,
            stamp_ns=stamp,
            p_c1=250000.0 + wiggle,
            p_c2=240000.0 - wiggle,
            p_m1=180000.0 + wiggle,  # below stall_inlet_pa: a motor at rest is plausible
            x=self.x + 1e-6 * (self.k % 2),
            theta=2 * math.pi * self.counts / 4000,
            omega=0.0,
            counts=self.counts,
        )
        values.update(fields)
        self.sup.check_sample(SensorSample(**values), raw_volts)
        for axis in command or ():
            self.sup.command(axis, u[0 if axis == "linear" else 1], stamp)
        return self.sup.outputs(stamp + T_NS)

    def run(self, n, **kw):
        out = None
        for _ in range(n):
            out = self.tick(**kw)
        return out


def rules(events, level=None):
    return [(e.axis, e.rule) for e in events if level is None or e.level == level]


def test_safety_yaml_is_the_documented_default():
    assert load_safety_params(CONFIG / "safety.yaml") == SafetyParams()


def test_nominal_commands_pass_and_nothing_before_them():
    r = Rig()
    assert r.tick(command=()) == (5.0, 5.0)
    st = r.sup.status
    assert st["linear"].state == "SAFE" and st["linear"].causes == ("no_command",)
    assert r.tick() == (7.0, 6.0)
    assert r.sup.status["rotary"].state == "OK"
    ev = r.sup.events()
    assert rules(ev, OK) == [("linear", "command"), ("rotary", "command")]
    assert not rules(ev, ERROR)


def test_watchdog_exactly_at_threshold_then_latched_until_acknowledged():
    r = Rig()
    r.tick()
    sup = r.sup
    stamp = r.k * T_NS  # the linear axis' last command answers this sample
    for _ in range(WD - 1):  # the linear controller falls silent, the rotary one goes on
        out = r.tick(command=("rotary",))
    # outputs at stamp + WD·T: age == watchdog_ms, not latched (5 V since the hold ended)
    assert out == (5.0, 6.0) and sup.status["linear"].state == "OK"
    assert not rules(sup.events(), ERROR)
    assert sup.outputs(stamp + WD * T_NS + 1) == (5.0, 6.0)  # 1 ns older: linear latched
    ev = sup.events()
    assert ("linear", "watchdog") in rules(ev, ERROR)
    assert sup.status["linear"].causes == ("watchdog",)
    # commands resume: still safe until acknowledged
    assert r.tick(u=(8.0, 6.0)) == (5.0, 6.0)
    assert ("linear", "watchdog") in rules(sup.events(), WARN)
    ok, msg = sup.acknowledge("linear")
    assert ok and "watchdog" in msg
    assert sup.outputs(r.k * T_NS + T_NS) == (8.0, 6.0)


def test_watchdog_acknowledged_without_commands_waits_for_them():
    r = Rig()
    r.tick()
    sup = r.sup
    assert r.run(WD + 1, command=()) == (5.0, 5.0)
    assert sup.status["linear"].causes == ("watchdog",)
    ok, _ = sup.acknowledge("linear")
    assert ok
    assert sup.status["linear"].causes == ("no_command",)
    assert r.tick(command=())[0] == 5.0
    assert r.tick(u=(3.0, 6.0), command=("linear",))[0] == 3.0


def test_a_command_for_no_sample_taken_or_older_than_the_watchdog_is_refused_and_counted():
    """Defence in depth against a publisher that is not the controller (or a clock gone
    wrong): a command stamped after the newest sample, or older than the watchdog, is not
    taken, keeps no watchdog alive and blocks no later command; counted, warned once."""
    sup = SafetySupervisor(SafetyParams(), sample_time_s=1e-3)
    sup.command("linear", 9.0, 0)  # before any sample: it answers nothing
    assert sup.counters["future_commands"] == 1
    r = Rig()
    r.tick()
    sup = r.sup
    k = r.k
    far = (k + 10**9) * T_NS  # 11.6 days ahead: would hold 10 V and starve the watchdog
    sup.command("linear", 10.0, far)
    sup.command("linear", 10.0, (k + 1) * T_NS)  # one sample ahead: not taken either
    assert sup.counters["future_commands"] == 2 and sup.outputs((k + 1) * T_NS) == (7.0, 6.0)
    ev = [e for e in sup.events() if e.level == WARN]
    assert rules(ev) == [("linear", "command_stamp")]  # once per axis and kind
    assert "stamped after the newest sample" in ev[0].message
    # the controller's next command is taken (the rogue stamp did not become the newest)
    assert r.tick(u=(4.0, 6.0)) == (4.0, 6.0)
    # a replay: the command answering a sample older than the watchdog
    r.run(WD)
    old = (r.k - WD - 1) * T_NS
    sup.command("rotary", 9.0, old)
    assert sup.counters["expired_commands"] == 1
    assert sup.outputs(r.k * T_NS + T_NS) == (7.0, 6.0)
    assert rules(sup.events(), WARN) == [("rotary", "command_stamp")]
    # the rogue commands keep nothing alive: silent controllers still trip the watchdog
    for j in range(WD + 3):
        sup.command("linear", 10.0, (r.k + 1 + j) * T_NS + 10**12)
        out = r.tick(command=())
    assert out == (5.0, 5.0)
    assert sup.status["linear"].causes == ("watchdog",)
    assert sup.counters["future_commands"] == WD + 5


def test_soft_limit_at_rest_exactly_at_the_margin():
    r = Rig()
    x_lo, x_hi = r.sup.soft_limits
    assert x_hi == pytest.approx(0.075 - 0.010)
    # at rest exactly at the boundary: the piston at the soft limit trips the axis (latched)
    # and commands toward the end stop are held at 5 V
    out = r.run(12, x=x_hi, u=(7.0, 6.0))
    assert out == (5.0, 6.0)
    assert r.sup.status["linear"].state == "SAFE"
    ev = r.sup.events()
    assert ("linear", "stroke_limit") in rules(ev, ERROR)
    assert ("linear", "soft_limit") in rules(ev, WARN)
    assert r.tick(x=x_hi, u=(3.0, 6.0)) == (5.0, 6.0)  # latched: nothing passes
    ok, msg = r.sup.acknowledge("linear")  # allowed while still out there: to retract it
    assert ok, msg
    assert r.tick(x=x_hi, u=(7.0, 6.0)) == (5.0, 6.0)  # the hold still refuses extending
    assert r.tick(x=x_hi, u=(3.0, 6.0)) == (3.0, 6.0)  # retracting passes
    assert r.sup.status["linear"].state == "LIMITED"
    # a hair inside: no trip, no hold
    r2 = Rig()
    assert r2.run(12, x=x_hi - 1e-9, u=(7.0, 6.0)) == (7.0, 6.0)
    assert r2.sup.status["linear"].state == "OK"
    # the lower end with the valve plumbed the other way round
    r3 = Rig(dataclasses.replace(SafetyParams(), extend_above_neutral=False))
    assert r3.run(12, x=x_lo, u=(7.0, 6.0)) == (5.0, 6.0)  # 7 V retracts here
    assert ("linear", "stroke_limit") in rules(r3.sup.events(), ERROR)
    assert r3.sup.acknowledge("linear")[0]
    assert r3.tick(x=x_lo, u=(7.0, 6.0)) == (5.0, 6.0)
    assert r3.tick(x=x_lo, u=(2.0, 6.0)) == (2.0, 6.0)


def test_soft_limit_counts_the_braking_distance():
    p = SafetyParams()
    x_hi = p.stroke_m / 2 - p.stroke_margin_m
    v = 1.0  # m/s: braking distance v^2 / (2 * 20 m/s^2) = 25 mm
    x_end = x_hi - 0.020  # 20 mm short of the soft limit, 5 mm less than the braking distance
    for direction, expect in ((+1, 5.0), (-1, 7.0)):
        r = Rig(p)
        out = None
        for i in range(12):
            out = r.tick(x=x_end - direction * v * (11 - i) * 1e-3, u=(7.0, 6.0))
        assert out[0] == expect, direction
    # slow enough that the braking distance ends inside the limit: passes
    r = Rig(p)
    for i in range(12):
        out = r.tick(x=x_end - 0.5 * (11 - i) * 1e-3, u=(7.0, 6.0))  # 0.5 m/s: 6.25 mm
    assert out[0] == 7.0
    # hysteresis: back away by more than stroke_hyst_m and the limit releases
    r = Rig(p)
    r.run(12, x=x_hi)  # at the limit: trips (stroke_limit), acknowledged to retract
    assert r.sup.acknowledge("linear")[0]
    r.sup.events()
    r.run(12, x=x_hi - 0.0015)
    assert ("linear", "soft_limit") in rules(r.sup.events(), OK)
    assert r.sup.status["linear"].state == "OK"


def test_overspeed_exactly_at_max_then_above():
    # 1500 rpm = 25 rev/s = 100 counts per ms at 4000 counts/rev
    r = Rig(rate=100)
    assert r.run(30) == (7.0, 6.0)
    r = Rig(rate=101)  # 1515 rpm
    out = r.run(30)
    assert out == (7.0, 5.0)
    ev = r.sup.events()
    assert ("rotary", "overspeed") in rules(ev, ERROR)
    assert r.sup.status["rotary"].present == ("overspeed",)
    assert r.sup.acknowledge("rotary")[0] is False  # still too fast
    r.rate = 90
    r.run(30)
    assert r.sup.acknowledge("rotary")[0] is True
    assert r.tick() == (7.0, 6.0)


def test_encoder_jump_boundary():
    p = dataclasses.replace(SafetyParams(), max_accel_rad_s2=0.0)  # bound = slack (2 counts)
    r = Rig(p, rate=20)
    r.run(5)
    assert r.tick(dcounts=22) == (7.0, 6.0)  # deviation 2 == slack: plausible
    r = Rig(p, rate=20)
    r.run(5)
    assert r.tick(dcounts=23) == (7.0, 5.0)
    assert ("rotary", "encoder_jump") in rules(r.sup.events(), ERROR)
    # the default acceleration bound: a 1000-count glitch is impossible, steady counting is fine
    sup = SafetySupervisor(SafetyParams())
    assert sup.encoder_jump_allowance(T_NS) == pytest.approx(
        5.0e4 * 1e-6 * 4000 / (2 * math.pi) + 2
    )
    r = Rig(rate=50)
    r.run(5)
    assert r.tick(dcounts=1050)[1] == 5.0


def test_non_finite_values_make_only_their_axis_safe():
    r = Rig()
    r.tick()
    assert r.tick(p_c1=math.nan) == (5.0, 6.0)
    assert ("linear", "non_finite") in rules(r.sup.events(), ERROR)
    r = Rig()
    assert r.tick(omega=math.inf) == (7.0, 5.0)
    r = Rig()
    assert r.tick(raw_volts=(2.0, 1.5, math.nan, 2.5)) == (7.0, 5.0)


def test_live_voltage_range_boundaries():
    lo, hi = SafetyParams().pressure_live_v
    r = Rig()
    assert r.tick(raw_volts=(hi, lo, 3.0, 5.3)) == (7.0, 6.0)  # exactly at the bounds: live
    assert r.tick(raw_volts=(math.nextafter(hi, 20.0), 1.5, 3.0, 2.5)) == (5.0, 6.0)
    ev = r.sup.events()
    [trip] = [e for e in ev if e.rule == "live_range"]
    assert trip.axis == "linear" and trip.level == ERROR and dict(trip.values)["sensor"] == "p_c1"
    r = Rig()
    assert r.tick(raw_volts=(2.0, 1.5, -0.31, 2.5)) == (7.0, 5.0)  # broken wire on the motor sensor
    r = Rig()
    assert r.tick(raw_volts=(2.0, 1.5, 3.0, 5.31)) == (5.0, 6.0)  # laser beam lost


def test_pressure_above_supply_plus_margin():
    p = SafetyParams()
    r = Rig()
    limit_lin = p.supply_linear_pa + p.pressure_margin_pa
    limit_rot = p.supply_rotary_pa + p.pressure_margin_pa
    assert r.tick(p_c2=limit_lin, p_m1=limit_rot) == (7.0, 6.0)
    assert r.tick(p_c2=limit_lin + 1.0) == (5.0, 6.0)
    r = Rig()
    assert r.tick(p_m1=limit_rot + 1.0) == (7.0, 5.0)
    assert ("rotary", "over_pressure") in rules(r.sup.events(), ERROR)


def test_position_beyond_the_end_stops_is_implausible():
    r = Rig()
    assert r.tick(x=-0.080, u=(3.0, 6.0))[0] == 5.0  # beyond the soft limit: tripped
    assert r.sup.status["linear"].state == "SAFE"
    assert ("linear", "stroke_limit") in rules(r.sup.events(), ERROR)
    assert r.sup.acknowledge("linear")[0]  # (to retract)
    assert r.tick(x=-0.080, u=(3.0, 6.0))[0] == 5.0  # the soft limit holds the retracting command
    assert r.sup.status["linear"].state == "LIMITED"
    assert r.tick(x=-0.080, u=(7.0, 6.0))[0] == 7.0  # at |x| = stroke/2 + margin: plausible
    assert r.tick(x=-0.0801, u=(7.0, 6.0))[0] == 5.0
    assert ("linear", "position_range") in rules(r.sup.events(), ERROR)


def test_stuck_value_exactly_at_stuck_ms():
    r = Rig()
    for _ in range(251):  # p_c1 identical from t = 0 to t = 250 ms: frozen for exactly stuck_ms
        out = r.tick(p_c1=2.5e5)
    assert out == (7.0, 6.0)
    assert r.tick(p_c1=2.5e5) == (5.0, 6.0)
    assert ("linear", "stuck") in rules(r.sup.events(), ERROR)
    ok, msg = r.sup.acknowledge("linear")
    assert not ok and "stuck:p_c1" in msg
    r.tick(p_c1=2.6e5)  # moves again
    assert ("linear", "stuck") in rules(r.sup.events(), WARN)
    assert r.sup.acknowledge("linear")[0]
    assert r.tick(p_c1=2.7e5) == (7.0, 6.0)
    # raw volts are watched when given: a frozen laser voltage trips the linear axis
    r = Rig()
    for _ in range(252):
        out = r.tick(
            raw_volts=(2.0 + 1e-4 * (r.k % 2), 1.5 - 1e-4 * (r.k % 2), 3.0 + 1e-4 * (r.k % 2), 2.5)
        )
    assert out == (5.0, 6.0)


def _volts_with_p_m1(r, v_m1):
    """Raw volts of tick r.k + 1: live (wiggling) cylinder and laser channels, p_m1 at v_m1."""
    w = 1e-4 * ((r.k + 1) % 2)
    return (2.0 + w, 1.5 - w, v_m1, 2.5 + w)


def test_a_vented_inlet_reading_the_sensor_floor_is_not_frozen():
    """p_m1 at 0 V (atmosphere: the 0-10 V sensor clips at its zero) while valve #2 vents the
    inlet is no frozen sensor, for as long as it lasts (the paper's plumbing holds the inlet
    vented at 0 V); the same reading with the inlet not vented, or any other constant reading
    while vented, trips after stuck_ms as before."""
    p = SafetyParams()
    n = int(p.stuck_ms)
    vented = 5.0 - p.stall_band_v - 0.01  # just beyond the band: the inlet open to exhaust
    r = Rig()
    for _ in range(3 * n):
        out = r.tick(raw_volts=_volts_with_p_m1(r, 0.0), u=(7.0, vented), p_m1=101325.0)
    assert out == (7.0, vented)
    assert not [e for e in r.sup.events() if e.level == ERROR]
    # the valve leaves the vent (the band's edge: not vented): the reading still at 0 V is
    # frozen from the first sample not vented on; the first strictly beyond stuck_ms trips
    edge = 5.0 - p.stall_band_v
    outs = [r.tick(raw_volts=_volts_with_p_m1(r, 0.0), u=(7.0, edge)) for _ in range(n + 2)]
    assert outs[n] == (7.0, edge) and outs[n + 1] == (7.0, 5.0)
    [ev] = [e for e in r.sup.events() if e.level == ERROR]
    assert (ev.axis, ev.rule) == ("rotary", "stuck") and "p_m1" in ev.message
    # vented, but stuck at a live value (not the floor): trips as any frozen sensor
    for u_r, v_m1 in ((0.0, 0.25), (7.0, 0.0), (5.0, 0.0)):
        r = Rig()
        outs = [r.tick(raw_volts=_volts_with_p_m1(r, v_m1), u=(7.0, u_r)) for _ in range(n + 2)]
        assert outs[-1][1] == 5.0, (u_r, v_m1)
        assert ("rotary", "stuck") in rules(r.sup.events(), ERROR)


def _volts_with_chambers(r, v_c1, v_c2):
    """Raw volts of tick r.k + 1: the chambers at v_c1, v_c2 (None: live), inlet and laser live."""
    w = 1e-4 * ((r.k + 1) % 2)
    return (2.0 + w if v_c1 is None else v_c1, 1.5 - w if v_c2 is None else v_c2, 3.0 + w, 2.5 + w)


def test_a_vented_chamber_reading_the_sensor_floor_is_not_frozen():
    """A rod held against a load near the cylinder's force keeps the other chamber vented:
    p_c2 at 0 V while valve #1 vents chamber 2 (above 5 V + the band), or p_c1 while it vents
    chamber 1 (below 5 V − the band), is no frozen sensor for as long as it lasts. The same
    reading with its chamber fed trips after stuck_ms; a valve crossing the band back and
    forth does not hide it: the clock counts the time not vented in all."""
    p = SafetyParams()
    n, band = int(p.stuck_ms), p.stall_band_v
    for chamber, vents in ((1, 5.0 - band - 0.01), (2, 5.0 + band + 0.01)):
        floor = (0.0, None) if chamber == 1 else (None, 0.0)
        r = Rig()
        outs = [
            r.tick(raw_volts=_volts_with_chambers(r, *floor), u=(vents, 6.0)) for _ in range(3 * n)
        ]
        assert outs[-1] == (vents, 6.0), chamber
        assert not [e for e in r.sup.events() if e.level == ERROR], chamber
        # fed (the valve beyond the band the other way): the same 0 V is a dead sensor
        feeds = 10.0 - vents
        r = Rig()
        outs = [
            r.tick(raw_volts=_volts_with_chambers(r, *floor), u=(feeds, 6.0)) for _ in range(n + 2)
        ]
        assert outs[n] == (feeds, 6.0) and outs[n + 1] == (5.0, 6.0), chamber
        [ev] = [e for e in r.sup.events() if e.level == ERROR]
        assert (ev.axis, ev.rule) == ("linear", "stuck") and f"p_c{chamber}" in ev.message
        # vented every other sample: it trips once stuck_ms not vented have passed in all
        r = Rig()
        outs = []
        for j in range(2 * n + 4):
            u = vents if j % 2 else feeds
            outs.append(r.tick(raw_volts=_volts_with_chambers(r, *floor), u=(u, 6.0)))
        tripped = [j for j, o in enumerate(outs) if o[0] == 5.0]
        # the supervisor at tick j reads the output of tick j − 1: ticks 2, 4, ... are vented,
        # the odd ones count; the 251st odd tick (2n + 1) is strictly beyond stuck_ms
        assert tripped[:1] == [2 * n + 1], tripped[:3]
    # the chamber's own valve side decides: p_c1 at 0 V while chamber 2 is vented trips
    r = Rig()
    outs = [
        r.tick(raw_volts=_volts_with_chambers(r, 0.0, None), u=(7.0, 6.0)) for _ in range(n + 2)
    ]
    assert outs[n + 1] == (5.0, 6.0)


def test_output_sanity_never_writes_a_bad_command():
    for bad in (math.nan, math.inf, -0.001, 10.001):
        r = Rig()
        assert r.tick(u=(bad, 6.0)) == (5.0, 6.0)
        assert ("linear", "output_sanity") in rules(r.sup.events(), ERROR)
        assert r.sup.counters["refused_commands"] == 1
    r = Rig()
    assert r.tick(u=(0.0, 10.0)) == (0.0, 10.0)  # the range ends are valid
    r.tick(u=(math.nan, 6.0))
    assert r.sup.acknowledge("linear")[0] is False  # the last command is still bad
    assert r.tick(u=(4.0, 6.0)) == (5.0, 6.0)  # a good one: still latched
    assert r.sup.acknowledge("linear")[0] is True
    assert r.tick(u=(4.0, 6.0)) == (4.0, 6.0)


def test_older_commands_are_ignored():
    r = Rig()
    r.tick()
    r.sup.command("linear", 2.0, r.k * T_NS - 3 * T_NS)
    assert r.sup.outputs(r.k * T_NS + T_NS) == (7.0, 6.0)
    assert r.sup.counters["stale_commands"] == 1
    with pytest.raises(ValueError, match="axis: 'z'"):
        r.sup.command("z", 5.0, 0)


def test_estop_latches_all_and_reset_needs_the_fault_gone():
    r = Rig()
    r.tick()
    r.sup.events()
    r.sup.estop("operator")
    assert r.tick() == (5.0, 5.0)
    ev = r.sup.events()
    assert [(e.axis, e.rule, e.level) for e in ev] == [("all", "estop", ERROR)]
    r.sup.estop("again")  # already latched: no second event, first reason kept
    assert r.sup.estopped == "operator" and not r.sup.events()
    # acknowledging an axis does not clear the e-stop
    ok, msg = r.sup.acknowledge("linear")
    assert ok and "e-stop still latched" in msg
    # a fault present now blocks the reset
    assert r.tick(raw_volts=(11.0, 1.5, 3.0, 2.5)) == (5.0, 5.0)
    ok, msg = r.sup.reset()
    assert not ok and "live_range:p_c1" in msg
    assert r.tick() == (5.0, 5.0)  # the sensor is back, still e-stopped
    ok, msg = r.sup.reset()
    assert ok and "e-stop (operator)" in msg and "linear:live_range:p_c1" in msg
    assert ("all", "reset") in rules(r.sup.events(), OK)
    assert r.tick() == (7.0, 6.0)
    assert r.sup.reset() == (True, "reset: nothing latched")


def test_unsafe_parameters_refused_unless_allowed():
    cases = {
        "stroke_margin_m": -0.001,
        "position_margin_m": -0.001,
        "pressure_margin_pa": -1.0,
        "watchdog_ms": 1000.5,
        "max_speed_rpm": 6000.5,
    }
    for key, value in cases.items():
        with pytest.raises(
            ParamError, match=rf"^{key}: {value!r} refused; allowed: .*allow_unsafe"
        ):
            from_dict(SafetyParams, {key: value}, strict=False)
        p = from_dict(SafetyParams, {key: value, "allow_unsafe": True}, strict=False)
        assert len(p.unsafe_overrides()) == 1 and key in p.unsafe_overrides()[0]
        ev = SafetySupervisor(p).events()
        assert [(e.axis, e.rule, e.level) for e in ev] == [("all", "allow_unsafe", WARN)]
    # the thresholds themselves are accepted
    p = from_dict(
        SafetyParams,
        {"watchdog_ms": 1000.0, "max_speed_rpm": 6000.0, "stroke_margin_m": 0.0},
        strict=False,
    )
    assert p.unsafe_overrides() == ()
    with pytest.raises(ParamError, match=r"watchdog_ms: 0.0 refused"):
        from_dict(SafetyParams, {"watchdog_ms": 0.0, "allow_unsafe": True}, strict=False)
    with pytest.raises(ParamError, match=r"pressure_live_v"):
        from_dict(SafetyParams, {"pressure_live_v": [10.0, 0.0]}, strict=False)
    with pytest.raises(ValueError, match="sample_time_s"):
        SafetySupervisor(SafetyParams(), sample_time_s=0.0)


def test_events_carry_time_and_string_key_values():
    r = Rig()
    r.tick()
    r.tick(p_m1=9.0e5)
    [ev] = [e for e in r.sup.events() if e.level == ERROR]
    assert ev.stamp_ns == r.k * T_NS
    d = ev.as_dict()
    assert d["axis"] == "rotary" and d["rule"] == "over_pressure"
    assert d["values"]["sensor"] == "p_m1" and float(d["values"]["pressure_pa"]) == 9.0e5
    assert all(isinstance(v, str) for _, v in ev.values)
    assert r.sup.events() == []  # drained


def test_no_rotation_driven_but_not_turning():
    """Valve beyond the band (forward: inlet above stall_inlet_pa), |speed| below
    stall_speed_rpm for more than stall_ms -> rotary safe; each condition at its threshold."""
    p = SafetyParams()
    high = p.stall_inlet_pa + 1.0
    u_fwd = (7.0, 7.0)
    # the first sample sees no output yet (5 V); from tick 1 the valve drives, the clock
    # runs from there: ticks 1 .. 1 + stall_ms pass (exactly stall_ms), the next trips
    r = Rig()
    n_pass = int(p.stall_ms) + 2
    for _ in range(n_pass):
        out = r.tick(p_m1=high, u=u_fwd)
    assert out == (7.0, 7.0)
    assert r.tick(p_m1=high, u=u_fwd) == (7.0, 5.0)  # trips, linear untouched
    [ev] = [e for e in r.sup.events() if e.level == ERROR]
    assert (ev.axis, ev.rule) == ("rotary", "no_rotation")
    assert ev.message.startswith(
        f"rotation stalled: motor at 0 rpm (below 5 rpm) for {p.stall_ms + 1:g} ms "
        f"(> {p.stall_ms:g} ms), driven forward: valve #2 at 7 V (> 5 + 0.3 V), inlet p_m1 at"
    )
    # the valve at 5 V now: not driven, the key goes, the latch stays until acknowledged
    r.tick(p_m1=high, u=u_fwd)
    assert ("rotary", "no_rotation") in rules(r.sup.events(), WARN)
    assert r.sup.acknowledge("rotary")[0]
    assert r.tick(p_m1=high, u=u_fwd) == (7.0, 7.0)
    # never (for twice stall_ms; a constant p_m1 would freeze after stuck_ms): the inlet
    # exactly at the threshold, the valve exactly at the band's edge, turning at 15 rpm
    # (a count per ms), reverse drive with the paper's plumbing (the inlet vents)
    for rig, kw in (
        (Rig(), dict(p_m1=p.stall_inlet_pa, u=u_fwd)),
        (Rig(), dict(p_m1=high, u=(7.0, 5.0 + p.stall_band_v))),
        (Rig(rate=1), dict(p_m1=high, u=u_fwd)),
        (Rig(), dict(p_m1=1.1e5, u=(7.0, 2.0))),
    ):
        for _ in range(int(2 * p.stall_ms)):
            assert rig.tick(**kw)[1] != 5.0, kw
    # slower than the threshold (a count every 20 ms: 0.75 rpm) is no rotation: trips
    r = Rig()
    outs = [r.tick(p_m1=high, u=u_fwd, dcounts=1 if k % 20 == 0 else 0) for k in range(200)]
    assert outs[-1] == (7.0, 5.0)
    assert ("rotary", "no_rotation") in rules(r.sup.events(), ERROR)


def test_no_rotation_in_reverse_with_the_bidirectional_plumbing():
    """Below 5 V − band drives port B: the clock runs from the valve alone (p_m2 unmeasured)."""
    p = SafetyParams(rotary_plumbing="bidirectional")
    r = Rig(p)
    for _ in range(int(p.stall_ms) + 2):
        assert r.tick(p_m1=1.1e5, u=(7.0, 3.0)) == (7.0, 3.0)
    assert r.tick(p_m1=1.1e5, u=(7.0, 3.0)) == (7.0, 5.0)
    [ev] = [e for e in r.sup.events() if e.level == ERROR]
    assert ev.rule == "no_rotation" and "driven in reverse: valve #2 at 3 V (< 5 - 1 V; " in (
        ev.message
    )
    # holding: the valve inside the band with both chambers pressurised never runs the clock
    r = Rig(p)
    for k in range(1000):
        u = 5.0 + p.stall_band_bidir_v * (1.0 if k % 2 else -1.0)
        assert r.tick(p_m1=4.0e5 + k % 3, u=(7.0, u)) == (7.0, u)
    assert r.sup.status["rotary"].state == "OK"
    # turning in reverse at 15 rpm (1 count per ms, backwards) is turning
    r = Rig(p, rate=-1)
    for _ in range(400):
        assert r.tick(u=(7.0, 3.0)) == (7.0, 3.0)


def test_angle_soft_limits_off_by_default():
    r = Rig(rate=100)  # 1500 rpm for 2 s: 50 turns, far beyond any tool's hose
    r.run(2000)
    assert r.sup.angle_soft_limits == (-math.inf, math.inf)
    assert r.sup.status["rotary"].state == "OK"
    assert not [e for e in r.sup.events() if e.rule in ("soft_limit", "angle_limit")]


def _limited(**kw):
    base = dict(angle_limits=True, angle_min_deg=-90.0, angle_max_deg=90.0, angle_margin_deg=10.0)
    return dataclasses.replace(SafetyParams(), **{**base, **kw})


def test_angle_soft_limit_at_rest_exactly_at_the_limit():
    p = _limited(rotary_plumbing="bidirectional")
    lo, hi = SafetySupervisor(p).angle_soft_limits
    assert (math.degrees(lo), math.degrees(hi)) == pytest.approx((-80.0, 80.0))
    at_hi = round(80.0 / 0.09)  # 889 counts = 80.01°: at or beyond the soft limit
    r = Rig(p)
    r.tick(dcounts=at_hi - 1)  # 79.92°, the first sample (no speed yet): inside
    assert r.run(5, dcounts=0, u=(7.0, 7.0)) == (7.0, 7.0)
    assert r.tick(dcounts=1, u=(7.0, 7.0)) == (7.0, 5.0)  # 80.01°: trips
    assert r.counts == at_hi
    ev = r.sup.events()
    assert ("rotary", "angle_limit") in rules(ev, ERROR)
    assert ("rotary", "soft_limit") in rules(ev, WARN)
    [trip] = [e for e in ev if e.rule == "angle_limit"]
    assert trip.message.startswith(
        "motor at θ = 80.01°, at or beyond the angle soft limit [-80, 80]°"
    )
    assert r.tick(u=(7.0, 3.0)) == (7.0, 5.0)  # latched: nothing passes
    ok, msg = r.sup.acknowledge("rotary")  # allowed while still out there: to turn it back
    assert ok, msg
    assert r.tick(u=(7.0, 7.0)) == (7.0, 5.0)  # the hold still refuses turning further
    assert r.tick(u=(7.0, 3.0)) == (7.0, 3.0)  # turning back passes
    assert r.sup.status["rotary"].state == "LIMITED"
    # the lower end: commands below 5 V (reverse) are held there, above 5 V pass
    r = Rig(p)
    r.tick(dcounts=-at_hi, u=(7.0, 3.0))
    r.run(12, dcounts=0, u=(7.0, 3.0))
    assert ("rotary", "angle_limit") in rules(r.sup.events(), ERROR)
    assert r.sup.acknowledge("rotary")[0]
    assert r.tick(u=(7.0, 3.0)) == (7.0, 5.0)
    assert r.tick(u=(7.0, 7.0)) == (7.0, 7.0)


@pytest.mark.parametrize(
    ("plumbing", "direction", "u", "idle"),
    [("paper", 1, 7.0, 0.0), ("bidirectional", 1, 7.0, 5.0), ("bidirectional", -1, 3.0, 5.0)],
)
def test_angle_soft_limit_counts_the_braking_angle(plumbing, direction, u, idle):
    """600 rpm = 40 counts/ms = 62.8 rad/s: braking |ω| t_lag + ω²/(2a) = 1.26 + 0.39 rad
    (95°) at the defaults; held where the motor does not turn: paper, the inlet vented."""
    p = _limited(angle_min_deg=-400.0, angle_max_deg=400.0, rotary_plumbing=plumbing)
    r = Rig(p, rate=40 * direction)  # soft limits ±390°
    outs = [r.tick(u=(7.0, u)) for _ in range(int(380 / 0.09 / 40))]  # to ±378°
    theta_in = [k for k, o in enumerate(outs) if o[1] == idle]
    assert theta_in, "never held"
    k = theta_in[0]
    deg = 0.09 * 40 * (k + 1)  # |θ| of the sample that started the hold
    w = 40 * 2 * math.pi / 4000 * 1e3
    b = math.degrees(w * p.angle_lag_ms * 1e-3 + w**2 / (2 * p.max_decel_rad_s2))
    assert deg + b >= 390.0 > deg + b - 0.09 * 40 * 1.001  # the first sample reaching it
    assert all(o[1] == idle for o in outs[k:])  # held from then on
    [ev] = [e for e in r.sup.events() if e.rule == "soft_limit"]
    assert ev.level == WARN and ev.axis == "rotary"
    side = "above" if direction > 0 else "below"
    assert f"outputs {side} {idle:g} V held at {idle:g} V" in ev.message
    assert r.sup.status["rotary"].state == "LIMITED"
    # stopped there (within the encoder's plausible deceleration), the braking angle is gone:
    # the hold releases (hysteresis 1°)
    r.tick(dcounts=20 * direction, u=(7.0, u))
    r.rate = 0
    r.run(20, u=(7.0, u))
    assert ("rotary", "soft_limit") in rules(r.sup.events(), OK)
    assert r.sup.status["rotary"].state == "OK"
    assert r.tick(u=(7.0, u)) == (7.0, u)


def test_new_safety_fields_refused_with_one_line_naming_them():
    cases = [
        (
            {"angle_max_deg": -4000.0},
            r"^angle_max_deg: -4000\.0 refused; allowed: more than angle_min_deg \(-3600 °\)",
        ),
        (
            {"angle_min_deg": -2.0e6},
            r"^angle_min_deg: -2000000\.0 refused; allowed: \[-1e\+06, 1e\+06\] °",
        ),
        (
            {"angle_margin_deg": 3600.0},
            r"^angle_margin_deg: 3600\.0 refused; allowed: less than half the angle range \(3600 °\)",
        ),
        (
            {"angle_margin_deg": -1.0},
            r"^angle_margin_deg: -1\.0 refused; allowed: ≥ 0 ° \(or set allow_unsafe: true\)",
        ),
        ({"angle_hyst_deg": 91.0}, r"^angle_hyst_deg: 91\.0 refused; allowed: \[0, 90\]"),
        ({"max_decel_rad_s2": 0.0}, r"^max_decel_rad_s2: 0\.0 refused; allowed: \(0, 1e\+06\]"),
        (
            {"rotary_plumbing": "both"},
            r"^rotary_plumbing: 'both' refused; allowed: one of paper, bidirectional",
        ),
        ({"stall_band_v": 5.0}, r"^stall_band_v: 5\.0 refused; allowed: \[0, 4\.5\]"),
        ({"stall_speed_rpm": 0.0}, r"^stall_speed_rpm: 0\.0 refused; allowed: \(0, 1000\]"),
        ({"angle_limits": 1}, r"^angle_limits: 1 refused; allowed: true or false"),
    ]
    for values, pattern in cases:
        with pytest.raises(ParamError, match=pattern):
            from_dict(SafetyParams, values, strict=False)
    p = from_dict(SafetyParams, {"angle_margin_deg": -1.0, "allow_unsafe": True}, strict=False)
    assert p.unsafe_overrides() == ("angle_margin_deg=-1 ° < 0: angle soft limit beyond the range",)


def test_a_second_publisher_on_a_command_topic_is_reported_or_trips_the_axis():
    """The graph's publisher count per command topic (what the driver and sim nodes read
    once a second): more than one is a warning; with publisher_trip the axis goes safe
    until the count is one again and the axis is acknowledged. The other axis goes on."""
    r = Rig()
    r.run(3)
    r.sup.events()
    r.sup.command_publishers({"linear": 2, "rotary": 1})
    assert rules(r.sup.events(), WARN) == [("linear", "publishers")]
    assert r.tick() == (7.0, 6.0)  # reported only
    r.sup.command_publishers({"linear": 2, "rotary": 1})
    assert r.sup.events() == []  # no repeat while it lasts
    r.sup.command_publishers({"linear": 1, "rotary": 1})
    assert rules(r.sup.events(), OK) == [("linear", "publishers")]

    r = Rig(dataclasses.replace(SafetyParams(), publisher_trip=True))
    r.run(3)
    r.sup.events()
    r.sup.command_publishers({"linear": 1, "rotary": 3})
    ev = r.sup.events()
    assert rules(ev, ERROR) == [("rotary", "publishers")]
    assert "3 publishers on the rotary valve command topic" in ev[0].message
    assert r.tick() == (7.0, 5.0)  # the rotary valve safe, the linear axis goes on
    assert r.sup.acknowledge("rotary")[0] is False  # still three
    r.sup.command_publishers({"linear": 1, "rotary": 1})
    assert r.tick() == (7.0, 5.0)  # latched until acknowledged
    assert r.sup.acknowledge("rotary")[0] is True
    assert r.tick() == (7.0, 6.0)
    assert r.sup.publishers == {"linear": 1, "rotary": 1}
    with pytest.raises(ValueError, match="axis: 'z'"):
        r.sup.command_publishers({"z": 2})
