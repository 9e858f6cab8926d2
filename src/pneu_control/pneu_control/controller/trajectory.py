"""Coordinated two-axis trajectories: both joints on one time base.

The data model mirrors ``trajectory_msgs/JointTrajectory`` (what ros2_control's
joint_trajectory_controller takes), ROS-free, so a ROS shell converts a message
1:1: ``joint_names`` (a subset of ``linear``, ``rotary``) and ``points``, each a
:class:`TrajectoryPoint` with ``positions``, optional ``velocities`` and
``accelerations`` (one value per joint, or none) and ``time_from_start`` (s).
SI throughout: the linear joint in m (x = 0 at mid-stroke, +x extending), the
rotary joint in rad (the encoder angle).

:func:`joint_reference` turns one joint into a :class:`JointReference`: a
:class:`~pneu_control.controller.references.Waypoints` whose knot table
``[t, r, v, a]`` is filled from the points, so the one ``waypoints_ref`` kernel
evaluates it (in Python and compiled into the fast loop): a quintic Hermite,
C², through every point with the given velocities and accelerations; where a
point gives none, the Fritsch–Carlson velocity and the central-difference
acceleration of :class:`Waypoints`. It holds the first point before it and the
last after it, at rest, so the first and last points must be at rest
(velocities and accelerations 0 where given).

Feeding the axis controllers: the linear axis takes ``joint_reference(traj,
"linear")`` as its position reference (m); the rotary axis takes
``joint_reference(traj, "rotary")`` as its angle reference (rad) under
``rotary_control: angle``. Under speed control it needs θ̇, θ̈, θ⃛: the kernel
gives θ̇ and θ̈ (its r_dot, r_ddot), not θ⃛ (the Hermite is C² only).

Shapes (each returns a :class:`JointTrajectory`, checked against the safety
limits of ``config/safety.yaml``; see :func:`check_limits`):

- :func:`screw`: a helix, x = x0 + p (θ − θ0)/(2π), both joints moving together;
  the path parameter φ = θ − θ0 accelerates to the cruise rate ω_c over
  ``ramp_s`` = D s with φ̈ = ω_c 6u(1 − u)/D (u = τ/D, so φ̇ = ω_c (3u² − 2u³): C²),
  cruises, and decelerates symmetrically;
- :func:`insert_then_twist`: x0 → x0 + dx, dwell, then θ0 → θ0 + dθ;
- :func:`twist_while_retracting`: θ0 → θ0 + dθ over ``duration`` s while
  x0 → x0 + dx (dx < 0 retracts) over the last ``duration − twist_lead`` s.

Point-to-point moves use the minimum-jerk quintic s(u) = 10u³ − 15u⁴ + 6u⁵
(Flash & Hogan 1985; rest to rest, φ̇ = φ̈ = 0 at both ends). Every piece of
every shape is a polynomial of degree ≤ 5 between points that carry its exact
position, velocity and acceleration, so the quintic Hermite reproduces it
exactly (to rounding); the points every ``dt_s`` in between are there for a
ROS trajectory message and plots, not for accuracy.

:func:`from_dict` reads the YAML shape of a task file (see its docstring);
:data:`UNITS` and :func:`to_si` convert mm/deg/turns at that edge.
"""

from __future__ import annotations

import itertools
import math
import numbers
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from pneu_driver.safety.params import SafetyParams
from pneu_msgs_py.contract.units import RPM_PER_RAD_S
from pneu_msgs_py.params.core import MISSING, ParamError

from pneu_control.controller.references import REF_WAYPOINTS, REFERENCE, Waypoints

__all__ = [
    "JOINTS",
    "UNITS",
    "JointReference",
    "JointTrajectory",
    "TrajectoryPoint",
    "check_limits",
    "from_dict",
    "from_stamped",
    "insert_then_twist",
    "joint_reference",
    "ns",
    "references",
    "screw",
    "to_dict",
    "to_stamped",
    "to_si",
    "twist_while_retracting",
]

