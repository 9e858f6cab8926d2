"""Excitation experiments as data: a fixed schedule of segments per axis, from a seed.

What each segment is for (the parameters it makes identifiable):

``hold``
    the valve at a fixed voltage. At 5 V from rest: the *quiet* segment (sensor
    noise, pressure offsets); after a pulse: a *blocked-valve decay* (centre
    leakage, the chamber volumes and the polytropic index through the slow
    pressure drift, the piston creeping under it).
``pulse``
    an open-loop valve step ``u`` (V) from a base -- or, a *flow ladder*, steps
    through ``ladder`` (V from the base, ``ladder_s`` each) first: from rest
    on the linear axis the valve's curve at known volume, opening by opening,
    until the guard: 5 V on the linear axis
    (from rest at one side: breakaway, valve dead band and flow scale, supply
    pressure, the chamber dynamics), the operating voltage of the previous
    closed-loop segment on the rotary axis (steps of several sizes in both
    directions around an operating speed: J_m, the motor volumes, the
    exhaust throttle, the valve's local gain). A *guard* on the measured
    output (mm or rpm) ends the step early: the linear valve closes (the
    remainder becomes a decay), the rotary valve goes back to its base --
    so the experiment stays inside the soft limits on any plausible plant.
``closed``
    a safe low-gain PID (:class:`ExcitationGains`) tracks a reference:
    ``move`` (quintic to a target), ``ramp`` (constant speed: the friction
    curve, A_f and c_v linear, M_c and M_v rotary), ``chirp`` (log sweep) and
    ``prbs`` (seeded pseudo-random levels) around an operating point.

The schedule is fixed in time (a guard shortens only the active part of a
segment), so a design and its seed say exactly what ran; the design, as
JSON, goes into the bag's metadata (``pneu.excite``). Different seeds give
different pulse orders, amplitudes and PRBS sequences: the held-out bags of
a validation are new experiments, not copies.

Units: positions in mm, speeds in rpm, voltages in V, times in s (the paper's
units, as the controllers' parameters).
"""

from __future__ import annotations

import bisect
import functools
import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from pneu_msgs_py.params.core import ParamError

__all__ = [
    "LEVELS",
    "ExcitationDesign",
    "ExcitationGains",
    "Segment",
    "design_for",
    "design_from_json",
]

LEVELS = ("full", "quick")  # full: <= 2 min per axis; quick: ~40 s (tests, CI)

SEGMENT_KINDS = ("hold", "pulse", "closed")
REFERENCE_KINDS = ("move", "ramp", "chirp", "prbs")


@dataclass(frozen=True)
class Segment:
    """One piece of the schedule (see the module docstring); times relative to the design's start."""

    kind: str
    t0_s: float
    duration_s: float
    label: str
    u: float = 5.0  # hold: the voltage; pulse: the step from the base (V)
    base: str = (
        "neutral"  # pulse base: neutral (5 V) | operating (last closed segment's mean command)
    )
    guard_lo: float = -math.inf  # pulse guard on the measured output (mm | rpm)
    guard_hi: float = math.inf
    ref: dict[str, Any] = field(default_factory=dict)  # closed: {"kind": ..., ...} (mm | rpm)
    ladder: tuple[float, ...] = ()  # pulse: steps from the base (V), each ladder_s long, then u
    ladder_s: float = 0.0

    @property
    def t1_s(self) -> float:
        """End of the segment, s from the start of the design."""
        return self.t0_s + self.duration_s


@dataclass(frozen=True)
class ExcitationGains:
    """The safe low-gain PID of the closed-loop segments (paper units, as ``pid.*``).

    Linear: about half the paper's Kp and Kd, a fifth of its Ki (the paper's
    set tracks on the nominal twin with a wide margin). Rotary: about half of
    ``pneu tune``'s re-tuned PI, whose loop gain at 1600 rpm/V is ≈ 0.4;
    the speed is low-passed (10 ms) against the encoder's 15 rpm quantum.
    """

    kp: float
    ki: float
    kd: float
    y_filter_tf: float


DEFAULT_GAINS = {
    "linear": ExcitationGains(kp=0.2, ki=1.0, kd=0.006, y_filter_tf=0.0),
    "rotary": ExcitationGains(kp=0.0002, ki=0.0025, kd=0.0, y_filter_tf=0.01),
}


