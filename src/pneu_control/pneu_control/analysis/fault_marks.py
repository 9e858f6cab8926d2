"""Fault intervals of a run: where faults were injected and where an axis was held safe.

Shared by the runner (its metrics) and :mod:`pneu_control.analysis.run_analysis` (a bag's
metrics), so both exclude exactly the same samples.

Two sources:

- *injected*: the run's fault specs (config echo ``faults``), active from
  k0·T to k1·T (:mod:`pneu_sim.faults.injection` rounds to samples);
- *safe*: the safety supervisor's transitions on ``/diagnostics``: an ERROR
  for an axis (or ``all``) starts a safe interval; an OK ``acknowledge`` or
  ``reset`` ends it; otherwise it lasts to the end of the run (faults latch).
  A WARN (soft limit, a fault condition gone but still latched) changes
  nothing. Status names follow ``<node>: safety <axis> <rule>`` (driver,
  sim node and runner alike).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

__all__ = [
    "FaultInterval",
    "diag_name",
    "exclusion_mask",
    "injected_intervals",
    "parse_safety_status",
    "safe_intervals",
]

_AXES = ("linear", "rotary")
_NAME = re.compile(r"safety (linear|rotary|all) (\w+)$")


@dataclass(frozen=True)
class FaultInterval:
    """``axis`` affected from ``start_s`` to ``end_s`` (s since the run's first sample; inf = to the end)."""

    axis: str
    start_s: float
    end_s: float
    kind: str  # "injected" | "safe"
    cause: str

    def to_dict(self) -> dict[str, Any]:
        """Plain data for JSON (an open end as ``None``)."""
        d = asdict(self)
        d["end_s"] = None if math.isinf(self.end_s) else self.end_s
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FaultInterval:
        """The interval of :meth:`to_dict`'s output (``end_s`` None: open to the run's end)."""
        end = d.get("end_s")
        return cls(
            d["axis"],
            float(d["start_s"]),
            math.inf if end is None else float(end),
            d["kind"],
            d["cause"],
        )


def diag_name(node: str, axis: str, rule: str) -> str:
    """The DiagnosticStatus name of a supervisor transition."""
    return f"{node}: safety {axis} {rule}"


def parse_safety_status(name: str) -> tuple[str, str] | None:
    """(axis, rule) of a supervisor status name, None for other statuses."""
    m = _NAME.search(name)
    return (m.group(1), m.group(2)) if m else None


def injected_intervals(
    faults: Iterable[dict[str, Any]], active_axes: Iterable[str], period_s: float
) -> list[FaultInterval]:
    """Intervals of the injected faults (dicts as ``FaultSpec.to_dict`` gives them)."""
    from pneu_sim.faults.injection import FaultSpec

    active = tuple(active_axes)
    out = []
    for d in faults:
        f = FaultSpec.from_dict(d)
        k0 = int(round(f.start_s / period_s))
        k1 = k0 + max(1, int(round(f.duration_s / period_s)))
        for axis in f.axes(active):
            out.append(FaultInterval(axis, k0 * period_s, k1 * period_s, "injected", f.label))
    return out


def safe_intervals(
    events: Iterable[tuple[int, str, str, int | str, str]], t0_ns: int = 0
) -> list[FaultInterval]:
    """Safe intervals from supervisor transitions ``(stamp_ns, axis, rule, level, message)``.

    ``level``: 0/1/2 or OK/WARN/ERROR. Events must be in time order.
    """
    level_of = {"OK": 0, "WARN": 1, "ERROR": 2}
    open_: dict[str, tuple[float, str]] = {}
    out = []
    for stamp_ns, axis, rule, level, message in events:
        lvl = level_of.get(level, level) if isinstance(level, str) else int(level)
        t = (int(stamp_ns) - t0_ns) * 1e-9
        targets = _AXES if axis == "all" else (axis,)
        if lvl >= 2:
            for a in targets:
                if a not in open_:
                    open_[a] = (t, f"{rule}: {message}")
        elif lvl == 0 and rule in ("acknowledge", "reset"):
            for a in targets:
                if a in open_:
                    start, cause = open_.pop(a)
                    out.append(FaultInterval(a, start, t, "safe", cause))
    for a, (start, cause) in open_.items():
        out.append(FaultInterval(a, start, math.inf, "safe", cause))
    return sorted(out, key=lambda iv: (iv.start_s, iv.axis))


def exclusion_mask(
    t: np.ndarray, intervals: Iterable[FaultInterval], axis: str
) -> np.ndarray | None:
    """Samples of ``axis`` (times ``t``, s since the first sample) inside any interval; None if none."""
    mask = None
    half = 0.5 * float(t[1] - t[0]) if len(t) > 1 else 0.0
    for iv in intervals:
        if iv.axis != axis:
            continue
        m = (t >= iv.start_s - half) & (t < iv.end_s - half)
        mask = m if mask is None else (mask | m)
    return mask
