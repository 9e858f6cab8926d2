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
   default, kept as an option for a rig with a quieter position sensor. Tasks
   turn it on (:data:`pneu_control.task.session.LINEAR`): a load step drives the
   command beyond ±1 V, where the chart's slope is 3–5× the 1 V secant and the
   loop without it rings on in a saturated cycle (a 60 N step at 30 mm;
   docs/composite-motion.md, "Holding a load").

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

The step is written once, as kernels on records (DESIGN §12):
:func:`plus_start`, :func:`plus_update`, :func:`plus_hint` on
:data:`ESO_SMC_PLUS_CONSTANTS`, :data:`ESO_SMC_PLUS_STATE` and the valve chart
(:mod:`.valve_curve`, rows du and flow); :class:`EsoSmcPlus` and the compiled loop
call the same functions.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from pneu_msgs_py.params.records import RecordType, kernel

from pneu_control.algorithms.base import MAX_HISTORY, AlgorithmKernel, KernelAlgorithm
from pneu_control.algorithms.eso_smc_plus_params import EsoSmcPlusParams
from pneu_control.algorithms.smc import (
    conditional_integral,
    reaching_command,
    sliding_surface,
    surface_step,
)
from pneu_control.algorithms.valve_curve import (
    VALVE_FIELDS,
    ValveCurve,
    to_linear,
    to_valve,
    valve_constants,
    valve_table,
)
from pneu_control.observers.eso import eso3_observe, eso_gains, extrapolate, predict3
from pneu_control.observers.eso_chain import chain_gains, eso4_step, predict4

if TYPE_CHECKING:
    from pneu_control.controller.params import AxisControllerParams

__all__ = [
    "ESO_SMC_PLUS_CONSTANTS",
    "ESO_SMC_PLUS_STATE",
    "EsoSmcPlus",
    "EsoSmcPlusParams",
    "ValveCurve",
    "plus_start",
    "plus_update",
]

NAN = math.nan

# Units: mm, rpm, rpm·s as in the module docstring; SI (N, m, Pa) in the force cascade.
ESO_SMC_PLUS_CONSTANTS = RecordType(
    "EsoSmcPlusConstants",
    [
        ("T", "f"), ("T2h", "f"), ("T3s", "f"),  # T, T²/2, T³/6
        ("c1", "f"), ("c2", "f"), ("b0", "f"), ("eps", "f"), ("delta", "f"), ("k", "f"),
        # observer gains: linear / speed l1..l3 (observers.eso), angle l1..l4 (eso_chain)
        ("l1", "f"), ("l2", "f"), ("l3", "f"), ("l4", "f"),
        # force cascade (linear_model force) and the Eq. 2 friction
        ("A_c1", "f"), ("A_c2", "f"), ("F_0", "f"), ("M_k", "f"), ("inv_M_k", "f"),
        ("A_f", "f"), ("c_v_k", "f"), ("inv_vs", "f"), ("k_F", "f"), ("inv_bF", "f"),
        ("nA1s", "f"), ("nA2s", "f"), ("V1_0", "f"), ("V2_0", "f"), ("b_F", "f"),
        # valve limits (deviation and linearised), delay
        ("u_n", "f"), ("lo", "f"), ("hi", "f"), ("v_lo", "f"), ("v_hi", "f"), ("tau", "f"),
        *VALVE_FIELDS,  # the valve map (valve_curve), read with the table
        # options: angle observer, rotary_model angle inputs, no valve map, force cascade,
        # friction feed-forward, delay compensation; ff pipe length d + 1
        ("angle", "i"), ("angle_inputs", "i"), ("lin_id", "i"), ("force", "i"), ("ffw", "i"),
        ("dc", "i"), ("n_ff", "i"),
    ],
)  # fmt: skip

# linear (z1, z2, z3) = (x, ẋ, f); rotary angle (z1..z4) = (θ, ω, ω̇, f); th_r: reference
# angle (rpm·s); v_in: linearised command on the valve last period; F_p (N), a_in (mm/s²):
# the force cascade's measured force and known acceleration; F_d_prev: the last reference
# force (N); ff_pipe[:n_ff]: feed-forward commands (V) oldest first, u_ff the last one;
# v_hist: the linearised commands the predictors run over (scratch)
ESO_SMC_PLUS_STATE = RecordType(
    "EsoSmcPlusState",
    [
        ("z1", "f", 0.0), ("z2", "f", 0.0), ("z3", "f", 0.0), ("z4", "f", 0.0),
        ("s", "f", 0.0), ("u_raw", "f", 0.0), ("integral", "f", 0.0), ("th_r", "f", 0.0),
        ("w_r_prev", "f", 0.0), ("v_in", "f", 0.0), ("F_p", "f"), ("a_in", "f", 0.0),
        ("F_d_prev", "f"), ("u_ff", "f", 0.0),
        ("ff_pipe", ("f", MAX_HISTORY)), ("v_hist", ("f", MAX_HISTORY)),
    ],
)  # fmt: skip


