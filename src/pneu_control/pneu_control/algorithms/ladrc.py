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

from pneu_control.algorithms.base import NAN, StepInput
from pneu_control.algorithms.smc import (
    POSITIVE,
    b_0_field,
    delay_compensation_field,
    omega_0_field,
)
from pneu_control.observers.eso import eso3_step, eso_gains, extrapolate, predict3

if TYPE_CHECKING:
    from pneu_control.controller.params import AxisControllerParams

__all__ = ["Ladrc", "LadrcParams"]


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


class Ladrc:
    name = "ladrc"
    uses_td = True
    uses_theta = False
    uses_pressures = False

    def __init__(self, params: AxisControllerParams, axis: str):
        p = params.ladrc
        T = params.sample_time_s
        self.T = T
        self.T2h = 0.5 * T * T
        self.kp = p.lambda_1 * p.lambda_1
        self.kd = 2.0 * p.lambda_1
        self.b0 = p.b_0
        self.ff = 1.0 if p.accel_feedforward else 0.0
        self.l1, self.l2, self.l3 = eso_gains(p.omega_0, T)
        lim = params.limits
        self.lo = lim.u_min - lim.u_neutral
        self.hi = lim.u_max - lim.u_neutral
        self.dc = p.delay_compensation and params.transport_delay_samples > 0
        self.tau = params.transport_delay_samples * T
        self.u_n = lim.u_neutral
        self.z1 = self.z2 = self.z3 = 0.0
        self.s = NAN
        self.u_raw = 0.0
        self.u_in = 0.0

    @property
    def hint(self) -> tuple[float, float, float]:
        return self.z1, self.z2, self.z3 + self.b0 * self.u_in

    def start(self, inp: StepInput, u_prev, hint):
        self.z1 = hint[0] if math.isfinite(hint[0]) else inp.y
        self.z2 = hint[1] if math.isfinite(hint[1]) else 0.0
        # z3 = ÿ − b0 u_applied: physically consistent (ÿ = 0 if unknown; cold start: 0)
        a = hint[2] if math.isfinite(hint[2]) else 0.0
        self.u_in = u_applied = inp.u_applied
        self.z3 = 0.0 if u_prev is None else a - self.b0 * u_applied
        u0 = self.kp * (inp.r - self.z1) + self.kd * (inp.r_dot - self.z2) + self.ff * inp.r_ddot
        u = (u0 - self.z3) / self.b0
        self.u_raw = u
        return self.hi if u > self.hi else (self.lo if u < self.lo else u)

    def update(self, inp: StepInput):
        T = self.T
        self.u_in = u_applied = inp.u_applied
        z3 = self.z3
        # ESO, Eq. 18 discretised (pneu_control.observers.eso)
        z1, z2, z3 = eso3_step(
            self.z1, self.z2, z3, z3 + self.b0 * u_applied, inp.y, T, self.T2h,
            self.l1, self.l2, self.l3,
        )  # fmt: skip
        self.z1, self.z2, self.z3 = z1, z2, z3
        r, r_dot, r_ddot = inp.r, inp.r_dot, inp.r_ddot
        if self.dc:  # act on the state the command will meet: t + d T (see eso_smc)
            z1, z2 = predict3(z1, z2, z3, inp.history, self.u_n, self.b0, 0.0, T, self.T2h)
            r, r_dot = extrapolate(r, r_dot, r_ddot, self.tau)
        u0 = self.kp * (r - z1) + self.kd * (r_dot - z2) + self.ff * r_ddot
        u = (u0 - z3) / self.b0
        self.u_raw = u
        return self.hi if u > self.hi else (self.lo if u < self.lo else u)
