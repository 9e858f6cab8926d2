"""The exciter core: answers each sensor sample with the designed valve command of one axis.

The same object runs in the in-process runner (``pneu excite``, through
:class:`pneu_sim.cycle.rig_cycle.RigCycle` with the supervisor on) and in the
ROS exciter node (``pneu_control.nodes.exciter_node``) against the sim node or
the driver, so an experiment on the rig is the one tested on the twin.

Per sample (time t from the first sample's stamp): the segment of the
:class:`~pneu_control.sysid.design.ExcitationDesign` active at t decides the
command -- a held voltage, an open-loop step from its base (cut back to the
base once the measured output leaves the guard band), or the PID algorithm of
:mod:`pneu_control.algorithms.pid` with the design's low gains tracking the
segment's reference. Entering a closed-loop segment is bumpless (the PID's
integral is chosen so that its first output equals the last command).
References start where the output is (move, ramp) or at the segment's
centre (chirp, PRBS).
"""

from __future__ import annotations

import math

import numpy as np
from pneu_msgs_py.contract.samples import NEUTRAL_V, SensorSample
from pneu_msgs_py.params.core import with_updates

from pneu_control.algorithms.base import NAN, StepInput
from pneu_control.algorithms.pid import Pid
from pneu_control.controller.params import AxisControllerParams
from pneu_control.controller.references import axis_scale
from pneu_control.sysid.design import ExcitationDesign, Segment

__all__ = ["ALGORITHM", "Exciter", "reference_at"]

ALGORITHM = "excite"  # the name in controller_state.header.frame_id and the run's algorithms
_OPERATING_WINDOW_S = 0.5  # the operating voltage: mean command over the last 0.5 s of closed loop
_GUARD_TF_S = 0.01  # low-pass of the guarded output (the encoder speed is quantised)


def _quintic(s: float) -> tuple[float, float]:
    """q(s) = 10s³ − 15s⁴ + 6s⁵ and q'(s) on [0, 1] (rest to rest)."""
    if s <= 0.0:
        return 0.0, 0.0
    if s >= 1.0:
        return 1.0, 0.0
    return s**3 * (10.0 - 15.0 * s + 6.0 * s * s), 30.0 * s * s * (1.0 - s) ** 2


def _prbs_levels(seed: int, n: int) -> np.ndarray:
    """±1 levels, each kept or flipped with probability ½ per dwell (seeded)."""
    flips = np.random.default_rng(seed).integers(0, 2, n)
    return np.where(np.cumsum(flips) % 2 == 0, 1.0, -1.0)


def reference_at(
    seg: Segment, tau: float, y0: float, levels: np.ndarray | None
) -> tuple[float, float]:
    """Reference (r, ṙ) of a closed-loop segment ``tau`` s after it began at output ``y0``."""
    ref = seg.ref
    kind = ref["kind"]
    if kind == "move":
        T = ref["time"]
        q, dq = _quintic(tau / T)
        d = ref["target"] - y0
        return y0 + d * q, d * dq / T
    if kind == "ramp":
        d = ref["target"] - y0
        v = math.copysign(ref["speed"], d)
        if abs(v * tau) >= abs(d):
            return ref["target"], 0.0
        return y0 + v * tau, v
    if kind == "chirp":  # log sweep f0 -> f1 over the segment
        f0, f1, T = ref["f0"], ref["f1"], seg.duration_s
        k = math.log(f1 / f0) / T
        phase = 2.0 * math.pi * f0 * math.expm1(k * tau) / k
        f = f0 * math.exp(k * tau)
        a = ref["amplitude"]
        return ref["centre"] + a * math.sin(phase), a * 2.0 * math.pi * f * math.cos(phase)
    if kind == "prbs":
        i = min(int(tau / ref["dwell"]), len(levels) - 1)
        return ref["centre"] + ref["amplitude"] * levels[i], 0.0
    raise ValueError(f"reference kind: {kind!r} refused; allowed: move, ramp, chirp, prbs")


