"""Tracking differentiator (paper Eq. 23–24; fhan of Han 2009, printed correctly).

Discrete second-order time-optimal tracker of the reference x_ref::

    v1(k+1) = v1(k) + T v2(k)                                   # Eq. 23
    v2(k+1) = v2(k) + T fst(v1(k), v2(k), x_ref(k), r, h)

with fst = fhan (Eq. 24). ``r`` bounds |dv2/dt| (units of the reference per
s²), ``h`` is the filter factor h0 (h = T gives the fastest overshoot-free
approach; h > T smooths more). v3 = fst is the reference acceleration the
ESO-SMC law uses (Eq. 30, ẍ_r).

Units: whatever the reference is in (the controllers use mm or rpm).
"""

from __future__ import annotations

import math

from pneu_msgs_py.params.records import kernel

__all__ = ["fhan", "td_step", "TrackingDifferentiator"]


def fhan(x1: float, x2: float, u: float, r: float, h: float) -> float:
    """Han's time-optimal synthesis function, Eq. 24 (x1 = v1, x2 = v2, u = x_ref)."""
    d = r * h
    d0 = d * h
    y = x1 - u + h * x2
    a0 = math.sqrt(d * d + 8.0 * r * abs(y))
    if abs(y) <= d0:
        a = x2 + y / h
    else:
        a = x2 + 0.5 * (a0 - d) * math.copysign(1.0, y)
    if abs(a) <= d:
        return -r * a / d
    return -r * math.copysign(1.0, a)


class TrackingDifferentiator:
    """State (v1, v2) of Eq. 23 plus v3 = the last fst; see module docstring.

    ``step(x_ref)`` advances one sample and returns nothing; read v1, v2, v3.
    The values after the step are used at this sample (Han's ADRC ordering).
    """

    __slots__ = ("T", "h", "r", "v1", "v2", "v3")

    def __init__(self, r: float, h: float, T: float):
        if not (r > 0.0 and h > 0.0 and T > 0.0):
            raise ValueError(f"TD needs r, h, T > 0 (got r={r!r}, h={h!r}, T={T!r})")
        self.r, self.h, self.T = float(r), float(h), float(T)
        self.v1 = self.v2 = self.v3 = 0.0

    def reset(self, v1: float, v2: float = 0.0) -> None:
        self.v1, self.v2, self.v3 = float(v1), float(v2), 0.0

    def step(self, x_ref: float) -> None:
        self.v1, self.v2, self.v3 = td_step(self.v1, self.v2, x_ref, self.r, self.h, self.T)


@kernel
def td_step(v1, v2, x_ref, r, h, T):
    """One sample of Eq. 23 with fhan (Eq. 24) inlined: returns (v1, v2, v3 = fst)."""
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
