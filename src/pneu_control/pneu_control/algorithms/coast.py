"""Coast: one-way angle positioning with a predicted coast-down stop (the paper's plumbing).

With the paper's plumbing one MPYE port feeds the motor's inlet and the motor
exhausts to the atmosphere through a silencer: a command above 5 V drives the
motor forward, below 5 V vents the inlet, and nothing brakes it but friction.
An angle is then reached the way a person stops a freewheeling spindle: drive,
cut the air early enough that the coast-down ends on the target, and if it ends
short, creep the rest. Per sample (y = θ in °, ESO on θ as in
:mod:`pneu_control.observers.eso`, ω̂ = z2 in °/s, e = r + wrap − z1)::

    d_stop = ω̂² / (2 a_c) + ω̂ t_lead              predicted coast distance (a_c: coast
                                                  deceleration, t_lead: the time the
                                                  torque takes to vanish after the cut)
    |e| ≤ tol                 → cut (vent: u_min)  settled
    e < −tol, ω̂ ≈ 0           → overshoot: ``reapproach`` (wrap += 360°: a full turn
                                 more, the only way back one-way), ``fault`` (cut, flag),
                                 or ``hold`` (cut, stay)
    d_stop ≥ e and ṙ ≤ 0      → cut                 coast to the target
    otherwise                 → drive: ω_r = clip(ṙ + k_e e, ω_creep, min(ω_max, √(2 a_c e)))
                                 u = u_0 + u_ff ω_r + k_p (ω_r − ω̂) + ∫k_i (ω_r − ω̂) dt,
                              0 ≤ u ≤ cap (u_0 + u_ff ω_r)

``a_c`` learns from every coast that ends (``learn_rate``): the distance actually
coasted from (θ_c, ω_c) gives a_eff = ω_c² / (2 (Δθ − ω_c t_lead)) and
a_c ← a_c + γ (a_eff − a_c), so a sequence of moves stops closer each time; the
state ``a_c`` shows what it learned. Not in the paper (ours); the parameter
defaults are estimated on the twin (``pneu task`` examples and the composite-motion
benchmark, docs/composite-motion.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pneu_msgs_py.params.core import param
from pneu_msgs_py.params.records import RecordType, kernel

from pneu_control.algorithms.base import NAN, AlgorithmKernel, KernelAlgorithm
from pneu_control.algorithms.smc import NONNEGATIVE, POSITIVE, b_0_field, omega_0_field
from pneu_control.observers.eso import eso3_step, eso_gains

if TYPE_CHECKING:
    from pneu_control.controller.params import AxisControllerParams

__all__ = ["COAST_CONSTANTS", "COAST_STATE", "Coast", "CoastParams", "OVERSHOOT_CODES"]

OVERSHOOT_CODES = {"reapproach": 0, "fault": 1, "hold": 2}
DEG_PER_S_PER_RPM = 6.0  # 1 rpm = 360°/60 s


@dataclass(frozen=True)
class CoastParams:
    """One-way angle positioning: drive, cut early, coast onto the target (module docstring)."""

    speed_max_rpm: float = param(
        600.0, unit="rpm", desc="highest drive speed ω_max", **POSITIVE, hi=3000.0
    )
    creep_rpm: float = param(
        60.0, unit="rpm", desc="lowest drive speed ω_creep (final approach)", **POSITIVE
    )
    position_gain: float = param(
        20.0, unit="1/s", desc="k_e: drive speed per degree of error", **POSITIVE
    )
    coast_decel: float = param(
        300000.0,
        unit="°/s²",
        desc="a_c: initial estimate of the deceleration with the inlet vented",
        **POSITIVE,
        source="estimated on the twin: coasts of 13° from 253 rpm and 36° from 527 rpm after a vent give 3e5 °/s² with a 6 ms lead; learnt from each coast",
    )
    lead_s: float = param(
        0.006,
        unit="s",
        desc="t_lead: torque fall time after the cut (valve + inlet volume venting)",
        **NONNEGATIVE,
        hi=0.5,
        source="estimated on the twin (the coasts above); the MPYE alone steps in ≈ 3 ms (Festo)",
    )
    learn_rate: float = param(
        0.5, desc="γ: how much of each measured coast corrects a_c (0 = fixed)", lo=0.0, hi=1.0
    )
    tolerance_deg: float = param(
        0.5, unit="°", desc="settled band |e| ≤ tol (no action inside)", **POSITIVE
    )
    overshoot: str = param(
        "reapproach",
        choices=tuple(OVERSHOOT_CODES),
        desc="past the target by more than tol: one more turn, a fault flag, or stay",
    )
    kp: float = param(0.00015, unit="V/(°/s)", desc="speed-loop proportional gain", **NONNEGATIVE)
    ki: float = param(0.02, unit="V/°", desc="speed-loop integral gain", **NONNEGATIVE)
    u_ff: float = param(
        0.0002,
        unit="V/(°/s)",
        desc="feed-forward opening per drive speed",
        **NONNEGATIVE,
        source="estimated on the twin: 0.3 V holds 253 rpm, 1 V 1200 rpm (open loop)",
    )
    u_start: float = param(
        0.15,
        unit="V",
        desc="opening added while driving: the vanes' breakaway",
        **NONNEGATIVE,
        hi=5.0,
        source="estimated on the twin: below ≈ 5.15 V the motor does not start",
    )
    opening_cap: float = param(
        2.0,
        desc="the drive opening stays within this multiple of its feed-forward (the integral "
        "too): a motor that breaks away late must not meet a wound-up valve",
        lo=1.0,
        hi=20.0,
    )
    omega_0: float = omega_0_field(300.0, "", "observer bandwidth ω0 (Eq. 17) of the angle ESO")
    b_0: float = b_0_field(
        100000.0, "estimated on the twin (°/s² per V)", desc="input gain b0 of the angle ESO"
    )


COAST_CONSTANTS = RecordType(
    "CoastConstants",
    [
        ("T", "f"), ("T2h", "f"), ("w_max", "f"), ("w_creep", "f"), ("k_e", "f"),
        ("t_lead", "f"), ("gamma", "f"), ("tol", "f"), ("kp", "f"), ("ki", "f"),
        ("u_ff", "f"), ("u_start", "f"), ("cap", "f"), ("b0", "f"), ("l1", "f"), ("l2", "f"), ("l3", "f"), ("lo", "f"),
        ("hi", "f"), ("a_c0", "f"), ("overshoot", "i"),
    ],
)  # fmt: skip
PHASE_DRIVE, PHASE_COAST, PHASE_SETTLED = 0, 1, 2
COAST_STATE = RecordType(
    "CoastState",
    [
        ("z1", "f", 0.0), ("z2", "f", 0.0), ("z3", "f", 0.0), ("s", "f"), ("u_raw", "f", 0.0),
        ("u_in", "f", 0.0), ("integral", "f", 0.0), ("wrap", "f", 0.0), ("a_c", "f"),
        ("phase", "i"), ("coast_w", "f", 0.0), ("coast_th", "f", 0.0), ("fault", "i"),
        ("n_coasts", "i"),
    ],
)  # fmt: skip


@kernel
def coast_hint(c, s):
    return s.z1, s.z2, s.z3 + c.b0 * s.u_in


@kernel
def _law(c, s, inp):
    """The command (deviation, V) for the current estimates (module docstring)."""
    w = s.z2 if s.z2 > 0.0 else 0.0
    e = inp.r + s.wrap - s.z1
    stopped = w < 0.25 * c.w_creep
    if s.phase == PHASE_COAST and stopped:  # a coast ended: learn a_c from its distance
        dist = s.z1 - s.coast_th - s.coast_w * c.t_lead
        if dist > 0.0 and s.coast_w > c.w_creep:
            a_eff = s.coast_w * s.coast_w / (2.0 * dist)
            s.a_c = s.a_c + c.gamma * (a_eff - s.a_c)
        s.n_coasts += 1
        s.phase = PHASE_SETTLED
    if -c.tol <= e <= c.tol:
        s.phase = PHASE_SETTLED if stopped else s.phase
        s.integral = 0.0
        s.u_raw = c.lo
        return c.lo
    if e < -c.tol:  # past the target
        if stopped and s.phase != PHASE_DRIVE:
            if c.overshoot == 0:
                s.wrap += 360.0  # one-way: the target again, one turn on
            elif c.overshoot == 1:
                s.fault = 1
        s.integral = 0.0
        s.u_raw = c.lo
        return c.lo
    d_stop = w * w / (2.0 * s.a_c) + w * c.t_lead
    if d_stop >= e and inp.r_dot <= 0.0:  # cut now: the coast ends on the target
        if s.phase != PHASE_COAST:
            s.phase = PHASE_COAST
            s.coast_w = w
            s.coast_th = s.z1
        s.integral = 0.0
        s.u_raw = c.lo
        return c.lo
    s.phase = PHASE_DRIVE
    w_r = inp.r_dot + c.k_e * e
    w_top = math.sqrt(2.0 * s.a_c * e)
    if w_top > c.w_max:
        w_top = c.w_max
    if w_r > w_top:
        w_r = w_top
    if w_r < c.w_creep:
        w_r = c.w_creep
    ew = w_r - s.z2
    u_ff = c.u_start + c.u_ff * w_r
    cap = c.cap * u_ff  # the opening stays near what the speed needs: no windup burst
    integral = s.integral + c.ki * ew * c.T
    integral = cap - u_ff if integral > cap - u_ff else (-u_ff if integral < -u_ff else integral)
    u = u_ff + c.kp * ew + integral
    top = cap if cap < c.hi else c.hi
    if u > top:
        u_sat = top
    elif u < 0.0:  # one way: never vent while driving
        u_sat = 0.0
    else:
        u_sat = u
    s.integral = integral
    s.u_raw = u
    return u_sat


@kernel
def coast_start(c, s, table, inp, u_prev, h0, h1, h2):
    s.z1 = h0 if math.isfinite(h0) else inp.y
    s.z2 = h1 if math.isfinite(h1) else 0.0
    a = h2 if math.isfinite(h2) else 0.0
    s.u_in = inp.u_applied
    s.z3 = 0.0 if u_prev != u_prev else a - c.b0 * inp.u_applied
    if s.a_c != s.a_c:
        s.a_c = c.a_c0
    s.integral = 0.0 if u_prev != u_prev else u_prev - c.u_ff * (s.z2 if s.z2 > 0.0 else 0.0)
    return _law(c, s, inp)


@kernel
def coast_update(c, s, table, inp):
    u_applied = inp.u_applied
    s.u_in = u_applied
    z3 = s.z3
    z1, z2, z3 = eso3_step(
        s.z1, s.z2, z3, z3 + c.b0 * u_applied, inp.y, c.T, c.T2h, c.l1, c.l2, c.l3
    )
    s.z1 = z1
    s.z2 = z2
    s.z3 = z3
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
        l1, l2, l3 = eso_gains(p.omega_0, T)
        lim = params.limits
        return COAST_CONSTANTS.new(
            T=T,
            T2h=0.5 * T * T,
            w_max=p.speed_max_rpm * DEG_PER_S_PER_RPM,
            w_creep=p.creep_rpm * DEG_PER_S_PER_RPM,
            k_e=p.position_gain,
            t_lead=p.lead_s,
            gamma=p.learn_rate,
            tol=p.tolerance_deg,
            kp=p.kp,
            ki=p.ki,
            u_ff=p.u_ff,
            u_start=p.u_start,
            cap=p.opening_cap,
            b0=p.b_0,
            l1=l1,
            l2=l2,
            l3=l3,
            lo=lim.u_min - lim.u_neutral,
            hi=lim.u_max - lim.u_neutral,
            a_c0=p.coast_decel,
            overshoot=OVERSHOOT_CODES[p.overshoot],
        )

    def initial_state(self, c):
        return COAST_STATE.new(a_c=c.a_c0, s=NAN)
