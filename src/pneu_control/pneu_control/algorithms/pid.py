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
from pneu_msgs_py.params.records import RecordType, kernel

from pneu_control.algorithms.base import (
    NAN,
    AlgorithmKernel,
    KernelAlgorithm,
    deviation_band,
)
from pneu_control.algorithms.smc import NONNEGATIVE, POSITIVE

if TYPE_CHECKING:
    from pneu_control.controller.params import AxisControllerParams

__all__ = ["PID_CONSTANTS", "PID_STATE", "Pid", "PidParams", "pid_start", "pid_update"]


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


AW_CODES = {"conditional": 0, "back_calculation": 1, "none": 2}

PID_CONSTANTS = RecordType(
    "PidConstants",
    [
        ("T", "f"), ("kp", "f"), ("ki", "f"), ("kd", "f"), ("a_d", "f"), ("a_y", "f"),
        ("kb", "f"), ("lo", "f"), ("hi", "f"), ("on_error", "i"), ("aw", "i"),
    ],
)  # fmt: skip
PID_STATE = RecordType(
    "PidState",
    [
        ("z1", "f"), ("z2", "f"), ("z3", "f"), ("s", "f"), ("u_raw", "f", 0.0),
        ("integral", "f", 0.0), ("d", "f", 0.0), ("y_f", "f", 0.0), ("r_dot", "f", 0.0),
    ],
)  # fmt: skip


@kernel
def pid_hint(c, s):
    return s.y_f, (s.r_dot - s.d if c.on_error else -s.d), NAN


@kernel
def pid_start(c, s, table, inp, u_prev, h0, h1, h2):
    y = inp.y
    r_dot = inp.r_dot
    s.y_f = y
    s.r_dot = r_dot
    yd = h1 if math.isfinite(h1) else 0.0
    s.d = (r_dot - yd) if c.on_error else -yd
    e = inp.r - y
    if u_prev != u_prev:  # NaN: a cold start
        s.integral = 0.0
    else:  # bumpless: choose I so that the output equals u_prev
        i = u_prev - c.kp * e - c.kd * s.d
        s.integral = min(max(i, c.lo), c.hi)
    u = c.kp * e + s.integral + c.kd * s.d
    s.u_raw = u
    return c.hi if u > c.hi else (c.lo if u < c.lo else u)


@kernel
def pid_update(c, s, table, inp):
    T = c.T
    y_prev = s.y_f
    y_f = y_prev + c.a_y * (inp.y - y_prev)
    s.y_f = y_f
    r_dot = inp.r_dot
    s.r_dot = r_dot
    dy = (y_f - y_prev) / T
    d_in = r_dot - dy if c.on_error else -dy
    a = c.a_d
    d = a * s.d + (1.0 - a) * d_in
    s.d = d
    e = inp.r - y_f
    di = c.ki * e * T
    integral = s.integral + di
    u = c.kp * e + integral + c.kd * d
    hi = c.hi
    lo = c.lo
    if u > hi:
        u_sat = hi
    elif u < lo:
        u_sat = lo
    else:
        u_sat = u
    aw = c.aw
    if aw == 0:  # conditional
        if (u > hi and di > 0.0) or (u < lo and di < 0.0):
            integral -= di  # conditional integration
        integral = hi if integral > hi else (lo if integral < lo else integral)
    elif aw == 1:  # back_calculation
        integral += c.kb * (u_sat - u)
    s.integral = integral
    s.u_raw = u
    return u_sat


class Pid(KernelAlgorithm):
    name = "pid"
    CONSTANTS = PID_CONSTANTS
    STATE = PID_STATE
    KERNEL = AlgorithmKernel(pid_start, pid_update, pid_hint)

    def constants(self, params: AxisControllerParams, axis: str):
        p = params.pid
        T = params.sample_time_s
        return PID_CONSTANTS.new(
            T=T,
            kp=p.kp,
            ki=p.ki,
            kd=p.kd,
            a_d=math.exp(-T / p.tf),
            a_y=1.0 - math.exp(-T / p.y_filter_tf) if p.y_filter_tf > 0.0 else 1.0,
            kb=T / p.tt,
            **deviation_band(params),
            on_error=int(p.derivative_on == "error"),
            aw=AW_CODES[p.anti_windup],
        )
