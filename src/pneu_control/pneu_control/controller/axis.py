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

``hold(u_v)``: the supervisor holds this axis' valve at ``u_v`` (its safe 5 V: a latched
fault, the e-stop) and its commands are not applied. Until ``hold(None)`` each update
computes as usual but returns ``u_v`` and records it as the command on the valve, so the
observers are fed what was applied; the first update after the release restarts the
algorithm from its estimates as a switch does (a fresh instance, first command = ``u_v``,
the offset decaying over ``bumpless_time_s``): the valve takes the controller back
without a jump, whatever its states did while it was overridden.

The ESO is fed the command that was actually on the valve during the last
sample period: with ``transport_delay_samples = d`` (DESIGN §3: 1) that is the
command computed d + 1 samples ago.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import DEFAULT_STATE_FIELDS
from pneu_msgs_py.params.core import ParamError, validate
from pneu_msgs_py.params.records import RecordType, kernel

from pneu_control.algorithms import make_algorithm
from pneu_control.algorithms.base import MAX_HISTORY, StepInput
from pneu_control.controller.params import (
    ANGLE_ONLY_ALGORITHMS,
    AXIS_ALGORITHMS,
    AxisControllerParams,
)
from pneu_control.controller.references import axis_scale, make_reference
from pneu_control.observers.td import td_step

# the algorithms that position a rotary angle (rotary_control: angle): the generic
# second-order laws, coast (one-way drive, the paper's plumbing) and pva (both ways, the
# bidirectional plumbing)
ANGLE_ALGORITHMS = ("pid", "ladrc", "eso_smc", "coast", "pva")

__all__ = [
    "ANGLE_ALGORITHMS",
    "AXIS_CONSTANTS",
    "AXIS_STATE",
    "AxisController",
    "ControllerState",
    "STATE_FIELDS",
]

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


# The axis's own steps, kernels on records (DESIGN §12): AxisController runs them
# here, the compiled loop (pneu_control.fastloop) runs the same functions.
AXIS_CONSTANTS = RecordType(
    "AxisConstants",
    [
        ("scale", "f"), ("T", "f"), ("neutral", "f"), ("td_r", "f"), ("td_h", "f"),
        ("measured", "i"),  # MEASURE_X, MEASURE_OMEGA or MEASURE_THETA
        ("angle", "i"), ("td_on", "i"), ("uses_td", "i"),
    ],
)  # fmt: skip
AXIS_STATE = RecordType(
    "AxisState",
    [
        ("started", "i"), ("u_last", "f"), ("th_r", "f", 0.0), ("v1_prev", "f", 0.0),
        ("td_v1", "f", 0.0), ("td_v2", "f", 0.0), ("td_v3", "f", 0.0),
    ],
)  # fmt: skip


MEASURE_X, MEASURE_OMEGA, MEASURE_THETA = 0, 1, 2


@kernel
def measured(a, x, omega, theta):
    """The controlled output in SI: x (m) linear, ω (rad/s) rotary speed, θ (rad) rotary angle."""
    if a.measured == MEASURE_X:
        return x
    if a.measured == MEASURE_OMEGA:
        return omega
    return theta


@kernel
def td_advance(a, st, rp, rdp, rddp):
    """The TD on the reference (Eq. 23–24) when on; else the reference itself: (v1, v2, v3)."""
    if a.td_on:
        v1, v2, v3 = td_step(st.td_v1, st.td_v2, rp, a.td_r, a.td_h, a.T)
        st.td_v1 = v1
        st.td_v2 = v2
        st.td_v3 = v3
        return v1, v2, v3
    return rp, rdp, rddp


