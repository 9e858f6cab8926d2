"""What the two angle laws share: the phase switch, the encoder's still counter, the fields
of the same meaning.

:mod:`.coast` (the paper's plumbing: drive one way, coast to a stop) and :mod:`.pva` (the
bidirectional plumbing: drive and brake both ways) are different laws, but both are state
machines that act on the encoder angle at rest and tap the rest with pulses; what they
mean alike is written here once.
"""

from __future__ import annotations

from typing import Any

from pneu_msgs_py.params.core import param
from pneu_msgs_py.params.records import kernel

from pneu_control.algorithms.smc import POSITIVE

__all__ = ["DEG_PER_S_PER_RPM", "pulse_step_field", "still_field", "tick", "to_phase"]

DEG_PER_S_PER_RPM = 6.0  # 1 rpm = 360°/60 s


@kernel
def to_phase(s, phase):
    """Into ``phase``; its sample count ``k_phase`` starts again."""
    s.phase = phase
    s.k_phase = 0


@kernel
def tick(s, y):
    """One sample: ``k_still`` counts the samples the encoder angle y has not changed
    (0 on a change, then y is the new ``y_last``), ``k_phase`` those in the phase."""
    if y != s.y_last:
        s.k_still = 0
        s.y_last = y
    else:
        s.k_still += 1
    s.k_phase += 1


def still_field(default: float, desc: str, source: str) -> Any:
    """``still_s``: at rest once the encoder is unchanged this long (n_still T)."""
    return param(default, unit="s", desc=f"n_still T: {desc}", **POSITIVE, source=source)


def pulse_step_field(default: float, source: str) -> Any:
    """``pulse_step_deg``: the first estimate of the smallest pulse step, learnt from then."""
    return param(
        default,
        unit="°",
        desc="d_min: first estimate of the smallest pulse step (learnt)",
        **POSITIVE,
        source=source,
    )
