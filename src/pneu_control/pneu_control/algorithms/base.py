"""The one interface every control algorithm implements.

Algorithms work in the paper's units (DESIGN §5): y in mm (linear position)
or rpm (rotary speed), the reference as (r, ṙ, r̈) in the same units, the
command as the valve-voltage deviation from the neutral 5 V (V). The
:class:`~pneu_control.controller.axis.AxisController` converts SI at its boundary, runs
the tracking differentiator when ``uses_td`` and adds the neutral voltage.

Per sample the controller calls exactly one of

- ``start(y, r, r_dot, r_ddot, u_prev, u_applied, hint) -> u`` -- first
  sample of this algorithm. ``u_prev`` is None on a cold start (states from
  the measurement, disturbance estimate and integral zero); on a run-time
  switch or parameter change it is the last command, ``u_applied`` the one on
  the valve during the last period and ``hint = (y, ẏ, ÿ)`` the previous
  algorithm's estimates (NaN if it had none). The states are initialised
  *physically consistently* (z3 = ÿ − b0 u_applied, assuming ÿ = 0 when
  unknown); PID chooses its integral so that its output equals ``u_prev``.
  Whatever difference remains between the returned command and ``u_prev`` is
  blended out by the controller (a decaying offset, ``bumpless_time_s``), so
  the valve command never jumps.
- ``update(y, r, r_dot, r_ddot, u_applied) -> u`` -- every later sample.
  ``u_applied`` is the (saturated) deviation that was on the valve during
  the last sample period (the ESO predicts with it).

Both return the saturated deviation and leave readable attributes:
``z1, z2, z3`` (observer states, NaN if none), ``s`` (sliding variable, NaN
if none), ``u_raw`` (unsaturated deviation) and ``hint`` (its estimates
(y, ẏ, ÿ), handed to the next algorithm on a switch). ``pending`` is the
controller's command history in V, oldest first (the command on the valve
during the last period, then the d commands in the transport pipeline); the
controller attaches it and updates it in place.
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
    pending: list[float]

    @property
    def hint(self) -> tuple[float, float, float]: ...

    def start(
        self,
        y: float,
        r: float,
        r_dot: float,
        r_ddot: float,
        u_prev: float | None,
        u_applied: float,
        hint: tuple[float, float, float],
    ) -> float: ...

    def update(
        self, y: float, r: float, r_dot: float, r_ddot: float, u_applied: float
    ) -> float: ...
