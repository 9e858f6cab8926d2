"""Plant samples for a sweep: the uncertain values of plant.yaml drawn by a seeded design.

Each range ``[lo, hi]`` of :class:`pneu_sim.physics.ranges.PlantRanges` is one
continuous factor, drawn uniformly. Alternatives with the same labels are one
discrete factor (``supply[gauge|absolute]`` sets both supplies at once: whoever
read one regulator as gauge read the other so too), each label equally likely.
The unit-cube design is a Latin hypercube (default; every factor's range cut
into N equal strata, one sample in each) or a scrambled Sobol sequence
(:mod:`scipy.stats.qmc`, ``rng=`` a seeded generator, scipy >= 1.15): the same
seed gives the same points. Points are drawn here, in the driver, never in a
worker, and stored with the results.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from pneu_msgs_py.params.core import ParamError, flatten, with_updates

__all__ = ["METHODS", "Factor", "draw_points", "factors_of", "plant_of"]

METHODS = ("lhs", "sobol")


@dataclass(frozen=True)
class Factor:
    """One sampled dimension: a continuous range, or a discrete choice of labelled readings."""

    name: str  # table column: the dotted plant name, or "<group>[label|label]"
    keys: tuple[str, ...]  # plant values it sets
    lo: float = math.nan  # continuous
    hi: float = math.nan
    labels: tuple[str, ...] = ()  # discrete
    values: tuple[tuple[float, ...], ...] = ()  # per label: one value per key

    @property
    def discrete(self) -> bool:
        """Is this a choice among labelled readings (not a continuous range)?"""
        return bool(self.labels)

    def value(self, u: float) -> float | str:
        """The factor's value at unit coordinate ``u`` in [0, 1)."""
        if self.discrete:
            return self.labels[min(int(u * len(self.labels)), len(self.labels) - 1)]
        return self.lo + u * (self.hi - self.lo)

    def updates(self, v: float | str) -> dict[str, float]:
        """Dotted plant updates for value ``v`` of this factor."""
        if self.discrete:
            vals = self.values[self.labels.index(str(v))]
            return dict(zip(self.keys, vals))
        return {self.keys[0]: float(v)}

    def code(self, v: float | str) -> float:
        """A number for rank statistics: the value, or the label's index."""
        return float(self.labels.index(str(v))) if self.discrete else float(v)


def _common_prefix(keys: list[str]) -> str:
    parts = [k.split(".")[:-1] for k in keys]
    out = []
    for level in zip(*parts):
        if len(set(level)) != 1:
            break
        out.append(level[0])
    return ".".join(out) or "plant"


def factors_of(ranges: Any, plant: Any) -> list[Factor]:
    """Factors of a :class:`PlantRanges`, in the plant's field order."""
    order = {k: i for i, k in enumerate(flatten(plant))}
    factors: list[tuple[int, Factor]] = []
    for key, (lo, hi) in ranges.ranges.items():
        factors.append((order[key], Factor(name=key, keys=(key,), lo=lo, hi=hi)))
    groups: dict[tuple[str, ...], list[str]] = {}
    for key, alts in ranges.alternatives.items():
        groups.setdefault(tuple(label for label, _ in alts), []).append(key)
    for labels, keys in groups.items():
        keys = sorted(keys, key=order.__getitem__)
        values = tuple(tuple(dict(ranges.alternatives[k])[label] for k in keys) for label in labels)
        name = f"{_common_prefix(keys)}[{'|'.join(labels)}]"
        factors.append(
            (order[keys[0]], Factor(name=name, keys=tuple(keys), labels=labels, values=values))
        )
    return [f for _, f in sorted(factors, key=lambda x: x[0])]


def unit_design(d: int, n: int, seed: int, method: str = "lhs") -> np.ndarray:
    """(n, d) points in [0, 1)^d: Latin hypercube or scrambled Sobol, seeded."""
    from scipy.stats import qmc

    if method not in METHODS:
        raise ValueError(f"sampler: {method!r} refused; allowed: one of {', '.join(METHODS)}")
    if n < 1:
        raise ValueError(f"samples: {n} refused; allowed: an integer >= 1")
    if d == 0:
        return np.zeros((n, 0))
    rng = np.random.default_rng(seed)
    if method == "lhs":
        return qmc.LatinHypercube(d, rng=rng).random(n)
    m = max(0, math.ceil(math.log2(n)))  # Sobol in powers of 2 (balance); the first n points
    return qmc.Sobol(d, rng=rng).random_base2(m)[:n]


def draw_points(
    factors: list[Factor], n: int, seed: int, method: str = "lhs"
) -> list[dict[str, float | str]]:
    """``n`` samples: per sample, factor name -> value (float or label)."""
    u = unit_design(len(factors), n, seed, method)
    return [{f.name: f.value(float(u[i, j])) for j, f in enumerate(factors)} for i in range(n)]


def plant_of(nominal: Any, factors: list[Factor], point: dict[str, float | str]) -> Any:
    """The nominal PlantParams with a sample's values (validated as one set)."""
    updates: dict[str, float] = {}
    for f in factors:
        updates.update(f.updates(point[f.name]))
    try:
        return with_updates(nominal, updates)
    except ParamError as err:  # a combination the plant refuses (e.g. r_m >= R_m)
        raise ParamError(err.key, err.value, f"{err.allowed} (a sample of the ranges)") from None
