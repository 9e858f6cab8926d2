"""ESO-SMC+ (ours, beyond the paper): the ESO-SMC law on better-measured states.

The law and the surface are the paper's ESO-SMC (:mod:`.eso_smc`, Eq. 26–30
fixed per errata); three model-based changes feed them better information.

1. Rotary axis: an ESO on the encoder **angle** (``rotary_observer: angle``).
   The valve drives the inlet pressure, the pressure the torque, so the speed
   is second order in u (ω̈ = f + b0 u, the paper's rotary model) and the
   angle third order. With θ in rpm·s (θ̇ = ω in rpm)::

       θ‴ = f + b0 u,   z = (θ̂, ω̂, ω̇̂, f̂)   (4-state ESO, all poles at −ω0,
                                                 :mod:`pneu_control.observers.eso_chain`)

   The paper's surface on the speed error e_ω = ω_r − ω contains ∫e_ω dt,
   which *is* the angle error e_θ = θ_r − θ with θ_r = ∫ω_r dt. ESO-SMC
   integrates it from the speed estimate (quantised to 15 rpm per count per
   ms, ±12 rpm vane ripple) and freezes it under anti-windup, so its ∫e drifts
   from the true angle error; here e_θ is measured (1.57 mrad per count)::

       e = θ_r − θ̂,  ė = ω_r − ω̂,  ë = ω̇_r − ω̇̂
       s = ë + 2λ ė + λ² e                       (= ė_ω + 2λ e_ω + λ² ∫e_ω, Eq. 26)
       ṡ = ω̈_r − f − b0 u + 2λ ë + λ² ė = −ε sat(s)                      (Eq. 28)
       u = (ε sat(s) + ω̈_r + 2λ ë + λ² ė − f̂) / b0                       (Eq. 30)

   On s = 0 the speed error obeys the paper's double pole at −λ and the angle
   error decays too, so the mean speed over any window (what a tachometer, and
   our per-revolution metric, reads) converges to the reference: over a window
   τ the mean speed error is (e_θ(t) − e_θ(t − τ))/τ.

2. Valve linearisation (``valve_linearisation``): the MPYE's flow is a
   progressive function F(|u − 5 V|) of the setpoint (Festo chart; the
   ±0.35 V "dead band" is its flat start). The law computes a *linearised*
   command v (the b0 model holds for v); the valve gets
   u = sign(v) F⁻¹(g |v|), g = F(u_1)/u_1 with u_1 = ``valve_unit_v`` (1 V:
   where ``pneu tune`` identifies b0 with ±1 V steps, so b0 keeps its
   meaning). Beyond full opening the map continues with unit slope, so it is
   a bijection; the ESO is fed F applied to the command that was really on
   the valve, v_applied = sign(u) F(|u|)/g (bumpless blending and saturation
   stay consistent). Measured on the twin, it does not pay: near zero it
   multiplies the command (and the laser noise in it) by up to 2.6, and the
   sine's 20 mm/0.25 Hz tracking got worse (RMSE 0.17 → 0.26 mm); off by
   default, kept as an option for a rig with a quieter position sensor.

3. Reference derivatives (``reference_derivatives``): ``analytic`` uses the
   exact (r, ṙ, r̈) of the known reference (no TD lag: the fhan TD lags a
   ramp by about two samples, 0.06 mm at the sine's peak speed); ``td`` keeps
   the paper's TD (a soft start from rest to a speed step).

Linear axis: the ESO-SMC law on the 3-state ESO of the position (y = x in
mm), with ∫e rectangle rule and conditional integration as in ESO-SMC.

Anti-windup on the angle: while the valve command is saturated and e pushes
further into the saturation, θ_r advances with the estimated speed instead of
ω_r (the angle error is frozen, exactly like ESO-SMC's frozen ∫e_ω). The
reaching law's |s| > Δ condition of ESO-SMC is not used on the angle: e_θ is
a measured quantity, and with |ṡ| ≤ ε the loop recovers it at a speed offset
of at most ε/λ².

4. Friction feed-forward through the pressure rate (``friction_feedforward``,
   linear, ``linear_model: position``). The valve sets the *rate* of the
   chamber pressures, Ḟ_p ≈ b_F u (b_F in N/s/V), so the known Eq. 2 friction
   of the reference speed, F_f(ṙ) = A_f tanh(ṙ/v_s) + c_v ṙ, is fed forward as
   its rate::

       u_ff(k) = (F_f(ṙ_k) − F_f(ṙ_{k−1})) / (T b_F)      (Σ u_ff T b_F = ΔF_f exactly)

   At each reversal this builds the 2 A_f force swing the ESO would otherwise
   have to discover from the position error. The ESO is fed the law's part
   only (u_applied − u_ff of the same period): the FF's effect is physics it
   observes, not b0·u_ff. b_F = 500 N/s/V: slope of the measured pressure force
   after ±1 V steps on the twin (1.8·10⁶ mm/s³/V × M, 3–10 ms after the step).

5. Pressure cascade (``linear_model: force``, experimental, off). The rig
   measures both chamber pressures, so the piston force is a measurement
   (errata Eq. 1)::

       F_p = A_c1 p_c1 − A_c2 p_c2 − A_r p_a,     A_r = A_c1 − A_c2

   Observer: the 3-state ESO on the laser with the measured acceleration as a
   known input, ẍ = f + (F_p − F_f(ẋ̂))/M (f: sensor offsets, static friction,
   model error). Outer loop: Eq. 26–30 asking for an acceleration a_d, i.e. a
   force F_d = M (a_d − r̈) + M r̈ + F_f(ṙ) (a_d includes −f̂). Inner loop, from
   the chamber equations (volume terms)::

       Ḟ_p = b_F u − n (A_c1² p_c1/V_1 + A_c2² p_c2/V_2) ẋ
       u = [Ḟ_r + k_F (F_d − F_p) + n (A_c1² p_c1/V_1 + A_c2² p_c2/V_2) ẋ̂] / b_F

   (Ḟ_r: rate of the reference's own force M r̈ + F_f(ṙ); the feedback part is
   not differentiated, it carries the laser noise.) Measured on the twin: the
   pressure-aided velocity estimate is 2.3× better than the laser ESO's at the
   same ω0 (6.8 vs 15.4 mm/s rms, tested), but the cascade needs the valve
   linearisation (the flow curve's slope varies 4×; k_F = 200 rad/s already
   limit-cycles against the 2.3 ms sensor lag and the delay), and its position
   error stays above ESO-SMC's (best found 0.63/0.70 mm e_max mean/worst,
   λ 120, ω0 60): it stick-slips at low speed after each reversal.

What did not work (measured, not kept): friction feed-forward of Eq. 2
through b0 (f_k = −F_f(ṙ)/M asks for A_f/(M b0) ≈ 4 V: on this plant u sets
the *rate* of the chamber pressures, so a force is not b0·u; item 4 is the
rate form); a 4-state ESO on the laser position (x‴ = f + b0 u), which needs
the acceleration from a 86 µm-noise signal; the same 4-state ESO with the
pressure acceleration as a second output and the law one order up
(s = ë + 2λė + λ²e on x‴ = f + b3 u): mm-level errors on the twin (valve dead
band, stick-slip, b3 varies 3× with the opening); correcting the 3-state
ESO's f̂ from the pressure acceleration: an undamped acceleration loop (the
model's b0·u is an acceleration, the plant's is a force rate).

Gains: a design rule, not a grid search. b0 = 1.5 × the b0 that ``pneu tune``
identifies from the twin's step response (2403 mm/s²/V, 2.31e6 rpm/s²/V at
1100 rpm), on both axes: the plant's input gain grows with the operating
point (the Festo flow curve is convex; the rotary b is 1.27e6 at 600 and
2.96e6 rpm/s²/V at 1500 rpm) and with supply and lighter inertia, and an ESO
whose b0 is below the plant's b loses its gain margin. With b0 at the
identified value the angle observer limit-cycled at 1100 rpm (≈ 20 Hz,
±30 rpm) and at the light-inertia/high-supply corner; with 1.5× it does not
(600–1100 rpm × ±30 % corners, tested). ω0: the re-tuned ESO-SMC's 51.4 rad/s
(linear); 120 rad/s for the 4-pole angle observer (below ≈ 90 rad/s it
oscillates). λ_R 20 (linear), 10 (rotary); ε/b0 = 0.4 V and k = 1/Δ,
Δ = 2εT, as the re-tuned ESO-SMC.

Delay compensation (optional, as in ESO-SMC): the law acts on the ESO state
predicted over the transport delay with the commands already sent.

Units: mm (linear) or rpm / rpm·s (rotary); λ 1/s; b0 (mm|rpm)/s²/V;
ε (mm|rpm)/s²; commands V (deviation from 5 V).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from pneu_control.algorithms.base import StepInput
from pneu_control.algorithms.eso_smc_plus_params import EsoSmcPlusParams
from pneu_control.algorithms.smc import conditional_integral, sat
from pneu_control.algorithms.valve_curve import IDENTITY, ValveCurve
from pneu_control.observers.eso import eso3_step, eso_gains, extrapolate, predict3
from pneu_control.observers.eso_chain import chain_gains, eso4_step, predict4

if TYPE_CHECKING:
    from pneu_control.controller.params import AxisControllerParams

__all__ = ["EsoSmcPlus", "EsoSmcPlusParams", "ValveCurve"]

_NAN = float("nan")


class EsoSmcPlus:
    name = "eso_smc_plus"

    def __init__(self, params: AxisControllerParams, axis: str):
        p = params.eso_smc_plus
        T = params.sample_time_s
        self.T = T
        self.T2h = 0.5 * T * T
        self.T3s = T * T * T / 6.0
        lam = p.lambda_r
        self.c1 = 2.0 * lam
        self.c2 = lam * lam
        self.b0 = p.b_0
        self.eps = p.epsilon
        self.delta = p.delta
        self.k = p.k
        self.uses_td = p.reference_derivatives == "td"
        self.angle = axis == "rotary" and p.rotary_observer == "angle"
        self.uses_theta = self.angle  # reads StepInput.theta (rpm·s)
        # rotary_model "angle" with a TD-using algorithm: the controller passes (θ, θ_r, ω_r, ω̇_r)
        self.angle_inputs = axis == "rotary" and params.rotary_model == "angle" and self.uses_td
        if self.angle:
            self.l4s = chain_gains(4, p.omega_0, T)
        else:
            self.l1, self.l2, self.l3 = eso_gains(p.omega_0, T)
        self.valve = (
            ValveCurve(p.valve_du_table, p.valve_flow_table, p.valve_unit_v)
            if p.valve_linearisation
            else IDENTITY
        )
        self.lin_id = not p.valve_linearisation
        self.to_lin = None if self.lin_id else self.valve.to_linear  # for the predictors
        # linear_model "force": the cascade on the measured chamber pressures (module docstring)
        self.force = axis == "linear" and p.linear_model == "force"
        self.uses_pressures = self.force
        self.A_c1, self.A_c2 = p.A_c1, p.A_c2
        self.F_0 = (p.A_c1 - p.A_c2) * p.p_a  # ambient pressure on the rod (errata Eq. 1), N
        self.M_k = 1e-3 * p.M  # N per mm/s²
        self.inv_M_k = 1.0 / self.M_k
        self.A_f, self.c_v_k = p.A_f, 1e-3 * p.c_v  # N, N per mm/s
        self.inv_vs = 1.0 / p.v_s
        self.k_F = p.force_bandwidth
        self.inv_bF = 1.0 / p.b_F
        # chamber stiffness (Eq. 3/4 volume terms): Ḟ_p ∋ −n (A1² p1/V1 + A2² p2/V2) ẋ
        self.nA1s, self.nA2s = p.n_poly * p.A_c1**2, p.n_poly * p.A_c2**2
        self.V1_0 = p.V_1d + p.A_c1 * 0.5 * p.L  # m³ at x = 0
        self.V2_0 = p.V_2d + p.A_c2 * 0.5 * p.L
        self.F_p = _NAN  # measured pressure force, N
        self.a_in = 0.0  # (F_p − F_f(ẋ̂))/M over the last period, mm/s²
        self.F_d_prev = _NAN
        self.ffw = axis == "linear" and p.linear_model == "position" and p.friction_feedforward
        self.b_F = p.b_F
        self.ff_pipe = [0.0] * (params.transport_delay_samples + 1)
        self.u_ff = 0.0  # friction feed-forward of the last update, V
        lim = params.limits
        self.u_n = lim.u_neutral
        self.lo = lim.u_min - lim.u_neutral  # valve deviation limits, V
        self.hi = lim.u_max - lim.u_neutral
        self.v_lo = self.valve.to_linear(self.lo)  # the same limits in the linearised command
        self.v_hi = self.valve.to_linear(self.hi)
        self.dc = p.delay_compensation and params.transport_delay_samples > 0
        self.tau = params.transport_delay_samples * T
        # states: linear (z1, z2, z3) = (x, ẋ, f); rotary angle (z1..z4) = (θ, ω, ω̇, f)
        self.z1 = self.z2 = self.z3 = self.z4 = 0.0
        self.integral = 0.0  # linear / speed observer: ∫e dt
        self.th_r = 0.0  # rotary angle observer: reference angle θ_r (rpm·s)
        self.w_r_prev = 0.0
        self.s = 0.0
        self.u_raw = 0.0
        self.v_in = 0.0  # linearised command on the valve last period

    # -- what the next algorithm starts from --------------------------------
    @property
    def hint(self) -> tuple[float, float, float]:
        if self.force:  # ẍ = z3 + a_in
            return self.z1, self.z2, self.z3 + self.a_in
        if not self.angle:
            return self.z1, self.z2, self.z3 + self.b0 * self.v_in
        if self.angle_inputs:  # angle domain: (θ, ω, ω̇)
            return self.z1, self.z2, self.z3
        return self.z2, self.z3, self.z4 + self.b0 * self.v_in  # speed domain: (ω, ω̇, ω̈)

    def _out(self, v: float) -> float:
        self.u_raw = u = v if self.lin_id else self.valve.to_valve(v)
        return self.hi if u > self.hi else (self.lo if u < self.lo else u)

    # -- first sample -------------------------------------------------------
    def start(self, inp: StepInput, u_prev, hint):
        y, r, r_dot, r_ddot = inp.y, inp.r, inp.r_dot, inp.r_ddot
        v_in = self.valve.to_linear(inp.u_applied)
        self.v_in = v_in
        b0 = self.b0
        h0 = hint[0] if math.isfinite(hint[0]) else _NAN
        h1 = hint[1] if math.isfinite(hint[1]) else 0.0
        h2 = hint[2] if math.isfinite(hint[2]) else 0.0
        if self.force:
            self.z1 = z1 = h0 if math.isfinite(h0) else y
            self.z2 = z2 = h1
            F_p = self._pressure_force(inp)
            self.F_p = F_p = F_p if math.isfinite(F_p) else 0.0
            self.a_in = (F_p - self._friction(z2)) * self.inv_M_k
            self.z3 = h2 - self.a_in  # cold start: at rest (ẍ = 0), the offsets go into f
            e, ed = r - z1, r_dot - z2
            self.integral = 0.0 if u_prev is None else -(ed + self.c1 * e) / self.c2
            self.F_d_prev = _NAN
            return self._out(self._law_force(inp, F_p, False))
        if not self.angle:
            self.z1 = z1 = h0 if math.isfinite(h0) else y
            self.z2 = z2 = h1
            self.z3 = 0.0 if u_prev is None else h2 - b0 * v_in
            e, ed = r - z1, r_dot - z2
            self.integral = 0.0 if u_prev is None else -(ed + self.c1 * e) / self.c2
            s = ed + self.c1 * e + self.c2 * self.integral
            self.s = s
            v = (
                self.eps * sat(s, self.delta, self.k)
                + r_ddot
                + self.c1 * ed
                + self.c2 * e
                - self.z3
            ) / b0
            return self._out(v)
        w_r, wd_r, wdd_r = self._speed_ref(r, r_dot, r_ddot)
        self.z1 = th = inp.theta
        if self.angle_inputs:  # hint in the angle domain: (θ, ω, ω̇)
            self.z2 = h1 if math.isfinite(hint[1]) else 0.0
            self.z3 = h2
            self.z4 = 0.0
        else:  # speed domain: (ω, ω̇, ω̈)
            self.z2 = h0 if math.isfinite(h0) else y
            self.z3 = h1
            self.z4 = 0.0 if u_prev is None else h2 - b0 * v_in
        ed, edd = w_r - self.z2, wd_r - self.z3
        # cold start: θ_r from the measured angle; switch: start on the surface (s = 0)
        e = 0.0 if u_prev is None else -(edd + self.c1 * ed) / self.c2
        self.th_r = th + e
        self.w_r_prev = w_r
        s = edd + self.c1 * ed + self.c2 * e
        self.s = s
        v = (
            self.eps * sat(s, self.delta, self.k) + wdd_r + self.c1 * edd + self.c2 * ed - self.z4
        ) / b0
        return self._out(v)

    def _speed_ref(self, r, r_dot, r_ddot):
        """(ω_r, ω̇_r, ω̈_r) from the controller's inputs (see angle_inputs)."""
        if self.angle_inputs:
            return r_dot, r_ddot, 0.0
        return r, r_dot, r_ddot

    # -- every later sample -------------------------------------------------
    def update(self, inp: StepInput):
        u_applied = inp.u_applied
        v_in = u_applied if self.lin_id else self.valve.to_linear(u_applied)
        self.v_in = v_in
        if self.angle:
            return self._update_angle(inp, v_in)
        if self.force:
            return self._update_force(inp)
        T = self.T
        if self.ffw:  # the ESO models the law's part only; the FF acts on the force
            ffp = self.ff_pipe
            v_in -= ffp[0]
            del ffp[0]
        # 3-state ESO (Eq. 18, exact ZOH current observer, pneu_control.observers.eso)
        z3 = self.z3
        z1, z2, z3 = eso3_step(
            self.z1, self.z2, z3, z3 + self.b0 * v_in, inp.y, T, self.T2h,
            self.l1, self.l2, self.l3,
        )  # fmt: skip
        self.z1, self.z2, self.z3 = z1, z2, z3
        r, r_dot, r_ddot = inp.r, inp.r_dot, inp.r_ddot
        if self.dc:
            z1, z2 = predict3(
                z1, z2, z3, inp.history, self.u_n, self.b0, 0.0, T, self.T2h, self.to_lin
            )
            r, r_dot = extrapolate(r, r_dot, r_ddot, self.tau)
        e = r - z1
        ed = r_dot - z2
        integral = self.integral + T * e
        c1, c2 = self.c1, self.c2
        s = ed + c1 * e + c2 * integral  # Eq. 26 (fixed)
        self.s = s
        v = (
            self.eps * sat(s, self.delta, self.k) + r_ddot + c1 * ed + c2 * e - z3
        ) / self.b0  # Eq. 30
        if self.ffw:
            # friction feed-forward through the pressure rate: u_ff = dF_f(ṙ)/dt / b_F (Eq. 2)
            F_r = self._friction(r_dot)
            u_ff = 0.0 if self.F_d_prev != self.F_d_prev else (F_r - self.F_d_prev) / (T * self.b_F)
            self.F_d_prev = F_r
            self.ff_pipe.append(u_ff)
            self.u_ff = u_ff
            v += u_ff
        # conditional integration (as ESO-SMC): valve saturation or |s| > Δ
        self.integral = conditional_integral(
            self.integral, integral, e, v, s, self.v_lo, self.v_hi, self.delta
        )
        return self._out(v)

    def _pressure_force(self, inp: StepInput) -> float:
        """F_p = A_c1 p_c1 − A_c2 p_c2 − A_r p_a (errata Eq. 1), N."""
        return self.A_c1 * inp.p_c1 - self.A_c2 * inp.p_c2 - self.F_0

    def _friction(self, v: float) -> float:
        """F_f(v) of Eq. 2, Coulomb sign smoothed (tanh over v_s), N; v in mm/s."""
        return self.A_f * math.tanh(v * self.inv_vs) + self.c_v_k * v

    def _update_force(self, inp: StepInput):
        T = self.T
        # 3-state ESO on the laser with the measured acceleration as known input:
        # ẍ = f + (F_p − F_f(ẋ))/M  (f: sensor offsets, static friction, model error)
        z3 = self.z3
        z1, z2, z3 = eso3_step(
            self.z1, self.z2, z3, z3 + self.a_in, inp.y, T, self.T2h, self.l1, self.l2, self.l3
        )
        self.z1, self.z2, self.z3 = z1, z2, z3
        F_p = self._pressure_force(inp)
        if not (-1e300 < F_p < 1e300):  # no pressures this sample: hold the last one
            F_p = self.F_p
        self.F_p = F_p
        self.a_in = (F_p - self._friction(z2)) * self.inv_M_k
        return self._out(self._law_force(inp, F_p, True))

    def _law_force(self, inp: StepInput, F_p, integrate):
        T, z1, z2, z3 = self.T, self.z1, self.z2, self.z3
        r, r_dot, r_ddot = inp.r, inp.r_dot, inp.r_ddot
        # outer loop: Eq. 26–30 on ẍ, asking for an acceleration a_d
        e = r - z1
        ed = r_dot - z2
        integral = self.integral + T * e
        c1, c2 = self.c1, self.c2
        s = ed + c1 * e + c2 * integral
        self.s = s
        a_d = self.eps * sat(s, self.delta, self.k) + r_ddot + c1 * ed + c2 * e - z3
        # desired piston force (Eq. 1 with the Eq. 2 friction of the reference speed)
        F_r = self.M_k * r_ddot + self._friction(r_dot)  # the reference's own force
        F_d = F_r + self.M_k * (a_d - r_ddot)
        # feed-forward of Ḟ_d: the reference part only (the feedback part carries laser noise)
        F_rp = self.F_d_prev
        self.F_d_prev = F_r
        F_d_dot = 0.0 if F_rp != F_rp else (F_r - F_rp) / T
        # inner loop: Ḟ_p = b_F u − n (A1² p1/V1 + A2² p2/V2) ẋ  (Eq. 3/4, volume terms)
        x_m = 1e-3 * z1
        K_s = self.nA1s * inp.p_c1 / (self.V1_0 + self.A_c1 * x_m) + self.nA2s * inp.p_c2 / (
            self.V2_0 - self.A_c2 * x_m
        )
        if not (-1e300 < K_s < 1e300):  # a NaN pressure this sample: no stiffness term
            K_s = 0.0
        v = (F_d_dot + self.k_F * (F_d - F_p) + K_s * 1e-3 * z2) * self.inv_bF
        if integrate:  # conditional integration (as ESO-SMC)
            self.integral = conditional_integral(
                self.integral, integral, e, v, s, self.v_lo, self.v_hi, self.delta
            )
        return v

    def _update_angle(self, inp: StepInput, v_in):
        T, T2h, T3s = self.T, self.T2h, self.T3s
        # 4-state ESO on the angle (θ‴ = f + b0 u; observers.eso_chain, exact ZOH current observer)
        z4 = self.z4
        z1, z2, z3, z4 = eso4_step(
            self.z1, self.z2, self.z3, z4, z4 + self.b0 * v_in, inp.theta, T, T2h, T3s, self.l4s
        )
        self.z1, self.z2, self.z3, self.z4 = z1, z2, z3, z4
        w_r, wd_r, wdd_r = self._speed_ref(inp.r, inp.r_dot, inp.r_ddot)
        # reference angle θ_r = ∫ω_r dt (trapezoid); the controller's own in angle_inputs
        if self.angle_inputs:
            th_r = inp.r
        else:
            th_r = self.th_r + 0.5 * T * (self.w_r_prev + w_r)
            self.w_r_prev = w_r
        th_c, w_c, wd_c = th_r, w_r, wd_r
        if self.dc:  # act on the state the command will meet: t + d T
            z1, z2, z3 = predict4(
                z1, z2, z3, z4, inp.history, self.u_n, self.b0, T, T2h, T3s, self.to_lin
            )
            tau = self.tau
            th_c += tau * w_r + 0.5 * tau * tau * wd_r
            w_c += tau * wd_r
        e = th_c - z1
        ed = w_c - z2
        edd = wd_c - z3
        c1, c2 = self.c1, self.c2
        s = edd + c1 * ed + c2 * e  # = ė_ω + 2λ e_ω + λ² ∫e_ω (Eq. 26 fixed)
        self.s = s
        v = (self.eps * sat(s, self.delta, self.k) + wdd_r + c1 * edd + c2 * ed - z4) / self.b0
        if not self.angle_inputs:
            # anti-windup: the angle error is frozen while the valve saturates in e's direction
            if (e > 0.0 and v > self.v_hi) or (e < 0.0 and v < self.v_lo):
                th_r = self.th_r + T * self.z2
            self.th_r = th_r
        return self._out(v)
