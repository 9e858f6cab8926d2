"""The safety supervisor's decision rules, written once, as kernels on records.

Every comparison of a sample or a command against a threshold is here, as a
:func:`~pneu_msgs_py.params.records.kernel` (plain Python from Python, compiled
into numba callers) on three records:

- ``th``, :data:`THRESHOLDS`: what the rules compare against, derived once from
  :class:`~pneu_driver.safety.params.SafetyParams` (:func:`thresholds`);
- ``s``, :data:`STATE`: what the rules remember (the velocity and speed windows,
  the last encoder step, the frozen values and since when, the stall clock, the
  stroke and angle soft-limit zones, the last command and the last output per axis,
  the pending refusals, the late, held and ramped ticks per axis);
- ``d``, :data:`FINDINGS`: the numbers behind a rule that fired this call (for
  the message), written only when it fires (``nf_fields``/``nf_volts`` always).

A rule returns a decision, never a message: the fault keys present as a bit mask
(:data:`SENSOR_KEYS`; bit ``a`` = axis ``a`` for the watchdog), or a code of what
changed (:func:`update_zone`, :func:`command`), or what a late command becomes
(:func:`late_command`; DESIGN §14). Two callers, one source:
:class:`~pneu_driver.safety.supervisor.SafetySupervisor` (events, messages,
latches, acknowledge) and the compiled closed loop's adapter
(:mod:`pneu_control.fastloop.supervisor`: latches as bits, the event flag).

Axes are indices here: 0 linear, 1 rotary (``AXES`` order). Stamps are int ns.
Each rule is "> threshold": a value exactly at it passes (``>=`` for the soft limits).

The rotary axis's direction: valve #2 above 5 V feeds motor port A and turns the motor
toward +θ (encoder counts up), below 5 V toward −θ only with the bidirectional plumbing
(port 2 on port B; with the paper's plumbing it vents the inlet): what every rotary
controller assumes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from pneu_msgs_py.contract.samples import AXES, U_MAX_V, U_MIN_V
from pneu_msgs_py.params.records import Record, RecordType, kernel

from pneu_driver.safety.events import SAFE_V, SENSOR_AXIS

__all__ = [
    "ANALOG",
    "FIELDS",
    "FINDINGS",
    "LATE_POLICIES",
    "SENSOR_KEYS",
    "STATE",
    "THRESHOLDS",
    "WINDOW_MAX",
    "angle_faults",
    "angle_zone",
    "chamber_vented",
    "command",
    "fresh_array",
    "inlet_vented",
    "jump_allowance",
    "late_command",
    "late_faults",
    "non_finite_fields",
    "output_v",
    "sample_faults",
    "sensor_key_axes",
    "stall_fault",
    "stroke_zone",
    "thresholds",
    "update_zone",
    "watchdog_faults",
]

# longest velocity / speed window in sample periods (the rings hold WINDOW_MAX + 1
# samples): every window SafetyParams allows (≤ 1000 ms) at 1 ms, the default 10 ms
# down to the shortest sim period (1e-5 s)
WINDOW_MAX = 1000
_W = WINDOW_MAX + 1
_TWO_PI = 2.0 * math.pi

ANALOG = ("p_c1", "p_c2", "p_m1", "x")  # the analog channels (raw volts order; laser = x)
# the pressure sensors' lowest output: Huba 511, 0-10 V for 0-10 bar gauge (rig.yaml); at or
# below atmosphere the reading clips here
P_FLOOR_V = 0.0
FIELDS = ("p_c1", "p_c2", "p_m1", "x", "theta", "omega")  # sample fields checked finite
FIELD_SENSOR = ("p_c1", "p_c2", "p_m1", "x", "encoder", "encoder")

# ------------------------------------------------------------ sensor fault keys, one bit each
NON_FINITE = 0  # non_finite:<p_c1|p_c2|p_m1|x>, bits 0..3; non_finite:encoder, bit 4
NON_FINITE_ENCODER = 4
LIVE_RANGE = 5  # live_range:<analog>, bits 5..8
OVER_PRESSURE = 9  # over_pressure:<p_c1|p_c2|p_m1>, bits 9..11
POSITION_RANGE = 12  # position_range:x
STROKE_LIMIT = 13  # stroke_limit:x (the piston at or beyond a soft limit)
STUCK = 14  # stuck:<analog>, bits 14..17
ENCODER_JUMP = 18  # encoder_jump:encoder
OVERSPEED = 19  # overspeed (not a sensor fault: no sensor in its key)
NO_ROTATION = 20  # no_rotation:encoder
ANGLE_LIMIT = 21  # angle_limit:encoder (the motor at or beyond an angle soft limit)
SENSOR_KEYS = (
    *(f"non_finite:{s}" for s in (*ANALOG, "encoder")),
    *(f"live_range:{s}" for s in ANALOG),
    *(f"over_pressure:{s}" for s in ANALOG[:3]),
    "position_range:x",
    "stroke_limit:x",
    *(f"stuck:{s}" for s in ANALOG),
    "encoder_jump:encoder",
    "overspeed",
    "no_rotation:encoder",
    "angle_limit:encoder",
)
KEY_SENSOR = tuple(k.split(":")[1] if ":" in k else "encoder" for k in SENSOR_KEYS)
KEY_AXIS = tuple(SENSOR_AXIS[s] for s in KEY_SENSOR)
LINEAR_KEYS = sum(1 << i for i, a in enumerate(KEY_AXIS) if a == AXES[0])
ROTARY_KEYS = sum(1 << i for i, a in enumerate(KEY_AXIS) if a == AXES[1])

# what update_zone changed: the stroke soft limits, then the angle soft limits
ZONE_HI_ENTERED, ZONE_HI_LEFT, ZONE_LO_ENTERED, ZONE_LO_LEFT = 1, 2, 4, 8
ANGLE_HI_ENTERED, ANGLE_HI_LEFT, ANGLE_LO_ENTERED, ANGLE_LO_LEFT = 16, 32, 64, 128
# what command did
CMD_REFUSED = 1  # outside [U_MIN_V, U_MAX_V] or NaN: not taken, output_sanity present
CMD_REFUSAL_GONE = 2  # a good command after a refused one: output_sanity gone
CMD_STALE = 4  # older than the last accepted one: ignored
CMD_FIRST = 8  # the axis's first accepted command (or the first after an acknowledge)
CMD_FUTURE = 16  # stamped for a sample not yet taken (or before any sample): not taken
CMD_EXPIRED = 32  # answering a sample older than the watchdog: not taken
# the late-command policy (SafetyParams.late_policy: its code is the index here)
LATE_POLICIES = ("hold", "ramp", "trip")
POLICY_HOLD, POLICY_RAMP, POLICY_TRIP = 0, 1, 2
# what late_command makes of an axis' last command at a tick
LATE_NO = 0  # fresh (one period old: it answers the newest sample), or no command yet
LATE_HOLD = 1  # late, within late_hold_ns: the last command is written (hold)
LATE_RAMP = 2  # late, within late_hold_ns: ramped toward SAFE_V (ramp)
LATE_CLOSED = 3  # late beyond late_hold_ns, or the trip policy: SAFE_V

# ------------------------------------------------------------------ records
THRESHOLDS = RecordType(
    "SafetyThresholds",
    [
        ("T_ns", "i"),  # sample period
        ("watchdog_ns", "i"),
        ("late_policy", "i"),  # POLICY_HOLD | POLICY_RAMP | POLICY_TRIP
        ("late_hold_ns", "i"),
        ("late_ramp_ns", "i"),
        ("stuck_ns", "i"),
        ("stall_ns", "i"),
        ("x_hi", "f"),  # soft limits [m]
        ("x_lo", "f"),
        ("x_abs_max", "f"),  # |x| beyond this is implausible [m]
        ("p_max_c1", "f"),  # supply + margin [Pa]
        ("p_max_c2", "f"),
        ("p_max_m1", "f"),
        ("p_live_lo", "f"),  # pressure sensors' live range [V]
        ("p_live_hi", "f"),
        ("x_live_lo", "f"),  # laser's live range [V]
        ("x_live_hi", "f"),
        ("u_toward_hi", "f"),  # +1: above SAFE_V drives toward +x
        ("max_decel_m_s2", "f"),
        ("stroke_hyst_m", "f"),
        ("max_speed_rpm", "f"),
        ("max_accel_rad_s2", "f"),
        ("counts_per_rev", "i"),
        ("encoder_slack_counts", "i"),
        ("stall_inlet_pa", "f"),
        ("stall_band_v", "f"),  # valve #2 beyond SAFE_V ± this drives the motor [V]
        ("stall_omega", "f"),  # |speed| below this is not turning [rad/s]
        ("stall_reverse", "i"),  # 1: below SAFE_V drives too (bidirectional plumbing)
        ("rad_per_count", "f"),  # 2π / counts_per_rev
        ("th_hi", "f"),  # angle soft limits [rad] (±inf: off)
        ("th_lo", "f"),
        ("angle_hyst", "f"),  # [rad]
        ("angle_lag_s", "f"),
        ("max_decel_rad_s2", "f"),
        ("rot_idle_v", "f"),  # valve #2's output that does not turn the motor [V]
        ("n_xw", "i"),  # velocity window: samples held (periods + 1)
        ("n_cw", "i"),  # speed window: samples held
    ],
)
STATE = RecordType(
    "SafetyRuleState",
    [
        ("have_sample", "i"),
        ("sample_t", "i"),  # stamp of the newest sample checked [ns]
        ("x", "f"),  # last finite position (NaN after a non-finite one) [m]
        ("v", "f", 0.0),  # piston velocity over the window [m/s]
        ("xw_t", ("i", _W)),  # velocity window ring: stamps, positions
        ("xw_x", ("f", _W)),
        ("xw_head", "i"),
        ("xw_n", "i"),
        ("cw_t", ("i", _W)),  # speed window ring: stamps, counts
        ("cw_c", ("i", _W)),
        ("cw_head", "i"),
        ("cw_n", "i"),
        ("enc_have", "i"),  # previous encoder sample: counts, stamp, counts/period
        ("enc_c", "i"),
        ("enc_t", "i"),
        ("enc_has_rate", "i"),
        ("enc_rate", "f", 0.0),
        ("frozen_v", ("f", 4), [math.nan] * 4),  # per analog channel: last value (NaN: fresh)
        ("frozen_t", ("i", 4)),  # and since when it holds it
        ("w", "f", 0.0),  # motor speed over the speed window [rad/s]
        ("stall_have", "i"),  # the stall clock runs: driven and not turning since stall_since
        ("stall_since", "i"),
        ("zone_hi", "i"),  # stroke soft-limit hold active
        ("zone_lo", "i"),
        ("azone_hi", "i"),  # angle soft-limit hold active
        ("azone_lo", "i"),
        ("cmd_have", ("i", 2)),  # per axis: a command accepted (0 after acknowledging a watchdog)
        ("cmd_u", ("f", 2)),
        ("cmd_t", ("i", 2)),
        ("refused", "i"),  # bit a: axis a's last command was refused (output_sanity present)
        ("u_out", ("f", 2), [SAFE_V, SAFE_V]),  # per axis: the last output (held since) [V]
        ("late_ticks", ("i", 2)),  # per axis: ticks with a late command, until the watchdog's
        ("held_ticks", ("i", 2)),  # ... of them written held (hold) / ramped (ramp)
        ("ramped_ticks", ("i", 2)),
    ],
)
FINDINGS = RecordType(
    "SafetyFindings",
    [
        ("nf_fields", "i"),  # bit i: FIELDS[i] not finite (written on every call)
        ("nf_volts", "i"),  # bit i: voltage i not finite (written on every call with volts)
        ("jump_counts", "i"),  # encoder_jump: the step, what the speed predicts, ± allowed
        ("jump_predicted", "f"),
        ("jump_deviation", "f"),
        ("jump_allowed", "f"),
        ("speed_rpm", "f"),  # overspeed
        ("braking_m", "f"),  # update_zone: v²/(2a)
        ("braking_rad", "f"),  # update_zone: ω²/(2a)
        ("stall_u", "f"),  # no_rotation: the valve voltage driving the motor
    ],
)


def thresholds(params: Any, sample_time_s: float) -> Record:
    """The :data:`THRESHOLDS` record of validated ``params`` at ``sample_time_s`` [s] (> 0)."""
    p = params
    half = p.stroke_m / 2.0
    x_hi = half - p.stroke_margin_m
    windows = []
    for name in ("velocity_window_ms", "speed_window_ms"):
        ms = getattr(p, name)
        n = max(1, round(ms * 1e-3 / sample_time_s))
        if n > WINDOW_MAX:
            raise ValueError(
                f"{name}: {ms!r} refused; allowed: (0, {WINDOW_MAX * sample_time_s * 1e3:g}] ms "
                f"(at most {WINDOW_MAX} sample periods of {sample_time_s!r} s)"
            )
        windows.append(n + 1)
    lin = p.supply_linear_pa + p.pressure_margin_pa
    both = p.rotary_plumbing == "bidirectional"
    th_hi, th_lo = math.inf, -math.inf
    if p.angle_limits:
        th_hi = math.radians(p.angle_max_deg - p.angle_margin_deg)
        th_lo = math.radians(p.angle_min_deg + p.angle_margin_deg)
    return THRESHOLDS.new(
        T_ns=round(sample_time_s * 1e9),
        watchdog_ns=round(p.watchdog_ms * 1e6),
        late_policy=LATE_POLICIES.index(p.late_policy),
        late_hold_ns=round(p.late_hold_ms * 1e6),
        late_ramp_ns=round(p.late_ramp_ms * 1e6),
        stuck_ns=round(p.stuck_ms * 1e6),
        stall_ns=round(p.stall_ms * 1e6),
        x_hi=x_hi,
        x_lo=-x_hi,
        x_abs_max=half + p.position_margin_m,
        p_max_c1=lin,
        p_max_c2=lin,
        p_max_m1=p.supply_rotary_pa + p.pressure_margin_pa,
        p_live_lo=p.pressure_live_v[0],
        p_live_hi=p.pressure_live_v[1],
        x_live_lo=p.laser_live_v[0],
        x_live_hi=p.laser_live_v[1],
        u_toward_hi=1.0 if p.extend_above_neutral else -1.0,
        max_decel_m_s2=p.max_decel_m_s2,
        stroke_hyst_m=p.stroke_hyst_m,
        max_speed_rpm=p.max_speed_rpm,
        max_accel_rad_s2=p.max_accel_rad_s2,
        counts_per_rev=p.counts_per_rev,
        encoder_slack_counts=p.encoder_slack_counts,
        stall_inlet_pa=p.stall_inlet_pa,
        stall_band_v=p.stall_band_bidir_v if both else p.stall_band_v,
        stall_omega=p.stall_speed_rpm * _TWO_PI / 60.0,
        stall_reverse=1 if both else 0,
        rad_per_count=_TWO_PI / p.counts_per_rev,
        th_hi=th_hi,
        th_lo=th_lo,
        angle_hyst=math.radians(p.angle_hyst_deg),
        angle_lag_s=p.angle_lag_ms * 1e-3,
        max_decel_rad_s2=p.max_decel_rad_s2,
        rot_idle_v=SAFE_V if both else U_MIN_V,
        n_xw=windows[0],
        n_cw=windows[1],
    )


def fresh_array(rt: RecordType) -> np.ndarray:
    """One record of ``rt`` as a structured array (for numba), every field at its default."""
    arr = rt.array(1)
    for name, kind, default in rt.defaults:
        if isinstance(kind, tuple):
            if any(default):
                arr[0][name][: len(default)] = default
        elif default != 0:  # NaN included
            arr[0][name] = default
    return arr


# ------------------------------------------------------------------ sample rules
@kernel
def non_finite_fields(d, p_c1, p_c2, p_m1, x, theta, omega):
    """NaN/inf sample fields: their ``non_finite`` keys; ``d.nf_fields`` which ones."""
    d.nf_fields = 0
    if math.isfinite(p_c1 + p_c2 + p_m1 + x + theta + omega):  # fast screen
        return 0
    bits = 0
    if not math.isfinite(p_c1):
        bits |= 1
    if not math.isfinite(p_c2):
        bits |= 2
    if not math.isfinite(p_m1):
        bits |= 4
    if not math.isfinite(x):
        bits |= 8
    if not math.isfinite(theta):
        bits |= 16
    if not math.isfinite(omega):
        bits |= 32
    d.nf_fields = bits
    return (bits & 15) << NON_FINITE | (1 << NON_FINITE_ENCODER if bits & 48 else 0)


@kernel
def _voltage_fault(v, lo, hi, i):
    """Channel i's voltage: non-finite, outside [lo, hi] (its keys), or live (0)."""
    if not math.isfinite(v):
        return 1 << (NON_FINITE + i)
    if v < lo or v > hi:
        return 1 << (LIVE_RANGE + i)
    return 0


