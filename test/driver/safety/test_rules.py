"""The safety rules are one source: the same kernels in Python and compiled give the same decisions.

A small numba driver runs every rule of :mod:`pneu_driver.safety.rules` on numba
records (elements of structured arrays) over a random stream of samples, commands
and output ticks; the same stream runs through the same functions on Python
records. Every decision (fault-key masks, command outcomes, stroke and angle zone
changes, output voltages), every number behind a fired rule and the final rule state
must agree bit for bit, with the angle soft limits off and on, both plumbings. (That :mod:`pneu_control.fastloop.supervisor` calls these rules and
holds no copy of one: test/control/fastloop/test_supervisor_single_source.py.)
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pneu_driver.safety import SafetyParams, SafetySupervisor, rules
from pneu_msgs_py.params.records import RecordType

numba = pytest.importorskip("numba")

P = SafetyParams()
T_NS = 1_000_000
X_HI = P.stroke_m / 2 - P.stroke_margin_m
P_LIN = P.supply_linear_pa + P.pressure_margin_pa
P_ROT = P.supply_rotary_pa + P.pressure_margin_pa
BAD = (math.nan, math.inf, -math.inf)
_ANGLE_ZONE = (
    rules.ANGLE_HI_ENTERED | rules.ANGLE_HI_LEFT | rules.ANGLE_LO_ENTERED | rules.ANGLE_LO_LEFT
)


@numba.njit(error_model="numpy")
def _drive(th_a, s_a, d_a, f, c, volts, have, u, u_t, now, blocked, sent, out_i, out_f):
    """Per step k: the sample rules, both commands, the watchdog, the late-command policy,
    the zone, both outputs."""
    th = th_a[0]
    s = s_a[0]
    d = d_a[0]
    for k in range(f.shape[0]):
        t = k * 1_000_000
        keys = rules.non_finite_fields(d, f[k, 0], f[k, 1], f[k, 2], f[k, 3], f[k, 4], f[k, 5])
        vals = volts[k] if have[k] else f[k, :4]
        keys |= rules.sample_faults(
            th, s, d, t, f[k, 0], f[k, 1], f[k, 2], f[k, 3], c[k], vals, have[k]
        )
        out_i[k, 0] = keys
        if sent[k, 0]:
            out_i[k, 1] = rules.command(th, s, 0, u[k, 0], u_t[k, 0])
        if sent[k, 1]:
            out_i[k, 2] = rules.command(th, s, 1, u[k, 1], u_t[k, 1])
        out_i[k, 3] = rules.watchdog_faults(th, s, now[k])
        out_i[k, 8] = rules.late_faults(th, s, now[k])
        out_i[k, 9] = rules.late_command(th, s, 0, now[k])
        out_i[k, 10] = rules.late_command(th, s, 1, now[k])
        out_i[k, 4] = rules.update_zone(th, s, d)
        out_i[k, 5] = rules.sensor_key_axes(keys)
        out_f[k, 0] = rules.output_v(th, s, 0, blocked[k, 0], now[k])
        out_f[k, 1] = rules.output_v(th, s, 1, blocked[k, 1], now[k])
        out_f[k, 2] = d.jump_deviation if keys & (1 << rules.ENCODER_JUMP) else 0.0
        out_f[k, 3] = d.speed_rpm if keys & (1 << rules.OVERSPEED) else 0.0
        out_f[k, 4] = d.braking_m if out_i[k, 4] else 0.0
        out_f[k, 5] = d.braking_rad if out_i[k, 4] & _ANGLE_ZONE else 0.0
        out_f[k, 6] = d.stall_u if keys & (1 << rules.NO_ROTATION) else 0.0
        out_i[k, 6] = d.nf_fields
        out_i[k, 7] = d.nf_volts if have[k] else 0


def _python(th, s, d, f, c, volts, have, u, u_t, now, blocked, sent):
    n = len(f)
    out_i = np.zeros((n, 11), dtype=np.int64)
    out_f = np.zeros((n, 7))
    for k in range(n):
        t = k * T_NS
        fk = f[k].tolist()
        keys = rules.non_finite_fields(d, *fk)
        vals = tuple(volts[k].tolist()) if have[k] else tuple(fk[:4])
        keys |= rules.sample_faults(th, s, d, t, *fk[:4], int(c[k]), vals, bool(have[k]))
        out_i[k, 0] = keys
        if sent[k, 0]:
            out_i[k, 1] = rules.command(th, s, 0, float(u[k, 0]), int(u_t[k, 0]))
        if sent[k, 1]:
            out_i[k, 2] = rules.command(th, s, 1, float(u[k, 1]), int(u_t[k, 1]))
        out_i[k, 3] = rules.watchdog_faults(th, s, int(now[k]))
        out_i[k, 8] = rules.late_faults(th, s, int(now[k]))
        out_i[k, 9] = rules.late_command(th, s, 0, int(now[k]))
        out_i[k, 10] = rules.late_command(th, s, 1, int(now[k]))
        out_i[k, 4] = rules.update_zone(th, s, d)
        out_i[k, 5] = rules.sensor_key_axes(keys)
        out_f[k, 0] = rules.output_v(th, s, 0, int(blocked[k, 0]), int(now[k]))
        out_f[k, 1] = rules.output_v(th, s, 1, int(blocked[k, 1]), int(now[k]))
        out_f[k, 2] = d.jump_deviation if keys & (1 << rules.ENCODER_JUMP) else 0.0
        out_f[k, 3] = d.speed_rpm if keys & (1 << rules.OVERSPEED) else 0.0
        out_f[k, 4] = d.braking_m if out_i[k, 4] else 0.0
        out_f[k, 5] = d.braking_rad if out_i[k, 4] & _ANGLE_ZONE else 0.0
        out_f[k, 6] = d.stall_u if keys & (1 << rules.NO_ROTATION) else 0.0
        out_i[k, 6] = d.nf_fields
        out_i[k, 7] = d.nf_volts if have[k] else 0
    return out_i, out_f


# one step of the stream: values near and beyond every threshold
_pressure_lin = st.sampled_from([2.5e5, 2.4e5, P_LIN, math.nextafter(P_LIN, 1e9), *BAD])
_pressure_rot = st.sampled_from([1.8e5, P.stall_inlet_pa, P.stall_inlet_pa + 1.0, P_ROT + 1, *BAD])
_x = st.sampled_from([0.0, 0.01, 0.05, X_HI, X_HI - 1e-9, -X_HI, 0.08, -0.0801, *BAD])
_volt = st.sampled_from([2.0, 2.0001, -0.3, 10.3, 5.3, 5.31, -0.31, 11.0, *BAD])
_step = st.tuples(
    st.tuples(
        _pressure_lin,
        _pressure_lin,
        _pressure_rot,
        _x,
        st.sampled_from([0.0, *BAD]),
        st.sampled_from([0.0, 1.0, *BAD]),
    ),
    st.sampled_from([0, 0, 1, 20, 100, 101, 1000, -50, -120]),  # counts step
    st.tuples(_volt, _volt, _volt, _volt),
    st.booleans(),  # raw volts given
    st.tuples(
        st.sampled_from([7.0, 3.0, 0.0, 10.0, -0.001, 10.001, *BAD]),
        # rotary: inside and beyond the stall band both ways, the centre, refused
        st.sampled_from([6.0, 5.0, 5.3, 5.31, 4.7, 4.69, 2.0, 10.0, math.nan]),
    ),
    # stamp offset [periods]: older, future, expired (short and default watchdogs)
    st.sampled_from([0, 0, 0, -3, 1, -5, -6, -21, -50, -51, 40]),
    # output tick [periods after the sample]: fresh, late within and beyond the holds and
    # the watchdogs (short and default)
    st.sampled_from([1, 1, 1, 2, 3, 4, 6, 21, 22, 30, 50, 51]),
    st.tuples(st.integers(0, 1), st.integers(0, 1)),  # axis blocked (latched, e-stop)
    # a command sent for the axis this step (a late controller sends none)
    st.tuples(st.sampled_from([1, 1, 0]), st.sampled_from([1, 1, 0])),
)
_params = st.sampled_from(
    [
        P,
        # the late-command policies: ramp and trip at the defaults, short clocks, no ramp
        dataclasses.replace(P, late_policy="ramp"),
        dataclasses.replace(P, late_policy="trip"),
        dataclasses.replace(
            P, late_policy="ramp", watchdog_ms=5.0, late_hold_ms=3.0, late_ramp_ms=2.0
        ),
        dataclasses.replace(P, late_policy="ramp", late_ramp_ms=0.0, late_hold_ms=0.0),
        dataclasses.replace(P, watchdog_ms=5.0, late_hold_ms=1.0, stuck_ms=3.0),
        dataclasses.replace(P, extend_above_neutral=False, max_accel_rad_s2=0.0, stuck_ms=3.0),
        dataclasses.replace(P, stall_ms=2.0, velocity_window_ms=3.0, speed_window_ms=1.0),
        # angle soft limits at ±25° (≈ 278 counts), the bidirectional stall rule, short clocks
        dataclasses.replace(
            P,
            angle_limits=True,
            angle_min_deg=-30.0,
            angle_max_deg=30.0,
            angle_margin_deg=5.0,
            angle_hyst_deg=0.5,
            max_decel_rad_s2=50.0,
            rotary_plumbing="bidirectional",
            stall_ms=2.0,
            stall_speed_rpm=20.0,
            speed_window_ms=2.0,
        ),
        dataclasses.replace(
            P,
            angle_limits=True,
            angle_min_deg=0.0,
            angle_max_deg=20.0,
            angle_margin_deg=0.0,
            angle_hyst_deg=0.0,
            stall_band_v=0.0,
            stall_ms=1.0,
        ),
    ]
)


def _arrays(steps):
    f = np.array([s[0] for s in steps], dtype=np.float64)
    c = np.cumsum([s[1] for s in steps]).astype(np.int64)
    volts = np.array([s[2] for s in steps], dtype=np.float64)
    have = np.array([s[3] for s in steps], dtype=np.int64)
    u = np.array([s[4] for s in steps], dtype=np.float64)
    k = np.arange(len(steps), dtype=np.int64)
    off = np.array([s[5] for s in steps], dtype=np.int64)
    u_t = np.stack([(k + off) * T_NS, k * T_NS], axis=1)
    now = (k + np.array([s[6] for s in steps], dtype=np.int64)) * T_NS
    blocked = np.array([s[7] for s in steps], dtype=np.int64)
    sent = np.array([s[8] for s in steps], dtype=np.int64)
    return f, c, volts, have, u, u_t, now, blocked, sent


def _same(a, b) -> bool:
    return all(x == y or (x != x and y != y) for x, y in zip(a, b, strict=True))


@settings(max_examples=100, deadline=None)
@given(params=_params, steps=st.lists(_step, min_size=1, max_size=80))
def test_compiled_and_python_rules_decide_the_same(params, steps):
    th = rules.thresholds(params, 1e-3)
    py = (th, rules.STATE.new(), rules.FINDINGS.new())
    arrs = tuple(rules.fresh_array(r.TYPE) for r in py)
    th.store(arrs[0][0])
    data = _arrays(steps)
    n = len(steps)
    out_i, out_f = np.zeros((n, 11), dtype=np.int64), np.zeros((n, 7))
    _drive(*arrs, *data, out_i, out_f)
    want_i, want_f = _python(*py, *data)
    assert np.array_equal(out_i, want_i)
    assert np.array_equal(out_f, want_f, equal_nan=True)
    back = rules.STATE.new()
    back.load(arrs[1][0])
    for name, value in py[1].values().items():  # the whole rule state, bit for bit
        got = getattr(back, name)
        assert _same(got, value) if isinstance(value, list) else _same([got], [value]), name


def test_the_rules_decide_in_a_supervisor_as_in_the_kernels():
    """SafetySupervisor's outputs and present keys are the rules' decisions (not a second copy)."""
    sup = SafetySupervisor(P, sample_time_s=1e-3)
    th, s, d = rules.thresholds(P, 1e-3), rules.STATE.new(), rules.FINDINGS.new()
    from pneu_msgs_py.contract.samples import SensorSample

    for k, x in enumerate([0.0, 0.02, 0.06, X_HI, 0.0801, 0.0]):
        smp = SensorSample(k, k * T_NS, 2.5e5 + k, 2.4e5 - k, 1.8e5 + k, x, 0.0, 0.0, 0)
        sup.check_sample(smp)
        keys = rules.non_finite_fields(d, 2.5e5 + k, 2.4e5 - k, 1.8e5 + k, x, 0.0, 0.0)
        keys |= rules.sample_faults(
            th,
            s,
            d,
            k * T_NS,
            2.5e5 + k,
            2.4e5 - k,
            1.8e5 + k,
            x,
            0,
            (2.5e5 + k, 2.4e5 - k, 1.8e5 + k, x),
            False,
        )
        present = {key for bit, key in enumerate(rules.SENSOR_KEYS) if keys >> bit & 1}
        assert set(sup.status["linear"].present) | set(sup.status["rotary"].present) == present


def test_fault_key_table():
    assert len(rules.SENSOR_KEYS) == len(set(rules.SENSOR_KEYS)) == 22
    assert rules.SENSOR_KEYS[rules.NON_FINITE_ENCODER] == "non_finite:encoder"
    assert rules.SENSOR_KEYS[rules.LIVE_RANGE + 3] == "live_range:x"
    assert rules.SENSOR_KEYS[rules.OVER_PRESSURE + 2] == "over_pressure:p_m1"
    assert rules.SENSOR_KEYS[rules.STROKE_LIMIT] == "stroke_limit:x"
    assert rules.SENSOR_KEYS[rules.STUCK] == "stuck:p_c1"
    assert rules.SENSOR_KEYS[rules.NO_ROTATION] == "no_rotation:encoder"
    assert rules.SENSOR_KEYS[rules.ANGLE_LIMIT] == "angle_limit:encoder"
    assert rules.sensor_key_axes(1 << rules.ANGLE_LIMIT | 1 << rules.NO_ROTATION) == 2
    assert rules.LINEAR_KEYS & rules.ROTARY_KEYS == 0
    assert rules.LINEAR_KEYS | rules.ROTARY_KEYS == (1 << len(rules.SENSOR_KEYS)) - 1
    assert rules.sensor_key_axes(1 << (rules.STUCK + 2)) == 2  # p_m1: the motor's sensor
    assert rules.sensor_key_axes(1 << rules.POSITION_RANGE | 1 << rules.OVERSPEED) == 3


def test_a_window_longer_than_the_rings_is_refused_naming_the_field():
    rules.thresholds(P, 1e-5)  # the default 10 ms at the shortest sim period: 1000 periods
    with pytest.raises(
        ValueError, match=r"^velocity_window_ms: 10\.0 refused; allowed: \(0, 5\] ms"
    ):
        SafetySupervisor(P, sample_time_s=5e-6)
    long = dataclasses.replace(P, speed_window_ms=1000.0)
    rules.thresholds(long, 1e-3)
    with pytest.raises(ValueError, match=r"^speed_window_ms: 1000\.0 refused"):
        rules.thresholds(long, 2e-4)


def test_int_array_fields_round_trip():
    rt = RecordType("R", [("t", ("i", 3)), ("v", ("f", 2), [math.nan, 1.0])])
    r = rt.new()
    assert r.t == [0, 0, 0] and all(isinstance(v, int) for v in r.t)
    r.t[1] = 2**62 + 1  # an int ns stamp beyond float64's 2^53
    arr = rules.fresh_array(rt)
    assert math.isnan(arr[0]["v"][0]) and arr[0]["v"][1] == 1.0
    r.store(arr[0])
    back = rt.new()
    back.load(arr[0])
    assert back.t == [0, 2**62 + 1, 0] and arr.dtype["t"].base == np.int64


def _run_both(params, steps):
    th = rules.thresholds(params, 1e-3)
    py = (th, rules.STATE.new(), rules.FINDINGS.new())
    arrs = tuple(rules.fresh_array(r.TYPE) for r in py)
    th.store(arrs[0][0])
    data = _arrays(steps)
    n = len(steps)
    out_i, out_f = np.zeros((n, 11), dtype=np.int64), np.zeros((n, 7))
    _drive(*arrs, *data, out_i, out_f)
    want_i, want_f = _python(*py, *data)
    assert np.array_equal(out_i, want_i)
    assert np.array_equal(out_f, want_f, equal_nan=True)
    return want_i, want_f


def test_the_rotary_rules_act_alike_in_a_stream_made_to_reach_them():
    """Angle zone in and out, the angle trip, both stall directions: compiled = Python."""
    params = dataclasses.replace(
        P,
        angle_limits=True,
        angle_min_deg=-30.0,
        angle_max_deg=30.0,
        angle_margin_deg=5.0,
        max_decel_rad_s2=50.0,
        rotary_plumbing="bidirectional",
        stall_ms=2.0,
        stall_speed_rpm=20.0,
        speed_window_ms=2.0,
    )

    def step(dc, u_rot, p_m1=3.0e5):
        f = (2.5e5, 2.4e5, p_m1, 0.0, 0.0, 0.0)
        return (f, dc, (2.0, 2.0, 2.0, 2.0), True, (5.0, u_rot), 0, 1, (0, 0), (1, 1))

    # forward at 20 counts/ms (300 rpm) into the +25° zone, on past it (trip), back out
    steps = [step(20, 8.0) for _ in range(20)]
    steps += [step(-20, 2.0) for _ in range(20)]
    steps += [step(0, 2.0) for _ in range(8)]  # reverse drive, not turning: stall
    steps += [step(0, 5.2) for _ in range(8)]  # inside the band: no clock
    steps += [step(0, 8.0, p_m1=1.5e5) for _ in range(8)]  # forward, inlet low: no clock
    steps += [step(0, 8.0) for _ in range(8)]  # forward, inlet high: stall
    keys, out_f = _run_both(params, steps)
    zone = keys[:, 4]
    assert zone.tolist().count(rules.ANGLE_HI_ENTERED) == 1
    assert any(z & rules.ANGLE_HI_LEFT for z in zone)
    k_in = int(np.argmax(zone == rules.ANGLE_HI_ENTERED))
    assert out_f[k_in, 1] == 5.0 and out_f[k_in - 1, 1] == 8.0  # forward held at 5 V
    trip = (keys[:, 0] >> rules.ANGLE_LIMIT) & 1
    c = np.cumsum([s[1] for s in steps])
    assert np.array_equal(trip == 1, np.abs(c * 360.0 / 4000) >= 25.0)
    stall = (keys[:, 0] >> rules.NO_ROTATION) & 1
    # sample k sees the valve of tick k - 1. Reverse: the 2 ms speed window is quiet from
    # k = 42, the clock runs 2 ms (passes), trips at 45 and until the valve is inside the band
    assert stall[40:49].tolist() == [0, 0, 0, 0, 0, 1, 1, 1, 1]
    assert not stall[49:64].any()
    assert stall[64:].tolist() == [0, 0, 0, 1, 1, 1, 1, 1]  # forward: from the inlet high
    assert set(out_f[stall == 1, 6]) == {2.0, 8.0}  # the driving voltage, each way


@pytest.mark.parametrize("policy", ["hold", "ramp", "trip"])
def test_the_late_rules_act_alike_in_a_stream_made_to_reach_them(policy):
    """The linear controller falls silent for longer than the watchdog after 5 fresh ticks:
    held or ramped, then 5 V, the trip bit, the counts, compiled = Python."""
    params = dataclasses.replace(P, late_policy=policy)
    hold, wd = round(params.late_hold_ms), round(params.watchdog_ms)

    def step(sent):
        f = (2.5e5, 2.4e5, 1.8e5, 0.0, 0.0, 0.0)
        return (f, 0, (2.0, 2.0, 2.0, 2.0), True, (9.0, 6.0), 0, 1, (0, 0), (sent, 1))

    steps = [step(1) for _ in range(5)] + [step(0) for _ in range(wd + 5)]
    keys, out_f = _run_both(params, steps)
    lin = out_f[5:, 0]  # late by 1, 2, ... periods
    ramp = params.late_ramp_ms
    want = {
        "hold": [9.0] * hold,
        "ramp": [9.0 - 4.0 * min(m / ramp, 1.0) for m in range(1, hold + 1)],
        "trip": [5.0] * hold,  # 5 V from the first late tick (and latched by the caller)
    }[policy]
    assert lin[:hold] == pytest.approx(want, abs=1e-12)
    assert lin[hold:].tolist() == [5.0] * (len(lin) - hold)
    assert out_f[:, 1].tolist() == [6.0] * len(steps)  # the rotary answers on time
    assert keys[:, 8].tolist() == [0] * 5 + [1 if policy == "trip" else 0] * (wd + 5)
    assert keys[:, 9].tolist() == [rules.LATE_NO] * 5 + [
        {"hold": rules.LATE_HOLD, "ramp": rules.LATE_RAMP, "trip": rules.LATE_CLOSED}[policy]
    ] * hold + [rules.LATE_CLOSED] * (wd + 5 - hold)
    assert keys[:, 3].tolist() == [0] * (5 + wd - 1) + [1] * 6  # the watchdog from the wd-th
