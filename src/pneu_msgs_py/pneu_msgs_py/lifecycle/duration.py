"""The one duration cap of every command (``pneu run``, ``pneu sim``, the experiments).

A run holds its time series in memory (preallocated for the capped duration)
and streams its bag, so the cap bounds memory and disk: at 1 kHz, 600 s are
600 000 samples, about 170 MB of float64 series for both axes and about
0.4 GB of bag. The lower bound is ten control periods, so that every run has
a first sample, a command and a metric.
"""

from __future__ import annotations

import math

from pneu_msgs_py.params.core import ParamError

__all__ = ["MAX_DURATION_S", "MIN_DURATION_S", "check_duration"]

MAX_DURATION_S = 600.0
MIN_DURATION_S = 0.01


def check_duration(value: object, field: str = "--duration") -> float:
    """``value`` as seconds in [MIN_DURATION_S, MAX_DURATION_S]; else :class:`ParamError` naming ``field``."""
    allowed = f"[{MIN_DURATION_S:g}, {MAX_DURATION_S:g}] s (the duration cap of every pneu command)"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParamError(field, value, f"a number of seconds, {allowed}")
    v = float(value)
    if not (math.isfinite(v) and MIN_DURATION_S <= v <= MAX_DURATION_S):
        raise ParamError(field, value, allowed)
    return v