@dataclass(frozen=True)
class ExcitationDesign:
    """The schedule of one axis."""

    axis: str
    seed: int
    level: str
    segments: tuple[Segment, ...]
    gains: ExcitationGains

    @property
    def duration_s(self) -> float:
        """The design's length in s (the end of its last segment)."""
        return self.segments[-1].t1_s if self.segments else 0.0

    @functools.cached_property
    def _ends(self) -> tuple[float, ...]:
        return tuple(s.t1_s for s in self.segments)

    def segment_at(self, t: float) -> int:
        """Index of the segment active at ``t`` (s from the start; the last one after the end):
        the first whose end is after ``t``."""
        return min(bisect.bisect_right(self._ends, t), len(self.segments) - 1)

    def make_controller(self, axis: str, sample_time_s: float = 1e-3) -> Any:
        """The per-sample core that runs this design (the runner's hook, ``RunSpec.controllers``)."""
        from pneu_control.sysid.exciter import Exciter

        if axis != self.axis:
            raise ParamError("axis", axis, f"{self.axis} (the design's axis)")
        return Exciter(self, sample_time_s)

    def to_dict(self) -> dict[str, Any]:
        """The design as plain data (infinite guards as ``None``)."""
        d = asdict(self)
        for s in d["segments"]:
            for key in ("guard_lo", "guard_hi"):
                if math.isinf(s[key]):
                    s[key] = None
        return d

    def to_json(self) -> str:
        """The design as JSON (the bag's ``pneu.excite`` record; read back by
        :func:`design_from_json`)."""
        return json.dumps(self.to_dict(), sort_keys=True)


def design_from_json(text: str | dict[str, Any]) -> ExcitationDesign:
    """The inverse of :meth:`ExcitationDesign.to_json` (what a bag's metadata holds)."""
    d = json.loads(text) if isinstance(text, str) else text
    segs = []
    for s in d["segments"]:
        s = dict(s)
        s["guard_lo"] = -math.inf if s.get("guard_lo") is None else s["guard_lo"]
        s["guard_hi"] = math.inf if s.get("guard_hi") is None else s["guard_hi"]
        s["ladder"] = tuple(s.get("ladder", ()))
        segs.append(Segment(**s))
    return ExcitationDesign(
        axis=d["axis"],
        seed=int(d["seed"]),
        level=d["level"],
        segments=tuple(segs),
        gains=ExcitationGains(**d["gains"]),
    )


class _Schedule:
    def __init__(self) -> None:
        self.segments: list[Segment] = []
        self.t = 0.0

    def add(self, kind: str, duration_s: float, label: str, **kw: Any) -> None:
        self.segments.append(Segment(kind, round(self.t, 6), float(duration_s), label, **kw))
        self.t += duration_s


def _flow_ladders(s: _Schedule, rng: np.random.Generator, side: float, stop: float) -> None:
    """Flow ladders (linear axis): from rest at ∓``side`` mm, the valve stepped through a
    ladder of openings until the guard at ±``stop`` mm, then blocked -- the valve's curve
    at known volume, voltage by voltage (the pulses give two to four sizes only)."""
    ladder = [0.3, 0.55, 0.8, 1.0, 1.2, 1.4, 1.7, 2.1, 2.6]
    scale = float(rng.uniform(0.95, 1.05))
    for sign in (1.0, -1.0):
        start = -sign * side
        s.add(
            "closed", 1.2, f"to {start:+.0f} mm", ref={"kind": "move", "target": start, "time": 1.0}
        )
        s.add(
            "pulse",
            1.8,
            f"flow ladder {sign * scale * ladder[0]:+.2f} .. {sign * scale * ladder[-1]:+.2f} V, then blocked",
            u=sign * scale * ladder[-1],
            guard_lo=-stop if sign < 0 else -math.inf,
            guard_hi=stop if sign > 0 else math.inf,
            ladder=tuple(sign * scale * a for a in ladder),
            ladder_s=0.07,
        )