@kernel
def voltage_faults(th, d, volts):
    """Raw volts (p_c1, p_c2, p_m1, laser) outside their sensors' live ranges, or non-finite."""
    d.nf_volts = 0
    plo = th.p_live_lo
    phi = th.p_live_hi
    v0 = volts[0]
    v1 = volts[1]
    v2 = volts[2]
    v3 = volts[3]
    if plo <= v0 <= phi and plo <= v1 <= phi and plo <= v2 <= phi:  # fast screen (NaN fails)
        if th.x_live_lo <= v3 <= th.x_live_hi:
            return 0
    keys = _voltage_fault(v0, plo, phi, 0)
    keys |= _voltage_fault(v1, plo, phi, 1)
    keys |= _voltage_fault(v2, plo, phi, 2)
    keys |= _voltage_fault(v3, th.x_live_lo, th.x_live_hi, 3)
    d.nf_volts = (keys >> NON_FINITE) & 15
    return keys


@kernel
def pressure_faults(th, p_c1, p_c2, p_m1):
    """A pressure above its supply + margin."""
    keys = 0
    if p_c1 > th.p_max_c1:
        keys |= 1 << OVER_PRESSURE
    if p_c2 > th.p_max_c2:
        keys |= 1 << (OVER_PRESSURE + 1)
    if p_m1 > th.p_max_m1:
        keys |= 1 << (OVER_PRESSURE + 2)
    return keys


