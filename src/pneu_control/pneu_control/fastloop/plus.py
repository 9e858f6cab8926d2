"""Compiled mirror of ESO-SMC+ (:mod:`pneu_control.algorithms.eso_smc_plus`), cold start on.

Every option: linear position (friction feed-forward, delay compensation) or force
cascade, rotary angle observer (4 states) or speed observer, the valve
linearisation (:class:`~pneu_control.algorithms.valve_curve.ValveCurve`) and
``rotary_model: angle`` inputs. Expressions in the Python order (:mod:`.algorithms`).
"""

from __future__ import annotations

import math

from numba import njit

from pneu_control.fastloop.algorithms import (
    clamp,
    conditional_integral,
    eso3_step,
    extrapolate,
    sat,
)
from pneu_control.fastloop.layout import (
    CI_NVT,
    CI_PL_ANGLE,
    CI_PL_ANGLE_INPUTS,
    CI_PL_DC,
    CI_PL_FFW,
    CI_PL_FORCE,
    CI_PL_LIN_ID,
    CS_FF,
    CS_HIST,
    CS_INTEGRAL,
    CS_PL_AIN,
    CS_PL_FDP,
    CS_PL_FP,
    CS_PL_THR,
    CS_PL_UFF,
    CS_PL_VIN,
    CS_PL_WRP,
    CS_S,
    CS_U_RAW,
    CS_Z1,
    CS_Z2,
    CS_Z3,
    CS_Z4,
    JIT,
    PL_AC1,
    PL_AC2,
    PL_AF,
    PL_B0,
    PL_BF,
    PL_C1,
    PL_C2,
    PL_CVK,
    PL_DELTA,
    PL_DUMAX,
    PL_EPS,
    PL_F0,
    PL_G,
    PL_HI,
    PL_INVBF,
    PL_INVG,
    PL_INVMK,
    PL_INVVS,
    PL_K,
    PL_KF,
    PL_L1,
    PL_L2,
    PL_L3,
    PL_L4A,
    PL_L4B,
    PL_L4C,
    PL_L4D,
    PL_LO,
    PL_MK,
    PL_NA1S,
    PL_NA2S,
    PL_T,
    PL_T2H,
    PL_T3S,
    PL_TAU,
    PL_UN,
    PL_V10,
    PL_V20,
    PL_VHI,
    PL_VLO,
    PL_VMAX,
)

__all__ = ["plus_start", "plus_update"]

_NAN = math.nan


