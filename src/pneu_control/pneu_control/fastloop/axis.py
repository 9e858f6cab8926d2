"""Compiled mirror of :meth:`pneu_control.controller.axis.AxisController.update`.

Covers what a run does: a cold start at the first sample, then plain updates (no
parameter change or algorithm switch in a run, so no bumpless blending). The state
values recorded per sample are :meth:`AxisController.state_values`.
"""

from __future__ import annotations

from numba import njit

from pneu_control.fastloop.algorithms import (
    ladrc_start,
    ladrc_update,
    pid_start,
    pid_update,
    smc_start,
    smc_update,
)
from pneu_control.fastloop.layout import (
    ALG_ESO_SMC,
    ALG_LADRC,
    ALG_PID,
    CI_ALG,
    CI_ANGLE,
    CI_DELAY,
    CI_LINEAR,
    CI_TD_ON,
    CI_USES_TD,
    CI_USES_THETA,
    CP_NEUTRAL,
    CP_SCALE,
    CP_T,
    CP_TD_H,
    CP_TD_R,
    CP_TD_T,
    CS_HIST,
    CS_S,
    CS_STARTED,
    CS_TD_V1,
    CS_TD_V2,
    CS_TD_V3,
    CS_TH_R,
    CS_U_LAST,
    CS_U_RAW,
    CS_V1_PREV,
    CS_Z1,
    CS_Z2,
    CS_Z3,
    JIT,
)
from pneu_control.fastloop.plus import plus_start, plus_update
from pneu_control.fastloop.reference import reference, td_step

__all__ = ["axis_update"]


@njit(**JIT)
def _start(cp, ci, cs, vt, y, r, r_dot, r_ddot, theta, p_c1, p_c2):
    alg = ci[CI_ALG]
    if alg == ALG_PID:
        return pid_start(cp, ci, cs, y, r, r_dot)
    if alg == ALG_LADRC:
        return ladrc_start(cp, cs, y, r, r_dot, r_ddot, 0.0)
    if alg == ALG_ESO_SMC:
        return smc_start(cp, ci, cs, y, r, r_dot, r_ddot, 0.0)
    return plus_start(cp, ci, cs, vt, y, r, r_dot, r_ddot, 0.0, theta, p_c1, p_c2)


@njit(**JIT)
def _update(cp, ci, cs, vt, n_hist, y, r, r_dot, r_ddot, u_applied, theta, p_c1, p_c2):
    alg = ci[CI_ALG]
    if alg == ALG_PID:
        return pid_update(cp, ci, cs, y, r, r_dot)
    if alg == ALG_LADRC:
        return ladrc_update(cp, ci, cs, n_hist, y, r, r_dot, r_ddot, u_applied)
    if alg == ALG_ESO_SMC:
        return smc_update(cp, ci, cs, n_hist, y, r, r_dot, r_ddot, u_applied)
    return plus_update(cp, ci, cs, vt, n_hist, y, r, r_dot, r_ddot, u_applied, theta, p_c1, p_c2)


@njit(**JIT)
def _record(cp, cs, rec, k, c, t, r, rd, y_si):
    """``AxisController.state_values()`` into rec[k, c:c + 11] (SI; then the command)."""
    scale = cp[CP_SCALE]
    rec[k, c] = t
    rec[k, c + 1] = r
    rec[k, c + 2] = rd
    rec[k, c + 3] = y_si
    rec[k, c + 4] = r - y_si
    rec[k, c + 5] = cs[CS_Z1] / scale
    rec[k, c + 6] = cs[CS_Z2] / scale
    rec[k, c + 7] = cs[CS_Z3] / scale
    rec[k, c + 8] = cs[CS_S] / scale
    rec[k, c + 9] = cs[CS_U_RAW] + cp[CP_NEUTRAL]
    rec[k, c + 10] = cs[CS_U_LAST]


@njit(**JIT)
def _hold(cp, cs, rec, k, c, t, r, rd, y_si):
    """A non-finite measurement: the last command again (``n_nonfinite`` in Python)."""
    _record(cp, cs, rec, k, c, t, r, rd, y_si)
    rec[k, c + 11] = cs[CS_U_LAST]
    return cs[CS_U_LAST]


