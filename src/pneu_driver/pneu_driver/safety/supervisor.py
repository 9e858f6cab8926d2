"""The safety supervisor: a ROS-free core between the controllers and the valves.

Shared by the driver loop, the sim node and the in-process runner. One object
per rig, stepped from one thread:

1. ``check_sample(sample, raw_volts)`` -- plausibility of the new sample
   (NaN/inf, live voltage range, pressure above supply + margin, position
   beyond the end stops, frozen values, impossible encoder jumps, overspeed);
2. ``command(axis, u, stamp_ns)`` -- a controller's command arrived; NaN or a
   value outside 0–10 V is refused (never written) and trips the axis;
3. ``outputs(now_ns)`` -- the two voltages to write, after the watchdog, the
   latched faults, the e-stop and the stroke soft limits.

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
  retract it (the hold keeps refusing the other way). Every transition is queued as a :class:`SafetyEvent` for
``/diagnostics`` and the bag (:meth:`~SafetySupervisor.events` drains them).

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

from pneu_driver.safety.events import (
    ERROR,
    OK,
    SAFE_V,
    SENSOR_AXIS,
    WARN,
    AxisStatus,
    SafetyEvent,
)
from pneu_driver.safety.params import SafetyParams

__all__ = ["SafetySupervisor"]

_ANALOG = ("p_c1", "p_c2", "p_m1", "x")  # raw_volts order: (p_c1, p_c2, p_m1, laser)
_FIELD_SENSOR = {
    "p_c1": "p_c1",
    "p_c2": "p_c2",
    "p_m1": "p_m1",
    "x": "x",
    "theta": "encoder",
    "omega": "encoder",
}
_TWO_PI = 2.0 * math.pi


def _fmt(v: Any) -> str:
    return f"{v:.6g}" if isinstance(v, float) else str(v)


_SANITY_GROUP = {axis: f"sanity:{axis}" for axis in AXES}


class SafetySupervisor:
    """Per-axis safety state machine (see the module docstring for the rules).

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
        self._T_ns = round(sample_time_s * 1e9)
        self._wd_ns = round(p.watchdog_ms * 1e6)
        self._stuck_ns = round(p.stuck_ms * 1e6)
        self._stall_ns = round(p.stall_ms * 1e6)
        self._stall_c: int | None = None
        self._stall_since = 0
        half = p.stroke_m / 2.0
        self._x_hi = half - p.stroke_margin_m  # soft-limit boundaries
        self._x_lo = -self._x_hi
        self._x_abs_max = half + p.position_margin_m
        self._p_max = {
            "p_c1": p.supply_linear_pa + p.pressure_margin_pa,
            "p_c2": p.supply_linear_pa + p.pressure_margin_pa,
            "p_m1": p.supply_rotary_pa + p.pressure_margin_pa,
        }
        self._live = {
            "p_c1": p.pressure_live_v,
            "p_c2": p.pressure_live_v,
            "p_m1": p.pressure_live_v,
            "x": p.laser_live_v,
        }
        self._u_toward_hi = 1.0 if p.extend_above_neutral else -1.0
        n_vel = max(1, round(p.velocity_window_ms * 1e-3 / sample_time_s))
        n_spd = max(1, round(p.speed_window_ms * 1e-3 / sample_time_s))
        self._x_win: deque[tuple[int, float]] = deque(maxlen=n_vel + 1)
        self._c_win: deque[tuple[int, int]] = deque(maxlen=n_spd + 1)
        self._enc_prev: tuple[int, int, float | None] | None = (
            None  # (counts, stamp, counts/period)
        )
        # per analog channel (_ANALOG order): last value and since when it holds it
        self._frozen_v: list[float] = [math.nan] * len(_ANALOG)  # NaN: never equal, starts fresh
        self._frozen_t: list[int] = [0] * len(_ANALOG)
        self._x = math.nan
        self._v = 0.0
        self._have_sample = False
        self._zone = {"hi": False, "lo": False}
        self._last_cmd: dict[str, tuple[float, int] | None] = dict.fromkeys(AXES)
        self._groups: dict[str, dict[tuple[str, str], tuple[str, dict[str, Any]]]] = {}
        self._latched: dict[str, dict[str, str]] = {a: {} for a in AXES}
        self._estop: str | None = None
        self._now_ns = 0
        self._events: deque[SafetyEvent] = deque(maxlen=10000)
        self.counters = {
            "refused_commands": 0,
            "stale_commands": 0,
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
        - |speed| over ``speed_window_ms`` > ``max_speed_rpm`` → rotary safe.
        """
        p = self.params
        now = int(sample.stamp_ns)
        self._now_ns = now
        present: dict[tuple[str, str], tuple[str, dict[str, Any]]] = {}

        def flag(sensor: str, rule: str, message: str, **values: Any) -> None:
            # fault key "rule:sensor"; overspeed is not a sensor fault: key "overspeed"
            key = rule if rule == "overspeed" else f"{rule}:{sensor}"
            present[(SENSOR_AXIS[sensor], key)] = (message, {"sensor": sensor, **values})

        s = sample
        if not math.isfinite(s.p_c1 + s.p_c2 + s.p_m1 + s.x + s.theta + s.omega):  # fast screen
            for name, sensor in _FIELD_SENSOR.items():
                v = getattr(sample, name)
                if not math.isfinite(v):
                    flag(sensor, "non_finite", f"{name} is {v}", value=v)
        if raw_volts is not None and not self._volts_live(raw_volts):
            for sensor, v in zip(_ANALOG, raw_volts):
                lo, hi = self._live[sensor]
                if not math.isfinite(v):
                    flag(sensor, "non_finite", f"{sensor} voltage is {v}", volts=v)
                elif v < lo or v > hi:
                    flag(
                        sensor,
                        "live_range",
                        f"{sensor} voltage {v:.4g} V outside its live range [{lo:g}, {hi:g}] V",
                        volts=v,
                        lo=lo,
                        hi=hi,
                    )
        pm = self._p_max
        if s.p_c1 > pm["p_c1"] or s.p_c2 > pm["p_c2"] or s.p_m1 > pm["p_m1"]:  # fast screen
            for sensor, p_max in pm.items():
                pv = getattr(sample, sensor)
                if pv > p_max:
                    flag(
                        sensor,
                        "over_pressure",
                        f"{sensor} = {pv:.6g} Pa above supply + margin = {p_max:.6g} Pa",
                        pressure_pa=pv,
                        limit_pa=p_max,
                    )
        x = sample.x
        if abs(x) > self._x_abs_max:
            flag(
                "x",
                "position_range",
                f"x = {x:.4g} m beyond the end stops (|x| ≤ {self._x_abs_max:g} m)",
                x_m=x,
            )
        elif x >= self._x_hi or x <= self._x_lo:
            # the hold did not stop the piston (see the module docstring): trip, latched
            flag(
                "x",
                "stroke_limit",
                f"piston at x = {x * 1e3:.4g} mm, at or beyond the soft limit "
                f"±{self._x_hi * 1e3:g} mm",
                x_m=x,
                limit_m=self._x_hi if x > 0 else self._x_lo,
            )
        # frozen analog values: the raw volts when given, else the SI value
        values = raw_volts if raw_volts is not None else (sample.p_c1, sample.p_c2, sample.p_m1, x)
        fv, ft, stuck_ns = self._frozen_v, self._frozen_t, self._stuck_ns
        for i, v in enumerate(values):
            if v != fv[i]:
                fv[i], ft[i] = v, now
            elif now - ft[i] > stuck_ns:
                sensor = _ANALOG[i]
                flag(
                    sensor,
                    "stuck",
                    f"{sensor} frozen at {v:.6g} for {(now - ft[i]) * 1e-6:.4g} ms (> {p.stuck_ms:g} ms)",
                    value=v,
                    frozen_ms=(now - ft[i]) * 1e-6,
                )
        # piston velocity over the window (for the braking distance)
        if math.isfinite(x):
            self._x_win.append((now, x))
            t0, x0 = self._x_win[0]
            self._v = (x - x0) / ((now - t0) * 1e-9) if now > t0 else 0.0
            self._x = x
        else:
            self._x = math.nan
        self._check_encoder(int(sample.counts), now, flag)
        self._check_stall(int(sample.counts), sample.p_m1, now, flag)
        self._have_sample = True
        self._update_group("sensor", present, now)

    def _check_stall(self, c: int, p_m1: float, now: int, flag: Any) -> None:
        """Dead encoder / blocked rotor: inlet able to turn the motor, yet no count for stall_ms.

        Catches what the jump rule cannot: an encoder that stops counting at low
        speed (a missed count there is within the jump allowance).
        """
        if not p_m1 > self.params.stall_inlet_pa or c != self._stall_c:
            self._stall_c, self._stall_since = c, now
            return
        if now - self._stall_since > self._stall_ns:
            flag(
                "encoder",
                "no_rotation",
                f"no encoder count for {(now - self._stall_since) * 1e-6:.4g} ms with the motor "
                f"inlet at {p_m1:.6g} Pa (> {self.params.stall_inlet_pa:g} Pa)",
                inlet_pa=p_m1,
                still_ms=(now - self._stall_since) * 1e-6,
            )

    def _volts_live(self, raw_volts: tuple[float, ...]) -> bool:
        """Fast screen: all four voltages finite and inside their live ranges (NaN fails)."""
        plo, phi = self.params.pressure_live_v
        llo, lhi = self.params.laser_live_v
        v0, v1, v2, v3 = raw_volts
        return plo <= v0 <= phi and plo <= v1 <= phi and plo <= v2 <= phi and llo <= v3 <= lhi

    def _check_encoder(self, c: int, now: int, flag: Any) -> None:
        p = self.params
        prev = self._enc_prev
        rate = None
        if prev is not None and now > prev[1]:
            c0, t0, rate0 = prev
            m = (now - t0) / self._T_ns  # periods since the previous sample
            dc = c - c0
            if rate0 is not None:
                allowed = self.encoder_jump_allowance(now - t0)
                deviation = abs(dc - rate0 * m)
                if deviation > allowed:
                    flag(
                        "encoder",
                        "encoder_jump",
                        f"encoder stepped {dc} counts where the previous speed predicts {rate0 * m:.4g} ± {allowed:.4g}",
                        step_counts=dc,
                        deviation_counts=deviation,
                        allowed_counts=allowed,
                    )
            rate = dc / m
        self._enc_prev = (c, now, rate)
        self._c_win.append((now, c))
        t0, c0 = self._c_win[0]
        if now > t0:
            rpm = (c - c0) * 60.0e9 / (p.counts_per_rev * (now - t0))
            if abs(rpm) > p.max_speed_rpm:
                flag(
                    "encoder",
                    "overspeed",
                    f"motor speed {rpm:.5g} rpm above max_speed_rpm = {p.max_speed_rpm:g}",
                    speed_rpm=rpm,
                    max_speed_rpm=p.max_speed_rpm,
                )

    def encoder_jump_allowance(self, dt_ns: int) -> float:
        """Largest plausible deviation [counts] of an encoder step over ``dt_ns`` from the previous speed.

        a_max · Δt² · cpr / 2π (the angle a full acceleration adds) + the quantisation slack.
        """
        p = self.params
        dt_s = dt_ns * 1e-9
        return (
            p.max_accel_rad_s2 * dt_s * dt_s * p.counts_per_rev / _TWO_PI + p.encoder_slack_counts
        )

    def command(self, axis: str, u: float, stamp_ns: int) -> None:
        """A controller's command for ``axis`` arrived, answering the sample stamped ``stamp_ns``.

        NaN/inf or outside [0, 10] V: refused (never written), the axis goes safe
        (latched ``output_sanity``). An older stamp than the last accepted one is ignored.
        """
        if axis not in self._last_cmd:
            raise ValueError(f"axis: {axis!r} refused; allowed: one of {', '.join(AXES)}")
        group = _SANITY_GROUP[axis]
        if not (U_MIN_V <= u <= U_MAX_V):  # NaN fails every comparison; ±inf is out of range
            self.counters["refused_commands"] += 1
            msg = f"{axis} command {u!r} V refused (allowed [{U_MIN_V:g}, {U_MAX_V:g}] V, finite)"
            self._update_group(
                group, {(axis, "output_sanity"): (msg, {"command_v": u})}, self._now_ns
            )
            return
        if self._groups.get(group):  # a refused command was pending: clear it
            self._update_group(group, {}, self._now_ns)
        last = self._last_cmd[axis]
        if last is not None and stamp_ns < last[1]:
            self.counters["stale_commands"] += 1
            return
        if last is None:
            self._emit(axis, "command", OK, f"{axis} commands arriving", {"command_v": u})
        self._last_cmd[axis] = (float(u), int(stamp_ns))

    # ----------------------------------------------------------------- outputs
    def outputs(self, now_ns: int) -> tuple[float, float]:
        """The voltages (linear, rotary) to write for the tick at ``now_ns``, after every rule."""
        now = int(now_ns)
        self._now_ns = now
        present = {}
        for axis, last in self._last_cmd.items():
            if last is not None and now - last[1] > self._wd_ns:
                age_ms = (now - last[1]) * 1e-6
                present[(axis, "watchdog")] = (
                    f"no fresh {axis} command for {age_ms:.4g} ms (> watchdog_ms = {self.params.watchdog_ms:g})",
                    {"age_ms": age_ms},
                )
        self._update_group("watchdog", present, now)
        self._update_zone(now)
        out = []
        for axis in AXES:
            last = self._last_cmd[axis]
            if (
                self._estop is not None
                or self._latched[axis]
                or last is None
                or not self._have_sample
            ):
                out.append(SAFE_V)
                continue
            u = last[0]
            if axis == "linear":
                push = (u - SAFE_V) * self._u_toward_hi  # > 0: drives toward +x
                if (self._zone["hi"] and push > 0.0) or (self._zone["lo"] and push < 0.0):
                    u = SAFE_V
            out.append(u)
        return out[0], out[1]

    def _update_zone(self, now: int) -> None:
        """Stroke soft limits with the braking distance v²/(2·a) (not latched, with hysteresis)."""
        p = self.params
        x, v = self._x, self._v
        if not math.isfinite(x):
            return  # the sensor rules have made the linear axis safe
        d_brake = v * v / (2.0 * p.max_decel_m_s2)
        reach_hi = x + (d_brake if v > 0.0 else 0.0)
        reach_lo = x - (d_brake if v < 0.0 else 0.0)
        zone = self._zone
        if not (zone["hi"] or zone["lo"]) and self._x_lo < reach_lo and reach_hi < self._x_hi:
            return  # hot path: far from both limits, nothing to change
        for side, inside, leave in (
            ("hi", reach_hi >= self._x_hi, reach_hi < self._x_hi - p.stroke_hyst_m),
            ("lo", reach_lo <= self._x_lo, reach_lo > self._x_lo + p.stroke_hyst_m),
        ):
            bound = self._x_hi if side == "hi" else self._x_lo
            values = {"x_m": x, "v_m_s": v, "braking_m": d_brake, "limit_m": bound}
            if not self._zone[side] and inside:
                self._zone[side] = True
                direction = "extending (+x)" if side == "hi" else "retracting (-x)"
                self._emit(
                    "linear",
                    "soft_limit",
                    WARN,
                    f"soft limit: x = {x:.4g} m, braking {d_brake:.3g} m reaches {bound:g} m; {direction} commands held at {SAFE_V:g} V",
                    values,
                    now,
                )
            elif self._zone[side] and leave:
                self._zone[side] = False
                self._emit(
                    "linear", "soft_limit", OK, f"soft limit released at x = {x:.4g} m", values, now
                )

    # ------------------------------------------------------------ operator side
    def estop(self, reason: str) -> None:
        """Latch every valve safe until :meth:`reset` succeeds."""
        if self._estop is None:
            self._estop = str(reason) or "e-stop"
            self.counters["trips"] += 1
            self._emit(
                "all",
                "estop",
                ERROR,
                f"e-stop: {self._estop}; all valves safe until reset",
                {"reason": self._estop},
            )

    def acknowledge(self, axis: str) -> tuple[bool, str]:
        """Clear ``axis``'s latched faults if none of them is still present.

        A tripped watchdog needs no fresh command to be acknowledged: the axis
        then waits (valve safe) until commands resume. The e-stop needs :meth:`reset`.
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
            if a == axis and key not in ("watchdog", "stroke_limit:x")
        ]

    def _clear_axis(self, axis: str) -> list[str]:
        wd = self._groups.get("watchdog", {})
        if (axis, "watchdog") in wd:
            del wd[(axis, "watchdog")]
            self._last_cmd[axis] = None  # wait for commands to resume
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
            if self._last_cmd[axis] is None:
                causes.append("no_command")
            if not self._have_sample:
                causes.append("no_sample")
            present = tuple(key for g in self._groups.values() for (a, key) in g if a == axis)
            limited = axis == "linear" and (self._zone["hi"] or self._zone["lo"])
            state = "SAFE" if causes else ("LIMITED" if limited else "OK")
            out[axis] = AxisStatus(axis, state, tuple(causes), present)
        return out

    def thresholds(self) -> dict[str, Any]:
        """What the rules compare against, derived once from :attr:`params` (SI; stamps int ns).

        For mirrors of these rules (``pneu_control.fastloop``, the compiled closed loop):
        the same numbers, not a second derivation of them.
        """
        return {
            "T_ns": self._T_ns,
            "watchdog_ns": self._wd_ns,
            "stuck_ns": self._stuck_ns,
            "stall_ns": self._stall_ns,
            "x_hi": self._x_hi,
            "x_lo": self._x_lo,
            "x_abs_max": self._x_abs_max,
            "p_max": dict(self._p_max),
            "live_v": dict(self._live),
            "u_toward_hi": self._u_toward_hi,
            "velocity_window": self._x_win.maxlen,
            "speed_window": self._c_win.maxlen,
        }

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
        return self._x_lo, self._x_hi

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
                self.counters["trips"] += 1
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
            self.counters["events_dropped"] += 1
        kv = tuple((k, _fmt(v)) for k, v in values.items())
        self._events.append(
            SafetyEvent(self._now_ns if now is None else now, axis, rule, level, message, kv)
        )
