"""Linear ADRC: TD + linear ESO (Eq. 18, Eq. 17 bandwidth gains) + PD on the estimates.

Law (Gao 2003 with the TD's (v1, v2); the paper does not print it)::

    u0 = λ1² (v1 − z1) + 2 λ1 (v2 − z2)   [+ v3 if accel_feedforward]
    u  = (u0 − z3) / b0

so that with z3 = f the loop is ÿ = u0: a critically damped pair at −λ1
(λ1 = ω_c). The paper's λ1 = 390 > ω0 = 31.5 (linear) inverts the usual
ω0 ≈ 3–5 ω_c rule: the observer then lags the loop it feeds and robustness to
b0 error is small; we implement the gains as printed and leave the verdict to
the twin (DESIGN §5). Units: mm or rpm; λ1 1/s; b0 (mm|rpm)/s²/V.

The ESO is the exact-ZOH current observer of :mod:`pneu_control.observers.eso`;
it is fed the saturated command that was on the valve, so z3 never winds up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pneu_msgs_py.params.core import param
from pneu_msgs_py.params.records import RecordType, kernel

from pneu_control.algorithms.base import AlgorithmKernel, KernelAlgorithm, deviation_band
from pneu_control.algorithms.smc import (
    POSITIVE,
    b_0_field,
    delay_compensation_field,
    omega_0_field,
)
from pneu_control.observers.eso import eso3_constants, eso3_observe, extrapolate, predict3

if TYPE_CHECKING:
    from pneu_control.controller.params import AxisControllerParams

__all__ = ["LADRC_CONSTANTS", "LADRC_STATE", "Ladrc", "LadrcParams", "ladrc_start", "ladrc_update"]


@dataclass(frozen=True)
class LadrcParams:
    """Linear ADRC (Gao 2003): linear ESO (Eq. 18, gains Eq. 17) and PD on the estimates.

    u0 = λ1² (v1 − z1) + 2 λ1 (v2 − z2),  u = (u0 − z3) / b0.
    λ1 is the controller bandwidth ω_c (critically damped PD). Paper: linear
    λ1 390, ω0 31.5, b0 5900; rotary λ1 10, ω0 15, b0 500.
    """

    lambda_1: float = param(
        390.0, unit="1/s", desc="controller bandwidth ω_c", **POSITIVE, source="paper"
    )
    omega_0: float = omega_0_field(31.5, "paper", "observer bandwidth ω0 (Eq. 17)")
    b_0: float = b_0_field(5900.0, "paper")
    accel_feedforward: bool = param(
        False, desc="add the TD's reference acceleration v3 to u0 (not in the paper)"
    )
    delay_compensation: bool = delay_compensation_field()


LADRC_CONSTANTS = RecordType(
    "LadrcConstants",
    [
        ("T", "f"), ("T2h", "f"), ("kp", "f"), ("kd", "f"), ("b0", "f"), ("ff", "f"),
        ("l1", "f"), ("l2", "f"), ("l3", "f"), ("lo", "f"), ("hi", "f"), ("tau", "f"),
        ("u_n", "f"), ("dc", "i"),
    ],
)  # fmt: skip
LADRC_STATE = RecordType(
    "LadrcState",
    [("z1", "f", 0.0), ("z2", "f", 0.0), ("z3", "f", 0.0), ("s", "f"), ("u_raw", "f", 0.0),
     ("u_in", "f", 0.0)],
)  # fmt: skip


@kernel
def ladrc_hint(c, s):
    return s.z1, s.z2, s.z3 + c.b0 * s.u_in


@kernel
def ladrc_start(c, s, table, inp, u_prev, h0, h1, h2):
    s.z1 = h0 if math.isfinite(h0) else inp.y
    s.z2 = h1 if math.isfinite(h1) else 0.0
    # z3 = ÿ − b0 u_applied: physically consistent (ÿ = 0 if unknown; cold start: 0)
    a = h2 if math.isfinite(h2) else 0.0
    u_applied = inp.u_applied
    s.u_in = u_applied
    s.z3 = 0.0 if u_prev != u_prev else a - c.b0 * u_applied
    u0 = c.kp * (inp.r - s.z1) + c.kd * (inp.r_dot - s.z2) + c.ff * inp.r_ddot
    u = (u0 - s.z3) / c.b0
    s.u_raw = u
    return c.hi if u > c.hi else (c.lo if u < c.lo else u)


@kernel
def ladrc_update(c, s, table, inp):
    T = c.T
    u_applied = inp.u_applied
    s.u_in = u_applied
    # ESO, Eq. 18 discretised (pneu_control.observers.eso)
    z1, z2, z3 = eso3_observe(c, s, s.z3 + c.b0 * u_applied, inp.y)
    r = inp.r
    r_dot = inp.r_dot
    r_ddot = inp.r_ddot
    if c.dc:  # act on the state the command will meet: t + d T (see eso_smc)
        z1, z2 = predict3(z1, z2, z3, inp.history, inp.n_hist, c.u_n, c.b0, 0.0, T, c.T2h)
        r, r_dot = extrapolate(r, r_dot, r_ddot, c.tau)
    u0 = c.kp * (r - z1) + c.kd * (r_dot - z2) + c.ff * r_ddot
    u = (u0 - z3) / c.b0
    s.u_raw = u
    return c.hi if u > c.hi else (c.lo if u < c.lo else u)


class Ladrc(KernelAlgorithm):
    name = "ladrc"
    uses_td = True
    CONSTANTS = LADRC_CONSTANTS
    STATE = LADRC_STATE
    KERNEL = AlgorithmKernel(ladrc_start, ladrc_update, ladrc_hint)

    def constants(self, params: AxisControllerParams, axis: str):
        p = params.ladrc
        T = params.sample_time_s
        lim = params.limits
        return LADRC_CONSTANTS.new(
            **eso3_constants(p.omega_0, T),
            kp=p.lambda_1 * p.lambda_1,
            kd=2.0 * p.lambda_1,
            b0=p.b_0,
            ff=1.0 if p.accel_feedforward else 0.0,
            **deviation_band(params),
            tau=params.transport_delay_samples * T,
            u_n=lim.u_neutral,
            dc=int(p.delay_compensation and params.transport_delay_samples > 0),
        )