# ------------------------------------------------------------------ valve map, model pieces
@kernel
def linearised(c, table, u):
    """The linearised command of the valve deviation u (identity without the valve map)."""
    return u if c.lin_id else to_linear(c, table, u)


@kernel
def plus_out(c, s, table, v):
    """The valve deviation for the linearised command v, saturated (u_raw: unsaturated)."""
    u = v if c.lin_id else to_valve(c, table, v)
    s.u_raw = u
    hi = c.hi
    lo = c.lo
    return hi if u > hi else (lo if u < lo else u)


@kernel
def model_history(c, s, table, inp):
    """(history, u_n) for the predictors: the commands themselves, or linearised in v_hist."""
    if c.lin_id:
        return inp.history, c.u_n
    h = inp.history
    v = s.v_hist
    u_n = c.u_n
    for i in range(1, inp.n_hist):
        v[i] = to_linear(c, table, h[i] - u_n)
    return v, 0.0  # v − 0.0 is v, bit for bit


@kernel
def pressure_force(c, p_c1, p_c2):
    """F_p = A_c1 p_c1 − A_c2 p_c2 − A_r p_a (errata Eq. 1), N."""
    return c.A_c1 * p_c1 - c.A_c2 * p_c2 - c.F_0


@kernel
def friction(c, v):
    """F_f(v) of Eq. 2, Coulomb sign smoothed (tanh over v_s), N; v in mm/s."""
    return c.A_f * math.tanh(v * c.inv_vs) + c.c_v_k * v


@kernel
def speed_ref(c, r, r_dot, r_ddot):
    """(ω_r, ω̇_r, ω̈_r) from the controller's inputs (see angle_inputs)."""
    if c.angle_inputs:
        return r_dot, r_ddot, 0.0
    return r, r_dot, r_ddot


@kernel
def plus_hint(c, s):
    if c.force:  # ẍ = z3 + a_in
        return s.z1, s.z2, s.z3 + s.a_in
    if not c.angle:
        return s.z1, s.z2, s.z3 + c.b0 * s.v_in
    if c.angle_inputs:  # angle domain: (θ, ω, ω̇)
        return s.z1, s.z2, s.z3
    return s.z2, s.z3, s.z4 + c.b0 * s.v_in  # speed domain: (ω, ω̇, ω̈)


# ------------------------------------------------------------------ force cascade
@kernel
def law_force(c, s, inp, F_p, integrate):
    """The cascade's linearised command: outer Eq. 26–30 on ẍ, inner force loop (Eq. 1–4)."""
    T = c.T
    z1 = s.z1
    z2 = s.z2
    z3 = s.z3
    r = inp.r
    r_dot = inp.r_dot
    r_ddot = inp.r_ddot
    # outer loop: Eq. 26–30 on ẍ, asking for an acceleration a_d
    e, ed, integral, sv = surface_step(c, s, r, r_dot, z1, z2)
    a_d = reaching_command(sv, e, ed, r_ddot, c.c1, c.c2, c.eps, c.delta, c.k) - z3
    # desired piston force (Eq. 1 with the Eq. 2 friction of the reference speed)
    F_r = c.M_k * r_ddot + friction(c, r_dot)  # the reference's own force
    F_d = F_r + c.M_k * (a_d - r_ddot)
    # feed-forward of Ḟ_d: the reference part only (the feedback part carries laser noise)
    F_rp = s.F_d_prev
    s.F_d_prev = F_r
    F_d_dot = 0.0 if F_rp != F_rp else (F_r - F_rp) / T
    # inner loop: Ḟ_p = b_F u − n (A1² p1/V1 + A2² p2/V2) ẋ  (Eq. 3/4, volume terms)
    x_m = 1e-3 * z1
    K_s = c.nA1s * inp.p_c1 / (c.V1_0 + c.A_c1 * x_m) + c.nA2s * inp.p_c2 / (c.V2_0 - c.A_c2 * x_m)
    if not (-1e300 < K_s < 1e300):  # a NaN pressure this sample: no stiffness term
        K_s = 0.0
    v = (F_d_dot + c.k_F * (F_d - F_p) + K_s * 1e-3 * z2) * c.inv_bF
    if integrate:  # conditional integration (as ESO-SMC)
        s.integral = conditional_integral(s.integral, integral, e, v, sv, c.v_lo, c.v_hi, c.delta)
    return v


