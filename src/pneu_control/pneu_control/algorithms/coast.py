"""Coast: one-way angle positioning with a predicted coast-down stop (the paper's plumbing).

With the paper's plumbing one MPYE port feeds the motor's inlet and the motor
exhausts to the atmosphere through a silencer: a command above 5 V drives the
motor forward, below 5 V vents the inlet, and nothing brakes it but friction.
Below ≈ 250 rpm it cannot run steadily (stick-slip), and from rest it breaks away
only once the inlet pressure has built up. An angle is then reached the way a
person stops a freewheeling spindle: drive, cut the air early enough that the
coast-down ends *short* of the target, then tap the rest with short pulses; only
a stop past the target calls the user's overshoot strategy. Per sample (y = θ,
the encoder angle in °; e = r + wrap − y) a small state machine:

``drive`` (speed loop on the ESO's speed ω̂ = z2, from the stable minimum ω_min up)::

    ω_r = clip(ṙ + k_e e, ω_min, ω_max)
    u   = u_0 + u_ff ω_r + k_p (ω_r − ω̂) + I,   I += k_i (ω_r − ω̂) T only while
          ω̂ > ω_r / 2 (not while breaking away), |I| ≤ I_max;   0 ≤ u ≤ u_max − 5 V
    ω_c = ω̂ + max(0, α̂) t_lead                  (α̂ = z3 + b0 u⁺: still accelerating)
    d_stop = κ (ω_c t_lead + ω_c² / (2 a_c))    predicted coast distance
    cut (→ coast) once (1 + m) d_stop + m_0 ≥ e and ṙ ≤ 0
          (aims short; m = m_first until a coast has been measured, then m_f)

``coast``: vent (u = u_min) until the motor stands: the encoder unchanged for n_still
samples and at least n_vent samples vented. Then learn from it and ``decide``.

``pulse`` (the low-speed approach of a motor that cannot creep): open at u_p until
either the encoder shows the breakaway and x more samples have passed, or, with no
breakaway yet, t_on + x samples have passed; then vent (→ coast). A breakaway seen
at sample t_b ≤ t_on sets t_on = t_b − n_lead: later taps vent just *before* the
breakaway and the pressure still rising in the vent lag breaks the motor away
barely (with breakaway friction 1.5 × M_c: 1.5° steps against 4.3° vented at the
breakaway; twin). A tap that did not move opens one sample longer next time
(t_on += 1, up to n_break); one that did not move in n_break samples raises
u_p by δu_p. The step follows d(x) = d_min (1 + x / x_0)² (twin: 5.8 V pulses), so ::

    x = round(clip(x_0 (√(a_p e / d_min) − 1), 0, x_max))      (a_p < 1: aims short)

and the first pulse of a run is the smallest (x = 0, t_on = n_break: it measures
d_min and t_b).

``decide`` (at rest, where y is exact), in order::

    e < −e_over           → overshoot strategy: ``reapproach`` (wrap += 360°: a full
                            turn more, the only way back one-way), ``fault`` (flag;
                            vented from then on), ``hold`` (vented)
    e ≤ tol, or (e < ρ d_min and e ≤ e_over)
                          → settled (vented; no smaller step exists)
    e ≤ e_pulse           → pulse
    otherwise             → drive

Learning (rate γ): after a drive's coast from (θ_c, ω_c) over Δθ,
κ ← κ + γ (Δθ / (ω_c t_lead + ω_c² / (2 a_c)) − κ), κ ∈ [0.2, 5]; after a pulse of x
samples that moved Δθ, d_min ← d_min + γ (Δθ / (1 + x/x_0)² − d_min). I is kept
between drives (a learnt feed-forward). The state shows what was learnt (``kappa``,
``d_min``, ``t_on``, ``pulse_du``, ``integral``); ``fault`` latches until the algorithm
restarts (a new parameter set).

Observer: the third-order ESO of :mod:`pneu_control.observers.eso` on θ (°), fed the
opening above neutral only, u⁺ = max(u_applied, 0): a vented inlet drives nothing
(fed the full −5 V vent it predicted a −5e5 °/s² pull and showed −200 rpm at rest).
ω0 = 600 rad/s: at 300 rad/s ω̂ lagged the accelerating drive by ≈ 15 % at the cut
(a 30 % shorter predicted coast); 1000 rad/s passes more encoder quantisation (twin).

Not in the paper (ours). Measured on the twin over 144 moves (90°, 360°, 3600°;
48 plants drawn from the plant band of config/plant.yaml): final |e| ≤ 2°, no
reapproach needed, never backwards. Every default's source is on its field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pneu_msgs_py.params.core import param
from pneu_msgs_py.params.records import RecordType, kernel

from pneu_control.algorithms.angle_law import (
    DEG_PER_S_PER_RPM,
    pulse_step_field,
    still_field,
    tick,
    to_phase,
)
from pneu_control.algorithms.base import (
    NAN,
    AlgorithmKernel,
    KernelAlgorithm,
    deviation_band,
    samples,
)
from pneu_control.algorithms.smc import NONNEGATIVE, POSITIVE, omega_0_field
from pneu_control.observers.eso import eso3_constants, eso3_observe

if TYPE_CHECKING:
    from pneu_control.controller.params import AxisControllerParams

__all__ = ["COAST_CONSTANTS", "COAST_STATE", "Coast", "CoastParams", "OVERSHOOT_CODES"]

OVERSHOOT_CODES = {"reapproach": 0, "fault": 1, "hold": 2}
TWIN = "estimated on the twin (nominal plant, paper plumbing): "


@dataclass(frozen=True)
class CoastParams:
    """One-way angle positioning: drive, cut early, coast short, tap the rest (module docstring)."""

    speed_max_rpm: float = param(
        500.0,
        unit="rpm",
        desc="ω_max: drive speed",
        **POSITIVE,
        hi=1400.0,
        source=TWIN
        + "twice the stable minimum, a third of the supervisor's 1500 rpm trip; the coast "
        "from it (≈ 30°) stays short against a 90° move",
    )
    speed_min_rpm: float = param(
        300.0,
        unit="rpm",
        desc="ω_min: lowest drive speed",
        **POSITIVE,
        source=TWIN + "below ≈ 250 rpm a continuous opening gives a 0–450 rpm stick-slip cycle",
    )
    position_gain: float = param(
        20.0,
        unit="1/s",
        desc="k_e: drive speed per degree of error (only below ω_max)",
        **POSITIVE,
        source="chosen: ω_max from 150° out, ω_min from 90° out; the cut comes first (≈ 40°)",
    )
    coast_decel: float = param(
        300000.0,
        unit="°/s²",
        desc="a_c: deceleration with the inlet vented",
        **POSITIVE,
        source=TWIN + "coasts of 13° from 253 rpm, 36° from 527 rpm, 117° from 1202 rpm",
    )
    lead_s: float = param(
        0.006,
        unit="s",
        desc="t_lead: torque fall time after the cut (valve + inlet volume venting)",
        **NONNEGATIVE,
        hi=0.5,
        source=TWIN + "the same coasts; the MPYE alone steps in ≈ 3 ms (Festo)",
    )
    learn_rate: float = param(
        0.5,
        desc="γ: share of each measured coast or pulse that corrects κ and d_min (0 = fixed)",
        lo=0.0,
        hi=1.0,
        source="chosen: halves a model error per move, averages the angle ripple of K(θ)",
    )
    margin_frac: float = param(
        0.3,
        desc="m_f: the cut aims short by this share of the predicted coast",
        **NONNEGATIVE,
        hi=2.0,
        source=TWIN + "the coast distance moves by up to ±30 % over the plant band (J_m ±50 %)",
    )
    margin_first: float = param(
        1.0,
        desc="m_f of the first coast (κ not learnt yet)",
        **NONNEGATIVE,
        hi=3.0,
        source=TWIN + "J_m +50 % with M_c −25 % coasts 1.5–2 × the nominal distance",
    )
    margin_deg: float = param(
        5.0,
        unit="°",
        desc="m_0: and by this angle (left to the pulses)",
        **NONNEGATIVE,
        source=TWIN + "a few pulse steps (so that the first pulse, the smallest, cannot overshoot)",
    )
    tolerance_deg: float = param(
        1.0,
        unit="°",
        desc="tol: settled once e ≤ tol (no pulse inside)",
        **POSITIVE,
        source="the ±1° settling band of project issue 20",
    )
    overshoot_deg: float = param(
        2.0,
        unit="°",
        desc="e_over: past the target by more than this, the overshoot strategy acts",
        **POSITIVE,
        source="the positioning target (project issue 20: final error ≤ 2°)",
    )
    overshoot: str = param(
        "reapproach",
        choices=tuple(OVERSHOOT_CODES),
        desc="past the target by more than e_over: one more turn, a fault flag, or stay",
    )
    settle_ratio: float = param(
        0.6,
        desc="ρ: settled below this share of the smallest pulse step (a pulse would land farther)",
        lo=0.0,
        hi=1.0,
        source="0.5 minimises |e − d_min| against e; 0.6 for the spread of d_min (estimated)",
    )
    pulse_max_deg: float = param(
        20.0,
        unit="°",
        desc="e_pulse: remainders up to this are tapped with pulses, larger ones driven",
        **POSITIVE,
        source=TWIN + "a pulse of x_max moves 10–25° over the plant band",
    )
    pulse_du: float = param(
        0.8,
        unit="V",
        desc="u_p: first pulse opening above neutral",
        **POSITIVE,
        hi=5.0,
        source=TWIN + "at 5.8 V the motor breaks away in 20–45 ms over the plant band, "
        "and the smallest step is ≈ 1° (4° with 1.5 × breakaway friction)",
    )
    pulse_du_step: float = param(
        0.1,
        unit="V",
        desc="δu_p: added to u_p after a pulse that did not break away",
        **POSITIVE,
        source=TWIN + "breakaway 20–45 ms at 5.8 V, ≈ 10 ms at 6.5 V: steps of a tenth of that",
    )
    pulse_break_s: float = param(
        0.08,
        unit="s",
        desc="n_break T: a pulse with no breakaway by then has failed",
        **POSITIVE,
        source=TWIN + "twice the slowest breakaway at 5.8 V over the plant band",
    )
    pulse_lead_s: float = param(
        0.002,
        unit="s",
        desc="after a breakaway at t_b, later pulses vent at t_b − this unless they break away "
        "sooner (the pressure still rises in the vent lag: the motor breaks away barely)",
        **NONNEGATIVE,
        source=TWIN + "with 1.5 × breakaway friction a 5.8 V pulse vented 2 ms before the "
        "breakaway steps 1.5° against 4.3° vented at it",
    )
    pulse_step_deg: float = pulse_step_field(
        2.0,
        TWIN + "0.8–1.4° at 5.8 V with J_m, M_c, V_m1 over their bands, 2.5–4.3° "
        "with 1.3–1.5 × breakaway friction: 2° errs neither way by much before the first pulse",
    )
    pulse_x0_s: float = param(
        0.0033,
        unit="s",
        desc="x_0 T: pulse step growth d(x) = d_min (1 + x/x_0)²",
        **POSITIVE,
        source=TWIN + "fits 3.3–5.6 ms over the plant band (pulses at 5.8 V held 0–8 ms); "
        "the fastest growth taken",
    )
    pulse_hold_max_s: float = param(
        0.012,
        unit="s",
        desc="x_max T: longest hold after breakaway",
        **NONNEGATIVE,
        source=TWIN + "d(12 ms) ≈ 15–25° at 5.8 V over the plant band: the pulse range",
    )
    pulse_aim: float = param(
        0.75,
        desc="a_p: a pulse aims at this share of the remainder",
        lo=0.0,
        lo_open=True,
        hi=1.0,
        source="the d(x) fit errs by ≈ ±25 % (estimated on the twin)",
    )
    still_s: float = still_field(
        0.015,
        "stopped once the encoder is unchanged this long",
        "one count (0.09°) in 15 ms is 6 °/s, gone in 20 µs at a_c",
    )
    vent_s: float = param(
        0.02,
        unit="s",
        desc="n_vent T: least venting between two actions (the inlet empties)",
        **NONNEGATIVE,
        source=TWIN + "t_lead with margin",
    )
    kp: float = param(
        0.00005,
        unit="V/(°/s)",
        desc="k_p: speed-loop proportional gain",
        **NONNEGATIVE,
        source=TWIN + "3600° moves on the five test plants peak at 600–810 rpm (ω_max 500); "
        "3 × as much peaks at 675–900 rpm; the final error does not depend on it (pulses)",
    )
    ki: float = param(
        0.002,
        unit="V/°",
        desc="k_i: speed-loop integral gain",
        **NONNEGATIVE,
        source=TWIN + "between 0 and 0.006 the peaks and final errors barely move (as k_p)",
    )
    integral_max: float = param(
        0.5,
        unit="V",
        desc="I_max: bound of the speed-loop integral",
        **NONNEGATIVE,
        source="chosen: about the whole feed-forward at ω_max (0.58 V), so the integral can "
        "halve or double it but not open the valve wide",
    )
    u_ff: float = param(
        0.00016,
        unit="V/(°/s)",
        desc="u_ff: feed-forward opening per drive speed",
        **NONNEGATIVE,
        source=TWIN + "5.3 V holds 253 rpm, 5.6 V 527 rpm, 6 V 1200 rpm (open loop)",
    )
    u_start: float = param(
        0.1,
        unit="V",
        desc="u_0: feed-forward opening at zero speed",
        **NONNEGATIVE,
        hi=5.0,
        source=TWIN + "the same open-loop speeds",
    )
    omega_0: float = omega_0_field(
        600.0,
        TWIN + "300 rad/s lags the accelerating drive by ≈ 15 % at the cut, 1000 rad/s passes "
        "the encoder quantisation (module docstring)",
        "observer bandwidth ω0 (Eq. 17) of the angle ESO",
    )
    b_0: float = param(
        100000.0,
        unit="°/s²/V",
        desc="input gain b0 of the angle ESO",
        **POSITIVE,
        source=TWIN + "the order of the drive's acceleration per volt above neutral; z3 "
        "takes the rest",
    )


COAST_CONSTANTS = RecordType(
    "CoastConstants",
    [
        ("T", "f"), ("T2h", "f"), ("b0", "f"), ("l1", "f"), ("l2", "f"), ("l3", "f"),
        ("w_max", "f"), ("w_min", "f"), ("k_e", "f"), ("a_c", "f"), ("t_lead", "f"),
        ("gamma", "f"), ("m_f", "f"), ("m_first", "f"), ("m_0", "f"), ("tol", "f"), ("e_over", "f"),
        ("rho", "f"), ("e_pulse", "f"), ("du_p0", "f"), ("du_step", "f"), ("n_break", "i"), ("n_lead", "i"),
        ("d_min0", "f"), ("x0", "f"), ("x_max", "f"), ("a_p", "f"), ("n_still", "i"),
        ("n_vent", "i"), ("kp", "f"), ("ki", "f"), ("i_max", "f"), ("u_ff", "f"),
        ("u_0", "f"), ("lo", "f"), ("hi", "f"), ("overshoot", "i"),
    ],
)  # fmt: skip
PHASE_DRIVE, PHASE_COAST, PHASE_SETTLED, PHASE_PULSE = 0, 1, 2, 3
# what a coast learns from when it ends: nothing, the drive before it, the pulse before it
FROM_NONE, FROM_DRIVE, FROM_PULSE = 0, 1, 2
COAST_STATE = RecordType(
    "CoastState",
    [
        ("z1", "f", 0.0), ("z2", "f", 0.0), ("z3", "f", 0.0), ("s", "f"), ("u_raw", "f", 0.0),
        ("u_in", "f", 0.0), ("integral", "f", 0.0), ("wrap", "f", 0.0), ("kappa", "f", 1.0),
        ("d_min", "f"), ("pulse_du", "f"), ("phase", "i", PHASE_COAST),
        ("coast_from", "i", FROM_NONE), ("coast_w", "f", 0.0), ("coast_th", "f", 0.0),
        ("x_hold", "f", 0.0), ("t_on", "f"), ("k_break", "i", -1), ("k_phase", "i", 0), ("k_still", "i", 0),
        ("y_last", "f"), ("fault", "i"), ("n_coasts", "i"), ("n_pulses", "i"),
    ],
)  # fmt: skip


@kernel
def coast_hint(c, s):
    return s.z1, s.z2, s.z3 + c.b0 * (s.u_in if s.u_in > 0.0 else 0.0)


@kernel
def _learn(c, s, y):
    """A coast has ended at rest at y: correct κ (after a drive) or d_min (after a pulse)."""
    dist = y - s.coast_th
    if s.coast_from == FROM_DRIVE:
        w = s.coast_w
        d_model = w * c.t_lead + w * w / (2.0 * c.a_c)
        if dist > 0.0 and d_model > 0.0:
            k = s.kappa + c.gamma * (dist / d_model - s.kappa)
            s.kappa = 0.2 if k < 0.2 else (5.0 if k > 5.0 else k)
        s.n_coasts += 1
    elif s.coast_from == FROM_PULSE:
        if dist > 0.0:
            g = 1.0 + s.x_hold / c.x0
            s.d_min = s.d_min + c.gamma * (dist / (g * g) - s.d_min)
            s.n_pulses += 1
        elif s.t_on < c.n_break:
            s.t_on += 1.0  # vented too early to break away: open a sample longer next
        else:  # no breakaway in n_break samples: open wider next
            du = s.pulse_du + c.du_step
            s.pulse_du = c.hi if du > c.hi else du
    s.coast_from = FROM_NONE


@kernel
def _decide(c, s, inp, y):
    """At rest: the overshoot strategy, settled, a pulse or a drive (module docstring)."""
    e = inp.r + s.wrap - y
    if s.fault == 0 and e < -c.e_over:
        if c.overshoot == 0:
            s.wrap += 360.0  # one-way: the target again, one turn on
            e += 360.0
        elif c.overshoot == 1:
            s.fault = 1
    small = e < c.rho * s.d_min and e <= c.e_over  # no smaller step, and already in the band
    if s.fault != 0 or e < -c.e_over or e <= c.tol or small:
        to_phase(s, PHASE_SETTLED)
    elif e <= c.e_pulse:
        x = c.x0 * (math.sqrt(c.a_p * e / s.d_min) - 1.0)
        if s.n_pulses == 0:
            x = 0.0  # the first pulse the smallest: it measures d_min
        s.x_hold = 0.0 if x < 0.0 else (c.x_max if x > c.x_max else math.floor(x + 0.5))
        s.k_break = -1
        s.coast_th = y
        to_phase(s, PHASE_PULSE)
    else:
        to_phase(s, PHASE_DRIVE)


@kernel
def _drive(c, s, inp, y):
    """The speed loop, or the cut (→ coast) when the predicted stop reaches the aim point."""
    e = inp.r + s.wrap - y
    u_drive = s.u_in if s.u_in > 0.0 else 0.0
    acc = s.z3 + c.b0 * u_drive  # ESO acceleration: the speed still grows during t_lead
    w = s.z2 + (acc * c.t_lead if acc > 0.0 else 0.0)
    w = w if w > 0.0 else 0.0
    d_stop = s.kappa * (w * c.t_lead + w * w / (2.0 * c.a_c))
    m_f = c.m_f if s.n_coasts > 0 else c.m_first  # nothing learnt yet: aim shorter
    if (1.0 + m_f) * d_stop + c.m_0 >= e and inp.r_dot <= 0.0:
        s.coast_from = FROM_DRIVE
        s.coast_w = w
        s.coast_th = y
        to_phase(s, PHASE_COAST)
        return c.lo
    w_r = inp.r_dot + c.k_e * e
    w_r = c.w_min if w_r < c.w_min else (c.w_max if w_r > c.w_max else w_r)
    ew = w_r - s.z2
    if s.z2 > 0.5 * w_r:  # running: the integral learns the opening (not while breaking away)
        i = s.integral + c.ki * ew * c.T
        s.integral = -c.i_max if i < -c.i_max else (c.i_max if i > c.i_max else i)
    u = c.u_0 + c.u_ff * w_r + c.kp * ew + s.integral
    s.u_raw = u
    return 0.0 if u < 0.0 else (c.hi if u > c.hi else u)  # one way: never vent while driving


@kernel
def _law(c, s, inp):
    """The command (deviation, V) for this sample (module docstring)."""
    y = inp.y
    tick(s, y)
    if s.phase == PHASE_COAST and s.k_still >= c.n_still and s.k_phase >= c.n_vent:
        _learn(c, s, y)
        _decide(c, s, inp, y)
    elif s.phase == PHASE_SETTLED:
        _decide(c, s, inp, y)  # stays settled unless the reference moved
    if s.phase == PHASE_DRIVE:
        return _drive(c, s, inp, y)
    if s.phase == PHASE_PULSE:
        if s.k_break < 0 and y > s.coast_th:  # the encoder shows the breakaway
            s.k_break = 0
            if s.k_phase <= s.t_on:  # open time to vent at, a little before it, from now on
                t = s.k_phase - c.n_lead
                s.t_on = 1.0 if t < 1.0 else float(t)
        elif s.k_break >= 0:
            s.k_break += 1
        if (s.k_break >= 0 and s.k_break >= s.x_hold) or (
            s.k_break < 0 and s.k_phase >= s.t_on + s.x_hold  # t_on ≤ n_break
        ):
            s.coast_from = FROM_PULSE  # vented: the breakaway may still come in the vent lag
            to_phase(s, PHASE_COAST)
        else:
            s.u_raw = s.pulse_du
            return s.pulse_du
    s.u_raw = c.lo
    return c.lo


@kernel
def coast_start(c, s, table, inp, u_prev, h0, h1, h2):
    s.z1 = h0 if math.isfinite(h0) else inp.y
    s.z2 = h1 if math.isfinite(h1) else 0.0
    a = h2 if math.isfinite(h2) else 0.0
    u_applied = inp.u_applied
    s.u_in = u_applied
    s.z3 = 0.0 if u_prev != u_prev else a - c.b0 * (u_applied if u_applied > 0.0 else 0.0)
    if s.d_min != s.d_min:
        s.d_min = c.d_min0
    if s.pulse_du != s.pulse_du:
        s.pulse_du = c.du_p0
    if s.t_on != s.t_on:
        s.t_on = float(c.n_break)
    s.y_last = inp.y
    s.k_still = 0
    s.coast_from = FROM_NONE
    to_phase(s, PHASE_COAST)  # vent first: the law acts from rest (a running motor coasts down)
    return _law(c, s, inp)


@kernel
def coast_update(c, s, table, inp):
    u_applied = inp.u_applied
    s.u_in = u_applied
    u_drive = u_applied if u_applied > 0.0 else 0.0  # a vented inlet drives nothing
    eso3_observe(c, s, s.z3 + c.b0 * u_drive, inp.y)
    return _law(c, s, inp)


class Coast(KernelAlgorithm):
    name = "coast"
    uses_td = False  # the law shapes its own approach; the reference as given
    CONSTANTS = COAST_CONSTANTS
    STATE = COAST_STATE
    KERNEL = AlgorithmKernel(coast_start, coast_update, coast_hint)

    def constants(self, params: AxisControllerParams, axis: str):
        p = params.coast
        T = params.sample_time_s
        return COAST_CONSTANTS.new(
            **eso3_constants(p.omega_0, T),
            b0=p.b_0,
            w_max=p.speed_max_rpm * DEG_PER_S_PER_RPM,
            w_min=p.speed_min_rpm * DEG_PER_S_PER_RPM,
            k_e=p.position_gain,
            a_c=p.coast_decel,
            t_lead=p.lead_s,
            gamma=p.learn_rate,
            m_f=p.margin_frac,
            m_first=p.margin_first,
            m_0=p.margin_deg,
            tol=p.tolerance_deg,
            e_over=p.overshoot_deg,
            rho=p.settle_ratio,
            e_pulse=p.pulse_max_deg,
            du_p0=p.pulse_du,
            du_step=p.pulse_du_step,
            n_break=samples(p.pulse_break_s, T),
            n_lead=samples(p.pulse_lead_s, T),
            d_min0=p.pulse_step_deg,
            x0=p.pulse_x0_s / T,
            x_max=float(samples(p.pulse_hold_max_s, T)),
            a_p=p.pulse_aim,
            n_still=samples(p.still_s, T),
            n_vent=samples(p.vent_s, T),
            kp=p.kp,
            ki=p.ki,
            i_max=p.integral_max,
            u_ff=p.u_ff,
            u_0=p.u_start,
            **deviation_band(params),
            overshoot=OVERSHOOT_CODES[p.overshoot],
        )

    def initial_state(self, c):
        return COAST_STATE.new(d_min=c.d_min0, pulse_du=c.du_p0, t_on=float(c.n_break), s=NAN)