@njit(**JIT)
def axis_update(cp, ci, cs, wp, vt, t, x, omega, theta_si, p_c1, p_c2, rec, k, c):
    """One ``AxisController.update(sample)`` (t = (stamp − first stamp)·1e-9 s); returns u (V).

    Records the state values and u into ``rec[k, c:c + 12]``.
    """
    y_si = x if ci[CI_LINEAR] else omega
    r, rd, rdd = reference(cp, ci, wp, t)
    scale = cp[CP_SCALE]
    angle = ci[CI_ANGLE]
    if angle:
        th = theta_si * scale
        if not (-1e300 < y_si < 1e300 and -1e300 < th < 1e300):  # NaN/inf: hold
            return _hold(cp, cs, rec, k, c, t, r, rd, y_si)
    else:
        th = 0.0
        if not (-1e300 < y_si < 1e300):
            return _hold(cp, cs, rec, k, c, t, r, rd, y_si)
    y = y_si * scale
    rp = r * scale
    rdp = rd * scale
    rddp = rdd * scale
    theta = 0.0
    if ci[CI_USES_THETA]:
        theta = theta_si * scale
        if not (-1e300 < theta < 1e300):
            return _hold(cp, cs, rec, k, c, t, r, rd, y_si)
    td_on = ci[CI_TD_ON]
    uses_td = ci[CI_USES_TD]
    neutral = cp[CP_NEUTRAL]
    n_hist = ci[CI_DELAY] + 1
    if cs[CS_STARTED] == 0.0:  # cold start (AxisController._switch): TD from the measurement
        v1 = y
        v2 = 0.0
        v3 = 0.0
        if td_on:
            v1, v2, v3 = td_step(v1, v2, rp, cp[CP_TD_R], cp[CP_TD_H], cp[CP_TD_T])
            cs[CS_TD_V1] = v1
            cs[CS_TD_V2] = v2
            cs[CS_TD_V3] = v3
        else:
            cs[CS_TD_V1] = y
            cs[CS_TD_V2] = 0.0
            cs[CS_TD_V3] = 0.0
            v1 = rp
            v2 = rdp
            v3 = rddp
        cs[CS_TH_R] = th
        cs[CS_V1_PREV] = v1
        cs[CS_STARTED] = 1.0
        if angle and uses_td:
            u_dev = _start(cp, ci, cs, vt, th, cs[CS_TH_R], v1, v2, theta, p_c1, p_c2)
        elif uses_td:
            u_dev = _start(cp, ci, cs, vt, y, v1, v2, v3, theta, p_c1, p_c2)
        else:
            u_dev = _start(cp, ci, cs, vt, y, rp, rdp, rddp, theta, p_c1, p_c2)
    else:
        if td_on:
            v1, v2, v3 = td_step(
                cs[CS_TD_V1], cs[CS_TD_V2], rp, cp[CP_TD_R], cp[CP_TD_H], cp[CP_TD_T]
            )
            cs[CS_TD_V1] = v1
            cs[CS_TD_V2] = v2
            cs[CS_TD_V3] = v3
        else:
            v1 = rp
            v2 = rdp
            v3 = rddp
        if angle:  # Eq. 25 on the angle: θ_r = ∫v1 dt (trapezoid)
            th_r = cs[CS_TH_R] + 0.5 * cp[CP_T] * (cs[CS_V1_PREV] + v1)
            cs[CS_TH_R] = th_r
            cs[CS_V1_PREV] = v1
            if uses_td:
                y, v1, v2, v3 = th, th_r, v1, v2
            else:
                v1, v2, v3 = rp, rdp, rddp
        elif not uses_td:
            v1, v2, v3 = rp, rdp, rddp
        u_applied = cs[CS_HIST] - neutral
        u_dev = _update(cp, ci, cs, vt, n_hist, y, v1, v2, v3, u_applied, theta, p_c1, p_c2)
    u = u_dev + neutral
    for i in range(n_hist - 1):  # del hist[0]; hist.append(u)
        cs[CS_HIST + i] = cs[CS_HIST + i + 1]
    cs[CS_HIST + n_hist - 1] = u
    cs[CS_U_LAST] = u
    _record(cp, cs, rec, k, c, t, r, rd, y_si)
    rec[k, c + 11] = u
    return u
