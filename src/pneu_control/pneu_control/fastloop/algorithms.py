"""Compiled mirrors of PID, LADRC and ESO-SMC (:mod:`pneu_control.algorithms`), cold start on.

One function per algorithm and call (``*_start`` = ``Algorithm.start`` with ``u_prev``
None and no hint: the only start a run makes; ``*_update`` = ``Algorithm.update``).
``cp``/``ci``/``cs`` are one axis's rows (:mod:`.layout`); the state lives in ``cs``
under the attribute names of the Python class. Each expression repeats the Python
one in the same order; the observer steps (:mod:`pneu_control.observers.eso`) and
the shared sliding-mode pieces (:mod:`pneu_control.algorithms.smc`) are mirrored
once here and used by ESO-SMC+ (:mod:`.plus`) too.
"""

from __future__ import annotations

import math

from numba import njit

from pneu_control.fastloop.layout import (
    AW_BACK_CALCULATION,
    AW_CONDITIONAL,
    CI_LA_DC,
    CI_PID_AW,
    CI_PID_ON_ERROR,
    CI_SM_ANGLE,
    CI_SM_AW,
    CI_SM_DC,
    CI_SM_FRIC,
    CS_F_K,
    CS_HIST,
    CS_INTEGRAL,
    CS_PID_D,
    CS_PID_RDOT,
    CS_PID_YF,
    CS_S,
    CS_U_IN,
    CS_U_RAW,
    CS_Z1,
    CS_Z2,
    CS_Z3,
    JIT,
    LA_B0,
    LA_FF,
    LA_HI,
    LA_KD,
    LA_KP,
    LA_L1,
    LA_L2,
    LA_L3,
    LA_LO,
    LA_T,
    LA_T2H,
    LA_TAU,
    LA_UN,
    PID_AD,
    PID_AY,
    PID_HI,
    PID_KB,
    PID_KD,
    PID_KI,
    PID_KP,
    PID_LO,
    PID_T,
    SM_B0,
    SM_C1,
    SM_C2,
    SM_DELTA,
    SM_EPS,
    SM_FC,
    SM_FS,
    SM_FV,
    SM_HI,
    SM_INVWS,
    SM_K,
    SM_L1,
    SM_L2,
    SM_L3,
    SM_LO,
    SM_MC,
    SM_MV,
    SM_T,
    SM_T2H,
    SM_TAU,
    SM_TWO,
    SM_UN,
)

__all__ = [
    "clamp",
    "conditional_integral",
    "eso3_step",
    "extrapolate",
    "ladrc_start",
    "ladrc_update",
    "pid_start",
    "pid_update",
    "sat",
    "smc_start",
    "smc_update",
]


# ------------------------------------------------------------------ shared pieces
@njit(**JIT)
def clamp(u, lo, hi):
    """``hi if u > hi else (lo if u < lo else u)`` (NaN passes through, as in Python)."""
    return hi if u > hi else (lo if u < lo else u)


@njit(**JIT)
def sat(s, delta, k):
    """:func:`pneu_control.algorithms.smc.sat` (Eq. 29)."""
    if s > delta:
        return 1.0
    if s < -delta:
        return -1.0
    return k * s


@njit(**JIT)
def conditional_integral(integral, integral_next, e, u, s, lo, hi, delta):
    """:func:`pneu_control.algorithms.smc.conditional_integral`."""
    if e > 0.0:
        return integral if (u > hi or s > delta) else integral_next
    return integral if (u < lo or s < -delta) else integral_next


@njit(**JIT)
def eso3_step(z1, z2, z3, acc, y, T, T2h, l1, l2, l3):
    """:func:`pneu_control.observers.eso.eso3_step` (Eq. 18, exact ZOH current observer)."""
    z1p = z1 + T * z2 + T2h * acc
    z2p = z2 + T * acc
    ey = y - z1p
    return z1p + l1 * ey, z2p + l2 * ey, z3 + l3 * ey


@njit(**JIT)
def extrapolate(r, r_dot, r_ddot, tau):
    """:func:`pneu_control.observers.eso.extrapolate`."""
    return r + tau * r_dot + 0.5 * tau * tau * r_ddot, r_dot + tau * r_ddot