# ------------------------------------------------------------------ valve curve
@njit(**JIT)
def _bisect_right(a, n, x):
    lo = 0
    hi = n
    while lo < hi:
        mid = (lo + hi) // 2
        if x < a[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@njit(**JIT)
def _to_linear(cp, ci, vt, u):
    """:meth:`ValveCurve.to_linear` (identity when the linearisation is off)."""
    if ci[CI_PL_LIN_ID]:
        return u
    if u != u:  # Python's bisect on NaN ends past the table (IndexError): never reached, NaN out
        return _NAN
    du = vt[0]
    fl = vt[1]
    n = ci[CI_NVT]
    a = u if u >= 0.0 else -u
    if a >= cp[PL_DUMAX]:
        v = cp[PL_VMAX] + (a - cp[PL_DUMAX])
    else:
        if a >= du[n - 1]:
            f = 1.0
        else:
            i = _bisect_right(du, n, a) - 1
            f = fl[i] + (fl[i + 1] - fl[i]) * (a - du[i]) / (du[i + 1] - du[i])
        v = f * cp[PL_INVG]
    return v if u >= 0.0 else -v


@njit(**JIT)
def _to_valve(cp, ci, vt, v):
    """:meth:`ValveCurve.to_valve`."""
    if v != v:
        return _NAN
    du = vt[0]
    fl = vt[1]
    a = v if v >= 0.0 else -v
    if a >= cp[PL_VMAX]:
        u = cp[PL_DUMAX] + (a - cp[PL_VMAX])
    else:
        q = a * cp[PL_G]
        n = ci[CI_NVT]
        i = _bisect_right(fl, n, q) - 1
        if i >= n - 1:  # q rounded up to the last flow: Python's du[i + 1] raises IndexError
            return _NAN
        u = du[i] + (du[i + 1] - du[i]) * (q - fl[i]) / (fl[i + 1] - fl[i])
    return u if v >= 0.0 else -u


@njit(**JIT)
def _out(cp, ci, cs, vt, v):
    u = v if ci[CI_PL_LIN_ID] else _to_valve(cp, ci, vt, v)
    cs[CS_U_RAW] = u
    return clamp(u, cp[PL_LO], cp[PL_HI])


# ------------------------------------------------------------------ model pieces
@njit(**JIT)
def _friction(cp, v):
    """F_f(v) of Eq. 2, tanh-smoothed, N; v in mm/s."""
    return cp[PL_AF] * math.tanh(v * cp[PL_INVVS]) + cp[PL_CVK] * v


@njit(**JIT)
def _pressure_force(cp, p_c1, p_c2):
    return cp[PL_AC1] * p_c1 - cp[PL_AC2] * p_c2 - cp[PL_F0]


@njit(**JIT)
def _law_force(cp, ci, cs, vt, r, r_dot, r_ddot, p_c1, p_c2, F_p, integrate):
    T = cp[PL_T]
    z1 = cs[CS_Z1]
    z2 = cs[CS_Z2]
    z3 = cs[CS_Z3]
    e = r - z1
    ed = r_dot - z2
    integral = cs[CS_INTEGRAL] + T * e
    c1 = cp[PL_C1]
    c2 = cp[PL_C2]
    s = ed + c1 * e + c2 * integral
    cs[CS_S] = s
    delta = cp[PL_DELTA]
    a_d = cp[PL_EPS] * sat(s, delta, cp[PL_K]) + r_ddot + c1 * ed + c2 * e - z3
    M_k = cp[PL_MK]
    F_r = M_k * r_ddot + _friction(cp, r_dot)
    F_d = F_r + M_k * (a_d - r_ddot)
    F_rp = cs[CS_PL_FDP]
    cs[CS_PL_FDP] = F_r
    F_d_dot = 0.0 if F_rp != F_rp else (F_r - F_rp) / T
    x_m = 1e-3 * z1
    K_s = cp[PL_NA1S] * p_c1 / (cp[PL_V10] + cp[PL_AC1] * x_m) + cp[PL_NA2S] * p_c2 / (
        cp[PL_V20] - cp[PL_AC2] * x_m
    )
    if not (-1e300 < K_s < 1e300):
        K_s = 0.0
    v = (F_d_dot + cp[PL_KF] * (F_d - F_p) + K_s * 1e-3 * z2) * cp[PL_INVBF]
    if integrate:
        cs[CS_INTEGRAL] = conditional_integral(
            cs[CS_INTEGRAL], integral, e, v, s, cp[PL_VLO], cp[PL_VHI], delta
        )
    return v


@njit(**JIT)
def _speed_ref(ci, r, r_dot, r_ddot):
    if ci[CI_PL_ANGLE_INPUTS]:
        return r_dot, r_ddot, 0.0
    return r, r_dot, r_ddot


# ------------------------------------------------------------------ start
@njit(**JIT)
def plus_start(cp, ci, cs, vt, y, r, r_dot, r_ddot, u_applied, theta, p_c1, p_c2):
    """``EsoSmcPlus.start(inp, None, (NaN, NaN, NaN))``."""
    v_in = _to_linear(cp, ci, vt, u_applied)
    cs[CS_PL_VIN] = v_in
    b0 = cp[PL_B0]
    c1 = cp[PL_C1]
    c2 = cp[PL_C2]
    h1 = 0.0
    h2 = 0.0
    if ci[CI_PL_FORCE]:
        cs[CS_Z1] = y
        cs[CS_Z2] = h1
        F_p = _pressure_force(cp, p_c1, p_c2)
        F_p = F_p if math.isfinite(F_p) else 0.0
        cs[CS_PL_FP] = F_p
        cs[CS_PL_AIN] = (F_p - _friction(cp, cs[CS_Z2])) * cp[PL_INVMK]
        cs[CS_Z3] = h2 - cs[CS_PL_AIN]
        cs[CS_INTEGRAL] = 0.0
        cs[CS_PL_FDP] = _NAN
        v = _law_force(cp, ci, cs, vt, r, r_dot, r_ddot, p_c1, p_c2, F_p, False)
        return _out(cp, ci, cs, vt, v)
    eps = cp[PL_EPS]
    delta = cp[PL_DELTA]
    k = cp[PL_K]
    if not ci[CI_PL_ANGLE]:
        z1 = y
        z2 = h1
        cs[CS_Z1] = z1
        cs[CS_Z2] = z2
        cs[CS_Z3] = 0.0
        e = r - z1
        ed = r_dot - z2
        cs[CS_INTEGRAL] = 0.0
        s = ed + c1 * e + c2 * cs[CS_INTEGRAL]
        cs[CS_S] = s
        v = (eps * sat(s, delta, k) + r_ddot + c1 * ed + c2 * e - cs[CS_Z3]) / b0
        return _out(cp, ci, cs, vt, v)
    w_r, wd_r, wdd_r = _speed_ref(ci, r, r_dot, r_ddot)
    th = theta
    cs[CS_Z1] = th
    if ci[CI_PL_ANGLE_INPUTS]:
        cs[CS_Z2] = 0.0
        cs[CS_Z3] = h2
        cs[CS_Z4] = 0.0
    else:
        cs[CS_Z2] = y
        cs[CS_Z3] = h1
        cs[CS_Z4] = 0.0
    ed = w_r - cs[CS_Z2]
    edd = wd_r - cs[CS_Z3]
    e = 0.0
    cs[CS_PL_THR] = th + e
    cs[CS_PL_WRP] = w_r
    s = edd + c1 * ed + c2 * e
    cs[CS_S] = s
    v = (eps * sat(s, delta, k) + wdd_r + c1 * edd + c2 * ed - cs[CS_Z4]) / b0
    return _out(cp, ci, cs, vt, v)


# ------------------------------------------------------------------ update
@njit(**JIT)
def _update_angle(cp, ci, cs, vt, n_hist, r, r_dot, r_ddot, theta, v_in):
    T = cp[PL_T]
    T2h = cp[PL_T2H]
    T3s = cp[PL_T3S]
    b0 = cp[PL_B0]
    z4 = cs[CS_Z4]
    # observers.eso_chain.eso4_step
    jerk = z4 + b0 * v_in
    z1 = cs[CS_Z1]
    z2 = cs[CS_Z2]
    z3 = cs[CS_Z3]
    z1p = z1 + T * z2 + T2h * z3 + T3s * jerk
    z2p = z2 + T * z3 + T2h * jerk
    z3p = z3 + T * jerk
    ey = theta - z1p
    z1 = z1p + cp[PL_L4A] * ey
    z2 = z2p + cp[PL_L4B] * ey
    z3 = z3p + cp[PL_L4C] * ey
    z4 = z4 + cp[PL_L4D] * ey
    cs[CS_Z1] = z1
    cs[CS_Z2] = z2
    cs[CS_Z3] = z3
    cs[CS_Z4] = z4
    w_r, wd_r, wdd_r = _speed_ref(ci, r, r_dot, r_ddot)
    angle_inputs = ci[CI_PL_ANGLE_INPUTS]
    if angle_inputs:
        th_r = r
    else:
        th_r = cs[CS_PL_THR] + 0.5 * T * (cs[CS_PL_WRP] + w_r)
        cs[CS_PL_WRP] = w_r
    th_c = th_r
    w_c = w_r
    wd_c = wd_r
    if ci[CI_PL_DC]:  # observers.eso_chain.predict4
        u_n = cp[PL_UN]
        for i in range(1, n_hist):
            du = cs[CS_HIST + i] - u_n
            jerk = z4 + b0 * (du if ci[CI_PL_LIN_ID] else _to_linear(cp, ci, vt, du))
            z1 += T * z2 + T2h * z3 + T3s * jerk
            z2 += T * z3 + T2h * jerk
            z3 += T * jerk
        tau = cp[PL_TAU]
        th_c += tau * w_r + 0.5 * tau * tau * wd_r
        w_c += tau * wd_r
    e = th_c - z1
    ed = w_c - z2
    edd = wd_c - z3
    c1 = cp[PL_C1]
    c2 = cp[PL_C2]
    s = edd + c1 * ed + c2 * e
    cs[CS_S] = s
    v = (cp[PL_EPS] * sat(s, cp[PL_DELTA], cp[PL_K]) + wdd_r + c1 * edd + c2 * ed - z4) / b0
    if not angle_inputs:
        if (e > 0.0 and v > cp[PL_VHI]) or (e < 0.0 and v < cp[PL_VLO]):
            th_r = cs[CS_PL_THR] + T * cs[CS_Z2]
        cs[CS_PL_THR] = th_r
    return _out(cp, ci, cs, vt, v)


@njit(**JIT)
def plus_update(cp, ci, cs, vt, n_hist, y, r, r_dot, r_ddot, u_applied, theta, p_c1, p_c2):
    """``EsoSmcPlus.update(inp)``."""
    v_in = u_applied if ci[CI_PL_LIN_ID] else _to_linear(cp, ci, vt, u_applied)
    cs[CS_PL_VIN] = v_in
    if ci[CI_PL_ANGLE]:
        return _update_angle(cp, ci, cs, vt, n_hist, r, r_dot, r_ddot, theta, v_in)
    T = cp[PL_T]
    T2h = cp[PL_T2H]
    if ci[CI_PL_FORCE]:  # _update_force
        z3 = cs[CS_Z3]
        z1, z2, z3 = eso3_step(
            cs[CS_Z1], cs[CS_Z2], z3, z3 + cs[CS_PL_AIN], y, T, T2h,
            cp[PL_L1], cp[PL_L2], cp[PL_L3],
        )  # fmt: skip
        cs[CS_Z1] = z1
        cs[CS_Z2] = z2
        cs[CS_Z3] = z3
        F_p = _pressure_force(cp, p_c1, p_c2)
        if not (-1e300 < F_p < 1e300):
            F_p = cs[CS_PL_FP]
        cs[CS_PL_FP] = F_p
        cs[CS_PL_AIN] = (F_p - _friction(cp, z2)) * cp[PL_INVMK]
        v = _law_force(cp, ci, cs, vt, r, r_dot, r_ddot, p_c1, p_c2, F_p, True)
        return _out(cp, ci, cs, vt, v)
    n_ff = n_hist  # the feed-forward pipe has d + 1 entries, like the history
    ffw = ci[CI_PL_FFW]
    if ffw:
        v_in -= cs[CS_FF]
        for i in range(n_ff - 1):  # del ffp[0]
            cs[CS_FF + i] = cs[CS_FF + i + 1]
    b0 = cp[PL_B0]
    z3 = cs[CS_Z3]
    z1, z2, z3 = eso3_step(
        cs[CS_Z1], cs[CS_Z2], z3, z3 + b0 * v_in, y, T, T2h, cp[PL_L1], cp[PL_L2], cp[PL_L3]
    )
    cs[CS_Z1] = z1
    cs[CS_Z2] = z2
    cs[CS_Z3] = z3
    if ci[CI_PL_DC]:  # observers.eso.predict3 with the valve map
        u_n = cp[PL_UN]
        for i in range(1, n_hist):
            du = cs[CS_HIST + i] - u_n
            acc = z3 + b0 * (du if ci[CI_PL_LIN_ID] else _to_linear(cp, ci, vt, du)) + 0.0
            z1 += T * z2 + T2h * acc
            z2 += T * acc
        r, r_dot = extrapolate(r, r_dot, r_ddot, cp[PL_TAU])
    e = r - z1
    ed = r_dot - z2
    integral = cs[CS_INTEGRAL] + T * e
    c1 = cp[PL_C1]
    c2 = cp[PL_C2]
    s = ed + c1 * e + c2 * integral
    cs[CS_S] = s
    delta = cp[PL_DELTA]
    v = (cp[PL_EPS] * sat(s, delta, cp[PL_K]) + r_ddot + c1 * ed + c2 * e - z3) / b0
    if ffw:
        F_r = _friction(cp, r_dot)
        F_dp = cs[CS_PL_FDP]
        u_ff = 0.0 if F_dp != F_dp else (F_r - F_dp) / (T * cp[PL_BF])
        cs[CS_PL_FDP] = F_r
        cs[CS_FF + n_ff - 1] = u_ff  # ff_pipe.append
        cs[CS_PL_UFF] = u_ff
        v += u_ff
    cs[CS_INTEGRAL] = conditional_integral(
        cs[CS_INTEGRAL], integral, e, v, s, cp[PL_VLO], cp[PL_VHI], delta
    )
    return _out(cp, ci, cs, vt, v)