JOINTS = ("linear", "rotary")
_SI_UNIT = {"linear": "m", "rotary": "rad"}
# SI per unit, at the edge only (task files): positions; velocities per s, accelerations per s²
UNITS: dict[str, dict[str, float]] = {
    "linear": {"m": 1.0, "mm": 1.0e-3},
    "rotary": {"rad": 1.0, "deg": math.pi / 180.0, "turns": 2.0 * math.pi},
}
_TWO_PI = 2.0 * math.pi


def to_si(joint: str, value: float, unit: str) -> float:
    """``value`` in ``unit`` (one of :data:`UNITS` ``[joint]``) → m or rad."""
    if joint not in UNITS:
        raise ParamError("joint", joint, "one of " + ", ".join(JOINTS))
    if unit not in UNITS[joint]:
        raise ParamError(f"{joint} unit", unit, "one of " + ", ".join(UNITS[joint]))
    return float(value) * UNITS[joint][unit]


@dataclass(frozen=True)
class TrajectoryPoint:
    """One point (``trajectory_msgs/JointTrajectoryPoint`` without effort), SI.

    ``velocities``/``accelerations``: one value per joint, or empty (then derived).
    """

    positions: tuple[float, ...]
    velocities: tuple[float, ...] = ()
    accelerations: tuple[float, ...] = ()
    time_from_start: float = 0.0


@dataclass(frozen=True)
class JointTrajectory:
    """Both joints on one time base (``trajectory_msgs/JointTrajectory``), validated.

    ``r_eq_m``: not part of the message (a ROS shell drops it) -- the length per
    radian that :mod:`pneu_control.analysis.path` uses to put the angle on the
    same scale as x (:func:`screw` sets p/(2π), the axial advance per radian);
    None: give it to the analysis.

    Refused, with one line naming the point and field: unknown or repeated joint
    names, no points, times not finite, negative or not strictly increasing,
    value lists of the wrong length, non-finite values, and a first or last
    point not at rest (the reference holds it with zero velocity).
    """

    joint_names: tuple[str, ...]
    points: tuple[TrajectoryPoint, ...]
    r_eq_m: float | None = None

    def __post_init__(self) -> None:
        names = tuple(self.joint_names) if isinstance(self.joint_names, Sequence) else ()
        if (
            isinstance(self.joint_names, str)
            or not names
            or len(set(names)) != len(names)
            or not set(names) <= set(JOINTS)
        ):
            raise ParamError(
                "joint_names", self.joint_names, "a non-empty subset of linear, rotary, each once"
            )
        pts = tuple(self.points)
        if not pts:
            raise ParamError("points", list(pts), "at least one point")
        if self.r_eq_m is not None and not (_finite(self.r_eq_m) and self.r_eq_m > 0.0):
            raise ParamError("r_eq_m", self.r_eq_m, "(0, inf) m or None")
        clean = []
        t_prev = None
        for i, p in enumerate(pts):
            if not isinstance(p, TrajectoryPoint):
                raise ParamError(f"points[{i}]", p, "a TrajectoryPoint")
            t = p.time_from_start
            if not _finite(t):
                raise ParamError(f"points[{i}].time_from_start", t, "a finite number of s")
            if t_prev is None and t < 0.0:
                raise ParamError(f"points[{i}].time_from_start", float(t), ">= 0 s")
            if t_prev is not None and t <= t_prev:
                raise ParamError(
                    f"points[{i}].time_from_start",
                    float(t),
                    f"> {t_prev:g} s (strictly increasing)",
                )
            t_prev = float(t)
            at_rest = i in (0, len(pts) - 1)
            values = [
                _clean_values(f"points[{i}].{field}", getattr(p, field), names, field, at_rest)
                for field in ("positions", "velocities", "accelerations")
            ]
            clean.append(TrajectoryPoint(*values, time_from_start=t_prev))
        object.__setattr__(self, "joint_names", names)
        object.__setattr__(self, "points", tuple(clean))

    @property
    def times(self) -> tuple[float, ...]:
        return tuple(p.time_from_start for p in self.points)

    @property
    def t_start(self) -> float:
        return self.points[0].time_from_start

    @property
    def t_end(self) -> float:
        return self.points[-1].time_from_start

    def index(self, joint: str) -> int:
        """Column of ``joint`` in the points' value lists."""
        if joint not in self.joint_names:
            raise ParamError("joint", joint, "one of " + ", ".join(self.joint_names))
        return self.joint_names.index(joint)

    def positions(self, joint: str) -> tuple[float, ...]:
        j = self.index(joint)
        return tuple(p.positions[j] for p in self.points)