@njit(**JIT)
def predict3(z1, z2, z3, cs, n_hist, u_n, b0, f_k, T, T2h):
    """:func:`pneu_control.observers.eso.predict3` without a valve map (history in ``cs``)."""
    for i in range(1, n_hist):
        du = cs[CS_HIST + i] - u_n
        acc = z3 + b0 * du + f_k
        z1 += T * z2 + T2h * acc
        z2 += T * acc
    return z1, z2


# ------------------------------------------------------------------ PID
@njit(**JIT)
def pid_start(cp, ci, cs, y, r, r_dot):
    cs[CS_PID_YF] = y
    cs[CS_PID_RDOT] = r_dot
    yd = 0.0  # hint NaN on a cold start
    d = (r_dot - yd) if ci[CI_PID_ON_ERROR] else -yd
    cs[CS_PID_D] = d
    e = r - y
    cs[CS_INTEGRAL] = 0.0
    u = cp[PID_KP] * e + cs[CS_INTEGRAL] + cp[PID_KD] * d
    cs[CS_U_RAW] = u
    return clamp(u, cp[PID_LO], cp[PID_HI])


@njit(**JIT)
def pid_update(cp, ci, cs, y, r, r_dot):
    T = cp[PID_T]
    y_prev = cs[CS_PID_YF]
    y_f = y_prev + cp[PID_AY] * (y - y_prev)
    cs[CS_PID_YF] = y_f
    cs[CS_PID_RDOT] = r_dot
    dy = (y_f - y_prev) / T
    d_in = r_dot - dy if ci[CI_PID_ON_ERROR] else -dy
    a = cp[PID_AD]
    d = a * cs[CS_PID_D] + (1.0 - a) * d_in
    cs[CS_PID_D] = d
    e = r - y_f
    di = cp[PID_KI] * e * T
    integral = cs[CS_INTEGRAL] + di
    u = cp[PID_KP] * e + integral + cp[PID_KD] * d
    hi = cp[PID_HI]
    lo = cp[PID_LO]
    if u > hi:
        u_sat = hi
    elif u < lo:
        u_sat = lo
    else:
        u_sat = u
    aw = ci[CI_PID_AW]
    if aw == AW_CONDITIONAL:
        if (u > hi and di > 0.0) or (u < lo and di < 0.0):
            integral -= di
        integral = hi if integral > hi else (lo if integral < lo else integral)
    elif aw == AW_BACK_CALCULATION:
        integral += cp[PID_KB] * (u_sat - u)
    cs[CS_INTEGRAL] = integral
    cs[CS_U_RAW] = u
    return u_sat


# ------------------------------------------------------------------ LADRC
@njit(**JIT)
def ladrc_start(cp, cs, y, r, r_dot, r_ddot, u_applied):
    cs[CS_Z1] = y
    cs[CS_Z2] = 0.0
    cs[CS_U_IN] = u_applied
    cs[CS_Z3] = 0.0
    u0 = cp[LA_KP] * (r - cs[CS_Z1]) + cp[LA_KD] * (r_dot - cs[CS_Z2]) + cp[LA_FF] * r_ddot
    u = (u0 - cs[CS_Z3]) / cp[LA_B0]
    cs[CS_U_RAW] = u
    return clamp(u, cp[LA_LO], cp[LA_HI])


@njit(**JIT)
def ladrc_update(cp, ci, cs, n_hist, y, r, r_dot, r_ddot, u_applied):
    T = cp[LA_T]
    T2h = cp[LA_T2H]
    b0 = cp[LA_B0]
    cs[CS_U_IN] = u_applied
    z3 = cs[CS_Z3]
    z1, z2, z3 = eso3_step(
        cs[CS_Z1], cs[CS_Z2], z3, z3 + b0 * u_applied, y, T, T2h,
        cp[LA_L1], cp[LA_L2], cp[LA_L3],
    )  # fmt: skip
    cs[CS_Z1] = z1
    cs[CS_Z2] = z2
    cs[CS_Z3] = z3
    if ci[CI_LA_DC]:
        z1, z2 = predict3(z1, z2, z3, cs, n_hist, cp[LA_UN], b0, 0.0, T, T2h)
        r, r_dot = extrapolate(r, r_dot, r_ddot, cp[LA_TAU])
    u0 = cp[LA_KP] * (r - z1) + cp[LA_KD] * (r_dot - z2) + cp[LA_FF] * r_ddot
    u = (u0 - z3) / b0
    cs[CS_U_RAW] = u
    return clamp(u, cp[LA_LO], cp[LA_HI])


