"""Each segment of a task as a joint trajectory: the one form both the twin and ROS carry out.

A segment's motion becomes a :class:`~pneu_control.controller.trajectory.JointTrajectory`
of both joints (positions, velocities and accelerations at knots every ≤ :data:`KNOT_S`,
exact values of the segment's profile), which each axis controller follows through
:func:`~pneu_control.controller.trajectory.joint_reference`. In-process the task runner
hands the references over directly; over ROS the task node publishes the same
trajectory as ``trajectory_msgs/JointTrajectory`` (times as integer nanoseconds both
ways, :func:`ns`), so lockstep results equal the in-process ones.

Profiles (SI, τ = t − t0):

- move / rotate: Eq. 38's smooth step of the moving joint, r = r0 + Δ (τ/D − sin(2πτ/D)/(2π));
- spin: the speed follows the same smooth step up over τ_r = min(:data:`SPIN_RAMP_S`, D/3),
  holds ω, and down over the last τ_r: angle ω (D − τ_r) in all;
- screw: :func:`~pneu_control.controller.trajectory.screw` (the helix);
- dwell / wait: both joints held (two points at rest).
"""

from __future__ import annotations

import math

from pneu_control.controller.references import SmoothStep
from pneu_control.controller.trajectory import JointTrajectory, TrajectoryPoint, ns, screw
from pneu_control.task.program import DEG_S_PER_RPM, SPIN_RAMP_S, Segment

__all__ = ["KNOT_S", "ns", "segment_trajectory", "spin_profile"]

KNOT_S = 0.02  # s between knots: the quintic Hermite matches the profiles to < 1e-4 of Δ
JOINTS = ("linear", "rotary")
_TWO_PI = 2.0 * math.pi


def _grid(t0: float, d: float) -> list[float]:
    n = max(1, math.ceil(d / KNOT_S - 1e-9))
    return [ns(t0 + d * i / n) * 1e-9 for i in range(n + 1)]


def spin_profile(w: float, d: float, tau: float):
    """(θ − θ0, ω, ω̇) at τ of a spin: smooth-step speed ramps of τ_r at both ends."""
    tr = min(SPIN_RAMP_S, d / 3.0)

    def up(x: float) -> tuple[float, float, float]:  # 0 <= x <= tr
        ph = _TWO_PI * x / tr
        return (
            w * (x * x / (2.0 * tr) + tr / (4.0 * math.pi**2) * (math.cos(ph) - 1.0)),
            w * (x / tr - math.sin(ph) / _TWO_PI),
            w / tr * (1.0 - math.cos(ph)),
        )

    if tau <= 0.0:
        return 0.0, 0.0, 0.0
    if tau >= d:
        return w * (d - tr), 0.0, 0.0
    if tau < tr:
        return up(tau)
    if tau <= d - tr:
        return w * tr / 2.0 + w * (tau - tr), w, 0.0
    p, v, a = up(d - tau)  # mirror: the total minus the remaining ramp-up
    return w * (d - tr) - p, v, -a


def segment_trajectory(seg: Segment, t0: float) -> JointTrajectory:
    """Both joints' trajectory of ``seg`` started at ``t0`` (s on the controllers' time base)."""
    t0 = ns(t0) * 1e-9
    d = seg.duration_s
    if seg.kind == "screw":
        return screw(
            seg.x_start, seg.theta_start, seg.args["pitch_mm"] * 1e-3, seg.args["turns"],
            seg.args["rate_turns_s"], seg.args.get("ramp_s", 0.25), t0=t0, dt_s=KNOT_S,
        )  # fmt: skip
    hold = (seg.x_start, seg.theta_start)
    if seg.kind in ("dwell", "wait") or d <= 0.0:
        end = (seg.x_end, seg.theta_end)
        return JointTrajectory(JOINTS, (_point(t0, end), _point(t0 + max(d, KNOT_S), end)))
    pts = []
    grid = _grid(t0, d)
    if seg.kind == "spin":
        w = seg.args["speed_rpm"] * DEG_S_PER_RPM * math.pi / 180.0
        for t in grid[1:-1]:
            p, v, a = spin_profile(w, d, t - t0)
            pts.append(_point(t, (hold[0], seg.theta_start + p), (0.0, v), (0.0, a)))
        ends = ((seg.x_start, seg.theta_start), (seg.x_end, seg.theta_end))
        return _at_rest(grid, ends, pts)
    j = 0 if seg.kind == "move" else 1
    r0, r1 = (seg.x_start, seg.x_end) if j == 0 else (seg.theta_start, seg.theta_end)
    step = SmoothStep(r0, r1, d, t0)
    for t in grid[1:-1]:
        r, rd, rdd = step(t)
        pos, vel, acc = list(hold), [0.0, 0.0], [0.0, 0.0]
        pos[j], vel[j], acc[j] = r, rd, rdd
        pts.append(_point(t, tuple(pos), tuple(vel), tuple(acc)))
    return _at_rest(grid, (hold, (seg.x_end, seg.theta_end)), pts)


def _at_rest(grid: list[float], ends, inner: list[TrajectoryPoint]) -> JointTrajectory:
    """The inner points between the exact start and end, both at rest."""
    pts = (_point(grid[0], ends[0]), *inner, _point(grid[-1], ends[1]))
    return JointTrajectory(JOINTS, pts)


def _point(t, pos, vel=(0.0, 0.0), acc=(0.0, 0.0)) -> TrajectoryPoint:
    return TrajectoryPoint(tuple(pos), tuple(vel), tuple(acc), time_from_start=t)