def _clean_values(
    key: str, vals: Any, names: tuple[str, ...], field: str, at_rest: bool
) -> tuple[float, ...]:
    """One value list of a point as floats: one per joint (or none for derivatives)."""
    n = len(names)
    if hasattr(vals, "__len__") and not isinstance(vals, (str, Mapping)):
        vals = tuple(vals)
    allowed = (n,) if field == "positions" else (0, n)
    if not isinstance(vals, tuple) or len(vals) not in allowed:
        want = f"{n} values, one per joint ({', '.join(names)})"
        raise ParamError(key, vals, want if field == "positions" else want + ", or none")
    per = {"positions": "", "velocities": "/s", "accelerations": "/s^2"}[field]
    for j, v in enumerate(vals):
        if not _finite(v):
            raise ParamError(
                f"{key}[{j}]", v, f"a finite number ({_SI_UNIT[names[j]]}{per}, joint {names[j]})"
            )
        if field != "positions" and at_rest and v != 0.0:
            raise ParamError(
                f"{key}[{j}]", v, "0 at the first and last point (the reference holds them at rest)"
            )
    return tuple(float(v) for v in vals)


def _finite(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v)


class JointReference(Waypoints):
    """One joint of a trajectory as a reference ``ref(t) -> (r, ṙ, r̈)`` (SI), C².

    A :class:`Waypoints` with its knot table set from the points (not from
    :class:`Waypoints`' own rule), evaluated by the same ``waypoints_ref`` kernel.
    """

    def __init__(
        self, t: Sequence[float], r: Sequence[float], v: Sequence[float], a: Sequence[float]
    ):
        # Waypoints.__init__ is not called: the knot velocities and accelerations are given
        self.t, self.r, self.v, self.a = list(t), list(r), list(v), list(a)
        self.knots = [self.t, self.r, self.v, self.a]
        self.rc = REFERENCE.new(kind=REF_WAYPOINTS, n=len(self.t))


def joint_reference(traj: JointTrajectory, joint: str) -> JointReference:
    """The reference of ``joint`` (m or rad): quintic Hermite through the points.

    Velocities where a point gives none: :class:`Waypoints`' Fritsch–Carlson rule
    on the positions (0 at the ends); accelerations where none: central
    differences of the knot velocities (0 at the ends), as :class:`Waypoints`.
    """
    j = traj.index(joint)
    t = list(traj.times)
    r = [p.positions[j] for p in traj.points]
    pchip = Waypoints(t, r).v
    v = [p.velocities[j] if p.velocities else pchip[i] for i, p in enumerate(traj.points)]
    n = len(t)
    a = [0.0] * n
    for i, p in enumerate(traj.points):
        if p.accelerations:
            a[i] = p.accelerations[j]
        elif 0 < i < n - 1:
            a[i] = (v[i + 1] - v[i - 1]) / (t[i + 1] - t[i - 1])
    return JointReference(t, r, v, a)


def references(traj: JointTrajectory) -> dict[str, JointReference]:
    """:func:`joint_reference` of every joint, by name."""
    return {name: joint_reference(traj, name) for name in traj.joint_names}


# --- the ROS message's time base -------------------------------------------------------------


def to_stamped(traj: JointTrajectory, base_ns: int) -> tuple[int, tuple[str, ...], list]:
    """``traj`` (times in s on a time base that starts at stamp ``base_ns``) as a message's
    (header.stamp ns, joint names, points with time_from_start in int ns from that stamp).

    Integer nanoseconds throughout (as a ROS Time and Duration carry them): a trajectory
    whose times are ``n * 1e-9`` for integers n (:func:`ns`) comes
    back from :func:`from_stamped` with the same bits.
    """
    t0 = ns(traj.t_start)
    stamp = int(base_ns) + t0
    pts = [
        (p.positions, p.velocities, p.accelerations, ns(p.time_from_start) - t0)
        for p in traj.points
    ]
    return stamp, traj.joint_names, pts