@kernel
def position_faults(th, x):
    """|x| beyond the end stops + margin; else the piston at or beyond a soft limit (the hold
    did not stop it: the trapped air can push it on, see the supervisor's docstring)."""
    if abs(x) > th.x_abs_max:
        return 1 << POSITION_RANGE
    if x >= th.x_hi or x <= th.x_lo:
        return 1 << STROKE_LIMIT
    return 0


@kernel
def angle_faults(th, c):
    """The motor at or beyond an angle soft limit (counts ``c``; the hold did not stop it:
    inertia, a load driving it on)."""
    theta = c * th.rad_per_count
    if theta >= th.th_hi or theta <= th.th_lo:
        return 1 << ANGLE_LIMIT
    return 0


@kernel
def inlet_vented(th, s):
    """Valve #2 held below SAFE_V − the stall band (``s.u_out[1]``, the last period's output):
    motor port A, the inlet p_m1, is open to the valve's exhaust (both plumbings)."""
    return SAFE_V - s.u_out[1] > th.stall_band_v


@kernel
def chamber_vented(th, s, i):
    """Valve #1 held beyond SAFE_V ± the stall band (``s.u_out[0]``) toward the exhaust of
    cylinder chamber ``i`` (0: chamber 1, p_c1, below 5 V; 1: chamber 2, p_c2, above): the
    MPYE's flow chart gives ≤ 1 % of its flow inside 0.36 V, the band of both valves."""
    d = s.u_out[0] - SAFE_V
    return (d if i == 1 else -d) > th.stall_band_v