def _linear(seed: int, level: str) -> list[Segment]:
    """Linear axis, x in mm from mid-stroke (soft limits ±65 mm less the braking distance)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 1]))
    full = level == "full"
    s = _Schedule()
    s.add("hold", 1.0, "quiet")  # at rest from x0 = 0: noise, offsets
    side = 40.0  # mm, pulse start positions ±side
    stop = 25.0  # mm, pulse guard: the valve closes once the piston passes ±stop on the far side
    sizes = [0.6, 1.0, 1.6, 2.5] if full else [0.7, 1.6]
    sizes = [float(a * rng.uniform(0.9, 1.1)) for a in rng.permutation(sizes)]
    for a in sizes:
        for sign in (1.0, -1.0):
            start = -sign * side
            s.add(
                "closed",
                1.5 if full else 1.2,
                f"to {start:+.0f} mm",
                ref={"kind": "move", "target": start, "time": 1.0},
            )
            s.add(
                "pulse",
                2.0 if full else 1.6,
                f"pulse {sign * a:+.2f} V, then blocked",
                u=sign * a,
                guard_lo=-stop if sign < 0 else -math.inf,
                guard_hi=stop if sign > 0 else math.inf,
            )
    _flow_ladders(s, rng, side, stop)
    # slow ramps both ways at several speeds (friction curve)
    speeds = [8.0, 20.0, 50.0] if full else [12.0, 40.0]
    s.add("closed", 1.5, "to -45 mm", ref={"kind": "move", "target": -45.0, "time": 1.0})
    for v in speeds:
        v = float(v * rng.uniform(0.9, 1.1))
        for target in (45.0, -45.0):
            s.add(
                "closed",
                90.0 / v + 0.5,
                f"ramp {v:.0f} mm/s to {target:+.0f}",
                ref={"kind": "ramp", "target": target, "speed": v},
            )
    # closed-loop chirp and PRBS about operating points
    centre = float(rng.uniform(-10.0, 10.0))
    s.add("closed", 1.0, "to centre", ref={"kind": "move", "target": centre, "time": 0.8})
    s.add(
        "closed",
        14.0 if full else 6.0,
        "chirp",
        ref={"kind": "chirp", "centre": centre, "amplitude": 8.0, "f0": 0.3, "f1": 4.0},
    )
    for c in [-25.0, 25.0] if full else [20.0]:
        c = float(c + rng.uniform(-5.0, 5.0))
        s.add("closed", 1.0, f"to {c:+.0f} mm", ref={"kind": "move", "target": c, "time": 0.8})
        s.add(
            "closed",
            8.0 if full else 5.0,
            "prbs",
            ref={
                "kind": "prbs",
                "centre": c,
                "amplitude": 6.0,
                "dwell": 0.15,
                "seed": int(rng.integers(1 << 30)),
            },
        )
    s.add("closed", 1.5, "to 0 mm", ref={"kind": "move", "target": 0.0, "time": 1.0})
    s.add("hold", 1.5 if full else 1.0, "blocked at rest")
    return s.segments


def _rotary(seed: int, level: str) -> list[Segment]:
    """Rotary axis, speed in rpm (overspeed trip 1500 rpm: guards at 1350 rpm)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 2]))
    full = level == "full"
    s = _Schedule()
    guard = 1350.0
    s.add("hold", 1.0, "quiet")
    points = [400.0, 800.0, 1150.0] if full else [500.0, 1000.0]
    steps = [0.03, 0.06, 0.12] if full else [0.04, 0.1]
    for w in points:
        w = float(w * rng.uniform(0.95, 1.05))
        s.add("closed", 3.0, f"to {w:.0f} rpm", ref={"kind": "move", "target": w, "time": 1.2})
        for a in rng.permutation(steps):
            a = float(a * rng.uniform(0.9, 1.1))
            for sign in rng.permutation([1.0, -1.0]):
                s.add(
                    "pulse",
                    0.6,
                    f"step {sign * a:+.3f} V at {w:.0f} rpm",
                    u=float(sign * a),
                    base="operating",
                    guard_hi=guard,
                )
                s.add(
                    "pulse", 0.4 if full else 0.3, "back", u=0.0, base="operating", guard_hi=guard
                )
    # coast-downs: valve closed (leakage keeps feeding it) and inlet vented
    for u in [5.0, 3.5] if full else [5.0]:
        s.add("closed", 2.0, "to 1000 rpm", ref={"kind": "move", "target": 1000.0, "time": 1.0})
        s.add("hold", 1.5, f"coast at {u:.1f} V", u=u)
    # slow speed ramps (friction curve)
    s.add("closed", 2.0, "to 250 rpm", ref={"kind": "move", "target": 250.0, "time": 1.2})
    ramp = 8.0 if full else 4.0
    for target in (1250.0, 250.0):
        s.add(
            "closed",
            ramp + 0.5,
            f"ramp to {target:.0f} rpm",
            ref={"kind": "ramp", "target": target, "speed": 1000.0 / ramp},
        )
    centre = float(rng.uniform(700.0, 900.0))
    s.add("closed", 1.5, "to centre", ref={"kind": "move", "target": centre, "time": 1.0})
    s.add(
        "closed",
        10.0 if full else 5.0,
        "chirp",
        ref={"kind": "chirp", "centre": centre, "amplitude": 120.0, "f0": 0.3, "f1": 5.0},
    )
    s.add(
        "closed",
        8.0 if full else 4.0,
        "prbs",
        ref={
            "kind": "prbs",
            "centre": centre,
            "amplitude": 150.0,
            "dwell": 0.2,
            "seed": int(rng.integers(1 << 30)),
        },
    )
    s.add("hold", 1.5, "valve closed", u=5.0)
    return s.segments


def design_for(axis: str, seed: int = 0, level: str = "full") -> ExcitationDesign:
    """The excitation schedule of ``axis`` for ``seed`` (``level`` full: <= 120 s; quick: ~40 s)."""
    if axis not in ("linear", "rotary"):
        raise ParamError("axis", axis, "one of linear, rotary")
    if level not in LEVELS:
        raise ParamError("level", level, "one of " + ", ".join(LEVELS))
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ParamError("seed", seed, "an integer >= 0")
    segs = _linear(int(seed), level) if axis == "linear" else _rotary(int(seed), level)
    return ExcitationDesign(axis, int(seed), level, tuple(segs), DEFAULT_GAINS[axis])