def from_stamped(
    stamp_ns: int, joint_names: Sequence[str], points: Sequence[Any], base_ns: int
) -> JointTrajectory:
    """A message's trajectory (:func:`to_stamped`'s form) on the time base that starts at
    stamp ``base_ns``: point times ``(stamp + time_from_start − base) · 1e-9`` s, exact.

    Refused as :class:`JointTrajectory` refuses (one line naming the point and field), and a
    start before ``base_ns`` (``points[0].time_from_start``: the past cannot be followed).
    """
    pts = []
    for i, (pos, vel, acc, t_ns) in enumerate(points):
        if t_ns < 0:
            raise ParamError(f"points[{i}].time_from_start", f"{t_ns} ns", ">= 0 ns")
        pts.append(
            TrajectoryPoint(pos, vel, acc, time_from_start=(int(stamp_ns) + t_ns - base_ns) * 1e-9)
        )
    if pts and pts[0].time_from_start < 0.0:
        raise ParamError(
            "header.stamp",
            f"{stamp_ns} ns",
            f">= {base_ns} ns (the first sample this controller took; 0 = its next sample)",
        )
    return JointTrajectory(tuple(joint_names), tuple(pts))


def ns(t: float) -> int:
    """A time (s) as the integer nanoseconds a ROS Time or Duration carries (back: ns · 1e-9)."""
    return int(round(t * 1e9))


# --- limits ----------------------------------------------------------------------------------


def _stroke(safety: SafetyParams) -> tuple[float, float]:
    half = safety.stroke_m / 2.0 - safety.stroke_margin_m  # the supervisor's soft limits
    return -half, half


def _stroke_text(safety: SafetyParams) -> str:
    lo, hi = _stroke(safety)
    return f"({lo:g}, {hi:g}) m (stroke soft limits, config/safety.yaml)"


def check_limits(traj: JointTrajectory, safety: SafetyParams | None = None) -> None:
    """Refuse a trajectory the safety supervisor would stop (``config/safety.yaml``).

    The references are evaluated at every point and 16 times per interval:
    linear: x plus the braking distance v²/(2 ``max_decel_m_s2``) in the
    direction of motion strictly inside the soft limits ±(stroke/2 − margin)
    (at a limit the supervisor holds the valve); rotary: |θ̇| ≤ ``max_speed_rpm``.
    The error names the point starting the interval where the limit is broken.
    """
    safety = SafetyParams() if safety is None else safety
    lo, hi = _stroke(safety)
    w_max = safety.max_speed_rpm / RPM_PER_RAD_S
    ts = traj.times
    for name in traj.joint_names:
        j = traj.index(name)
        ref = joint_reference(traj, name)
        for i in range(len(ts)):
            steps = 16 if i < len(ts) - 1 else 1
            for k in range(steps):
                t = ts[i] + (ts[i + 1] - ts[i]) * k / steps if k else ts[i]
                r, rd, _ = ref(t)
                if name == "linear":
                    reach = r + math.copysign(rd * rd / (2.0 * safety.max_decel_m_s2), rd)
                    if not lo < reach < hi:
                        raise ParamError(
                            f"points[{i}].positions[{j}]",
                            traj.points[i].positions[j],
                            f"x + braking distance v^2/(2*{safety.max_decel_m_s2:g} m/s^2) within "
                            f"{_stroke_text(safety)}; reaches {reach:.4g} m at t = {t:.4g} s",
                        )
                elif abs(rd) > w_max * (1.0 + 1e-12):
                    raise ParamError(
                        f"points[{i}].velocities[{j}]",
                        round(rd, 6),
                        f"|dtheta/dt| <= {w_max:.6g} rad/s (max_speed_rpm = "
                        f"{safety.max_speed_rpm:g}, config/safety.yaml); reached at t = {t:.4g} s",
                    )


def _check_x(key: str, value: float, x: float, safety: SafetyParams, what: str) -> None:
    """Refuse argument ``value`` of ``key`` when the position ``x`` it gives is outside the stroke."""
    lo, hi = _stroke(safety)
    if not lo < x < hi:
        raise ParamError(key, value, f"{what} within {_stroke_text(safety)}; here {x:.6g} m")