@kernel
def frozen_faults(th, s, now, values, have_volts):
    """An analog value (``values``: the raw volts, else the SI values) bit-identical for
    longer than ``stuck_ms``.

    Not frozen: a pressure's raw reading at or below :data:`P_FLOOR_V` while its valve vents
    that volume (the inlet: :func:`inlet_vented`; a cylinder chamber: :func:`chamber_vented`):
    at atmosphere a 0–10 V gauge sensor's output clips at its zero, a constant that a live
    sensor gives (the paper's plumbing holds the inlet vented at 0 V; a rod held against a
    load near the cylinder's force keeps the other chamber vented). Its clock stands still
    in such samples: a reading stuck at 0 V trips once the volume has been not vented for
    ``stuck_ms`` in all since the reading froze (fed or closed, its pressure rises; a valve
    crossing the band back and forth does not hide a dead sensor), a reading stuck anywhere
    else as before. Without raw volts, no exemption.
    """
    keys = 0
    for i in range(4):
        v = values[i]
        vented = False
        if have_volts and i < 3 and v <= P_FLOOR_V:
            vented = inlet_vented(th, s) if i == 2 else chamber_vented(th, s, i)
        if v != s.frozen_v[i]:
            s.frozen_v[i] = v
            s.frozen_t[i] = now
        elif vented:  # only the time not vented counts (v unchanged: a previous sample)
            s.frozen_t[i] += now - s.sample_t
        elif now - s.frozen_t[i] > th.stuck_ns:
            keys |= 1 << (STUCK + i)
    return keys


