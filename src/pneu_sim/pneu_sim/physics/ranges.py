"""Uncertain plant values: the range each may take, or its discrete alternatives.

DESIGN §11: values from the paper's Table 1 and datasheets are facts with
tolerances; "estimated" values are guesses with a range. Each uncertain field
of :class:`~pneu_sim.physics.params.PlantParams` declares ``band=(lo, hi)``
(continuous, same unit as the value) or ``alternatives=((label, value), ...)``
(discrete readings, e.g. the supply as gauge or absolute) beside its value, with
the reason in its ``source``. ``config/plant.yaml`` carries them as the optional
leaf keys ``range: [lo, hi]`` and ``alternatives: {label: value, ...}``
(:mod:`pneu_sim.physics.plant_file`); a file without them still loads (no
uncertainty). Sweeps (``pneu sweep``) draw plants from these.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from pneu_msgs_py.params.core import ParamError

__all__ = ["PlantRanges", "check_alternatives", "check_range", "table_ranges"]


@dataclass(frozen=True)
class PlantRanges:
    """Dotted plant names (``rotary.J_m``) -> range or alternatives, in plant field order."""

    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    alternatives: dict[str, tuple[tuple[str, float], ...]] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return bool(self.ranges or self.alternatives)


def _real(x: Any) -> bool:
    return not isinstance(x, bool) and isinstance(x, (int, float)) and math.isfinite(x)


def _allowed(meta: Mapping[str, Any]) -> tuple[str, Any]:
    lo, hi = meta.get("lo"), meta.get("hi")
    left = "(" if meta.get("lo_open") else "["
    right = ")" if meta.get("hi_open") else "]"
    text = (
        f"{left}{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}{right}"
    )

    def ok(v: float) -> bool:
        if lo is not None and (v < lo or (meta.get("lo_open") and v == lo)):
            return False
        return not (hi is not None and (v > hi or (meta.get("hi_open") and v == hi)))

    return text, ok


def check_range(name: str, value: Any, rng: Any, meta: Mapping[str, Any]) -> tuple[float, float]:
    """``range: [lo, hi]`` of leaf ``name``: two numbers, lo < hi, inside the field's
    allowed interval, and holding the value. Returns ``(lo, hi)`` as floats."""
    unit = f" {meta['unit']}" if meta.get("unit") else ""
    if not (isinstance(rng, (list, tuple)) and len(rng) == 2 and all(_real(v) for v in rng)):
        raise ParamError(f"{name}.range", rng, f"[lo, hi], two finite numbers in{unit}")
    lo, hi = float(rng[0]), float(rng[1])
    text, ok = _allowed(meta)
    if not lo < hi or not (ok(lo) and ok(hi)):
        raise ParamError(f"{name}.range", [lo, hi], f"lo < hi, both in {text}{unit}")
    if _real(value) and ok(value) and not lo <= value <= hi:  # a bad value: its own error
        raise ParamError(
            f"{name}.range", [lo, hi], f"an interval holding the value {value:g}{unit}"
        )
    return lo, hi


def check_alternatives(
    name: str, value: Any, alts: Any, meta: Mapping[str, Any]
) -> tuple[tuple[str, float], ...]:
    """``alternatives: {label: value, ...}``: at least two distinct readings, each in
    the field's allowed interval, one of them the value."""
    text, ok = _allowed(meta)
    unit = f" {meta['unit']}" if meta.get("unit") else ""
    need = f"a mapping label: value of >= 2 distinct numbers in {text}{unit}, one of them the value"
    if not isinstance(alts, Mapping) or len(alts) < 2:
        raise ParamError(f"{name}.alternatives", alts, need)
    out = []
    for label, v in alts.items():
        if not (isinstance(label, str) and label.strip() and _real(v) and ok(float(v))):
            raise ParamError(f"{name}.alternatives.{label}", v, need)
        out.append((label, float(v)))
    values = [v for _, v in out]
    if len(set(values)) != len(values) or (_real(value) and ok(value) and value not in values):
        raise ParamError(f"{name}.alternatives", dict(alts), need)
    return tuple(out)


def table_ranges(p: Any | None = None) -> PlantRanges:
    """The ranges and alternatives declared in the parameter table, for the values of ``p``.

    Where a value of ``p`` lies outside its declared band (an identified plant),
    the band moves with it: scaled by value / table default, so it keeps its
    relative width (the uncertainty of the source), clipped to the allowed
    interval. Alternatives that do not hold the value are left out.
    """
    from pneu_sim.physics.params import PlantParams

    p = p if p is not None else PlantParams()
    out = PlantRanges()
    _collect(p, type(p)(), "", out)
    return out


def _collect(obj: Any, default: Any, prefix: str, out: PlantRanges) -> None:
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        name = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(v):
            _collect(v, getattr(default, f.name), f"{name}.", out)
            continue
        band, alts = f.metadata.get("band"), f.metadata.get("alternatives")
        if band is not None:
            lo, hi = band
            if not lo <= v <= hi:
                d = getattr(default, f.name)
                scale = v / d if d else math.nan
                lo, hi = _clip(f.metadata, lo * scale, hi * scale)
            if lo < hi and all(map(_allowed(f.metadata)[1], (lo, hi))):
                out.ranges[name] = (float(lo), float(hi))
        if alts is not None and any(a == v for _, a in alts):
            out.alternatives[name] = tuple((label, float(a)) for label, a in alts)


def _clip(meta: Mapping[str, Any], lo: float, hi: float) -> tuple[float, float]:
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return math.nan, math.nan
    if meta.get("lo") is not None:
        lo = max(lo, meta["lo"])
    if meta.get("hi") is not None:
        hi = min(hi, meta["hi"])
    return lo, hi