@kernel
def update_force(c, s, table, inp):
    # 3-state ESO on the laser with the measured acceleration as known input:
    # ẍ = f + (F_p − F_f(ẋ))/M  (f: sensor offsets, static friction, model error)
    z2 = eso3_observe(c, s, s.z3 + s.a_in, inp.y)[1]
    F_p = pressure_force(c, inp.p_c1, inp.p_c2)
    if not (-1e300 < F_p < 1e300):  # no pressures this sample: hold the last one
        F_p = s.F_p
    s.F_p = F_p
    s.a_in = (F_p - friction(c, z2)) * c.inv_M_k
    return plus_out(c, s, table, law_force(c, s, inp, F_p, True))


# ------------------------------------------------------------------ angle observer
@kernel
def update_angle(c, s, table, inp, v_in):
    T = c.T
    T2h = c.T2h
    T3s = c.T3s
    b0 = c.b0
    # 4-state ESO on the angle (θ‴ = f + b0 u; observers.eso_chain, exact ZOH current observer)
    z4 = s.z4
    z1, z2, z3, z4 = eso4_step(
        s.z1, s.z2, s.z3, z4, z4 + b0 * v_in, inp.theta, T, T2h, T3s, c.l1, c.l2, c.l3, c.l4
    )
    s.z1 = z1
    s.z2 = z2
    s.z3 = z3
    s.z4 = z4
    w_r, wd_r, wdd_r = speed_ref(c, inp.r, inp.r_dot, inp.r_ddot)
    # reference angle θ_r = ∫ω_r dt (trapezoid); the controller's own in angle_inputs
    angle_inputs = c.angle_inputs
    if angle_inputs:
        th_r = inp.r
    else:
        th_r = s.th_r + 0.5 * T * (s.w_r_prev + w_r)
        s.w_r_prev = w_r
    th_c = th_r
    w_c = w_r
    wd_c = wd_r
    if c.dc:  # act on the state the command will meet: t + d T
        hist, u_n = model_history(c, s, table, inp)
        z1, z2, z3 = predict4(z1, z2, z3, z4, hist, inp.n_hist, u_n, b0, T, T2h, T3s)
        tau = c.tau
        th_c += tau * w_r + 0.5 * tau * tau * wd_r
        w_c += tau * wd_r
    e = th_c - z1
    ed = w_c - z2
    edd = wd_c - z3
    c1 = c.c1
    c2 = c.c2
    sv = sliding_surface(ed, edd, e, c1, c2)  # = ė_ω + 2λ e_ω + λ² ∫e_ω (Eq. 26 fixed)
    s.s = sv
    v = (reaching_command(sv, ed, edd, wdd_r, c1, c2, c.eps, c.delta, c.k) - z4) / b0
    if not angle_inputs:
        # anti-windup: the angle error is frozen while the valve saturates in e's direction
        if (e > 0.0 and v > c.v_hi) or (e < 0.0 and v < c.v_lo):
            th_r = s.th_r + T * s.z2
        s.th_r = th_r
    return plus_out(c, s, table, v)