@kernel
def _ring(head, n, size):
    """``deque(maxlen=size).append`` on a ring: (slot to write, next head, count, oldest slot)."""
    nxt = head + 1
    if nxt == size:
        nxt = 0
    if n < size:
        n += 1
    return head, nxt, n, (nxt if n == size else 0)


@kernel
def track_velocity(th, s, now, x):
    """Piston velocity over the velocity window (for the braking distance); NaN x: unknown."""
    if not math.isfinite(x):
        s.x = math.nan
        return
    j, s.xw_head, s.xw_n, o = _ring(s.xw_head, s.xw_n, th.n_xw)
    s.xw_t[j] = now
    s.xw_x[j] = x
    t0 = s.xw_t[o]
    s.v = (x - s.xw_x[o]) / ((now - t0) * 1e-9) if now > t0 else 0.0
    s.x = x


@kernel
def jump_allowance(th, dt_ns):
    """Largest plausible deviation [counts] of an encoder step over ``dt_ns`` from the previous
    speed: a_max · Δt² · cpr / 2π (the angle a full acceleration adds) + the quantisation slack."""
    dt_s = dt_ns * 1e-9
    return th.max_accel_rad_s2 * dt_s * dt_s * th.counts_per_rev / _TWO_PI + th.encoder_slack_counts