@kernel
def measure(a, inp, y_si, theta_si, p_c1, p_c2, needs_theta):
    """Paper units of one sample: (finite, y, θ); fills the angle and pressures of ``inp``.

    y: mm or rpm; θ (rpm·s) only in ``rotary_model: angle`` (else 0). Not finite (a NaN
    or inf measurement, or angle where it is read): the caller holds the last command.
    """
    k = a.scale
    if a.angle:
        th = theta_si * k  # rpm·s: the angle whose derivative is the speed in rpm
        if not (-1e300 < y_si < 1e300 and -1e300 < th < 1e300):
            return False, 0.0, 0.0
    else:
        th = 0.0
        if not (-1e300 < y_si < 1e300):
            return False, 0.0, 0.0
    if needs_theta:  # an angle-observer algorithm (ESO-SMC+) reads the encoder angle, rpm·s
        th_a = theta_si * k
        if not (-1e300 < th_a < 1e300):
            return False, 0.0, 0.0
        inp.theta = th_a
    inp.p_c1 = p_c1  # chamber pressures, Pa abs (read by uses_pressures algorithms)
    inp.p_c2 = p_c2
    return True, y_si * k, th


@kernel
def fill_inputs(a, st, inp, y, th, rp, rdp, rddp, v1, v2, v3, u_applied):
    """The step input: TD output or raw reference; angle domain (θ, θ_r) or speed/position."""
    if a.angle and a.uses_td:
        inp.y = th
        inp.r = st.th_r
        inp.r_dot = v1
        inp.r_ddot = v2
    elif a.uses_td:
        inp.y = y
        inp.r = v1
        inp.r_dot = v2
        inp.r_ddot = v3
    else:
        inp.y = y
        inp.r = rp
        inp.r_dot = rdp
        inp.r_ddot = rddp
    inp.u_applied = u_applied


@kernel
def cold_inputs(a, st, inp, y, th, rp, rdp, rddp):
    """First sample: the TD starts at the measurement (a soft start), θ_r at the angle."""
    st.td_v1 = y
    st.td_v2 = 0.0
    st.td_v3 = 0.0
    v1, v2, v3 = td_advance(a, st, rp, rdp, rddp)
    st.th_r = th
    st.v1_prev = v1
    st.started = 1
    fill_inputs(a, st, inp, y, th, rp, rdp, rddp, v1, v2, v3, 0.0)


@kernel
def step_inputs(a, st, inp, y, th, rp, rdp, rddp):
    """Every later sample: the TD, Eq. 25 on the angle (θ_r = ∫v1 dt, trapezoid), u_applied."""
    v1, v2, v3 = td_advance(a, st, rp, rdp, rddp)
    if a.angle:
        st.th_r = st.th_r + 0.5 * a.T * (st.v1_prev + v1)
        st.v1_prev = v1
    fill_inputs(a, st, inp, y, th, rp, rdp, rddp, v1, v2, v3, inp.history[0] - a.neutral)


@kernel
def finish(st, inp, u):
    """u (V) becomes the newest command of the history (oldest dropped) and the last one."""
    n = inp.n_hist
    hist = inp.history
    for i in range(n - 1):
        hist[i] = hist[i + 1]
    hist[n - 1] = u
    st.u_last = u
    return u


@kernel
def state_values(a, st, t, r, rd, y_si, z1, z2, z3, s, u_raw):
    """The :data:`STATE_FIELDS` values of the last update (SI; valve volts absolute)."""
    k = a.scale
    return (
        t, r, rd, y_si, r - y_si, z1 / k, z2 / k, z3 / k, s / k, u_raw + a.neutral, st.u_last,
    )  # fmt: skip