def _check_speed(key: str, value: float, w_peak: float, safety: SafetyParams, what: str) -> None:
    rpm = abs(w_peak) * RPM_PER_RAD_S
    if rpm > safety.max_speed_rpm * (1.0 + 1e-12):  # at the limit passes (rounding allowed)
        raise ParamError(
            key,
            value,
            f"peak speed <= max_speed_rpm = {safety.max_speed_rpm:g} rpm (config/safety.yaml); "
            f"here {what} = {rpm:.5g} rpm",
        )


def _positive(key: str, value: float, unit: str, zero_ok: bool = False) -> float:
    if not _finite(value) or value < 0.0 or (value == 0.0 and not zero_ok):
        raise ParamError(key, value, f"{'[0' if zero_ok else '(0'}, inf) {unit}")
    return float(value)


def _finite_arg(key: str, value: float, unit: str) -> float:
    if not _finite(value):
        raise ParamError(key, value, f"a finite number of {unit}")
    return float(value)


# --- profiles: (φ, φ̇, φ̈) of a piece at local time τ --------------------------------------


def _min_jerk(delta: float, dur: float, tau: float) -> tuple[float, float, float]:
    """Rest-to-rest minimum-jerk move of ``delta`` over ``dur`` s: 10u³ − 15u⁴ + 6u⁵."""
    u = min(max(tau / dur, 0.0), 1.0)
    s = u * u * u * (10.0 + u * (-15.0 + 6.0 * u))
    sd = 30.0 * u * u * (1.0 - u) * (1.0 - u)
    sdd = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u)
    return delta * s, delta * sd / dur, delta * sdd / (dur * dur)


def _ramp_up(w_c: float, dur: float, tau: float) -> tuple[float, float, float]:
    """Speed 0 → ω_c over ``dur`` s with φ̈ = ω_c 6u(1 − u)/dur (φ quartic, φ̈ 0 at both ends)."""
    u = tau / dur
    return (
        w_c * dur * (u**3 - 0.5 * u**4),
        w_c * (3.0 * u * u - 2.0 * u**3),
        w_c * 6.0 * u * (1.0 - u) / dur,
    )


def _grid(breaks: list[float], dt_s: float) -> list[float]:
    """The breakpoints and points every ≤ dt_s between them."""
    out = [breaks[0]]
    for a, b in itertools.pairwise(breaks):
        if b <= a:
            continue
        k = max(1, math.ceil((b - a) / dt_s - 1e-9))
        out += [a + (b - a) * m / k for m in range(1, k)] + [b]
    return out


def _build(
    times: list[float], f_x: Any, f_th: Any, t0: float, r_eq_m: float | None = None
) -> JointTrajectory:
    pts = []
    for t in times:
        x, xd, xdd = f_x(t)
        th, thd, thdd = f_th(t)
        pts.append(TrajectoryPoint((x, th), (xd, thd), (xdd, thdd), t0 + t))
    # the ends exactly at rest (profiles give 0 there up to rounding)
    pts[0] = TrajectoryPoint(pts[0].positions, (0.0, 0.0), (0.0, 0.0), pts[0].time_from_start)
    pts[-1] = TrajectoryPoint(pts[-1].positions, (0.0, 0.0), (0.0, 0.0), pts[-1].time_from_start)
    return JointTrajectory(JOINTS, tuple(pts), r_eq_m)


def _piecewise(x0: float, pieces: list[tuple[float, float, Any]]) -> Any:
    """f(t) of consecutive pieces (t_a, t_b, profile(τ) → increments), holding between/after."""

    def f(t: float) -> tuple[float, float, float]:
        base = x0
        for t_a, t_b, prof in pieces:
            if t < t_b:
                if t <= t_a:
                    return base, 0.0, 0.0
                r, rd, rdd = prof(t - t_a)
                return base + r, rd, rdd
            base += prof(t_b - t_a)[0]
        return base, 0.0, 0.0

    return f


