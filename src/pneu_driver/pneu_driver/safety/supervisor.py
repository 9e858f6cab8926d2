"""The safety supervisor: a ROS-free core between the controllers and the valves.

Shared by the driver loop, the sim node and the in-process runner. One object
per rig, stepped from one thread:

1. ``check_sample(sample, raw_volts)`` -- plausibility of the new sample
   (NaN/inf, live voltage range, pressure above supply + margin, position
   beyond the end stops, frozen values, impossible encoder jumps, overspeed,
   a stalled rotation, the stroke and angle soft-limit trips);
2. ``command(axis, u, stamp_ns)`` -- a controller's command arrived; NaN or a
   value outside 0–10 V is refused (never written) and trips the axis;
3. ``outputs(now_ns)`` -- the two voltages to write, after the late-command
   policy, the watchdog, the latched faults, the e-stop and the stroke and angle
   soft limits.

A command late for a tick (older than one period when the output takes effect: the
controller has not answered the newest sample) is dealt with by ``late_policy``
(DESIGN §14): ``hold`` writes the last command, ``ramp`` moves it linearly to 5 V
over ``late_ramp_ms``, for at most ``late_hold_ms``, then 5 V (not latched) until a
fresh command; ``trip`` takes the axis safe at the first late tick (latched,
``late_command``). Whatever the policy, the watchdog latches an axis whose controller
is gone (no fresh command for ``watchdog_ms``), and the soft limits act on the held
or ramped output as on any. Counted per axis: ``<axis>.late_ticks`` (until the
watchdog's), ``<axis>.held_ticks``, ``<axis>.ramped_ticks``.

Faults latch per axis: the valve stays at its safe value (5 V, closed centre)
until the condition is gone *and* :meth:`SafetySupervisor.acknowledge` (or
:meth:`~SafetySupervisor.reset`) is called. The stroke soft limits act twice:

- *hold* (not latched): while the piston plus its braking distance v²/(2a)
  reaches a soft limit, commands driving it further are held at 5 V;
- *trip* (latched, ``stroke_limit``): the piston at or beyond a soft limit
  takes the linear axis safe. Holding is not braking: the closed centre traps
  the chamber pressures, and with the cap side near supply and the rod side
  near atmosphere the trapped air keeps pushing until it balances -- beyond
  the end stop for a piston driven there at full opening (a 500 mm sine
  reference reached the end stop at 75.3 mm under a "hold" that never tripped,
  so the run reported OK). The trip makes that visible (exit code 3); it can
  be acknowledged while the piston is still out there, so a controller can
  retract it (the hold keeps refusing the other way).

The angle soft limits (``angle_limits``, off by default) act the same way on the
motor angle θ from the encoder counts, with the braking angle ω²/(2a): a hold of
commands turning further (above 5 V toward +θ, below toward −θ) at 5 V, and a
latched trip (``angle_limit``) at or beyond a soft limit, acknowledgeable out
there so a controller can turn back.

A stalled rotation (``no_rotation``): valve #2 held beyond 5 V ± ``stall_band_v``
(``stall_band_bidir_v`` with the bidirectional plumbing) toward a port that drives the motor (forward with the inlet p_m1 above
``stall_inlet_pa``; reverse only with the bidirectional plumbing, from the valve
alone: port B is not measured) while |ω| over the speed window stays below
``stall_speed_rpm`` for longer than ``stall_ms``: a blocked rotor or a dead
encoder. Holding an angle (valve within the band) never runs its clock.

Every transition is queued as a :class:`SafetyEvent` for ``/diagnostics`` and the
bag (:meth:`~SafetySupervisor.events` drains them).

The decisions themselves are :mod:`pneu_driver.safety.rules` (kernels on records,
the same source the compiled closed loop runs); this module words them as events,
latches them and handles acknowledge, reset and the e-stop.

Time: all stamps are int nanoseconds on one clock (the sample clock). A
command carries the stamp of the sample it answers; ``outputs(now_ns)`` gets
the time the output takes effect (tick k+1), so a command answering the latest
sample is one period old (DESIGN §3).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

from pneu_msgs_py.contract.samples import AXES, U_MAX_V, U_MIN_V, SensorSample
from pneu_msgs_py.params.core import validate

from pneu_driver.safety import rules
from pneu_driver.safety.events import ERROR, OK, SAFE_V, WARN, AxisStatus, SafetyEvent
from pneu_driver.safety.params import SafetyParams
from pneu_driver.safety.rules import ANALOG, KEY_AXIS, KEY_SENSOR, SENSOR_KEYS

__all__ = ["SafetySupervisor"]

_AXIS_INDEX = {axis: a for a, axis in enumerate(AXES)}
_SANITY_GROUP = {axis: f"sanity:{axis}" for axis in AXES}
_LIVE_KEYS = 15 << rules.LIVE_RANGE
_STROKE_ZONE = (
    rules.ZONE_HI_ENTERED | rules.ZONE_HI_LEFT | rules.ZONE_LO_ENTERED | rules.ZONE_LO_LEFT
)
_ANGLE_ZONE = (
    rules.ANGLE_HI_ENTERED | rules.ANGLE_HI_LEFT | rules.ANGLE_LO_ENTERED | rules.ANGLE_LO_LEFT
)


def _fmt(v: Any) -> str:
    return f"{v:.6g}" if isinstance(v, float) else str(v)


class SafetySupervisor:
    """Per-axis safety state machine (see the module docstring for the rules).

    The decisions are :mod:`pneu_driver.safety.rules` (shared with the compiled closed
    loop); this class keeps what they lead to: the events and their messages, the
    latches, acknowledge/reset, the e-stop and the counters.

    Not thread-safe: call it from one thread (the driver loop wraps it in a lock).
    """

    def __init__(self, params: SafetyParams, sample_time_s: float = 1e-3):
        if not (
            isinstance(sample_time_s, (int, float))
            and math.isfinite(sample_time_s)
            and sample_time_s > 0
        ):
            raise ValueError(f"sample_time_s: {sample_time_s!r} refused; allowed: a period > 0 s")
        self.params = validate(params)
        p = self.params
        self.sample_time_s = float(sample_time_s)
        self._th = rules.thresholds(p, sample_time_s)
        self._s = rules.STATE.new()
        self._d = rules.FINDINGS.new()
        # group -> the fault keys present, (axis, key) -> (message, values)
        self._groups: dict[str, dict[tuple[str, str], tuple[str, dict[str, Any]]]] = {}
        self._latched: dict[str, dict[str, str]] = {a: {} for a in AXES}
        self._estop: str | None = None
        self._now_ns = 0
        self._stamp_warned: set[tuple[str, str]] = set()
        self._publishers: dict[str, int] = {}
        self._events: deque[SafetyEvent] = deque(maxlen=10000)
        self._counts = {
            "refused_commands": 0,
            "stale_commands": 0,
            "future_commands": 0,
            "expired_commands": 0,
            "trips": 0,
            "events_dropped": 0,
        }
        if p.allow_unsafe and p.unsafe_overrides():
            self._emit(
                "all",
                "allow_unsafe",
                WARN,
                "protections weakened by allow_unsafe: " + "; ".join(p.unsafe_overrides()),
                {"allow_unsafe": True},
            )

    # ------------------------------------------------------------------ inputs
    def check_sample(
        self, sample: SensorSample, raw_volts: tuple[float, ...] | None = None
    ) -> None:
        """Plausibility of a new sample (and of its raw AI volts when a driver has them).

        ``raw_volts`` = (p_c1, p_c2, p_m1, laser) [V]. Rules, each "> threshold"
        (a value exactly at the threshold passes):

        - non-finite field → its axis safe;
        - voltage outside the sensor's live range → its axis safe;
        - pressure > supply + ``pressure_margin_pa`` → its axis safe;
        - |x| > stroke/2 + ``position_margin_m`` → linear safe;
        - analog value bit-identical for > ``stuck_ms`` → its axis safe;
        - encoder step deviating from the previous speed by > a·Δt²·cpr/2π + slack counts → rotary safe;
        - |speed| over ``speed_window_ms`` > ``max_speed_rpm`` → rotary safe;
        - θ at or beyond an angle soft limit (``angle_limits`` on) → rotary safe;
        - driven beyond the band yet below ``stall_speed_rpm`` for > ``stall_ms`` → rotary safe.
        """
        s = sample
        now = int(s.stamp_ns)
        self._now_ns = now
        # frozen analog values: the raw volts when given, else the SI value
        values = raw_volts if raw_volts is not None else (s.p_c1, s.p_c2, s.p_m1, s.x)
        keys = rules.non_finite_fields(self._d, s.p_c1, s.p_c2, s.p_m1, s.x, s.theta, s.omega)
        keys |= rules.sample_faults(
            self._th, self._s, self._d, now, s.p_c1, s.p_c2, s.p_m1, s.x, int(s.counts),
            values, raw_volts is not None,
        )  # fmt: skip
        if keys or self._groups.get("sensor"):
            present = self._sensor_faults(keys, s, values, raw_volts is not None, now)
            self._update_group("sensor", present, now)
        else:
            self._groups.setdefault("sensor", {})  # the groups' order is the order they appear

    def _sensor_faults(
        self, keys: int, s: SensorSample, values: Any, have_volts: bool, now: int
    ) -> dict[tuple[str, str], tuple[str, dict[str, Any]]]:
        """The sensor fault keys ``keys`` with their messages, in the rules' order."""
        present: dict[tuple[str, str], tuple[str, dict[str, Any]]] = {}
        if not keys:
            return present

        def flag(bit: int, message: str, **kv: Any) -> None:
            present[(KEY_AXIS[bit], SENSOR_KEYS[bit])] = (
                message,
                {"sensor": KEY_SENSOR[bit], **kv},
            )

        self._input_faults(flag, keys, s, values, have_volts)
        self._range_faults(flag, keys, s, values, now)
        self._encoder_faults(flag, keys, s, now)
        return present

    def _input_faults(self, flag: Any, keys: int, s: SensorSample, volts: Any, have: bool) -> None:
        """Messages of the non-finite fields and of the voltages outside their live range."""
        d, th = self._d, self._th
        for i, name in enumerate(rules.FIELDS):
            if d.nf_fields >> i & 1:
                v = getattr(s, name)
                flag(min(i, rules.NON_FINITE_ENCODER), f"{name} is {v}", value=v)
        if not (have and (d.nf_volts or keys & _LIVE_KEYS)):
            return
        for i, sensor in enumerate(ANALOG):
            v = volts[i]
            lo, hi = (th.x_live_lo, th.x_live_hi) if i == 3 else (th.p_live_lo, th.p_live_hi)
            if d.nf_volts >> i & 1:
                flag(rules.NON_FINITE + i, f"{sensor} voltage is {v}", volts=v)
            elif keys >> (rules.LIVE_RANGE + i) & 1:
                flag(
                    rules.LIVE_RANGE + i,
                    f"{sensor} voltage {v:.4g} V outside its live range [{lo:g}, {hi:g}] V",
                    volts=v,
                    lo=lo,
                    hi=hi,
                )

    def _range_faults(self, flag: Any, keys: int, s: SensorSample, values: Any, now: int) -> None:
        """Messages of over-pressure, position, soft-limit trip and frozen values."""
        th, st = self._th, self._s
        p_max = (th.p_max_c1, th.p_max_c2, th.p_max_m1)
        for i, sensor in enumerate(ANALOG[:3]):
            if keys >> (rules.OVER_PRESSURE + i) & 1:
                pv = getattr(s, sensor)
                flag(
                    rules.OVER_PRESSURE + i,
                    f"{sensor} = {pv:.6g} Pa above supply + margin = {p_max[i]:.6g} Pa",
                    pressure_pa=pv,
                    limit_pa=p_max[i],
                )
        x = s.x
        if keys >> rules.POSITION_RANGE & 1:
            flag(
                rules.POSITION_RANGE,
                f"x = {x:.4g} m beyond the end stops (|x| ≤ {th.x_abs_max:g} m)",
                x_m=x,
            )
        elif keys >> rules.STROKE_LIMIT & 1:
            # the hold did not stop the piston (see the module docstring): trip, latched
            flag(
                rules.STROKE_LIMIT,
                f"piston at x = {x * 1e3:.4g} mm, at or beyond the soft limit "
                f"±{th.x_hi * 1e3:g} mm",
                x_m=x,
                limit_m=th.x_hi if x > 0 else th.x_lo,
            )
        if keys >> rules.ANGLE_LIMIT & 1:
            deg = math.degrees(int(s.counts) * th.rad_per_count)
            lo, hi = math.degrees(th.th_lo), math.degrees(th.th_hi)
            flag(
                rules.ANGLE_LIMIT,
                f"motor at θ = {deg:.5g}°, at or beyond the angle soft limit [{lo:.6g}, {hi:.6g}]°",
                theta_deg=deg,
                limit_deg=hi if deg > 0 else lo,
            )
        for i, sensor in enumerate(ANALOG):
            if keys >> (rules.STUCK + i) & 1:
                v, frozen_ms = values[i], (now - st.frozen_t[i]) * 1e-6
                flag(
                    rules.STUCK + i,
                    f"{sensor} frozen at {v:.6g} for {frozen_ms:.4g} ms (> {self.params.stuck_ms:g} ms)",
                    value=v,
                    frozen_ms=frozen_ms,
                )

    def _encoder_faults(self, flag: Any, keys: int, s: SensorSample, now: int) -> None:
        """Messages of the encoder jump, overspeed and no-rotation rules."""
        d, p = self._d, self.params
        if keys >> rules.ENCODER_JUMP & 1:
            flag(
                rules.ENCODER_JUMP,
                f"encoder stepped {d.jump_counts} counts where the previous speed predicts "
                f"{d.jump_predicted:.4g} ± {d.jump_allowed:.4g}",
                step_counts=d.jump_counts,
                deviation_counts=d.jump_deviation,
                allowed_counts=d.jump_allowed,
            )
        if keys >> rules.OVERSPEED & 1:
            flag(
                rules.OVERSPEED,
                f"motor speed {d.speed_rpm:.5g} rpm above max_speed_rpm = {p.max_speed_rpm:g}",
                speed_rpm=d.speed_rpm,
                max_speed_rpm=p.max_speed_rpm,
            )
        if keys >> rules.NO_ROTATION & 1:
            still_ms = (now - self._s.stall_since) * 1e-6
            rpm = self._s.w * 60.0 / (2.0 * math.pi)
            u = d.stall_u
            if u > SAFE_V:
                how = (
                    f"driven forward: valve #2 at {u:.4g} V (> {SAFE_V:g} + {self._th.stall_band_v:g} V), "
                    f"inlet p_m1 at {s.p_m1:.6g} Pa (> {p.stall_inlet_pa:g} Pa)"
                )
            else:
                how = (
                    f"driven in reverse: valve #2 at {u:.4g} V (< {SAFE_V:g} - {self._th.stall_band_v:g} V; "
                    "port B's pressure not measured)"
                )
            flag(
                rules.NO_ROTATION,
                f"rotation stalled: motor at {rpm:.3g} rpm (below {p.stall_speed_rpm:g} rpm) "
                f"for {still_ms:.4g} ms (> {p.stall_ms:g} ms), {how}",
                valve_v=u,
                inlet_pa=s.p_m1,
                speed_rpm=rpm,
                still_ms=still_ms,
            )

    def encoder_jump_allowance(self, dt_ns: int) -> float:
        """Largest plausible deviation [counts] of an encoder step over ``dt_ns`` from the previous speed.

        a_max · Δt² · cpr / 2π (the angle a full acceleration adds) + the quantisation slack.
        """
        return rules.jump_allowance(self._th, dt_ns)

    @property
    def counters(self) -> dict[str, int]:
        """What was refused, ignored, tripped or dropped, and per axis the late ticks and
        those written held or ramped (the rules' state), as one flat dict (a copy)."""
        st = self._s
        out = dict(self._counts)
        for a, axis in enumerate(AXES):
            out[f"{axis}.late_ticks"] = st.late_ticks[a]
            out[f"{axis}.held_ticks"] = st.held_ticks[a]
            out[f"{axis}.ramped_ticks"] = st.ramped_ticks[a]
        return out

    def command(self, axis: str, u: float, stamp_ns: int) -> None:
        """A controller's command for ``axis`` arrived, answering the sample stamped ``stamp_ns``.

        NaN/inf or outside [0, 10] V: refused (never written), the axis goes safe
        (latched ``output_sanity``). An older stamp than the last accepted one is ignored.
        Stamped for a sample not yet taken, or older than the watchdog: not taken, counted
        (``future_commands``, ``expired_commands``), a warning the first time per axis.
        """
        a = _AXIS_INDEX.get(axis)
        if a is None:
            raise ValueError(f"axis: {axis!r} refused; allowed: one of {', '.join(AXES)}")
        done = rules.command(self._th, self._s, a, float(u), int(stamp_ns))
        if done & (rules.CMD_FUTURE | rules.CMD_EXPIRED):
            kind = "future" if done & rules.CMD_FUTURE else "expired"
            self._counts[f"{kind}_commands"] += 1
            if (axis, kind) not in self._stamp_warned:
                self._stamp_warned.add((axis, kind))
                why = (
                    "stamped after the newest sample"
                    if kind == "future"
                    else f"older than watchdog_ms = {self.params.watchdog_ms:g}"
                )
                self._emit(
                    axis,
                    "command_stamp",
                    WARN,
                    f"{axis} command refused: {why} (sample {self._s.sample_t} ns, command {int(stamp_ns)} ns); counted in {kind}_commands",
                    {"stamp_ns": int(stamp_ns), "sample_ns": self._s.sample_t},
                )
            return
        group = _SANITY_GROUP[axis]
        if done & rules.CMD_REFUSED:
            self._counts["refused_commands"] += 1
            msg = f"{axis} command {u!r} V refused (allowed [{U_MIN_V:g}, {U_MAX_V:g}] V, finite)"
            self._update_group(
                group, {(axis, "output_sanity"): (msg, {"command_v": u})}, self._now_ns
            )
            return
        if done & rules.CMD_REFUSAL_GONE:
            self._update_group(group, {}, self._now_ns)
        if done & rules.CMD_STALE:
            self._counts["stale_commands"] += 1
            return
        if done & rules.CMD_FIRST:
            self._emit(axis, "command", OK, f"{axis} commands arriving", {"command_v": u})

    # ----------------------------------------------------------------- outputs
    def outputs(self, now_ns: int) -> tuple[float, float]:
        """The voltages (linear, rotary) to write for the tick at ``now_ns``, after every rule."""
        now = int(now_ns)
        self._now_ns = now
        th, st = self._th, self._s
        gone = rules.watchdog_faults(th, st, now)
        late = rules.late_faults(th, st, now)
        if gone or late or self._groups.get("watchdog"):
            self._update_group("watchdog", self._command_faults(gone, late, now), now)
        else:
            self._groups.setdefault("watchdog", {})
        changed = rules.update_zone(th, st, self._d)
        if changed:
            self._zone_events(changed, now)
        estop = self._estop is not None
        return (
            rules.output_v(th, st, 0, estop or bool(self._latched[AXES[0]]), now),
            rules.output_v(th, st, 1, estop or bool(self._latched[AXES[1]]), now),
        )

    def _command_faults(
        self, gone: int, late: int, now: int
    ) -> dict[tuple[str, str], tuple[str, dict[str, Any]]]:
        """The watchdog's keys (``gone``) and the trip policy's (``late``), with messages."""
        present = {}
        for a, axis in enumerate(AXES):
            age_ms = (now - self._s.cmd_t[a]) * 1e-6
            if late >> a & 1:
                present[(axis, "late_command")] = (
                    f"{axis} command late: {age_ms:.4g} ms old at the tick, the newest sample "
                    f"not answered (late_policy: trip)",
                    {"age_ms": age_ms},
                )
            if gone >> a & 1:
                present[(axis, "watchdog")] = (
                    f"no fresh {axis} command for {age_ms:.4g} ms (> watchdog_ms = {self.params.watchdog_ms:g})",
                    {"age_ms": age_ms},
                )
        return present

    def _zone_events(self, changed: int, now: int) -> None:
        """The soft-limit transitions :func:`rules.update_zone` reported, as events."""
        if changed & _STROKE_ZONE:
            self._stroke_events(changed, now)
        if changed & _ANGLE_ZONE:
            self._angle_events(changed, now)

    def _angle_events(self, changed: int, now: int) -> None:
        """The angle soft-limit transitions, as events."""
        th, st = self._th, self._s
        deg = math.degrees(st.enc_c * th.rad_per_count)
        rpm = st.w * 60.0 / (2.0 * math.pi)
        b_deg = math.degrees(self._d.braking_rad)
        idle = th.rot_idle_v
        for bound, entered, left, side in (
            (th.th_hi, rules.ANGLE_HI_ENTERED, rules.ANGLE_HI_LEFT, "above"),
            (th.th_lo, rules.ANGLE_LO_ENTERED, rules.ANGLE_LO_LEFT, "below"),
        ):
            limit = math.degrees(bound)
            values = {"theta_deg": deg, "speed_rpm": rpm, "braking_deg": b_deg, "limit_deg": limit}
            if changed & entered:
                self._emit(
                    "rotary",
                    "soft_limit",
                    WARN,
                    f"angle soft limit: θ = {deg:.5g}°, braking {b_deg:.3g}° reaches {limit:.6g}°; outputs {side} {idle:g} V held at {idle:g} V",
                    values,
                    now,
                )
            elif changed & left:
                self._emit(
                    "rotary",
                    "soft_limit",
                    OK,
                    f"angle soft limit released at θ = {deg:.5g}°",
                    values,
                    now,
                )

    def _stroke_events(self, changed: int, now: int) -> None:
        """The stroke soft-limit transitions, as events."""
        th, st = self._th, self._s
        x, v, d_brake = st.x, st.v, self._d.braking_m
        for bound, entered, left, direction in (
            (th.x_hi, rules.ZONE_HI_ENTERED, rules.ZONE_HI_LEFT, "extending (+x)"),
            (th.x_lo, rules.ZONE_LO_ENTERED, rules.ZONE_LO_LEFT, "retracting (-x)"),
        ):
            values = {"x_m": x, "v_m_s": v, "braking_m": d_brake, "limit_m": bound}
            if changed & entered:
                self._emit(
                    "linear",
                    "soft_limit",
                    WARN,
                    f"soft limit: x = {x:.4g} m, braking {d_brake:.3g} m reaches {bound:g} m; {direction} commands held at {SAFE_V:g} V",
                    values,
                    now,
                )
            elif changed & left:
                self._emit(
                    "linear", "soft_limit", OK, f"soft limit released at x = {x:.4g} m", values, now
                )

    # ------------------------------------------------------------------- graph
    def command_publishers(self, counts: dict[str, int]) -> None:
        """The publishers the ROS graph shows on each axis' valve command topic.

        One is the controller; more is a second controller or somebody else's process (a
        command topic is not access-controlled without SROS2): a warning when it starts and
        an OK when it ends, and with ``publisher_trip`` the axis safe (latched,
        ``publishers``) until the count is back to one and the axis acknowledged.
        """
        present = {}
        for axis, n in counts.items():
            if axis not in self._latched:
                raise ValueError(f"axis: {axis!r} refused; allowed: one of {', '.join(AXES)}")
            n = int(n)
            was = self._publishers.get(axis, 0)
            self._publishers[axis] = n
            msg = f"{n} publishers on the {axis} valve command topic (one expected: its controller)"
            if n > 1:
                present[(axis, "publishers")] = (msg, {"publishers": n})
            if (n > 1) == (was > 1):
                continue
            if n > 1 and not self.params.publisher_trip:
                self._emit(axis, "publishers", WARN, msg, {"publishers": n})
            elif n <= 1:
                self._emit(
                    axis,
                    "publishers",
                    OK,
                    f"{n} publisher(s) on the {axis} valve command topic",
                    {"publishers": n},
                )
        if self.params.publisher_trip:
            self._update_group("publishers", present, self._now_ns)

    @property
    def publishers(self) -> dict[str, int]:
        """The last publisher counts given to :meth:`command_publishers`, per axis."""
        return dict(self._publishers)

    # ------------------------------------------------------------ operator side
    def estop(self, reason: str) -> None:
        """Latch every valve safe until :meth:`reset` succeeds."""
        if self._estop is None:
            self._estop = str(reason) or "e-stop"
            self._counts["trips"] += 1
            self._emit(
                "all",
                "estop",
                ERROR,
                f"e-stop: {self._estop}; all valves safe until reset",
                {"reason": self._estop},
            )

    def acknowledge(self, axis: str) -> tuple[bool, str]:
        """Clear ``axis``'s latched faults if none of them is still present.

        A tripped watchdog (or ``late_command``) needs no fresh command to be acknowledged:
        the axis then waits (valve safe) until commands resume. The e-stop needs :meth:`reset`.
        """
        if axis not in self._latched:
            raise ValueError(f"axis: {axis!r} refused; allowed: one of {', '.join(AXES)}")
        blocking = self._blocking(axis)
        if blocking:
            msg = f"{axis}: acknowledge refused, fault still present: " + "; ".join(blocking)
            return False, msg
        cleared = self._clear_axis(axis)
        msg = f"{axis}: acknowledged" + (
            f" ({', '.join(cleared)})" if cleared else " (nothing latched)"
        )
        if self._estop is not None:
            msg += "; e-stop still latched (reset to clear)"
        if cleared:
            self._emit(axis, "acknowledge", OK, msg, {"cleared": ",".join(cleared)})
        return True, msg

    def reset(self) -> tuple[bool, str]:
        """Clear the e-stop and every latched fault, only when no fault condition is present."""
        blocking = [f"{axis}: {b}" for axis in AXES for b in self._blocking(axis)]
        if blocking:
            return False, "reset refused, fault still present: " + "; ".join(blocking)
        was = self._estop
        self._estop = None
        cleared = [f"{axis}:{key}" for axis in AXES for key in self._clear_axis(axis)]
        if was is None and not cleared:
            return True, "reset: nothing latched"
        msg = "reset: " + ", ".join(([f"e-stop ({was})"] if was else []) + cleared) + " cleared"
        self._emit("all", "reset", OK, msg, {"cleared": ",".join(cleared), "estop": was or ""})
        return True, msg

    def _blocking(self, axis: str) -> list[str]:
        return [
            f"{key} ({msg})"
            for group in self._groups.values()
            for (a, key), (msg, _v) in group.items()
            if a == axis
            and key not in ("watchdog", "late_command", "stroke_limit:x", "angle_limit:encoder")
        ]

    def _clear_axis(self, axis: str) -> list[str]:
        wd = self._groups.get("watchdog", {})
        for key in ("watchdog", "late_command"):
            if (axis, key) in wd:
                del wd[(axis, key)]
                self._s.cmd_have[_AXIS_INDEX[axis]] = 0  # wait for commands to resume
        cleared = list(self._latched[axis])
        self._latched[axis].clear()
        return cleared

    # ----------------------------------------------------------------- reports
    def events(self) -> list[SafetyEvent]:
        """Drain the transitions queued since the last call (oldest first)."""
        if not self._events:
            return []
        out = list(self._events)
        self._events.clear()
        return out

    @property
    def status(self) -> dict[str, AxisStatus]:
        out = {}
        for axis in AXES:
            causes = []
            if self._estop is not None:
                causes.append("estop")
            causes.extend(self._latched[axis])
            if not self._s.cmd_have[_AXIS_INDEX[axis]]:
                causes.append("no_command")
            if not self._s.have_sample:
                causes.append("no_sample")
            present = tuple(key for g in self._groups.values() for (a, key) in g if a == axis)
            zones = (
                (self._s.zone_hi, self._s.zone_lo)
                if axis == "linear"
                else (self._s.azone_hi, self._s.azone_lo)
            )
            limited = bool(zones[0] or zones[1])
            state = "SAFE" if causes else ("LIMITED" if limited else "OK")
            out[axis] = AxisStatus(axis, state, tuple(causes), present)
        return out

    def thresholds(self) -> dict[str, Any]:
        """What the rules compare against, derived once from :attr:`params` (SI; stamps int ns).

        The fields of :attr:`threshold_record` (:func:`rules.thresholds`), grouped per sensor.
        """
        th = self._th
        return {
            "T_ns": th.T_ns,
            "watchdog_ns": th.watchdog_ns,
            "late_policy": th.late_policy,
            "late_hold_ns": th.late_hold_ns,
            "late_ramp_ns": th.late_ramp_ns,
            "stuck_ns": th.stuck_ns,
            "stall_ns": th.stall_ns,
            "x_hi": th.x_hi,
            "x_lo": th.x_lo,
            "x_abs_max": th.x_abs_max,
            "p_max": {"p_c1": th.p_max_c1, "p_c2": th.p_max_c2, "p_m1": th.p_max_m1},
            "live_v": {
                **dict.fromkeys(ANALOG[:3], (th.p_live_lo, th.p_live_hi)),
                "x": (th.x_live_lo, th.x_live_hi),
            },
            "u_toward_hi": th.u_toward_hi,
            "velocity_window": th.n_xw,
            "speed_window": th.n_cw,
            "theta_hi": th.th_hi,
            "theta_lo": th.th_lo,
            "stall_band_v": th.stall_band_v,
            "stall_omega": th.stall_omega,
            "stall_reverse": th.stall_reverse,
        }

    @property
    def threshold_record(self) -> Any:
        """The :data:`rules.THRESHOLDS` record the rules read (do not modify)."""
        return self._th

    @property
    def tripped(self) -> bool:
        """True while the e-stop or any axis's fault is latched (the heartbeat stops)."""
        return self._estop is not None or bool(self._latched["linear"] or self._latched["rotary"])

    @property
    def estopped(self) -> str | None:
        """The e-stop reason while latched, else None."""
        return self._estop

    @property
    def soft_limits(self) -> tuple[float, float]:
        """(x_lo, x_hi) [m]: the soft-limit boundaries inside the end stops."""
        return self._th.x_lo, self._th.x_hi

    @property
    def angle_soft_limits(self) -> tuple[float, float]:
        """(θ_lo, θ_hi) [rad]: the angle soft limits (±inf while ``angle_limits`` is off)."""
        return self._th.th_lo, self._th.th_hi

    # ----------------------------------------------------------------- internal
    def _update_group(
        self, group: str, present: dict[tuple[str, str], tuple[str, dict[str, Any]]], now: int
    ) -> None:
        prev = self._groups.get(group)
        if not present and not prev:
            self._groups[group] = present
            return
        prev = prev or {}
        for key in present.keys() - prev.keys():
            axis, fault = key
            msg, values = present[key]
            if fault not in self._latched[axis]:
                self._counts["trips"] += 1
            self._latched[axis][fault] = msg
            self._emit(
                axis,
                fault.split(":")[0],
                ERROR,
                f"{msg}: {axis} valve safe until acknowledged",
                values,
                now,
            )
        for key in prev.keys() - present.keys():
            axis, fault = key
            if fault in self._latched[axis]:
                msg = prev[key][0]
                self._emit(
                    axis,
                    fault.split(":")[0],
                    WARN,
                    f"{fault} gone ({msg}); {axis} stays safe until acknowledged",
                    prev[key][1],
                    now,
                )
        self._groups[group] = present

    def _emit(
        self,
        axis: str,
        rule: str,
        level: str,
        message: str,
        values: dict[str, Any],
        now: int | None = None,
    ) -> None:
        if len(self._events) == self._events.maxlen:
            self._counts["events_dropped"] += 1
        kv = tuple((k, _fmt(v)) for k, v in values.items())
        self._events.append(
            SafetyEvent(self._now_ns if now is None else now, axis, rule, level, message, kv)
        )
