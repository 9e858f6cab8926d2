"""The one interface every control algorithm implements, and its per-step input.

Algorithms work in the paper's units (DESIGN §5): y in mm (linear position)
or rpm (rotary speed), the reference as (r, ṙ, r̈) in the same units, the
command as the valve-voltage deviation from the neutral 5 V (V). The
:class:`~pneu_control.controller.axis.AxisController` converts SI at its
boundary, runs the tracking differentiator when ``uses_td``, fills one
:class:`StepInput` per sample and adds the neutral voltage to the result.

Per sample the controller calls exactly one of

- ``start(inp, u_prev, hint) -> u`` -- first sample of this algorithm.
  ``u_prev`` is None on a cold start (states from the measurement,
  disturbance estimate and integral zero); on a run-time switch or parameter
  change it is the last command, ``inp.u_applied`` the one on the valve
  during the last period and ``hint = (y, ẏ, ÿ)`` the previous algorithm's
  estimates (NaN if it had none). The states are initialised *physically
  consistently* (z3 = ÿ − b0 u_applied, assuming ÿ = 0 when unknown); PID
  chooses its integral so that its output equals ``u_prev``. Whatever
  difference remains between the returned command and ``u_prev`` is blended
  out by the controller (a decaying offset, ``bumpless_time_s``), so the
  valve command never jumps.
- ``update(inp) -> u`` -- every later sample.

Both return the saturated deviation and leave readable attributes:
``z1, z2, z3`` (observer states, NaN if none), ``s`` (sliding variable, NaN
if none), ``u_raw`` (unsaturated deviation) and ``hint`` (its estimates
(y, ẏ, ÿ), handed to the next algorithm on a switch). The flags
``uses_td``, ``uses_theta`` and ``uses_pressures`` say which inputs the
algorithm reads; the controller fills ``theta`` and checks it only for an
algorithm that reads it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

__all__ = ["Algorithm", "NAN", "StepInput"]

NAN = float("nan")


@dataclass(slots=True)
class StepInput:
    """One sample's input to an algorithm (paper units). Filled in place by the controller.

    ``y``, ``r``, ``r_dot``, ``r_ddot``: measurement and reference with its
    derivatives (mm or rpm; with ``rotary_model: angle`` and a TD algorithm,
    the angle θ and θ_r in rpm·s). ``u_applied``: the saturated deviation on
    the valve during the last sample period (V; the ESO predicts with it).
    ``history``: the commands in V, oldest first -- the one on the valve
    during the last period, then the ``transport_delay_samples`` commands
    already sent but not yet applied (the controller's own list: read only).
    ``theta``: encoder angle in rpm·s (``uses_theta``). ``p_c1``, ``p_c2``:
    chamber pressures in Pa absolute (``uses_pressures``).
    """

    y: float = 0.0
    r: float = 0.0
    r_dot: float = 0.0
    r_ddot: float = 0.0
    u_applied: float = 0.0
    history: list[float] = field(default_factory=list)
    theta: float = NAN
    p_c1: float = NAN
    p_c2: float = NAN


class Algorithm(Protocol):
    name: str
    uses_td: bool
    uses_theta: bool
    uses_pressures: bool
    z1: float
    z2: float
    z3: float
    s: float
    u_raw: float

    @property
    def hint(self) -> tuple[float, float, float]: ...

    def start(
        self, inp: StepInput, u_prev: float | None, hint: tuple[float, float, float]
    ) -> float: ...

    def update(self, inp: StepInput) -> float: ...