def screw(
    x0: float,
    theta0: float,
    pitch_m: float,
    turns: float,
    rate_turns_per_s: float,
    ramp_s: float = 0.25,
    *,
    t0: float = 0.0,
    dt_s: float = 0.05,
    safety: SafetyParams | None = None,
) -> JointTrajectory:
    """Helix x = x0 + p (θ − θ0)/(2π) over ``turns`` (signed) at ``rate_turns_per_s``.

    x0 m, theta0 rad, pitch_m m per turn (signed: a negative pitch retracts while
    turning forward), t0 the start time, points every ≤ ``dt_s`` s. The rate is
    reached after ``ramp_s`` s (advancing 0.5 rate·ramp_s turns) and left
    symmetrically: total time |turns|/rate + ramp_s. ``r_eq_m`` = p/(2π).
    """
    safety = SafetyParams() if safety is None else safety
    x0 = _finite_arg("screw.x0", x0, "m")
    theta0 = _finite_arg("screw.theta0", theta0, "rad")
    pitch_m = _finite_arg("screw.pitch_m", pitch_m, "m")
    if pitch_m == 0.0:
        raise ParamError(
            "screw.pitch_m", pitch_m, "non-zero m per turn (a pure twist: insert_then_twist)"
        )
    turns = _finite_arg("screw.turns", turns, "turns")
    if turns == 0.0:
        raise ParamError("screw.turns", turns, "non-zero turns")
    rate = _positive("screw.rate_turns_per_s", rate_turns_per_s, "turns/s")
    ramp = _positive("screw.ramp_s", ramp_s, "s")
    _positive("screw.dt_s", dt_s, "s")
    _positive("screw.t0", t0, "s", zero_ok=True)
    t_turn = abs(turns) / rate  # φ = ω_c (T_c + ramp) in total
    if ramp > t_turn:
        raise ParamError("screw.ramp_s", ramp, f"(0, {t_turn:g}] s (|turns|/rate)")
    _check_x("screw.x0", x0, x0, safety, "x0")
    _check_x("screw.turns", turns, x0 + pitch_m * turns, safety, "x0 + pitch_m*turns")
    w_c = math.copysign(_TWO_PI * rate, turns)
    _check_speed("screw.rate_turns_per_s", rate, w_c, safety, "60 rate")
    t_c = t_turn - ramp
    phi_up = 0.5 * w_c * ramp  # angle covered by each ramp

    def phi(t: float) -> tuple[float, float, float]:
        if t <= ramp:
            return _ramp_up(w_c, ramp, t)
        if t <= ramp + t_c:
            return phi_up + w_c * (t - ramp), w_c, 0.0
        r, rd, rdd = _ramp_up(w_c, ramp, 2.0 * ramp + t_c - t)  # mirrored
        return _TWO_PI * turns - r, rd, -rdd

    k = pitch_m / _TWO_PI  # Eq. of the helix: dx/dθ = p/(2π)

    def f_x(t: float) -> tuple[float, float, float]:
        r, rd, rdd = phi(t)
        return x0 + k * r, k * rd, k * rdd

    def f_th(t: float) -> tuple[float, float, float]:
        r, rd, rdd = phi(t)
        return theta0 + r, rd, rdd

    times = _grid([0.0, ramp, ramp + t_c, 2.0 * ramp + t_c], dt_s)
    traj = _build(times, f_x, f_th, t0, r_eq_m=abs(k))
    check_limits(traj, safety)
    return traj


