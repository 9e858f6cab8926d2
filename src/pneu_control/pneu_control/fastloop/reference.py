"""Compiled mirrors of the references (:mod:`pneu_control.controller.references`) and the TD.

Each expression is the Python one in the same order (a + b + c is (a + b) + c; Python's
``10 * s3`` is float(10)·s3), so the values are bit-identical.
"""

from __future__ import annotations

import math

from numba import njit

from pneu_control.fastloop.layout import (
    CI_NWP,
    CI_REF_KIND,
    CP_REF0,
    CP_REF1,
    CP_REF2,
    CP_REF3,
    JIT,
    REF_CONSTANT,
    REF_RAMP,
    REF_SINE,
    REF_SMOOTH_STEP,
)

__all__ = ["reference", "td_step"]

_TWO_PI = 2.0 * math.pi


@njit(**JIT)
def _waypoints(wp, n, t):
    """:class:`~pneu_control.controller.references.Waypoints`: quintic Hermite through n knots."""
    ts = wp[0]
    rs = wp[1]
    if t <= ts[0]:
        return rs[0], 0.0, 0.0
    if t >= ts[n - 1]:
        return rs[n - 1], 0.0, 0.0
    lo = 0  # bisect.bisect_right(ts, t)
    hi = n
    while lo < hi:
        mid = (lo + hi) // 2
        if t < ts[mid]:
            hi = mid
        else:
            lo = mid + 1
    i = lo - 1
    h = ts[i + 1] - ts[i]
    s = (t - ts[i]) / h
    p0 = rs[i]
    p1 = rs[i + 1]
    v0 = wp[2, i] * h
    v1 = wp[2, i + 1] * h
    a0 = wp[3, i] * h * h
    a1 = wp[3, i + 1] * h * h
    s2 = s * s
    s3 = s * s * s
    s4 = s3 * s
    s5 = s3 * s2
    h00 = 1.0 - 10.0 * s3 + 15.0 * s4 - 6.0 * s5
    h10 = s - 6.0 * s3 + 8.0 * s4 - 3.0 * s5
    h20 = 0.5 * (s2 - 3.0 * s3 + 3.0 * s4 - s5)
    h01 = 10.0 * s3 - 15.0 * s4 + 6.0 * s5
    h11 = -4.0 * s3 + 7.0 * s4 - 3.0 * s5
    h21 = 0.5 * (s3 - 2.0 * s4 + s5)
    d00 = -30.0 * s2 + 60.0 * s3 - 30.0 * s4
    d10 = 1.0 - 18.0 * s2 + 32.0 * s3 - 15.0 * s4
    d20 = 0.5 * (2.0 * s - 9.0 * s2 + 12.0 * s3 - 5.0 * s4)
    d11 = -12.0 * s2 + 28.0 * s3 - 15.0 * s4
    d21 = 0.5 * (3.0 * s2 - 8.0 * s3 + 5.0 * s4)
    e00 = -60.0 * s + 180.0 * s2 - 120.0 * s3
    e10 = -36.0 * s + 96.0 * s2 - 60.0 * s3
    e20 = 0.5 * (2.0 - 18.0 * s + 36.0 * s2 - 20.0 * s3)
    e11 = -24.0 * s + 84.0 * s2 - 60.0 * s3
    e21 = 0.5 * (6.0 * s - 24.0 * s2 + 20.0 * s3)
    r = h00 * p0 + h10 * v0 + h20 * a0 + h01 * p1 + h11 * v1 + h21 * a1
    rd = d00 * p0 + d10 * v0 + d20 * a0 - d00 * p1 + d11 * v1 + d21 * a1
    rdd = e00 * p0 + e10 * v0 + e20 * a0 - e00 * p1 + e11 * v1 + e21 * a1
    return r, rd / h, rdd / (h * h)


@njit(**JIT)
def reference(cp, ci, wp, t):
    """(r, ṙ, r̈) in SI at t s: the axis's reference kind (see the Python classes)."""
    kind = ci[CI_REF_KIND]
    if kind == REF_CONSTANT:
        return cp[CP_REF0], 0.0, 0.0
    if kind == REF_SINE:  # Sine(a, w, c, t0)
        tau = t - cp[CP_REF3]
        if tau <= 0.0:
            return cp[CP_REF2], 0.0, 0.0
        a = cp[CP_REF0]
        w = cp[CP_REF1]
        sn = math.sin(w * tau)
        cs = math.cos(w * tau)
        return cp[CP_REF2] + a * sn, a * w * cs, -a * w * w * sn
    if kind == REF_SMOOTH_STEP:  # SmoothStep(r0, dr, d, t0)
        tau = t - cp[CP_REF3]
        r0 = cp[CP_REF0]
        dr = cp[CP_REF1]
        if tau <= 0.0:
            return r0, 0.0, 0.0
        d = cp[CP_REF2]
        if tau >= d:
            return r0 + dr, 0.0, 0.0
        ph = _TWO_PI * tau / d
        g = dr / d
        return (
            r0 + dr * (tau / d - math.sin(ph) / _TWO_PI),
            g * (1.0 - math.cos(ph)),
            g * (_TWO_PI / d) * math.sin(ph),
        )
    if kind == REF_RAMP:  # Ramp(r0, k, d, t0)
        tau = t - cp[CP_REF3]
        r0 = cp[CP_REF0]
        if tau <= 0.0:
            return r0, 0.0, 0.0
        k = cp[CP_REF1]
        d = cp[CP_REF2]
        if d > 0.0 and tau >= d:
            return r0 + k * d, 0.0, 0.0
        return r0 + k * tau, k, 0.0
    return _waypoints(wp, ci[CI_NWP], t)


@njit(**JIT)
def td_step(v1, v2, x_ref, r, h, T):
    """:meth:`~pneu_control.observers.td.TrackingDifferentiator.step`: returns (v1, v2, v3)."""
    d = r * h
    y = v1 - x_ref + h * v2
    ay = abs(y)
    if ay <= d * h:
        a = v2 + y / h
    else:
        a = v2 + 0.5 * (math.sqrt(d * d + 8.0 * r * ay) - d) * (1.0 if y > 0.0 else -1.0)
    if -d <= a <= d:
        fst = -r * a / d
    else:
        fst = -r if a > 0.0 else r
    return v1 + T * v2, v2 + T * fst, fst  # Eq. 23