@kernel
def encoder_faults(th, s, d, now, c):
    """A count step deviating from the previous speed by more than :func:`jump_allowance`;
    |speed| over the speed window above ``max_speed_rpm`` (``s.w``: that speed in rad/s)."""
    keys = 0
    has_rate = 0
    rate = 0.0
    if s.enc_have and now > s.enc_t:
        t0 = s.enc_t
        m = (now - t0) / th.T_ns  # periods since the previous sample
        dc = c - s.enc_c
        if s.enc_has_rate:
            allowed = jump_allowance(th, now - t0)
            predicted = s.enc_rate * m
            deviation = abs(dc - predicted)
            if deviation > allowed:
                keys |= 1 << ENCODER_JUMP
                d.jump_counts = dc
                d.jump_predicted = predicted
                d.jump_deviation = deviation
                d.jump_allowed = allowed
        rate = dc / m
        has_rate = 1
    s.enc_have = 1
    s.enc_c = c
    s.enc_t = now
    s.enc_has_rate = has_rate
    s.enc_rate = rate
    j, s.cw_head, s.cw_n, o = _ring(s.cw_head, s.cw_n, th.n_cw)
    s.cw_t[j] = now
    s.cw_c[j] = c
    t0 = s.cw_t[o]
    s.w = 0.0
    if now > t0:
        rpm = (c - s.cw_c[o]) * 60.0e9 / (th.counts_per_rev * (now - t0))
        s.w = (c - s.cw_c[o]) * th.rad_per_count * 1e9 / (now - t0)
        if abs(rpm) > th.max_speed_rpm:
            keys |= 1 << OVERSPEED
            d.speed_rpm = rpm
    return keys


@kernel
def stall_fault(th, s, d, now, p_m1):
    """Dead encoder or blocked rotor: the motor driven, yet |speed| over the speed window
    below ``stall_omega`` for longer than ``stall_ns``.

    Driven: the valve held during the last period (``s.u_out[1]``) beyond SAFE_V ±
    ``stall_band_v`` (the paper's or the bidirectional plumbing's band) toward a port that drives: forward (above) with the inlet p_m1 above
    ``stall_inlet_pa`` (the torque is there), reverse (below) only with the bidirectional
    plumbing and from the valve alone (port B's pressure p_m2 is not measured). Inside the
    band (holding an angle, both chambers trapped) the clock does not run; a breakaway that
    turns the motor within ``stall_ns`` restarts it.
    """
    du = s.u_out[1] - SAFE_V
    driven = (du > th.stall_band_v and p_m1 > th.stall_inlet_pa) or (
        th.stall_reverse != 0 and -du > th.stall_band_v
    )
    if not driven or abs(s.w) >= th.stall_omega or not s.stall_have:
        s.stall_have = 1 if driven else 0
        s.stall_since = now
        return 0
    if now - s.stall_since > th.stall_ns:
        d.stall_u = s.u_out[1]
        return 1 << NO_ROTATION
    return 0


@kernel
def sample_faults(th, s, d, now, p_c1, p_c2, p_m1, x, c, values, have_volts):
    """Every sample rule but :func:`non_finite_fields`, in order; the sensor keys present.

    ``values``: the raw volts (p_c1, p_c2, p_m1, laser) when ``have_volts``, else the SI
    values (p_c1, p_c2, p_m1, x), watched for freezing; ``c``: the encoder counts.
    """
    keys = 0
    if have_volts:
        keys |= voltage_faults(th, d, values)
    keys |= pressure_faults(th, p_c1, p_c2, p_m1)
    keys |= position_faults(th, x)
    keys |= frozen_faults(th, s, now, values, have_volts)
    track_velocity(th, s, now, x)
    keys |= encoder_faults(th, s, d, now, c)
    keys |= angle_faults(th, c)
    keys |= stall_fault(th, s, d, now, p_m1)
    s.have_sample = 1
    s.sample_t = now
    return keys


@kernel
def sensor_key_axes(keys):
    """The axes (bit 0 linear, bit 1 rotary) that sensor fault ``keys`` make safe."""
    return (1 if keys & LINEAR_KEYS else 0) | (2 if keys & ROTARY_KEYS else 0)


