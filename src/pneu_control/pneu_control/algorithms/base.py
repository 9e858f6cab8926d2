"""The one interface every control algorithm implements.

Algorithms work in the paper's units (DESIGN §5): y in mm (linear position)
or rpm (rotary speed), the reference as (r, ṙ, r̈) in the same units, the
command as the valve-voltage deviation from the neutral 5 V (V). The
:class:`~pneu_control.axis.AxisController` converts SI at its boundary, runs
the tracking differentiator when ``uses_td`` and adds the neutral voltage.

Per sample the controller calls exactly one of

- ``start(y, r, r_dot, r_ddot, u_prev, y_dot_hint) -> u`` -- first sample of
  this algorithm: initialise the states from the measurement. With
  ``u_prev = None`` (cold start) the disturbance estimate/integral start at
  zero; with ``u_prev`` (a run-time switch, or a parameter change) they are
  chosen so that the returned command equals ``u_prev``: bumpless.
- ``update(y, r, r_dot, r_ddot, u_applied) -> u`` -- every later sample.
  ``u_applied`` is the (saturated) deviation that was on the valve during
  the last sample period (the ESO predicts with it).

Both return the saturated deviation and leave readable attributes:
``z1, z2, z3`` (observer states, NaN if none), ``s`` (sliding variable, NaN
if none), ``u_raw`` (unsaturated deviation), ``y_dot_est`` (the algorithm's
own estimate of ẏ, used as the hint of the next algorithm on a switch).
"""

from __future__ import annotations

from typing import Protocol

__all__ = ["Algorithm", "NAN"]

NAN = float("nan")


class Algorithm(Protocol):
    name: str
    uses_td: bool
    z1: float
    z2: float
    z3: float
    s: float
    u_raw: float

    @property
    def y_dot_est(self) -> float: ...

    def start(
        self,
        y: float,
        r: float,
        r_dot: float,
        r_ddot: float,
        u_prev: float | None,
        y_dot_hint: float,
    ) -> float: ...

    def update(
        self, y: float, r: float, r_dot: float, r_ddot: float, u_applied: float
    ) -> float: ...