# ------------------------------------------------------------------ start, update
@kernel
def plus_start(c, s, table, inp, u_prev, h0, h1, h2):
    y = inp.y
    r = inp.r
    r_dot = inp.r_dot
    r_ddot = inp.r_ddot
    v_in = linearised(c, table, inp.u_applied)
    s.v_in = v_in
    b0 = c.b0
    c1 = c.c1
    c2 = c.c2
    h0 = h0 if math.isfinite(h0) else NAN
    h1 = h1 if math.isfinite(h1) else 0.0
    h2 = h2 if math.isfinite(h2) else 0.0
    cold = u_prev != u_prev
    if c.force:
        z1 = h0 if math.isfinite(h0) else y
        z2 = h1
        s.z1 = z1
        s.z2 = z2
        F_p = pressure_force(c, inp.p_c1, inp.p_c2)
        F_p = F_p if math.isfinite(F_p) else 0.0
        s.F_p = F_p
        a_in = (F_p - friction(c, z2)) * c.inv_M_k
        s.a_in = a_in
        s.z3 = h2 - a_in  # cold start: at rest (ẍ = 0), the offsets go into f
        e = r - z1
        ed = r_dot - z2
        s.integral = 0.0 if cold else -(ed + c1 * e) / c2
        s.F_d_prev = NAN
        return plus_out(c, s, table, law_force(c, s, inp, F_p, False))
    if not c.angle:
        z1 = h0 if math.isfinite(h0) else y
        z2 = h1
        s.z1 = z1
        s.z2 = z2
        z3 = 0.0 if cold else h2 - b0 * v_in
        s.z3 = z3
        e = r - z1
        ed = r_dot - z2
        integral = 0.0 if cold else -(ed + c1 * e) / c2
        s.integral = integral
        sv = sliding_surface(e, ed, integral, c1, c2)
        s.s = sv
        v = (reaching_command(sv, e, ed, r_ddot, c1, c2, c.eps, c.delta, c.k) - z3) / b0
        return plus_out(c, s, table, v)
    w_r, wd_r, wdd_r = speed_ref(c, r, r_dot, r_ddot)
    th = inp.theta
    s.z1 = th
    if c.angle_inputs:  # hint in the angle domain: (θ, ω, ω̇)
        z2 = h1
        z3 = h2
        z4 = 0.0
    else:  # speed domain: (ω, ω̇, ω̈)
        z2 = h0 if math.isfinite(h0) else y
        z3 = h1
        z4 = 0.0 if cold else h2 - b0 * v_in
    s.z2 = z2
    s.z3 = z3
    s.z4 = z4
    ed = w_r - z2
    edd = wd_r - z3
    # cold start: θ_r from the measured angle; switch: start on the surface (s = 0)
    e = 0.0 if cold else -(edd + c1 * ed) / c2
    s.th_r = th + e
    s.w_r_prev = w_r
    sv = sliding_surface(ed, edd, e, c1, c2)
    s.s = sv
    v = (reaching_command(sv, ed, edd, wdd_r, c1, c2, c.eps, c.delta, c.k) - z4) / b0
    return plus_out(c, s, table, v)


@kernel
def plus_update(c, s, table, inp):
    v_in = linearised(c, table, inp.u_applied)
    s.v_in = v_in
    if c.angle:
        return update_angle(c, s, table, inp, v_in)
    if c.force:
        return update_force(c, s, table, inp)
    T = c.T
    b0 = c.b0
    ffw = c.ffw
    if ffw:  # the ESO models the law's part only; the FF acts on the force
        ffp = s.ff_pipe
        v_in -= ffp[0]
        for i in range(c.n_ff - 1):
            ffp[i] = ffp[i + 1]
    # 3-state ESO (Eq. 18, exact ZOH current observer, pneu_control.observers.eso)
    z1, z2, z3 = eso3_observe(c, s, s.z3 + b0 * v_in, inp.y)
    r = inp.r
    r_dot = inp.r_dot
    r_ddot = inp.r_ddot
    if c.dc:
        hist, u_n = model_history(c, s, table, inp)
        z1, z2 = predict3(z1, z2, z3, hist, inp.n_hist, u_n, b0, 0.0, T, c.T2h)
        r, r_dot = extrapolate(r, r_dot, r_ddot, c.tau)
    e, ed, integral, sv = surface_step(c, s, r, r_dot, z1, z2)  # Eq. 26 (fixed)
    v = (reaching_command(sv, e, ed, r_ddot, c.c1, c.c2, c.eps, c.delta, c.k) - z3) / b0  # Eq. 30
    if ffw:
        # friction feed-forward through the pressure rate: u_ff = dF_f(ṙ)/dt / b_F (Eq. 2)
        F_r = friction(c, r_dot)
        F_dp = s.F_d_prev
        u_ff = 0.0 if F_dp != F_dp else (F_r - F_dp) / (T * c.b_F)
        s.F_d_prev = F_r
        s.ff_pipe[c.n_ff - 1] = u_ff
        s.u_ff = u_ff
        v += u_ff
    # conditional integration (as ESO-SMC): valve saturation or |s| > Δ
    s.integral = conditional_integral(s.integral, integral, e, v, sv, c.v_lo, c.v_hi, c.delta)
    return plus_out(c, s, table, v)