# ------------------------------------------------------------------ ESO-SMC
@njit(**JIT)
def _friction_term(cp, ci, z1, z2):
    """:meth:`pneu_control.algorithms.eso_smc.EsoSmc.friction_term` (f_k, rpm/s²)."""
    if not ci[CI_SM_FRIC]:
        return 0.0
    if ci[CI_SM_ANGLE]:
        return -cp[SM_FS] * (cp[SM_MC] * math.tanh(z2 * cp[SM_INVWS]) + cp[SM_MV] * z2)
    x = abs(z1) * cp[SM_INVWS]
    # Python's cosh(x) ** 2 is pow(c, 2.0); the exponent comes from cp so that LLVM
    # cannot fold it into c * c (which differs from pow in the last bit)
    sech2 = 0.0 if x > 30.0 else 1.0 / (math.cosh(x) ** cp[SM_TWO])
    return -(cp[SM_FV] + cp[SM_FC] * sech2) * z2


@njit(**JIT)
def smc_start(cp, ci, cs, y, r, r_dot, r_ddot, u_applied):
    z1 = y
    z2 = 0.0
    cs[CS_Z1] = z1
    cs[CS_Z2] = z2
    f_k = _friction_term(cp, ci, z1, z2)
    cs[CS_F_K] = f_k
    cs[CS_U_IN] = u_applied
    e = r - z1
    ed = r_dot - z2
    cs[CS_Z3] = 0.0
    cs[CS_INTEGRAL] = 0.0
    c1 = cp[SM_C1]
    c2 = cp[SM_C2]
    s = ed + c1 * e + c2 * cs[CS_INTEGRAL]
    cs[CS_S] = s
    nominal = cp[SM_EPS] * sat(s, cp[SM_DELTA], cp[SM_K]) + r_ddot + c1 * ed + c2 * e - f_k
    u = (nominal - cs[CS_Z3]) / cp[SM_B0]
    cs[CS_U_RAW] = u
    return clamp(u, cp[SM_LO], cp[SM_HI])


@njit(**JIT)
def smc_update(cp, ci, cs, n_hist, y, r, r_dot, r_ddot, u_applied):
    T = cp[SM_T]
    T2h = cp[SM_T2H]
    b0 = cp[SM_B0]
    cs[CS_U_IN] = u_applied
    z3 = cs[CS_Z3]
    z1, z2, z3 = eso3_step(
        cs[CS_Z1], cs[CS_Z2], z3, z3 + b0 * u_applied + cs[CS_F_K], y, T, T2h,
        cp[SM_L1], cp[SM_L2], cp[SM_L3],
    )  # fmt: skip
    cs[CS_Z1] = z1
    cs[CS_Z2] = z2
    cs[CS_Z3] = z3
    if ci[CI_SM_DC]:
        z1, z2 = predict3(z1, z2, z3, cs, n_hist, cp[SM_UN], b0, cs[CS_F_K], T, T2h)
        r, r_dot = extrapolate(r, r_dot, r_ddot, cp[SM_TAU])
    e = r - z1
    ed = r_dot - z2
    integral = cs[CS_INTEGRAL] + T * e
    c1 = cp[SM_C1]
    c2 = cp[SM_C2]
    s = ed + c1 * e + c2 * integral
    cs[CS_S] = s
    if ci[CI_SM_FRIC]:
        f_k = _friction_term(cp, ci, z1, z2)
        cs[CS_F_K] = f_k
    else:
        f_k = 0.0
    delta = cp[SM_DELTA]
    u = (cp[SM_EPS] * sat(s, delta, cp[SM_K]) + r_ddot + c1 * ed + c2 * e - z3 - f_k) / b0
    cs[CS_U_RAW] = u
    lo = cp[SM_LO]
    hi = cp[SM_HI]
    if ci[CI_SM_AW]:
        cs[CS_INTEGRAL] = conditional_integral(cs[CS_INTEGRAL], integral, e, u, s, lo, hi, delta)
    else:
        cs[CS_INTEGRAL] = integral
    return clamp(u, lo, hi)
