"""Linear ADRC: TD + linear ESO (Eq. 18, Eq. 17 bandwidth gains) + PD on the estimates.

Law (Gao 2003 with the TD's (v1, v2); the paper does not print it)::

    u0 = λ1² (v1 − z1) + 2 λ1 (v2 − z2)   [+ v3 if accel_feedforward]
    u  = (u0 − z3) / b0

so that with z3 = f the loop is ÿ = u0: a critically damped pair at −λ1
(λ1 = ω_c). The paper's λ1 = 390 > ω0 = 31.5 (linear) inverts the usual
ω0 ≈ 3–5 ω_c rule: the observer then lags the loop it feeds and robustness to
b0 error is small; we implement the gains as printed and leave the verdict to
the twin (DESIGN §5). Units: mm or rpm; λ1 1/s; b0 (mm|rpm)/s²/V.

The ESO is the exact-ZOH current observer of :mod:`pneu_control.observers.eso`
(inlined here for speed, same arithmetic); it is fed the saturated command
that was on the valve, so z3 never winds up.
"""

from __future__ import annotations

import math

from pneu_control.algorithms.base import NAN
from pneu_control.controller.params import AxisControllerParams
from pneu_control.observers.eso import eso_gains

__all__ = ["Ladrc"]


class Ladrc:
    name = "ladrc"
    uses_td = True

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
        # delay compensation: the controller attaches its command history (V, oldest first)
        self.dc = p.delay_compensation and params.transport_delay_samples > 0
        self.tau = params.transport_delay_samples * T
        self.u_n = lim.u_neutral
        self.pending: list[float] = [lim.u_neutral] * (params.transport_delay_samples + 1)
        self.z1 = self.z2 = self.z3 = 0.0
        self.s = NAN
        self.u_raw = 0.0
        self.u_in = 0.0

    @property
    def hint(self) -> tuple[float, float, float]:
        return self.z1, self.z2, self.z3 + self.b0 * self.u_in

    def start(self, y, r, r_dot, r_ddot, u_prev, u_applied, hint):
        self.z1 = hint[0] if math.isfinite(hint[0]) else y
        self.z2 = hint[1] if math.isfinite(hint[1]) else 0.0
        # z3 = ÿ − b0 u_applied: physically consistent (ÿ = 0 if unknown; cold start: 0)
        a = hint[2] if math.isfinite(hint[2]) else 0.0
        self.u_in = u_applied
        self.z3 = 0.0 if u_prev is None else a - self.b0 * u_applied
        u0 = self.kp * (r - self.z1) + self.kd * (r_dot - self.z2) + self.ff * r_ddot
        u = (u0 - self.z3) / self.b0
        self.u_raw = u
        return self.hi if u > self.hi else (self.lo if u < self.lo else u)

    def update(self, y, r, r_dot, r_ddot, u_applied):
        # ESO, Eq. 18 discretised (pneu_control.observers.eso.LinearEso.update)
        T = self.T
        z2, z3 = self.z2, self.z3
        self.u_in = u_applied
        acc = z3 + self.b0 * u_applied
        z1p = self.z1 + T * z2 + self.T2h * acc
        z2p = z2 + T * acc
        ey = y - z1p
        z1 = z1p + self.l1 * ey
        z2 = z2p + self.l2 * ey
        z3 = z3 + self.l3 * ey
        self.z1, self.z2, self.z3 = z1, z2, z3
        if self.dc:  # act on the state the command will meet: t + d T (see eso_smc)
            T2h, b0, u_n = self.T2h, self.b0, self.u_n
            pend = self.pending
            for i in range(1, len(pend)):
                acc = z3 + b0 * (pend[i] - u_n)
                z1 += T * z2 + T2h * acc
                z2 += T * acc
            tau = self.tau
            r += tau * r_dot + 0.5 * tau * tau * r_ddot
            r_dot += tau * r_ddot
        u0 = self.kp * (r - z1) + self.kd * (r_dot - z2) + self.ff * r_ddot
        u = (u0 - z3) / self.b0
        self.u_raw = u
        return self.hi if u > self.hi else (self.lo if u < self.lo else u)