def insert_then_twist(
    x0: float,
    dx: float,
    theta0: float,
    dtheta: float,
    t_insert: float,
    t_twist: float,
    dwell: float = 0.0,
    *,
    t0: float = 0.0,
    dt_s: float = 0.05,
    safety: SafetyParams | None = None,
) -> JointTrajectory:
    """x0 → x0 + dx over ``t_insert`` s (θ held), ``dwell`` s, then θ0 → θ0 + dθ over ``t_twist``.

    SI (m, rad, s); each move minimum-jerk; dx > 0 extends (inserts).
    """
    safety = SafetyParams() if safety is None else safety
    name = "insert_then_twist"
    x0 = _finite_arg(f"{name}.x0", x0, "m")
    dx = _finite_arg(f"{name}.dx", dx, "m")
    theta0 = _finite_arg(f"{name}.theta0", theta0, "rad")
    dtheta = _finite_arg(f"{name}.dtheta", dtheta, "rad")
    t_insert = _positive(f"{name}.t_insert", t_insert, "s")
    t_twist = _positive(f"{name}.t_twist", t_twist, "s")
    dwell = _positive(f"{name}.dwell", dwell, "s", zero_ok=True)
    _positive(f"{name}.dt_s", dt_s, "s")
    _positive(f"{name}.t0", t0, "s", zero_ok=True)
    _check_x(f"{name}.x0", x0, x0, safety, "x0")
    _check_x(f"{name}.dx", dx, x0 + dx, safety, "x0 + dx")
    _check_speed(
        f"{name}.t_twist", t_twist, 1.875 * dtheta / t_twist, safety, "1.875 |dtheta|/t_twist"
    )
    t_a = t_insert + dwell
    f_x = _piecewise(x0, [(0.0, t_insert, lambda tau: _min_jerk(dx, t_insert, tau))])
    f_th = _piecewise(theta0, [(t_a, t_a + t_twist, lambda tau: _min_jerk(dtheta, t_twist, tau))])
    traj = _build(_grid([0.0, t_insert, t_a, t_a + t_twist], dt_s), f_x, f_th, t0)
    check_limits(traj, safety)
    return traj


def twist_while_retracting(
    x0: float,
    dx: float,
    theta0: float,
    dtheta: float,
    duration: float,
    twist_lead: float = 0.0,
    *,
    t0: float = 0.0,
    dt_s: float = 0.05,
    safety: SafetyParams | None = None,
) -> JointTrajectory:
    """θ0 → θ0 + dθ over ``duration`` s; x0 → x0 + dx over its last ``duration − twist_lead`` s.

    SI (m, rad, s); both moves minimum-jerk and ending together; dx < 0 retracts.
    ``twist_lead`` > 0 starts the twist first (to break the grip before pulling).
    """
    safety = SafetyParams() if safety is None else safety
    name = "twist_while_retracting"
    x0 = _finite_arg(f"{name}.x0", x0, "m")
    dx = _finite_arg(f"{name}.dx", dx, "m")
    theta0 = _finite_arg(f"{name}.theta0", theta0, "rad")
    dtheta = _finite_arg(f"{name}.dtheta", dtheta, "rad")
    duration = _positive(f"{name}.duration", duration, "s")
    lead = _positive(f"{name}.twist_lead", twist_lead, "s", zero_ok=True)
    if lead >= duration:
        raise ParamError(f"{name}.twist_lead", lead, f"[0, {duration:g}) s (less than duration)")
    _positive(f"{name}.dt_s", dt_s, "s")
    _positive(f"{name}.t0", t0, "s", zero_ok=True)
    _check_x(f"{name}.x0", x0, x0, safety, "x0")
    _check_x(f"{name}.dx", dx, x0 + dx, safety, "x0 + dx")
    _check_speed(
        f"{name}.duration", duration, 1.875 * dtheta / duration, safety, "1.875 |dtheta|/duration"
    )
    t_x = duration - lead
    f_x = _piecewise(x0, [(lead, duration, lambda tau: _min_jerk(dx, t_x, tau))])
    f_th = _piecewise(theta0, [(0.0, duration, lambda tau: _min_jerk(dtheta, duration, tau))])
    traj = _build(_grid([0.0, lead, duration], dt_s), f_x, f_th, t0)
    check_limits(traj, safety)
    return traj


# --- YAML-shaped input -----------------------------------------------------------------------

_POINT_KEYS = ("time_from_start", "positions", "velocities", "accelerations")