class AxisController:
    """Controller core of one axis (``"linear"`` or ``"rotary"``); see module docstring."""

    def __init__(self, axis: str, params: AxisControllerParams):
        if axis not in ("linear", "rotary"):
            raise ParamError("axis", axis, "one of linear, rotary")
        self.axis = axis
        self._linear = axis == "linear"
        self._control = "position" if self._linear else params.rotary_control
        self._scale = axis_scale(axis, params.rotary_control)
        self._angle = axis == "rotary" and params.rotary_model == "angle"
        built = self._build(params)
        self._commit(built)
        self._pending = None
        self._held: float | None = None  # the valve value the supervisor holds (V), or None
        self.n_rejoins = 0  # releases after a hold (restarts from the estimates)
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
        angle_control = not self._linear and params.rotary_control == "angle"
        if angle_control and params.algorithm == "eso_smc" and params.eso_smc.friction_compensation:
            raise ParamError(
                "eso_smc.friction_compensation",
                True,
                "false with rotary_control: angle (Eq. 31 is the speed loop's)",
            )
        if angle_control and params.algorithm not in ANGLE_ALGORITHMS:
            raise ParamError(
                "algorithm",
                params.algorithm,
                f"one of {', '.join(ANGLE_ALGORITHMS)} with rotary_control: angle",
            )
        if not angle_control and params.algorithm in ANGLE_ONLY_ALGORITHMS:
            raise ParamError(
                "algorithm",
                params.algorithm,
                f"{', '.join(AXIS_ALGORITHMS)} ({params.algorithm} positions an angle: "
                "rotary_control: angle)",
            )
        ref = make_reference(
            params.reference, self.axis, params.sample_time_s, rotary_control=params.rotary_control
        )
        alg = make_algorithm(params, self.axis)
        return params, ref, alg

    def _commit(self, built) -> None:
        params, ref, alg = built
        self._td_was_on = getattr(self, "_td_on", params.td.enabled)
        self._T = params.sample_time_s
        old = getattr(self, "_params", None)
        # a reference given by set_reference (a task's, a joint trajectory's) outlives a
        # change of gains; a change of the reference parameters replaces it
        if not (getattr(self, "_given_ref", False) and old.reference == params.reference):
            self._ref, self._next_ref, self._given_ref = ref, None, False
        self._params = params
        self._alg = alg
        self._td_on = params.td.enabled
        self._neutral = params.limits.u_neutral
        self._delay = params.transport_delay_samples
        self._u_lo = params.limits.u_min
        self._u_hi = params.limits.u_max
        self._a_blend = math.exp(-params.sample_time_s / params.bumpless_time_s)
        self._c = self.constants(params, alg)

    def constants(self, params: AxisControllerParams, alg) -> Any:
        """The :data:`AXIS_CONSTANTS` record of ``params`` with algorithm ``alg``."""
        return AXIS_CONSTANTS.new(
            scale=self._scale,
            T=params.sample_time_s,
            neutral=params.limits.u_neutral,
            td_r=float(params.td.r),
            td_h=float(params.td.h),
            measured=MEASURE_X
            if self._linear
            else (MEASURE_THETA if params.rotary_control == "angle" else MEASURE_OMEGA),
            angle=int(self._angle),
            td_on=int(params.td.enabled),
            uses_td=int(alg.uses_td),
        )

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
        if params.rotary_control != old.rotary_control:
            raise ParamError(
                "rotary_control",
                params.rotary_control,
                f"read-only at run time ({old.rotary_control})",
            )
        if params.rotary_model != old.rotary_model:
            raise ParamError(
                "rotary_model", params.rotary_model, f"read-only at run time ({old.rotary_model})"
            )
        self._pending = self._build(params)

    @property
    def held(self) -> float | None:
        """The valve voltage the supervisor holds this axis at (:meth:`hold`), or None."""
        return self._held

    def hold(self, u_v: float | None) -> None:
        """The supervisor holds the valve at ``u_v`` (V) -- or releases it (None): see the
        module docstring. A release restarts the algorithm at the next update, bumplessly
        from ``u_v`` (a pending parameter set is applied then, as usual)."""
        if u_v is not None and not (self._u_lo <= u_v <= self._u_hi):
            raise ParamError("hold", u_v, f"a voltage within [{self._u_lo:g}, {self._u_hi:g}] V")
        was, self._held = self._held, (None if u_v is None else float(u_v))
        if was is not None and u_v is None and self._st.started:
            if self._pending is None:  # the same set, a fresh instance: no wound-up state
                self._pending = (self._params, self._ref, make_algorithm(self._params, self.axis))
            self.n_rejoins += 1

    def _out(self, st, inp, u: float) -> float:
        """``finish`` with the supervisor's hold: the held value is what the valve gets."""
        return finish(st, inp, u if self._held is None else self._held)

    def set_reference(self, ref: Any, start_s: float | None = None) -> None:
        """Follow ``ref``: a callable t -> (r, ṙ, r̈) in SI (m, rad/s or rad), t on this
        controller's time base (s since its first sample).

        From the next update on, or with ``start_s`` from the first update at t >= start_s,
        the reference followed until then going on (joint_trajectory_controller's rule for
        a trajectory that starts in the future; a later call replaces one not yet started).
        The algorithm keeps running (no restart, no blending): a new setpoint or
        trajectory, as a task or a joint trajectory gives it. The TD, when on, tracks it
        from where it is. A change of the gains keeps it; one of ``reference.*`` ends it.
        """
        if not callable(ref):
            raise ParamError("reference", type(ref).__name__, "a callable t -> (r, r_dot, r_ddot)")
        if start_s is None:
            self._ref, self._next_ref = ref, None
        else:
            self._next_ref = (float(start_s), ref)
        self._given_ref = True

    @property
    def t0_ns(self) -> int | None:
        """The stamp of the first sample since the last reset (t = 0 there), None before it."""
        return self._t0_ns

    @property
    def controls(self) -> str:
        """What the output tracks: ``position`` (linear), ``speed`` or ``angle`` (rotary)."""
        return self._control

    @property
    def time_s(self) -> float:
        """The time of the last update on this controller's time base (s)."""
        return self._t

    def reset(self) -> None:
        """Forget all dynamic state; the next update is a cold start (t = 0 at its stamp)."""
        if self._pending is not None:
            self._commit(self._pending)
            self._pending = None
        p = self._params
        self._alg = make_algorithm(p, self.axis)
        self._t0_ns: int | None = None
        self._st = AXIS_STATE.new(u_last=self._neutral)
        n = self._delay + 1
        # the algorithms' input, filled per sample; its history: V, oldest first
        self._inp = StepInput(n_hist=n, history=[self._neutral] * n + [0.0] * (MAX_HISTORY - n))
        self._blend = 0.0  # V, decaying bumpless offset
        self._t = 0.0
        self._r = self._rd = self._y = _NAN
        self._dirty = True
        self.n_nonfinite = 0

    @property
    def _u_last(self) -> float:
        return self._st.u_last

    # -- the cycle ----------------------------------------------------------
    def update(self, sample: SensorSample) -> float:
        """One control cycle; returns the saturated valve voltage (V)."""
        stamp = sample.stamp_ns
        if self._t0_ns is None:
            self._t0_ns = stamp
        t = (stamp - self._t0_ns) * 1e-9
        c = self._c
        y_si = measured(c, sample.x, sample.omega, sample.theta)
        if self._next_ref is not None and t >= self._next_ref[0]:
            self._ref, self._next_ref = self._next_ref[1], None
        r, rd, rdd = self._ref(t)
        self._t, self._r, self._rd, self._y = t, r, rd, y_si
        self._dirty = True
        st, inp = self._st, self._inp
        pending = self._pending
        needs_theta = self._alg.uses_theta or (pending is not None and pending[2].uses_theta)
        ok, y, th = measure(c, inp, y_si, sample.theta, sample.p_c1, sample.p_c2, needs_theta)
        if not ok:  # NaN/inf: hold, count
            self.n_nonfinite += 1
            return st.u_last
        k = self._scale
        rp, rdp, rddp = r * k, rd * k, rdd * k
        if pending is not None or not st.started:
            return self._switch(y, th, rp, rdp, rddp)
        step_inputs(c, st, inp, y, th, rp, rdp, rddp)
        u = self._alg.update(inp) + self._neutral
        if self._blend != 0.0:
            u = self._blended(u)
        return self._out(st, inp, u)

    def _blended(self, u: float) -> float:
        b = self._blend * self._a_blend
        self._blend = b if abs(b) > 1e-12 else 0.0
        u += b
        return self._u_hi if u > self._u_hi else (self._u_lo if u < self._u_lo else u)

    def _switch(self, y, th, rp, rdp, rddp) -> float:
        """Cold start, or apply the pending set bumplessly (see module docstring)."""
        st, inp = self._st, self._inp
        if not st.started:  # cold start: TD from the measured speed/position (soft start)
            if self._pending is not None:
                self._apply_pending()
                rp, rdp, rddp = self._reference_now()
            cold_inputs(self._c, st, inp, y, th, rp, rdp, rddp)
            u = self._alg.start(inp, None, (_NAN, _NAN, _NAN))
            return self._out(st, inp, u + self._neutral)
        old_alg = self._alg
        u_applied_v = inp.history[0]
        # advance the reference pipeline with the old set, then bring the old algorithm's
        # estimates to this sample (its command is discarded)
        step_inputs(self._c, st, inp, y, th, rp, rdp, rddp)
        old_alg.update(inp)
        hint = old_alg.hint
        self._apply_pending()
        rp, rdp, rddp = self._reference_now()
        new_alg = self._alg
        c = self._c
        if self._td_on:
            if not self._td_was_on:  # TD just enabled: start it on the reference
                st.td_v1, st.td_v2 = rp - 2.0 * c.td_h * rdp, rdp  # fhan's steady ramp lag is 2h
                st.td_v3 = 0.0
                td_advance(c, st, rp, rdp, rddp)
            v1, v2, v3 = st.td_v1, st.td_v2, st.td_v3
        else:
            v1, v2, v3 = rp, rdp, rddp
        if self._angle and old_alg.uses_td != new_alg.uses_td:  # speed ↔ angle domain
            hint = (th, hint[0], hint[1]) if new_alg.uses_td else (hint[1], hint[2], _NAN)
        n = self._neutral
        fill_inputs(c, st, inp, y, th, rp, rdp, rddp, v1, v2, v3, u_applied_v - n)
        u_new = new_alg.start(inp, st.u_last - n, hint) + n
        # bumpless: the first command equals the last one; the offset then decays
        self._blend = (st.u_last - u_new) / self._a_blend  # _blended() decays it once
        return self._out(st, inp, (self._blended(u_new) - n) + n)  # as u_dev + neutral

    def _apply_pending(self) -> None:
        params, ref, new_alg = self._pending  # a fresh instance: no shared state
        self._pending = None
        self._commit((params, ref, new_alg))

    def _reference_now(self) -> tuple[float, float, float]:
        """The (possibly new) reference at this sample's time, in paper units."""
        k = self._scale
        r_si, rd_si, rdd_si = self._ref(self._t)
        self._r, self._rd = r_si, rd_si
        return r_si * k, rd_si * k, rdd_si * k

    # -- what it did --------------------------------------------------------
    @property
    def state(self) -> ControllerState:
        """The last update's :class:`ControllerState` (refreshed in place; copy to keep)."""
        st = self._state
        if self._dirty:
            (
                st.t, st.reference, st.reference_dot, st.measured, st.error, st.z1, st.z2,
                st.z3, st.s, st.u_raw, st.u_sat,
            ) = self._values()  # fmt: skip
            st.algorithm = self._alg.name
            self._dirty = False
        return st

    def state_values(self) -> tuple[float, ...]:
        """The float fields of :attr:`state` in :data:`STATE_FIELDS` order."""
        st = self.state
        return (
            st.t, st.reference, st.reference_dot, st.measured, st.error, st.z1, st.z2, st.z3,
            st.s, st.u_raw, st.u_sat,
        )  # fmt: skip

    def _values(self) -> tuple[float, ...]:
        a = self._alg
        return state_values(
            self._c, self._st, self._t, self._r, self._rd, self._y, a.z1, a.z2, a.z3, a.s,
            a.u_raw,
        )  # fmt: skip