# ------------------------------------------------------------------ commands and outputs
@kernel
def command(th, s, axis, u, stamp):
    """Axis ``axis``'s command ``u`` [V] answering the sample stamped ``stamp``: what it did
    (``CMD_*`` bits; 0: taken, nothing to report). A command answers a sample that was
    taken: one stamped after the newest sample (a clock gone wrong, or a publisher that is
    not a controller) or older than the watchdog (a replay) is not taken and keeps no
    watchdog alive (DESIGN §3)."""
    if not s.have_sample or stamp > s.sample_t:
        return CMD_FUTURE
    if s.sample_t - stamp > th.watchdog_ns:
        return CMD_EXPIRED
    bit = 1 << axis
    if not (U_MIN_V <= u <= U_MAX_V):  # NaN fails every comparison; ±inf is out of range
        s.refused |= bit
        return CMD_REFUSED
    out = 0
    if s.refused & bit:
        s.refused &= ~bit
        out = CMD_REFUSAL_GONE
    if s.cmd_have[axis] and stamp < s.cmd_t[axis]:
        return out | CMD_STALE
    if not s.cmd_have[axis]:
        out |= CMD_FIRST
    s.cmd_u[axis] = u
    s.cmd_t[axis] = stamp
    s.cmd_have[axis] = 1
    return out


@kernel
def watchdog_faults(th, s, now):
    """Bit a: axis a's last command is older than ``watchdog_ns`` at ``now``."""
    keys = 0
    for a in range(2):
        if s.cmd_have[a] and now - s.cmd_t[a] > th.watchdog_ns:
            keys |= 1 << a
    return keys


@kernel
def late_command(th, s, axis, now):
    """What the late-command policy makes of axis ``axis``'s last command at the tick whose
    output takes effect at ``now`` (a ``LATE_*`` code; pure).

    Fresh: one period old (``now`` − its stamp ≤ ``T_ns``), i.e. the answer to the newest
    sample the controller could answer (DESIGN §3). Older, by ``late`` = age − ``T_ns``:
    within ``late_hold_ns`` it is held (``hold``) or ramped (``ramp``), beyond it (and at
    once with ``trip``) the output is SAFE_V. Not latched here: :func:`late_faults` (trip)
    and :func:`watchdog_faults` (gone) latch (DESIGN §14).
    """
    if not (s.cmd_have[axis] and s.have_sample):
        return LATE_NO
    late = now - s.cmd_t[axis] - th.T_ns
    if late <= 0:
        return LATE_NO
    if th.late_policy == POLICY_TRIP or late > th.late_hold_ns:
        return LATE_CLOSED
    if th.late_policy == POLICY_RAMP:
        return LATE_RAMP
    return LATE_HOLD


@kernel
def late_faults(th, s, now):
    """Bit a: axis a's command is late at ``now`` under the ``trip`` policy (latched)."""
    keys = 0
    if th.late_policy == POLICY_TRIP:
        for a in range(2):
            if late_command(th, s, a, now) != LATE_NO:
                keys |= 1 << a
    return keys


@kernel
def ramp_v(th, s, axis, now):
    """The ``ramp`` policy's output: the last command u_c moved toward SAFE_V linearly in the
    lateness, u_c + (SAFE_V − u_c)·min(late / late_ramp_ns, 1) [V]."""
    u = s.cmd_u[axis]
    late = now - s.cmd_t[axis] - th.T_ns
    if late >= th.late_ramp_ns:
        return SAFE_V
    return u + (SAFE_V - u) * (late / th.late_ramp_ns)


@kernel
def zone_changes(on_hi, on_lo, pos, vel, brake, lo, hi, hyst):
    """One axis' pair of soft-limit zones, entered where the reach (``pos`` plus the braking
    way ``brake`` in the direction of ``vel``) meets a limit, left ``hyst`` back (not
    latched): bits 1 high entered, 2 high left, 4 low entered, 8 low left."""
    reach_hi = pos + (brake if vel > 0.0 else 0.0)
    reach_lo = pos - (brake if vel < 0.0 else 0.0)
    out = 0
    if not on_hi and reach_hi >= hi:
        out |= 1
    elif on_hi and reach_hi < hi - hyst:
        out |= 2
    if not on_lo and reach_lo <= lo:
        out |= 4
    elif on_lo and reach_lo > lo + hyst:
        out |= 8
    return out