class EsoSmcPlus(KernelAlgorithm):
    name = "eso_smc_plus"
    CONSTANTS = ESO_SMC_PLUS_CONSTANTS
    STATE = ESO_SMC_PLUS_STATE
    KERNEL = AlgorithmKernel(plus_start, plus_update, plus_hint)

    def __init__(self, params: AxisControllerParams, axis: str):
        super().__init__(params, axis)
        c = self.c
        self.uses_td = params.eso_smc_plus.reference_derivatives == "td"
        self.uses_theta = bool(c.angle)  # reads StepInput.theta (rpm·s)
        self.uses_pressures = bool(c.force)
        # the valve map of the linearised command (None without it)
        self.valve = None if c.lin_id else ValveCurve(*self._chart(params))

    @staticmethod
    def _chart(params: AxisControllerParams) -> tuple[Any, Any, float]:
        p = params.eso_smc_plus
        return p.valve_du_table, p.valve_flow_table, p.valve_unit_v

    def table(self, params: AxisControllerParams, axis: str) -> Any:
        """The valve chart, rows (du, flow) as lists (the compiled loop: ``np.asarray``)."""
        du, fl, _ = self._chart(params)
        return valve_table(du, fl)

    def constants(self, params: AxisControllerParams, axis: str):
        p = params.eso_smc_plus
        T = params.sample_time_s
        lam = p.lambda_r
        uses_td = p.reference_derivatives == "td"
        angle = axis == "rotary" and p.rotary_observer == "angle"
        if angle:
            l1, l2, l3, l4 = chain_gains(4, p.omega_0, T)
        else:
            l1, l2, l3 = eso_gains(p.omega_0, T)
            l4 = NAN
        lin_id = not p.valve_linearisation
        lim = params.limits
        lo = lim.u_min - lim.u_neutral  # valve deviation limits, V
        hi = lim.u_max - lim.u_neutral
        c = ESO_SMC_PLUS_CONSTANTS.new(
            T=T,
            T2h=0.5 * T * T,
            T3s=T * T * T / 6.0,
            c1=2.0 * lam,
            c2=lam * lam,
            b0=p.b_0,
            eps=p.epsilon,
            delta=p.delta,
            k=p.k,
            l1=l1,
            l2=l2,
            l3=l3,
            l4=l4,
            A_c1=p.A_c1,
            A_c2=p.A_c2,
            F_0=(p.A_c1 - p.A_c2) * p.p_a,  # ambient pressure on the rod (errata Eq. 1), N
            M_k=1e-3 * p.M,  # N per mm/s²
            inv_M_k=1.0 / (1e-3 * p.M),
            A_f=p.A_f,  # N
            c_v_k=1e-3 * p.c_v,  # N per mm/s
            inv_vs=1.0 / p.v_s,
            k_F=p.force_bandwidth,
            inv_bF=1.0 / p.b_F,
            # chamber stiffness (Eq. 3/4 volume terms): Ḟ_p ∋ −n (A1² p1/V1 + A2² p2/V2) ẋ
            nA1s=p.n_poly * p.A_c1**2,
            nA2s=p.n_poly * p.A_c2**2,
            V1_0=p.V_1d + p.A_c1 * 0.5 * p.L,  # m³ at x = 0
            V2_0=p.V_2d + p.A_c2 * 0.5 * p.L,
            b_F=p.b_F,
            u_n=lim.u_neutral,
            lo=lo,
            hi=hi,
            tau=params.transport_delay_samples * T,
            angle=int(angle),
            # rotary_model "angle" with a TD-using algorithm: the controller passes
            # (θ, θ_r, ω_r, ω̇_r)
            angle_inputs=int(axis == "rotary" and params.rotary_model == "angle" and uses_td),
            lin_id=int(lin_id),
            force=int(axis == "linear" and p.linear_model == "force"),
            ffw=int(axis == "linear" and p.linear_model == "position" and p.friction_feedforward),
            dc=int(p.delay_compensation and params.transport_delay_samples > 0),
            n_ff=params.transport_delay_samples + 1,
            **valve_constants(*self._chart(params)),  # used with the valve map only
        )
        # the same limits in the linearised command
        tab = self.table(params, axis)
        c.v_lo = linearised(c, tab, lo)
        c.v_hi = linearised(c, tab, hi)
        return c

    # thin views of the kernels (tests, analysis)
    def _pressure_force(self, inp: Any) -> float:
        """F_p = A_c1 p_c1 − A_c2 p_c2 − A_r p_a (errata Eq. 1), N."""
        return pressure_force(self.c, inp.p_c1, inp.p_c2)

    def _friction(self, v: float) -> float:
        """F_f(v) of Eq. 2, Coulomb sign smoothed (tanh over v_s), N; v in mm/s."""
        return friction(self.c, v)
