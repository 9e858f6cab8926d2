"""A task: a declarative motion program of both joints, read and checked before anything runs.

A task file (YAML, read by the one strict reader :mod:`pneu_msgs_py.params.yaml_file`)::

    name: coupling_insert_lock
    description: insert a coupling 40 mm, then lock it with a 90° turn
    plumbing: bidirectional          # the twin's rotary plumbing (paper | bidirectional); optional
    controllers:                     # dotted overrides of config/controllers.yaml, per axis
      rotary: {algorithm: ladrc}
    loads: {T_bk: 0.05}              # the twin's loads at the start (load.* fields of plant.yaml)
    limits: {angle_min_deg: -720, angle_max_deg: 720}   # optional: the angles the tool tolerates
    segments:
      - move: {to_mm: 40, speed_mm_s: 40}
        until: {settled: {tol_mm: 0.5, for_s: 0.05}}
        timeout_s: 3
        on_timeout: abort            # abort (default) | continue
      - rotate: {by_deg: 90, speed_rpm: 60}
      - spin: {speed_rpm: 300, duration_s: 2}
      - screw: {pitch_mm: 1.5, turns: 3, rate_turns_s: 1}
      - dwell: {duration_s: 0.5}
      - wait: {}
        until: {pressure: {sensor: p_c1, above_kpa: 400}}
        load: {T_bk: 0.0}            # loads changed when the segment starts

Segments (targets chain: a segment starts where the previous one's reference ended):

- ``move``: the rod to ``to_mm`` (absolute) or by ``by_mm``, at peak ``speed_mm_s`` or in
  ``duration_s`` (Eq. 38's smooth step: peak speed 2Δ/D);
- ``rotate``: the rotary angle to ``to_deg`` or by ``by_deg`` or ``turns``, at peak
  ``speed_rpm`` or in ``duration_s`` (smooth step on the angle);
- ``spin``: turn at ``speed_rpm`` for ``duration_s`` (smooth speed ramps of
  min(0.25 s, duration/3) inside it), then hold;
- ``screw``: helix of ``pitch_mm`` per turn over ``turns`` at ``rate_turns_s``
  (:func:`pneu_control.controller.trajectory.screw`); both joints move together;
- ``dwell``: hold for ``duration_s``; ``wait``: hold until its ``until`` holds.

``until`` (what ends a segment; default: ``settled`` for move, rotate, screw; the planned
time for spin and dwell): ``settled`` -- both joints within ``tol_mm`` / ``tol_deg`` of
the segment's targets for ``for_s`` after its motion; ``pressure`` -- a sensor (p_c1,
p_c2, p_m1) ``above_kpa`` or ``below_kpa`` (absolute); ``force`` -- the rod force of
the chamber pressures (p_c1 A_c1 − p_c2 A_c2 − p_a (A_c1 − A_c2)) ``above_n`` or
``below_n``; ``time`` -- the planned duration. ``timeout_s`` (default: the planned
duration + 2 s) and ``on_timeout``: ``abort`` ends the task (valves safe), ``continue``
goes on with the next segment, the segment reported not reached.

Every check runs before anything is written, each refusal one line naming the segment
and the field: the rod inside the supervisor's soft limits, speeds within its limits,
the angle inside ``limits`` (and within the paper plumbing's one direction), a timeout
no shorter than the motion it bounds, every motion and timeout, and all the timeouts
together, within the duration cap of a run (:data:`MAX_TASK_S`), a settled tolerance
narrower than the stroke or a turn, no ``reference.*`` among the controllers' overrides.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pneu_msgs_py.contract.units import DEG_PER_RAD, MM_PER_M
from pneu_msgs_py.lifecycle.duration import MAX_DURATION_S
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.yaml_file import load_yaml

__all__ = [
    "KINDS",
    "MAX_TASK_S",
    "SAFE_TAIL_S",
    "SPIN_RAMP_S",
    "Segment",
    "TaskProgram",
    "load_task",
    "parse_task",
]

KINDS = ("move", "rotate", "spin", "screw", "dwell", "wait")
CONDITIONS = ("settled", "pressure", "force", "time")
SENSORS = ("p_c1", "p_c2", "p_m1")
DEG_S_PER_RPM = 6.0  # 1 rpm = 360°/60 s
SPIN_RAMP_S = 0.25  # s: a spin reaches its speed (and leaves it) over min(this, duration/3)
_MOTION_FIELDS = {
    "move": {"to_mm", "by_mm", "speed_mm_s", "duration_s"},
    "rotate": {"to_deg", "by_deg", "turns", "speed_rpm", "duration_s"},
    "spin": {"speed_rpm", "duration_s"},
    "screw": {"pitch_mm", "turns", "rate_turns_s", "ramp_s"},
    "dwell": {"duration_s"},
    "wait": set(),
}
_SEGMENT_KEYS = {"name", "until", "timeout_s", "on_timeout", "load"}
_TASK_KEYS = {"name", "description", "plumbing", "controllers", "loads", "limits", "segments"}
DEFAULT_TOL_MM = 0.5
DEFAULT_TOL_DEG = 1.0
DEFAULT_FOR_S = 0.05
TIMEOUT_MARGIN_S = 2.0
# one control sample (the controllers' sample_time_s, the paper's T = 1 ms): a motion that
# takes less is a step between two samples, which no trajectory can carry
MIN_MOTION_S = 0.001
SAFE_TAIL_S = 0.2  # s the run goes on with both valves safe after an abort (seen in the bag)
# every segment to its timeout, and the safe tail, fit in one run (the duration cap): a
# motion, a timeout or all of them together longer than this could never run to its end
MAX_TASK_S = MAX_DURATION_S - SAFE_TAIL_S


@dataclass(frozen=True)
class Segment:
    """One checked segment: what it does, its targets (SI) and what ends it."""

    index: int
    kind: str
    name: str
    args: dict[str, float]  # the motion's fields as given (user units)
    x_start: float  # m, the reference at the segment's start
    x_end: float  # m, at its end
    theta_start: float  # rad
    theta_end: float  # rad
    duration_s: float  # the planned motion (0 for wait)
    until: dict[str, Any]  # {"kind": ..., fields}
    timeout_s: float
    on_timeout: str
    load: dict[str, Any] = field(default_factory=dict)

    @property
    def label(self) -> str:
        return f"segments[{self.index}]" + (f" ({self.name})" if self.name else "")


@dataclass(frozen=True)
class TaskProgram:
    """A checked task: its segments in order, the twin's settings, the controllers' overrides."""

    name: str
    description: str
    plumbing: str | None
    controllers: dict[str, dict[str, Any]]
    loads: dict[str, Any]
    angle_limits_deg: tuple[float, float] | None
    segments: tuple[Segment, ...]
    source: str = ""

    @property
    def planned_s(self) -> float:
        """The longest the task can take: every segment to its timeout."""
        return sum(s.timeout_s for s in self.segments)


def load_task(path: str | Path, **kw: Any) -> TaskProgram:
    """Read and check the task file ``path`` (:func:`parse_task` with ``kw``); errors name it."""
    p = Path(path)
    if not p.is_file():
        raise ParamError("task", str(path), "an existing task file (YAML)")
    data = load_yaml(p)
    try:
        return parse_task(data, source=str(p), **kw)
    except ParamError as err:
        raise ParamError(f"{p}: {err.key}", err.value, err.allowed) from None


def parse_task(
    data: Any,
    *,
    x0_m: float = 0.0,
    theta0_rad: float = 0.0,
    safety: Any = None,
    source: str = "",
    plant_plumbing: str = "paper",
) -> TaskProgram:
    """Check a task mapping completely; the first problem raises one :class:`ParamError`.

    ``x0_m``/``theta0_rad``: where the joints start; ``safety``: the supervisor's
    parameters (default ones); ``plant_plumbing``: the plumbing when the task names none.
    """
    from pneu_driver.safety import SafetyParams

    safety = safety if safety is not None else SafetyParams()
    if not isinstance(data, Mapping):
        raise ParamError("task", type(data).__name__, "a mapping with a 'segments:' list")
    _no_unknown("task", data, _TASK_KEYS)
    for key in ("name", "description"):
        if not isinstance(data.get(key, ""), str):
            raise ParamError(key, data[key], "a text (a string)")
    name = str(data.get("name", Path(source).stem if source else "task"))
    plumbing = data.get("plumbing")
    if plumbing is not None and plumbing not in ("paper", "bidirectional"):
        raise ParamError("plumbing", plumbing, "paper or bidirectional")
    controllers = _controllers(data.get("controllers", {}))
    loads = _mapping("loads", data.get("loads", {}))
    limits = _tool_range(_limits(data.get("limits")), safety)
    soft = None
    if limits is not None:  # the supervisor's soft limits: angle_margin_deg inside the range
        soft = (limits[0] + safety.angle_margin_deg, limits[1] - safety.angle_margin_deg)
        if not soft[0] < soft[1]:
            raise ParamError(
                "limits",
                f"[{limits[0]:g}, {limits[1]:g}]°",
                f"a range wider than 2 × angle_margin_deg ({2 * safety.angle_margin_deg:g}°, "
                "the supervisor's soft limits lie that far inside)",
            )
    segs = data.get("segments")
    if not isinstance(segs, list) or not segs:
        raise ParamError("segments", segs, "a non-empty list of segments")
    one_way = (plumbing or plant_plumbing) == "paper"  # the motor drives one way
    x, th = x0_m, theta0_rad
    out = []
    from pneu_control.task.plan import segment_trajectory

    total_s = 0.0
    for i, raw in enumerate(segs):
        seg = _segment(i, raw, x, th, safety, soft, one_way)
        total_s += seg.timeout_s
        if total_s > MAX_TASK_S:  # before its trajectory is built (a day-long one fills memory)
            raise ParamError(
                "segments",
                f"{total_s:.6g} s of timeouts to {seg.label}",
                f"at most {MAX_TASK_S:g} s in all (the duration cap of a run, "
                f"{MAX_DURATION_S:g} s, less the {SAFE_TAIL_S:g} s safe tail)",
            )
        try:  # the trajectory the segment becomes: whatever it refuses, refused here
            segment_trajectory(seg, 0.0)
        except ParamError as err:
            raise ParamError(f"{seg.label}.{seg.kind}: {err.key}", err.value, err.allowed) from None
        out.append(seg)
        x, th = seg.x_end, seg.theta_end
    return TaskProgram(
        name, str(data.get("description", "")), plumbing, controllers, loads, limits,
        tuple(out), source,
    )  # fmt: skip


def _no_unknown(where: str, data: Mapping, allowed: set[str]) -> None:
    for key in data:
        if key not in allowed:
            known = f"one of {', '.join(sorted(allowed))}" if allowed else "no fields here"
            raise ParamError(f"{where}.{key}", data[key], known)


def _mapping(key: str, v: Any) -> dict[str, Any]:
    if v is None:
        return {}
    if not isinstance(v, Mapping):
        raise ParamError(key, v, "a mapping of dotted names to values")
    return dict(v)


def _controllers(v: Any) -> dict[str, dict[str, Any]]:
    v = _mapping("controllers", v)
    for axis, sets in v.items():
        if axis not in ("linear", "rotary"):
            raise ParamError(f"controllers.{axis}", sets, "linear or rotary")
        v[axis] = _mapping(f"controllers.{axis}", sets)
        for key in v[axis]:  # the segments are the references: one set here would be unused
            if str(key) == "reference" or str(key).startswith("reference."):
                raise ParamError(
                    f"controllers.{axis}.{key}",
                    v[axis][key],
                    "a controller parameter other than reference.* (the task's segments "
                    "are the references)",
                )
        if axis == "rotary" and v[axis].get("rotary_control", "angle") != "angle":
            raise ParamError(
                "controllers.rotary.rotary_control",
                v[axis]["rotary_control"],
                "angle (a task positions the rotary angle)",
            )
    return v


def _limits(v: Any) -> tuple[float, float] | None:
    if v is None:
        return None
    v = _mapping("limits", v)
    _no_unknown("limits", v, {"angle_min_deg", "angle_max_deg"})
    lo = _number("limits.angle_min_deg", v.get("angle_min_deg", -math.inf), "°")
    hi = _number("limits.angle_max_deg", v.get("angle_max_deg", math.inf), "°")
    if not lo < hi:
        raise ParamError("limits.angle_min_deg/angle_max_deg", f"{lo:g}/{hi:g} °", "min < max")
    return lo, hi


def _tool_range(limits: tuple[float, float] | None, safety: Any) -> tuple[float, float] | None:
    """The angles the tool tolerates: the task's ``limits`` within the supervisor's range
    (``angle_limits`` on in safety.yaml); None when neither limits the angle."""
    if safety.angle_limits:
        own = (safety.angle_min_deg, safety.angle_max_deg)
        limits = own if limits is None else (max(limits[0], own[0]), min(limits[1], own[1]))
        if not limits[0] < limits[1]:
            raise ParamError(
                "limits",
                "outside the supervisor's",
                f"a range overlapping [{own[0]:g}, {own[1]:g}]°",
            )
    return limits


def _number(key: str, v: Any, unit: str, *, positive: bool = False, nonzero: bool = False):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ParamError(key, v, f"a number ({unit})")
    v = float(v)
    if math.isnan(v):
        raise ParamError(key, v, f"a number ({unit}), not NaN")
    if positive and not (0.0 < v < math.inf):
        raise ParamError(key, v, f"(0, inf) {unit}")
    if nonzero and (v == 0.0 or not math.isfinite(v)):
        raise ParamError(key, v, f"a finite non-zero number ({unit})")
    return v


def _segment(i: int, raw: Any, x: float, th: float, safety, limits, one_way: bool) -> Segment:
    where = f"segments[{i}]"
    if not isinstance(raw, Mapping):
        raise ParamError(where, raw, f"a mapping with one of {', '.join(KINDS)}")
    kinds = [k for k in raw if k in KINDS]
    if len(kinds) != 1:
        raise ParamError(where, sorted(raw), f"exactly one of {', '.join(KINDS)}")
    kind = kinds[0]
    _no_unknown(where, {k: v for k, v in raw.items() if k != kind}, _SEGMENT_KEYS)
    name = raw.get("name", "")
    if not isinstance(name, str):
        raise ParamError(f"{where}.name", name, "a text (a string)")
    args = _mapping(f"{where}.{kind}", raw[kind])
    _no_unknown(f"{where}.{kind}", args, _MOTION_FIELDS[kind])
    at = f"{where}.{kind}"
    x1, th1, dur = _plan(kind, args, at, x, th, safety, one_way)
    _check_stroke(at, x1, safety)
    if limits is not None:
        for value in (th, th1) if kind != "screw" else (th1,):
            deg = value * DEG_PER_RAD
            if not limits[0] <= deg <= limits[1]:
                raise ParamError(
                    at,
                    f"{deg:.6g}°",
                    f"an angle inside the soft limits [{limits[0]:g}, {limits[1]:g}]° "
                    "(the tool's range, angle_margin_deg inside)",
                )
    until = _until(where, raw.get("until"), kind, safety)
    timeout = min(dur + TIMEOUT_MARGIN_S, MAX_TASK_S)  # the default
    if "timeout_s" in raw:
        timeout = _number(f"{where}.timeout_s", raw["timeout_s"], "s")
        if not (timeout >= dur and 0.0 < timeout <= MAX_TASK_S):
            raise ParamError(
                f"{where}.timeout_s",
                timeout,
                (f"[{dur:.6g}" if dur > 0.0 else "(0") + f", {MAX_TASK_S:g}] s (at least the "
                f"motion it bounds, {dur:.6g} s; at most the duration cap of a run less the "
                "safe tail)",
            )
    if until["kind"] == "settled" and dur + until["for_s"] > timeout:  # could never end it
        raise ParamError(
            f"{where}.until.settled.for_s",
            until["for_s"],
            f"(0, {timeout - dur:.6g}] s: settled within the timeout ({timeout:.6g} s, "
            f"the motion taking {dur:.6g} s)",
        )
    if kind == "wait" and until["kind"] == "time":
        raise ParamError(
            f"{where}.until", "time", "settled, pressure or force (a wait ends on a condition)"
        )
    on_timeout = raw.get("on_timeout", "abort")
    if on_timeout not in ("abort", "continue"):
        raise ParamError(f"{where}.on_timeout", on_timeout, "abort or continue")
    load = _mapping(f"{where}.load", raw.get("load", {}))
    return Segment(
        i, kind, name, {k: float(v) for k, v in args.items()}, x, x1, th, th1, dur, until,
        timeout, on_timeout, load,
    )  # fmt: skip


def _check_stroke(at: str, x_m: float, safety) -> None:
    limit = safety.stroke_m / 2.0 - safety.stroke_margin_m
    if not -limit <= x_m <= limit:
        raise ParamError(
            at,
            f"{x_m * MM_PER_M:.6g} mm",
            f"a rod position inside the soft limits [{-limit * MM_PER_M:g}, {limit * MM_PER_M:g}] mm",
        )


def _check_rpm(key: str, rpm: float, safety) -> None:
    if abs(rpm) > safety.max_speed_rpm:
        raise ParamError(
            key,
            f"{rpm:.6g} rpm",
            f"a peak speed within the supervisor's max_speed_rpm ±{safety.max_speed_rpm:g} rpm",
        )


def _forward(key: str, value: float, one_way: bool, unit: str) -> None:
    if one_way and value < 0.0:
        raise ParamError(
            key,
            value,
            f"> 0 {unit} with the paper's plumbing (the motor drives one way); "
            "plumbing: bidirectional turns both ways",
        )


def _duration(
    at: str, args: dict, delta: float, speed_key: str, per_s: float, top: float = math.inf
) -> float:
    """Smooth-step duration from a peak speed (2Δ/D) or given; 0 for no motion. ``top``: the
    fastest the supervisor allows (in the speed's unit)."""
    if "duration_s" in args and speed_key in args:
        raise ParamError(at, sorted(args), f"one of {speed_key}, duration_s")
    if "duration_s" in args:
        return _motion_s(f"{at}.duration_s", args["duration_s"])
    if speed_key not in args:
        raise ParamError(at, sorted(args), f"{speed_key} or duration_s")
    unit = speed_key.split("_", 1)[1].replace("_", "/")
    v = _number(f"{at}.{speed_key}", args[speed_key], unit, positive=True)
    dur = 2.0 * abs(delta) / (v * per_s) if delta != 0.0 else 0.0
    if dur > 0.0 and not MIN_MOTION_S <= dur <= MAX_TASK_S:
        slowest, fastest = (2.0 * abs(delta) / (t * per_s) for t in (MAX_TASK_S, MIN_MOTION_S))
        if slowest > top:  # no speed does it: the way is too long for one run
            w_unit = "mm" if speed_key == "speed_mm_s" else "°"
            raise ParamError(
                at,
                f"{abs(delta):.6g}{w_unit}",
                f"a motion of at most {top * per_s * MAX_TASK_S / 2.0:.6g}{w_unit} (at "
                f"{top:g} {unit}, the supervisor's top speed, within {MAX_TASK_S:g} s: the "
                "duration cap)",
            )
        raise ParamError(
            f"{at}.{speed_key}",
            v,
            f"[{slowest:.6g}, {min(fastest, top):.6g}] {unit}: the motion over at least one "
            f"control sample ({MIN_MOTION_S * 1e3:g} ms) and at most {MAX_TASK_S:g} s (the "
            "duration cap)",
        )
    return dur


def _motion_s(key: str, v: Any) -> float:
    """A duration of a motion: at least one control sample (:data:`MIN_MOTION_S`)."""
    d = _number(key, v, "s", positive=True)
    if not MIN_MOTION_S <= d <= MAX_TASK_S:
        raise ParamError(
            key,
            d,
            f"[{MIN_MOTION_S:g}, {MAX_TASK_S:g}] s: at least one control sample, at most the "
            "duration cap of a run less the safe tail",
        )
    return d


def _plan(kind, args, at, x, th, safety, one_way) -> tuple[float, float, float]:
    """(x_end m, θ_end rad, planned duration s) of one segment, checking its numbers."""
    if kind == "move":
        given = [k for k in ("to_mm", "by_mm") if k in args]
        if len(given) != 1:
            raise ParamError(at, sorted(args), "one of to_mm, by_mm")
        v = _number(f"{at}.{given[0]}", args[given[0]], "mm") / MM_PER_M
        x1 = v if given[0] == "to_mm" else x + v
        dur = _duration(at, args, (x1 - x) * MM_PER_M, "speed_mm_s", 1.0)
        return x1, th, dur
    if kind == "rotate":
        given = [k for k in ("to_deg", "by_deg", "turns") if k in args]
        if len(given) != 1:
            raise ParamError(at, sorted(args), "one of to_deg, by_deg, turns")
        g = given[0]
        v = _number(f"{at}.{g}", args[g], "turns" if g == "turns" else "°")
        d_deg = v * 360.0 if g == "turns" else (v if g == "by_deg" else v - th * DEG_PER_RAD)
        if g == "to_deg" and one_way and d_deg < 0.0:
            raise ParamError(
                f"{at}.to_deg",
                v,
                f"> {th * DEG_PER_RAD:.6g}° (the angle before it) with the paper's plumbing "
                "(the motor drives one way); plumbing: bidirectional turns both ways",
            )
        _forward(f"{at}.{g}", v, one_way, "turns" if g == "turns" else "°")
        dur = _duration(at, args, d_deg, "speed_rpm", DEG_S_PER_RPM, safety.max_speed_rpm)
        if dur > 0.0:
            _check_rpm(f"{at}", 2.0 * d_deg / dur / DEG_S_PER_RPM, safety)
        return x, th + d_deg / DEG_PER_RAD, dur
    if kind == "spin":
        for key in ("speed_rpm", "duration_s"):
            if key not in args:
                raise ParamError(at, sorted(args), "speed_rpm and duration_s")
        rpm = _number(f"{at}.speed_rpm", args["speed_rpm"], "rpm", nonzero=True)
        _forward(f"{at}.speed_rpm", rpm, one_way, "rpm")
        _check_rpm(f"{at}.speed_rpm", rpm, safety)
        dur = _motion_s(f"{at}.duration_s", args["duration_s"])
        cruise = dur - min(SPIN_RAMP_S, dur / 3.0)  # the ramps in and out (task/plan.py)
        return x, th + rpm * DEG_S_PER_RPM * cruise / DEG_PER_RAD, dur
    if kind == "screw":
        for key in ("pitch_mm", "turns", "rate_turns_s"):
            if key not in args:
                raise ParamError(
                    at, sorted(args), "pitch_mm, turns and rate_turns_s (ramp_s optional)"
                )
        pitch = _number(f"{at}.pitch_mm", args["pitch_mm"], "mm", nonzero=True) / MM_PER_M
        turns = _number(f"{at}.turns", args["turns"], "turns", nonzero=True)
        _forward(f"{at}.turns", turns, one_way, "turns")
        rate = _number(f"{at}.rate_turns_s", args["rate_turns_s"], "turns/s", positive=True)
        ramp = _motion_s(f"{at}.ramp_s", args.get("ramp_s", 0.25))
        _check_rpm(f"{at}.rate_turns_s", rate * 60.0, safety)
        if abs(turns) / rate + ramp > MAX_TASK_S:  # a helix longer than any run
            top = safety.max_speed_rpm / 60.0
            slowest = abs(turns) / (MAX_TASK_S - ramp) if ramp < MAX_TASK_S else math.inf
            if slowest > top:  # no rate does it: too many turns for one run
                raise ParamError(
                    f"{at}.turns",
                    turns,
                    f"at most {top * (MAX_TASK_S - ramp):.6g} turns either way (at {top:g} "
                    f"turns/s, max_speed_rpm, within {MAX_TASK_S:g} s: the duration cap)",
                )
            raise ParamError(
                f"{at}.rate_turns_s",
                rate,
                f"[{slowest:.6g}, {top:g}] turns/s: the helix ({abs(turns):g} turns, ramp_s "
                f"{ramp:g} s) within {MAX_TASK_S:g} s (the duration cap), at most max_speed_rpm",
            )
        if ramp > abs(turns) / rate:  # the rate is reached and left within the turns
            raise ParamError(
                f"{at}.ramp_s" if "ramp_s" in args else f"{at}.turns",
                ramp if "ramp_s" in args else turns,
                f"ramp_s <= |turns|/rate_turns_s ({abs(turns) / rate:.6g} s; ramp_s "
                f"{ramp:g} s{'' if 'ramp_s' in args else ', the default'})",
            )
        return x + pitch * turns, th + 2.0 * math.pi * turns, abs(turns) / rate + ramp
    if kind == "dwell":
        if "duration_s" not in args:
            raise ParamError(at, sorted(args), "duration_s")
        return x, th, _motion_s(f"{at}.duration_s", args["duration_s"])
    return x, th, 0.0  # wait


def _until(where: str, v: Any, kind: str, safety: Any) -> dict[str, Any]:
    if v is None:
        if kind in ("move", "rotate", "screw"):
            return {"kind": "settled", "tol_mm": DEFAULT_TOL_MM, "tol_deg": DEFAULT_TOL_DEG,
                    "for_s": DEFAULT_FOR_S}  # fmt: skip
        if kind == "wait":
            raise ParamError(f"{where}.until", None, "a condition: settled, pressure or force")
        return {"kind": "time"}
    if isinstance(v, str) and v == "time":
        return {"kind": "time"}
    if not isinstance(v, Mapping) or len(v) != 1 or next(iter(v)) not in CONDITIONS:
        raise ParamError(f"{where}.until", v, f"one of {', '.join(CONDITIONS)} (a mapping)")
    ck, body = next(iter(v.items()))
    at = f"{where}.until.{ck}"
    body = _mapping(at, body if body is not None else {})
    if ck == "time":
        _no_unknown(at, body, set())
        return {"kind": "time"}
    if ck == "settled":
        _no_unknown(at, body, {"tol_mm", "tol_deg", "for_s"})
        stroke_mm = safety.stroke_m * MM_PER_M
        return {
            "kind": "settled",
            "tol_mm": _tolerance(at, body, "tol_mm", DEFAULT_TOL_MM, stroke_mm, "the stroke"),
            "tol_deg": _tolerance(at, body, "tol_deg", DEFAULT_TOL_DEG, 360.0, "a turn"),
            "for_s": _number(f"{at}.for_s", body.get("for_s", DEFAULT_FOR_S), "s", positive=True),
        }
    if ck == "pressure":
        _no_unknown(at, body, {"sensor", "above_kpa", "below_kpa"})
        sensor = body.get("sensor")
        if sensor not in SENSORS:
            raise ParamError(f"{at}.sensor", sensor, f"one of {', '.join(SENSORS)}")
        side, value = _threshold(at, body, "kpa", "kPa (absolute)")
        lo, hi = _SENSED_PA[0] / 1e3, _SENSED_PA[1] / 1e3
        if not lo <= value <= hi:  # a threshold the sensor can never read ends nothing
            raise ParamError(
                f"{at}.{side}_kpa", value, f"[{lo:g}, {hi:g}] kPa absolute (the sensors' range)"
            )
        return {"kind": "pressure", "sensor": sensor, "side": side, "value": value * 1e3}
    _no_unknown(at, body, {"above_n", "below_n"})
    side, value = _threshold(at, body, "n", "N")
    if not abs(value) <= _FORCE_MAX_N:
        raise ParamError(
            f"{at}.{side}_n",
            value,
            f"[{-_FORCE_MAX_N:.4g}, {_FORCE_MAX_N:.4g}] N (the sensors' full scale on the piston)",
        )
    return {"kind": "force", "side": side, "value": value}


def _tolerance(at: str, body: Mapping, key: str, default: float, widest: float, what: str):
    """A settled tolerance: narrower than ``widest`` (the stroke, a turn), which always holds
    and so would settle nothing."""
    unit = "mm" if key == "tol_mm" else "°"
    tol = _number(f"{at}.{key}", body.get(key, default), unit)
    if not 0.0 < tol < widest:
        raise ParamError(f"{at}.{key}", tol, f"(0, {widest:g}) {unit} (narrower than {what})")
    return tol


def _sensed() -> tuple[tuple[float, float], float]:
    """The absolute pressures the sensors read (Huba 511: ambient to ambient + full scale) and
    the largest rod force they can show (full scale on the larger piston area)."""
    from pneu_sim.physics.params import PlantParams

    p = PlantParams()
    p_a, fs = p.ambient.p_a, p.sensors.pressure.fs
    return (p_a, p_a + fs), (p_a + fs) * p.linear.A_c1


_SENSED_PA, _FORCE_MAX_N = _sensed()


def _threshold(at: str, body: Mapping, suffix: str, unit: str) -> tuple[str, float]:
    keys = [k for k in (f"above_{suffix}", f"below_{suffix}") if k in body]
    if len(keys) != 1:
        raise ParamError(at, sorted(body), f"one of above_{suffix}, below_{suffix}")
    return keys[0].split("_")[0], _number(f"{at}.{keys[0]}", body[keys[0]], unit)