def _values(key: str, raw: Any, names: tuple[str, ...], per: str) -> tuple[Any, ...]:
    """A list (SI, in joint order) or a mapping ``{<joint>_<unit>: value}`` → SI tuple."""
    if raw is None:
        return ()
    if isinstance(raw, Mapping):
        out: dict[str, float] = {}
        for k, v in raw.items():
            joint, _, unit = str(k).partition("_")
            if joint not in names or unit not in UNITS[joint] or joint in out:
                allowed = ", ".join(f"{n}_{u}" for n in names for u in UNITS[n])
                raise ParamError(f"{key}.{k}", v, f"one key per joint, of {allowed} ({per})")
            if not _finite(v):
                raise ParamError(f"{key}.{k}", v, f"a finite number ({unit}{per})")
            out[joint] = to_si(joint, v, unit)
        missing = [n for n in names if n not in out]
        if missing:
            raise ParamError(
                f"{key}.{missing[0]}_<unit>", MISSING, f"a value for joint {missing[0]}"
            )
        return tuple(out[n] for n in names)
    if isinstance(raw, (list, tuple)):
        return tuple(raw)
    raise ParamError(
        key,
        raw,
        f"a list in SI (joint order {', '.join(names)}) or a mapping <joint>_<unit>: value",
    )


def from_dict(
    data: Mapping[str, Any], safety: SafetyParams | None = None, check: bool = True
) -> JointTrajectory:
    """Build a trajectory from its YAML shape, validated (and limit-checked when ``check``).

    ::

        joint_names: [linear, rotary]
        r_eq_m: 0.000159            # optional (analysis.path)
        points:
          - {time_from_start: 0.0, positions: [0.0, 0.0]}            # SI: m, rad
          - time_from_start: 1.0
            positions: {linear_mm: 10.0, rotary_deg: 360.0}          # or units at the edge
            velocities: {linear_mm: 0.0, rotary_turns: 0.5}          # per s (per s² for accel.)

    Value lists are SI in ``joint_names`` order (as the ROS message); a mapping
    gives each joint once as ``<joint>_<unit>`` with a unit of :data:`UNITS`.
    """
    if not isinstance(data, Mapping):
        raise ParamError("trajectory", data, "a mapping with joint_names and points")
    for k in data:
        if k not in ("joint_names", "points", "r_eq_m"):
            raise ParamError(k, data[k], "no such key; known: joint_names, points, r_eq_m")
    for k in ("joint_names", "points"):
        if k not in data:
            raise ParamError(k, MISSING, "joint_names (subset of linear, rotary) and points")
    names = data["joint_names"]
    if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names):
        raise ParamError("joint_names", names, "a non-empty subset of linear, rotary, each once")
    names = tuple(names)
    if not set(names) <= set(JOINTS) or len(set(names)) != len(names) or not names:
        raise ParamError(
            "joint_names", list(names), "a non-empty subset of linear, rotary, each once"
        )
    raw_pts = data["points"]
    if not isinstance(raw_pts, (list, tuple)):
        raise ParamError("points", raw_pts, "a list of points")
    pts = []
    for i, p in enumerate(raw_pts):
        key = f"points[{i}]"
        if not isinstance(p, Mapping):
            raise ParamError(key, p, "a mapping with time_from_start and positions")
        for k in p:
            if k not in _POINT_KEYS:
                raise ParamError(
                    f"{key}.{k}", p[k], "no such key; known: " + ", ".join(_POINT_KEYS)
                )
        for k in ("time_from_start", "positions"):
            if k not in p:
                raise ParamError(f"{key}.{k}", MISSING, "time_from_start (s) and positions")
        pts.append(
            TrajectoryPoint(
                _values(f"{key}.positions", p["positions"], names, ""),
                _values(f"{key}.velocities", p.get("velocities"), names, "/s"),
                _values(f"{key}.accelerations", p.get("accelerations"), names, "/s^2"),
                p["time_from_start"],
            )
        )
    traj = JointTrajectory(names, tuple(pts), data.get("r_eq_m"))
    if check:
        check_limits(traj, safety)
    return traj


def to_dict(traj: JointTrajectory) -> dict[str, Any]:
    """The YAML shape of ``traj`` (SI lists), which :func:`from_dict` reads back to an equal one."""
    out: dict[str, Any] = {"joint_names": list(traj.joint_names)}
    if traj.r_eq_m is not None:
        out["r_eq_m"] = traj.r_eq_m
    pts = []
    for p in traj.points:
        d: dict[str, Any] = {"time_from_start": p.time_from_start, "positions": list(p.positions)}
        if p.velocities:
            d["velocities"] = list(p.velocities)
        if p.accelerations:
            d["accelerations"] = list(p.accelerations)
        pts.append(d)
    out["points"] = pts
    return out
