"""What the sliding-mode laws share (ESO-SMC and ESO-SMC+): sat, the ∫e step, the gain fields.

Surface and reaching law (paper Eq. 26–29, fixed per errata)::

    s = ė + 2 λ e + λ² ∫e dt,      ṡ = −ε sat(s),
    sat(s) = sign(s) for |s| > Δ,  k s inside            (Eq. 29)

Each gain field is declared once here (unit, range, description) and used by
every parameter group that has it, with the group's own default and source.
"""

from __future__ import annotations

from typing import Any

from pneu_msgs_py.params.core import param
from pneu_msgs_py.params.records import kernel

__all__ = [
    "POSITIVE",
    "NONNEGATIVE",
    "b_0_field",
    "conditional_integral",
    "delay_compensation_field",
    "delta_field",
    "epsilon_field",
    "k_field",
    "lambda_r_field",
    "omega_0_field",
    "reaching_command",
    "sat",
    "sliding_surface",
]

POSITIVE = {"lo": 0.0, "lo_open": True}  # strictly positive
NONNEGATIVE = {"lo": 0.0}


@kernel
def sat(s: float, delta: float, k: float) -> float:
    """Eq. 29: sign(s) outside the boundary layer |s| > Δ, k s inside."""
    if s > delta:
        return 1.0
    if s < -delta:
        return -1.0
    return k * s


@kernel
def sliding_surface(e: float, ed: float, integral: float, c1: float, c2: float) -> float:
    """Eq. 26 (fixed, errata: a double pole at −λ): s = ė + c1 e + c2 ∫e, c1 = 2λ, c2 = λ²."""
    return ed + c1 * e + c2 * integral


@kernel
def surface_step(c, s, r: float, r_dot: float, z1: float, z2: float):
    """Eq. 26 on the observer's estimates: (e, ė, ∫e after this sample, s), with s stored in
    the state ``s.s``; whether the integral is kept is the caller's (conditional integration).
    Reads ``c.T``, ``c.c1``, ``c.c2`` and ``s.integral``."""
    e = r - z1
    ed = r_dot - z2
    integral = s.integral + c.T * e
    sv = sliding_surface(e, ed, integral, c.c1, c.c2)
    s.s = sv
    return e, ed, integral, sv


@kernel
def reaching_command(
    sv: float, e: float, ed: float, r_ddot: float, c1: float, c2: float,
    eps: float, delta: float, k: float,
) -> float:  # fmt: skip
    """Eq. 29–30 (fixed): the second derivative that makes ṡ = −ε sat(s):
    ε sat(s) + r̈ + c1 ė + c2 e (the law subtracts the disturbance estimate and divides by b0)."""
    return eps * sat(sv, delta, k) + r_ddot + c1 * ed + c2 * e


@kernel
def conditional_integral(
    integral: float,
    integral_next: float,
    e: float,
    u: float,
    s: float,
    lo: float,
    hi: float,
    delta: float,
) -> float:
    """∫e after one rectangle step, unless e pushes further into a saturation.

    The step is skipped (``integral`` kept) while e > 0 and the command is
    above ``hi`` or the reaching law saturated (s > Δ), and symmetrically
    for e ≤ 0: conditional integration, see :mod:`.eso_smc`.
    """
    if e > 0.0:
        return integral if (u > hi or s > delta) else integral_next
    return integral if (u < lo or s < -delta) else integral_next


def lambda_r_field(default: float, source: str = "") -> Any:
    return param(
        default, unit="1/s", desc="sliding surface pole λ_R (double)", **POSITIVE, source=source
    )


def omega_0_field(default: float, source: str = "", desc: str = "observer bandwidth ω0") -> Any:
    return param(
        default,
        unit="rad/s",
        desc=desc,
        **POSITIVE,
        source=source,
        # the upper bound depends on the controller's period (AxisControllerParams._check)
        allowed="(0, π/sample_time_s] rad/s: up to the Nyquist frequency (3141.59 rad/s at "
        "the paper's T = 1 ms)",
    )


def b_0_field(default: float, source: str = "", desc: str = "input gain estimate b0") -> Any:
    return param(default, unit="mm/s²/V | rpm/s²/V", desc=desc, **POSITIVE, source=source)


def epsilon_field(default: float, source: str = "") -> Any:
    return param(
        default,
        unit="mm/s² | rpm/s²",
        desc="reaching-law gain ε (Eq. 28)",
        **POSITIVE,
        source=source,
    )


def delta_field(default: float, source: str = "") -> Any:
    return param(
        default,
        unit="mm/s | rpm/s",
        desc="boundary layer half-width Δ (Eq. 29)",
        **POSITIVE,
        source=source,
    )


def k_field(default: float, source: str = "") -> Any:
    return param(
        default,
        unit="s/mm | s/rpm",
        desc="slope of sat inside the layer (Eq. 29); continuous only for k = 1/Δ",
        **POSITIVE,
        source=source,
    )


def delay_compensation_field() -> Any:
    return param(
        False,
        desc="predict the ESO state over the transport delay with the commands already sent "
        "and act on the prediction (not in the paper)",
    )