class Exciter:
    """One axis's excitation, a sample at a time (see the module docstring)."""

    algorithm = ALGORITHM

    def __init__(self, design: ExcitationDesign, sample_time_s: float = 1e-3):
        self.design = design
        self.axis = design.axis
        self._k = axis_scale(design.axis)  # SI -> mm | rpm
        g = design.gains
        self._pid_params = with_updates(
            AxisControllerParams(sample_time_s=sample_time_s),
            {
                "algorithm": "pid",
                "pid.kp": g.kp,
                "pid.ki": g.ki,
                "pid.kd": g.kd,
                "pid.y_filter_tf": g.y_filter_tf,
            },
        )
        self._T = sample_time_s
        self._a_guard = 1.0 - math.exp(-sample_time_s / _GUARD_TF_S)
        self._n_op = max(1, round(_OPERATING_WINDOW_S / sample_time_s))
        self._levels = {
            i: _prbs_levels(s.ref["seed"], int(math.ceil(s.duration_s / s.ref["dwell"])) + 1)
            for i, s in enumerate(design.segments)
            if s.kind == "closed" and s.ref.get("kind") == "prbs"
        }
        self.reset()

    def reset(self) -> None:
        """Back to before the first sample: no segment, neutral command, guards clear."""
        self._t0_ns: int | None = None
        self._seg = -1
        self._pid: Pid | None = None
        self._inp = StepInput()
        self._u = NEUTRAL_V
        self._recent: list[float] = []  # closed-loop commands (for the operating voltage)
        self._u_op = NEUTRAL_V
        self._u_start: float | None = None
        self._y0 = 0.0
        self._y_f = math.nan
        self._tripped = False
        self._t = 0.0
        self._y = math.nan
        self._r = self._rd = self._r_paper = math.nan
        self.guard_trips = 0

    @property
    def segment(self) -> int:
        """Index of the active segment (-1 before the first sample)."""
        return self._seg

    def _enter(self, i: int, y: float) -> None:
        prev = self.design.segments[self._seg] if self._seg >= 0 else None
        seg = self.design.segments[i]
        if prev is not None and prev.kind == "closed" and self._recent:
            self._u_op = float(np.mean(self._recent[-self._n_op :]))
        if seg.kind == "closed":
            if prev is None or prev.kind != "closed" or not math.isfinite(self._r_paper):
                self._y0 = y
                self._pid = None  # a fresh, bumpless start
                # the motor after a hold restarts from its last operating voltage, not
                # from the held one (a PI from 5 V would take seconds to wind up)
                rotary_restart = self.axis == "rotary" and prev is not None and prev.kind == "hold"
                self._u_start = self._u_op if rotary_restart else None
            else:
                self._y0 = self._r_paper  # continue from where the last reference ended
            self._recent = []
        self._tripped = False
        self._seg = i

    def update(self, sample: SensorSample) -> float:
        """The valve command (V) answering ``sample``."""
        if self._t0_ns is None:
            self._t0_ns = sample.stamp_ns
        t = (sample.stamp_ns - self._t0_ns) * 1e-9
        y_si = sample.x if self.axis == "linear" else sample.omega
        y = y_si * self._k
        self._t, self._y = t, y_si
        if not math.isfinite(y):  # hold the last command; the supervisor judges the sensor
            return self._u
        self._y_f = (
            y if not math.isfinite(self._y_f) else self._y_f + self._a_guard * (y - self._y_f)
        )
        i = self.design.segment_at(t)
        if i != self._seg:
            self._enter(i, y)
        seg = self.design.segments[i]
        tau = t - seg.t0_s
        self._r = self._rd = math.nan
        if seg.kind != "closed":
            self._r_paper = math.nan
        if seg.kind == "hold":
            u = seg.u
        elif seg.kind == "pulse":
            base = NEUTRAL_V if seg.base == "neutral" else self._u_op
            yg = y if self.axis == "linear" else self._y_f
            if not self._tripped and not (seg.guard_lo <= yg <= seg.guard_hi):
                self._tripped = True
                self.guard_trips += 1
            step = seg.u
            if seg.ladder:  # a flow ladder: its steps, then u
                i_step = int(tau / seg.ladder_s) if seg.ladder_s > 0.0 else len(seg.ladder)
                step = seg.ladder[i_step] if i_step < len(seg.ladder) else seg.u
            u = base if self._tripped else base + step
        else:
            r, rd = reference_at(seg, tau, self._y0, self._levels.get(i))
            self._r, self._rd, self._r_paper = r / self._k, rd / self._k, r
            inp = self._inp
            inp.y, inp.r, inp.r_dot, inp.r_ddot = y, r, rd, 0.0
            inp.u_applied = self._u - NEUTRAL_V
            if self._pid is None:
                self._pid = Pid(self._pid_params, self.axis)
                u0 = self._u if self._u_start is None else self._u_start
                u = NEUTRAL_V + self._pid.start(inp, u0 - NEUTRAL_V, (y, NAN, NAN))
            else:
                u = NEUTRAL_V + self._pid.update(inp)
            self._recent.append(u)
        u = min(max(u, 0.0), 10.0)
        self._u = u
        return u

    def state_values(self) -> tuple[float, ...]:
        """:data:`pneu_control.controller.axis.STATE_FIELDS` of the last update (SI; NaN off closed loop)."""
        err = self._r - self._y if math.isfinite(self._r) else math.nan
        return (
            self._t,
            self._r,
            self._rd,
            self._y,
            err,
            NAN,
            NAN,
            NAN,
            NAN,
            self._u,
            self._u,
        )
