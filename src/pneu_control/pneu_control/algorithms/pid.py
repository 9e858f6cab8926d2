"""PID with a filtered derivative and anti-windup (paper gains, Results section).

Discrete law at sample k (T = sample time, e = r − y_f)::

    y_f(k)  = y_f(k−1) + a_y (y(k) − y_f(k−1))       measurement low-pass, a_y = 1 − exp(−T/T_y)
    D_in(k) = ṙ(k) − (y_f(k) − y_f(k−1))/T            derivative_on = error (analytic ṙ, no kick)
            = −(y_f(k) − y_f(k−1))/T                  derivative_on = measurement
    d(k)    = a d(k−1) + (1 − a) D_in(k),  a = exp(−T/T_f)   (exact ZOH of 1/(T_f s + 1))
    I(k)    = I(k−1) + Ki e(k) T                      (Ki inside the sum: gain changes never jump)
    u       = Kp e + I + Kd d,  saturated to [u_min, u_max] − u_n

Anti-windup: ``conditional`` undoes the integration step when the output is
saturated and e pushes further into saturation, and keeps I within the output
range; ``back_calculation`` adds (T/T_t)(u_sat − u_raw) to I; ``none``.
Units: e in mm (linear) or rpm (rotary); gains V/mm, V/(mm·s), V·s/mm or per rpm.
The rotary speed is quantised (15 rpm at 1000 P/R X4, 1 ms): with Kd = 0.004
V·s/rpm an unfiltered derivative would swing ±60 V per count, hence T_f.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pneu_msgs_py.params.core import param

from pneu_control.algorithms.base import NAN, StepInput
from pneu_control.algorithms.smc import NONNEGATIVE, POSITIVE

if TYPE_CHECKING:
    from pneu_control.controller.params import AxisControllerParams

__all__ = ["Pid", "PidParams"]


@dataclass(frozen=True)
class PidParams:
    """Parallel PID, u = u_n + Kp e + Ki ∫e dt + Kd ė_f (e = reference − measured).

    Paper (Results): linear Kp 0.38, Ki 4.6, Kd 0.0128; rotary Kp 0.25,
    Ki 0.22, Kd 0.004. The derivative is filtered (first order, time constant
    ``tf``); the paper is silent on filtering (our choice, see DESIGN §8).
    """

    kp: float = param(
        0.38, unit="V/mm | V/rpm", desc="proportional gain", **POSITIVE, source="paper"
    )
    ki: float = param(
        4.6, unit="V/(mm·s) | V/(rpm·s)", desc="integral gain", **NONNEGATIVE, source="paper"
    )
    kd: float = param(
        0.0128, unit="V·s/mm | V·s/rpm", desc="derivative gain", **NONNEGATIVE, source="paper"
    )
    tf: float = param(
        0.002,
        unit="s",
        desc="derivative low-pass time constant (exact ZOH discretisation)",
        **POSITIVE,
    )
    derivative_on: str = param(
        "error", choices=("error", "measurement"), desc="differentiate the error or −measurement"
    )
    anti_windup: str = param(
        "conditional",
        choices=("conditional", "back_calculation", "none"),
        desc="integrator anti-windup strategy",
    )
    tt: float = param(0.05, unit="s", desc="back-calculation tracking time constant", **POSITIVE)
    y_filter_tf: float = param(
        0.0,
        unit="s",
        desc="first-order low-pass on the raw measurement before P and D (0 = off)",
        lo=0.0,
        hi=1.0,
    )


class Pid:
    name = "pid"
    uses_td = False
    uses_theta = False
    uses_pressures = False

    def __init__(self, params: AxisControllerParams, axis: str):
        p = params.pid
        T = params.sample_time_s
        self.T = T
        self.kp, self.ki, self.kd = p.kp, p.ki, p.kd
        self.a_d = math.exp(-T / p.tf)
        self.a_y = 1.0 - math.exp(-T / p.y_filter_tf) if p.y_filter_tf > 0.0 else 1.0
        self.on_error = p.derivative_on == "error"
        self.aw = p.anti_windup
        self.kb = T / p.tt
        lim = params.limits
        self.lo = lim.u_min - lim.u_neutral
        self.hi = lim.u_max - lim.u_neutral
        self.z1 = self.z2 = self.z3 = self.s = NAN
        self.u_raw = 0.0
        self.integral = 0.0
        self.d = 0.0
        self.y_f = 0.0
        self.r_dot = 0.0

    @property
    def hint(self) -> tuple[float, float, float]:
        return self.y_f, (self.r_dot - self.d if self.on_error else -self.d), NAN

    def start(self, inp: StepInput, u_prev, hint):
        y, r, r_dot = inp.y, inp.r, inp.r_dot
        self.y_f = y
        self.r_dot = r_dot
        yd = hint[1] if math.isfinite(hint[1]) else 0.0
        self.d = (r_dot - yd) if self.on_error else -yd
        e = r - y
        if u_prev is None:
            self.integral = 0.0
        else:  # bumpless: choose I so that the output equals u_prev
            i = u_prev - self.kp * e - self.kd * self.d
            self.integral = min(max(i, self.lo), self.hi)
        u = self.kp * e + self.integral + self.kd * self.d
        self.u_raw = u
        return self.hi if u > self.hi else (self.lo if u < self.lo else u)

    def update(self, inp: StepInput):
        y, r_dot = inp.y, inp.r_dot
        T = self.T
        y_prev = self.y_f
        y_f = y_prev + self.a_y * (y - y_prev)
        self.y_f = y_f
        self.r_dot = r_dot
        dy = (y_f - y_prev) / T
        d_in = r_dot - dy if self.on_error else -dy
        a = self.a_d
        d = a * self.d + (1.0 - a) * d_in
        self.d = d
        e = inp.r - y_f
        di = self.ki * e * T
        integral = self.integral + di
        u = self.kp * e + integral + self.kd * d
        hi, lo = self.hi, self.lo
        if u > hi:
            u_sat = hi
        elif u < lo:
            u_sat = lo
        else:
            u_sat = u
        aw = self.aw
        if aw == "conditional":
            if (u > hi and di > 0.0) or (u < lo and di < 0.0):
                integral -= di  # conditional integration
            integral = hi if integral > hi else (lo if integral < lo else integral)
        elif aw == "back_calculation":
            integral += self.kb * (u_sat - u)
        self.integral = integral
        self.u_raw = u
        return u_sat
