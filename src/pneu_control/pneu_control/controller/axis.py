"""One axis controller: reference + (TD) + algorithm + output limits + bumpless switching.

:class:`AxisController` is the core behind both controller nodes and the
in-process runner. Per :class:`~pneu_msgs_py.contract.samples.SensorSample` it

1. takes the measurement (``sample.x`` in m for the linear axis, ``sample.omega``
   in rad/s for the rotary axis -- raw, quantised; any filtering belongs to the
   algorithm) and converts it to the paper's units (mm, rpm);
2. evaluates the reference at t = (stamp_ns − first stamp_ns)·1e-9 s;
3. runs the tracking differentiator (Eq. 23–24) on the reference every sample
   when ``td.enabled`` (cold start at the measurement: a soft start); LADRC and
   ESO-SMC take its (v1, v2, v3), PID the analytic (r, ṙ, r̈);
4. fills one :class:`~pneu_control.algorithms.base.StepInput` (measurement,
   reference, the command on the valve, the command history, the encoder
   angle and chamber pressures), calls the algorithm, which returns the
   saturated deviation from the neutral voltage, and returns neutral +
   deviation (V, within [u_min, u_max]).

Rotary ``rotary_model``: ``speed`` (default, the brief's reading): y = ω (rpm),
ÿ = f + b0 u (valve → pressure → torque makes the speed second order in u).
``angle`` (the other plausible reading of the paper's Eq. 25/31, DESIGN §5):
LADRC and ESO-SMC act on the angle y = θ (in rpm·s, so that ẏ is the speed in
rpm) with θ̈ = f + b0 u (b0 in rpm/s/V) and the reference θ_r = ∫v1 dt
(trapezoid, started at the measured angle), ṙ = v1, r̈ = v2; PID stays on the
speed. Observer states are then θ, ω, ω̇-disturbance (rad, rad/s, rad/s²).
Algorithms with ``uses_theta`` (ESO-SMC+'s angle observer) also get the
encoder angle ``sample.theta`` in rpm·s (``StepInput.theta``), whatever
``rotary_model`` is; for them a non-finite angle is held like a non-finite
measurement.

``set_params`` validates the whole new set (including the reference and its
waypoint file) before anything changes; the new set takes effect at the next
``update``. Every change, including an algorithm switch, is bumpless: a fresh
instance of the (new) algorithm starts from the old one's estimates (y, ẏ, ÿ)
with physically consistent states (see :mod:`.algorithms.base`); the
difference δ between its first command and the last command is added as an
offset that decays as exp(−t/bumpless_time_s). The first command after a
switch equals the last one; the TD keeps running through the switch.

The ESO is fed the command that was actually on the valve during the last
sample period: with ``transport_delay_samples = d`` (DESIGN §3: 1) that is the
command computed d + 1 samples ago.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import DEFAULT_STATE_FIELDS
from pneu_msgs_py.params.core import ParamError, validate

from pneu_control.algorithms import make_algorithm
from pneu_control.algorithms.base import StepInput
from pneu_control.controller.params import AxisControllerParams
from pneu_control.controller.references import axis_scale, make_reference
from pneu_control.observers.td import TrackingDifferentiator

__all__ = ["AxisController", "ControllerState", "STATE_FIELDS"]

_NAN = float("nan")


@dataclass(slots=True)
class ControllerState:
    """What the controller did at its last update (SI; NaN where not defined).

    Linear: m, m/s, m/s². Rotary (speed loop): rad/s, rad/s², rad/s³.
    ``reference``/``reference_dot`` are the reference as given (not the TD
    output); ``error`` = reference − measured (DESIGN §7); ``z1, z2, z3`` the
    observer's output, its derivative and the total disturbance; ``s`` the
    sliding variable (units of ė: m/s or rad/s²); ``u_raw``/``u_sat`` the
    unsaturated and the applied valve command in V (absolute, 5 V neutral).
    """

    t: float = 0.0
    reference: float = _NAN
    reference_dot: float = _NAN
    measured: float = _NAN
    error: float = _NAN
    z1: float = _NAN
    z2: float = _NAN
    z3: float = _NAN
    s: float = _NAN
    u_raw: float = _NAN
    u_sat: float = _NAN
    algorithm: str = ""


# the float fields of ControllerState, in the order of /pneu/<axis>/controller_state (one
# definition: the message contract's)
STATE_FIELDS: tuple[str, ...] = DEFAULT_STATE_FIELDS


class AxisController:
    """Controller core of one axis (``"linear"`` or ``"rotary"``); see module docstring."""

    def __init__(self, axis: str, params: AxisControllerParams):
        if axis not in ("linear", "rotary"):
            raise ParamError("axis", axis, "one of linear, rotary")
        self.axis = axis
        self._scale = axis_scale(axis)
        self._linear = axis == "linear"
        self._angle = axis == "rotary" and params.rotary_model == "angle"
        built = self._build(params)
        self._commit(built)
        self._pending = None
        self._state = ControllerState()
        self.reset()

    # -- parameters ---------------------------------------------------------
    def _build(self, params: AxisControllerParams):
        """Validate ``params`` completely and build every object; nothing is applied."""
        if not isinstance(params, AxisControllerParams):
            raise ParamError("params", type(params).__name__, "an AxisControllerParams")
        validate(params)
        if self._linear and params.eso_smc.friction_compensation:
            raise ParamError(
                "eso_smc.friction_compensation", True, "false on the linear axis (Eq. 31 is rotary)"
            )
        ref = make_reference(params.reference, self.axis, sample_time_s=params.sample_time_s)
        alg = make_algorithm(params, self.axis)
        return params, ref, alg

    def _commit(self, built) -> None:
        params, ref, alg = built
        self._td_was_on = getattr(self, "_td_on", params.td.enabled)
        self._T = params.sample_time_s
        self._params = params
        self._ref = ref
        self._alg = alg
        self._td_on = params.td.enabled
        self._neutral = params.limits.u_neutral
        self._delay = params.transport_delay_samples
        self._u_lo = params.limits.u_min
        self._u_hi = params.limits.u_max
        self._a_blend = math.exp(-params.sample_time_s / params.bumpless_time_s)

    @property
    def params(self) -> AxisControllerParams:
        return self._params

    @property
    def algorithm(self) -> str:
        return self._alg.name

    @property
    def bumpless_offset(self) -> float:
        """The decaying offset (V) still being added after the last switch (0 when done)."""
        return self._blend

    def set_params(self, params: AxisControllerParams) -> None:
        """Validate the whole set now (ParamError, old set kept); apply at the next update."""
        old = self._params
        if params.sample_time_s != old.sample_time_s:
            raise ParamError(
                "sample_time_s",
                params.sample_time_s,
                f"read-only at run time ({old.sample_time_s:g} s)",
            )
        if params.transport_delay_samples != old.transport_delay_samples:
            raise ParamError(
                "transport_delay_samples",
                params.transport_delay_samples,
                f"read-only at run time ({old.transport_delay_samples})",
            )
        if params.rotary_model != old.rotary_model:
            raise ParamError(
                "rotary_model", params.rotary_model, f"read-only at run time ({old.rotary_model})"
            )
        self._pending = self._build(params)

    def reset(self) -> None:
        """Forget all dynamic state; the next update is a cold start (t = 0 at its stamp)."""
        if self._pending is not None:
            self._commit(self._pending)
            self._pending = None
        p = self._params
        self._alg = make_algorithm(p, self.axis)
        self._td = TrackingDifferentiator(p.td.r, p.td.h, p.sample_time_s)
        self._t0_ns: int | None = None
        self._started = False
        self._u_hist = [self._neutral] * (self._delay + 1)  # V, oldest first
        self._inp = StepInput(history=self._u_hist)  # the algorithms' input, filled per sample
        self._u_last = self._neutral
        self._blend = 0.0  # V, decaying bumpless offset
        self._t = 0.0
        self._th_r = self._v1_prev = 0.0  # rotary angle mode: θ_r and the last v1
        self._r = self._rd = self._y = _NAN
        self._dirty = True
        self.n_nonfinite = 0

    # -- the cycle ----------------------------------------------------------
    def update(self, sample: SensorSample) -> float:
        """One control cycle; returns the saturated valve voltage (V)."""
        stamp = sample.stamp_ns
        if self._t0_ns is None:
            self._t0_ns = stamp
        t = (stamp - self._t0_ns) * 1e-9
        y_si = sample.x if self._linear else sample.omega
        r, rd, rdd = self._ref(t)
        self._t, self._r, self._rd, self._y = t, r, rd, y_si
        self._dirty = True
        k = self._scale
        if self._angle:
            th = sample.theta * k  # rpm·s: the angle whose derivative is the speed in rpm
            if not (-1e300 < y_si < 1e300 and -1e300 < th < 1e300):  # NaN/inf: hold, count
                self.n_nonfinite += 1
                return self._u_last
        else:
            th = 0.0
            if not (-1e300 < y_si < 1e300):
                self.n_nonfinite += 1
                return self._u_last
        y = y_si * k
        rp, rdp, rddp = r * k, rd * k, rdd * k
        inp = self._inp
        if self._alg.uses_theta or (self._pending is not None and self._pending[2].uses_theta):
            # an angle-observer algorithm (ESO-SMC+) reads the encoder angle, rpm·s
            th_a = sample.theta * k
            if not (-1e300 < th_a < 1e300):
                self.n_nonfinite += 1
                return self._u_last
            inp.theta = th_a
        inp.p_c1 = sample.p_c1  # chamber pressures, Pa abs (read by uses_pressures algorithms)
        inp.p_c2 = sample.p_c2
        if self._pending is not None or not self._started:
            return self._switch(y, th, rp, rdp, rddp)
        if self._td_on:  # the TD runs on the reference whatever the algorithm
            td = self._td
            td.step(rp)
            v1, v2, v3 = td.v1, td.v2, td.v3
        else:
            v1, v2, v3 = rp, rdp, rddp
        alg = self._alg
        if self._angle:  # Eq. 25 on the angle: reference θ_r = ∫v1 dt (trapezoid)
            th_r = self._th_r + 0.5 * self._T * (self._v1_prev + v1)
            self._th_r, self._v1_prev = th_r, v1
            if alg.uses_td:
                y, v1, v2, v3 = th, th_r, v1, v2
            else:
                v1, v2, v3 = rp, rdp, rddp
        elif not alg.uses_td:
            v1, v2, v3 = rp, rdp, rddp
        hist = self._u_hist
        neutral = self._neutral
        inp.y, inp.r, inp.r_dot, inp.r_ddot = y, v1, v2, v3
        inp.u_applied = hist[0] - neutral
        u = alg.update(inp) + neutral
        if self._blend != 0.0:
            u = self._blended(u)
        del hist[0]
        hist.append(u)
        self._u_last = u
        return u

    def _blended(self, u: float) -> float:
        b = self._blend * self._a_blend
        self._blend = b if abs(b) > 1e-12 else 0.0
        u += b
        return self._u_hi if u > self._u_hi else (self._u_lo if u < self._u_lo else u)

    def _finish(self, u_dev: float) -> float:
        u = u_dev + self._neutral
        hist = self._u_hist
        del hist[0]
        hist.append(u)
        self._u_last = u
        return u

    def _inputs(self, alg, y, th, rp, rdp, rddp, v1, v2, v3, u_applied) -> StepInput:
        """The step input for ``alg``: TD output or raw reference; angle or speed domain."""
        inp = self._inp
        if self._angle and alg.uses_td:
            inp.y, inp.r, inp.r_dot, inp.r_ddot = th, self._th_r, v1, v2
        elif alg.uses_td:
            inp.y, inp.r, inp.r_dot, inp.r_ddot = y, v1, v2, v3
        else:
            inp.y, inp.r, inp.r_dot, inp.r_ddot = y, rp, rdp, rddp
        inp.u_applied = u_applied
        return inp

    def _switch(self, y, th, rp, rdp, rddp) -> float:
        """Cold start, or apply the pending set bumplessly (see module docstring)."""
        started = self._started
        old_alg = self._alg
        td = self._td
        u_applied_v = self._u_hist[0]
        n_old = self._neutral
        hint = (_NAN, _NAN, _NAN)
        if started:
            # advance the reference pipeline with the old set, then bring the old
            # algorithm's estimates to this sample (its command is discarded)
            if self._td_on:
                td.step(rp)
                v1, v2, v3 = td.v1, td.v2, td.v3
            else:
                v1, v2, v3 = rp, rdp, rddp
            if self._angle:
                self._th_r += 0.5 * self._T * (self._v1_prev + v1)
                self._v1_prev = v1
            old_alg.update(
                self._inputs(old_alg, y, th, rp, rdp, rddp, v1, v2, v3, u_applied_v - n_old)
            )
            hint = old_alg.hint
        if self._pending is not None:
            params, ref, new_alg = self._pending  # a fresh instance: no shared state
            self._pending = None
            self._commit((params, ref, new_alg))
            # the reference may have changed: re-evaluate at this sample's time
            k = self._scale
            r_si, rd_si, rdd_si = ref(self._t)
            self._r, self._rd = r_si, rd_si
            rp, rdp, rddp = r_si * k, rd_si * k, rdd_si * k
            td.r, td.h = params.td.r, params.td.h
        new_alg = self._alg
        if not started:  # cold start: TD from the measured speed/position (soft start)
            td.reset(y, 0.0)
            if self._td_on:
                td.step(rp)
            v1, v2, v3 = (td.v1, td.v2, td.v3) if self._td_on else (rp, rdp, rddp)
            self._th_r, self._v1_prev = th, v1
            self._started = True
            inp = self._inputs(new_alg, y, th, rp, rdp, rddp, v1, v2, v3, 0.0)
            return self._finish(new_alg.start(inp, None, (_NAN, _NAN, _NAN)))
        if self._td_on:
            if not self._td_was_on:  # TD just enabled: start it on the reference
                td.reset(rp - 2.0 * td.h * rdp, rdp)  # fhan's steady ramp lag is 2h
                td.step(rp)
            v1, v2, v3 = td.v1, td.v2, td.v3
        else:
            v1, v2, v3 = rp, rdp, rddp
        if self._angle and old_alg.uses_td != new_alg.uses_td:  # speed ↔ angle domain
            hint = (th, hint[0], hint[1]) if new_alg.uses_td else (hint[1], hint[2], _NAN)
        n = self._neutral
        inp = self._inputs(new_alg, y, th, rp, rdp, rddp, v1, v2, v3, u_applied_v - n)
        u_new = new_alg.start(inp, self._u_last - n, hint) + n
        # bumpless: the first command equals the last one; the offset then decays
        self._blend = (self._u_last - u_new) / self._a_blend  # _blended() decays it once
        return self._finish(self._blended(u_new) - n)

    # -- what it did --------------------------------------------------------
    @property
    def state(self) -> ControllerState:
        """The last update's :class:`ControllerState` (refreshed in place; copy to keep)."""
        st = self._state
        if self._dirty:
            k = self._scale
            a = self._alg
            st.t = self._t
            st.reference = self._r
            st.reference_dot = self._rd
            st.measured = self._y
            st.error = self._r - self._y
            st.z1 = a.z1 / k
            st.z2 = a.z2 / k
            st.z3 = a.z3 / k
            st.s = a.s / k
            st.u_raw = a.u_raw + self._neutral
            st.u_sat = self._u_last
            st.algorithm = a.name
            self._dirty = False
        return st

    def state_values(self) -> tuple[float, ...]:
        """The float fields of :attr:`state` in :data:`STATE_FIELDS` order."""
        st = self.state
        return (
            st.t,
            st.reference,
            st.reference_dot,
            st.measured,
            st.error,
            st.z1,
            st.z2,
            st.z3,
            st.s,
            st.u_raw,
            st.u_sat,
        )