@kernel
def zone_after(on, changes, entered, left):
    """A zone's flag after ``changes`` (its ``entered``/``left`` bits)."""
    if changes & entered:
        return 1
    if changes & left:
        return 0
    return on


@kernel
def stroke_zone(th, s, d):
    """Stroke soft limits with the braking distance v²/(2a): what changed (``ZONE_*``
    bits); ``d.braking_m`` when something did."""
    x = s.x
    v = s.v
    if not math.isfinite(x):
        return 0  # the sensor rules have made the linear axis safe
    b = v * v / (2.0 * th.max_decel_m_s2)
    c = zone_changes(s.zone_hi, s.zone_lo, x, v, b, th.x_lo, th.x_hi, th.stroke_hyst_m)
    if c:
        s.zone_hi = zone_after(s.zone_hi, c, 1, 2)
        s.zone_lo = zone_after(s.zone_lo, c, 4, 8)
        d.braking_m = b
    return c  # ZONE_HI_ENTERED .. ZONE_LO_LEFT = 1, 2, 4, 8


@kernel
def angle_zone(th, s, d):
    """Angle soft limits with the braking angle |ω| t_lag + ω²/(2a) (ω over the speed
    window), as the stroke's: what changed (``ANGLE_*`` bits); ``d.braking_rad`` when
    something did. The lag term: a held pneumatic motor turns on while its valve closes and
    its chambers' air vents or is trapped (twin: ≈ ω · 10-19 ms at 5 V, 250-1700 rpm).
    With the limits off (±inf) nothing is ever reached."""
    if not s.enc_have:
        return 0
    theta = s.enc_c * th.rad_per_count
    w = s.w
    b = abs(w) * th.angle_lag_s + w * w / (2.0 * th.max_decel_rad_s2)
    c = zone_changes(s.azone_hi, s.azone_lo, theta, w, b, th.th_lo, th.th_hi, th.angle_hyst)
    if c:
        s.azone_hi = zone_after(s.azone_hi, c, 1, 2)
        s.azone_lo = zone_after(s.azone_lo, c, 4, 8)
        d.braking_rad = b
    return c << 4  # ANGLE_HI_ENTERED .. ANGLE_LO_LEFT = 16, 32, 64, 128


@kernel
def update_zone(th, s, d):
    """The stroke and angle soft-limit zones (:func:`stroke_zone`, :func:`angle_zone`):
    what changed (``ZONE_*`` | ``ANGLE_*`` bits)."""
    return stroke_zone(th, s, d) | angle_zone(th, s, d)


@kernel
def output_v(th, s, axis, blocked, now):
    """The voltage to write for ``axis`` at the tick taking effect at ``now`` (kept in
    ``s.u_out``): SAFE_V while ``blocked`` (a latched fault, the e-stop), before its first
    command or the first sample; a late command as the policy says (:func:`late_command`:
    held, ramped or SAFE_V); a command driving further into an active stroke soft-limit zone
    is held at SAFE_V, the held and ramped ones included.

    Counted per axis (call once per axis and tick): ``late_ticks``, a late command not yet
    older than the watchdog (blocked or not); ``held_ticks`` / ``ramped_ticks``, those
    written held or ramped.

    The rotary axis in an active angle zone: no output turning further, SAFE_V included,
    is written; it is held at ``rot_idle_v``, the output that does not drive the motor
    (bidirectional: SAFE_V, both ports closed; paper: the inlet vented, U_MIN_V, because
    the closed centre's leakage turns the motor on at 35-55 rpm on the nominal twin).
    """
    u = SAFE_V
    late = late_command(th, s, axis, now)
    if late != LATE_NO and now - s.cmd_t[axis] <= th.watchdog_ns:
        s.late_ticks[axis] += 1
    if not blocked and s.cmd_have[axis] and s.have_sample:
        u = s.cmd_u[axis]
        if late == LATE_HOLD:
            s.held_ticks[axis] += 1
        elif late == LATE_RAMP:
            s.ramped_ticks[axis] += 1
            u = ramp_v(th, s, axis, now)
        elif late == LATE_CLOSED:
            u = SAFE_V
        if axis == 0:
            push = (u - SAFE_V) * th.u_toward_hi  # > 0: drives toward +x
            if (s.zone_hi and push > 0.0) or (s.zone_lo and push < 0.0):
                u = SAFE_V
    if axis == 1:
        idle = th.rot_idle_v  # above: turns toward +θ (port A); below: toward −θ (port B)
        if (s.azone_hi and u > idle) or (s.azone_lo and u < idle):
            u = idle
    s.u_out[axis] = u
    return u
