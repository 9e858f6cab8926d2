"""A task on the twin: the runner's own control cycle, the segments switched by a hook.

:class:`TaskDriver` is the runner's per-cycle hook
(:func:`pneu_control.experiment.runner.run`): at each sample it checks what ends the
current segment (:mod:`.program`), and on a segment's start it sets the twin's loads
and gives each axis controller its reference for the segment
(:meth:`~pneu_control.controller.axis.AxisController.set_reference`: a smooth step of
the rod or the angle, a ramp of the angle, a helix as a joint trajectory, or a hold).
So a task is one run: one bag, one supervisor, the same cycle as every experiment.
A timeout with ``on_timeout: abort`` (or a safety trip) ends the task safe: the
supervisor's e-stop holds both valves at 5 V for :data:`SAFE_TAIL_S`, then the run
ends. The report lists every segment: reached or not, when, how long, the joints'
errors to its targets at its end (and the path error of a helix).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from pneu_msgs_py.contract.units import DEG_PER_RAD, MM_PER_M

from pneu_control.controller.trajectory import from_stamped, references, to_stamped
from pneu_control.task.program import SAFE_TAIL_S, Segment, TaskProgram

__all__ = [
    "SAFE_TAIL_S",
    "START_DELAY_S",
    "segment_references",
    "SegmentResult",
    "TaskDriver",
    "TaskEvent",
    "rod_force",
]

# a segment's trajectory starts this long after the sample that started it: time for a
# trajectory published over ROS to reach the controllers (the in-process runner waits too,
# so both give the same numbers)
START_DELAY_S = 0.01


def rod_force(p_c1: float, p_c2: float, A_c1: float, A_c2: float, p_a: float) -> float:
    """Net pneumatic force on the rod (N): Eq. 2's p_c1 A_c1 − p_c2 A_c2 − p_a (A_c1 − A_c2)."""
    return p_c1 * A_c1 - p_c2 * A_c2 - p_a * (A_c1 - A_c2)


@dataclass
class SegmentResult:
    """What one segment did (report units: s, mm, °)."""

    index: int
    kind: str
    name: str
    reached: bool = False
    status: str = "not started"  # reached | timeout | aborted | interrupted | not started
    t_start_s: float = math.nan
    t_end_s: float = math.nan
    error_mm: float = math.nan  # linear target − measured at the segment's end
    error_deg: float = math.nan  # rotary target − measured
    path_error_max_mm: float = math.nan
    path_error_rms_mm: float = math.nan
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return self.t_end_s - self.t_start_s


@dataclass(frozen=True)
class TaskEvent:
    """One thing a task decided at a sample (:meth:`TaskDriver.decide`).

    ``kind``: ``start`` (segment ``index`` starts: its ``trajectory`` of both joints and
    the twin's ``loads``, plant short names), ``reached`` / ``timeout`` (it ended),
    ``aborted`` (both valves safe: the supervisor's e-stop, ``reason``), ``end`` (the
    run stops here; the outcome is :attr:`TaskDriver.outcome`).
    """

    kind: str
    index: int
    trajectory: Any = None
    loads: dict[str, float] = field(default_factory=dict)
    reason: str = ""


class TaskDriver:
    """Runs ``program``: :meth:`decide` per sample (ROS-free, no side effects; the task node
    publishes what it decides), and, in process, the runner's hook
    (``driver(k, s, cycle, controllers)``) that carries it out on the twin."""

    def __init__(self, program: TaskProgram, *, A_c1: float, A_c2: float, p_a: float):
        self.program = program
        self.results = [SegmentResult(s.index, s.kind, s.name) for s in program.segments]
        self.i = -1  # the current segment
        self.t_seg = 0.0
        self.t_settled: float | None = None
        self.t_stop: float | None = None  # after an abort: when the run ends
        self.outcome = "running"  # completed | aborted | interrupted
        self.reason = ""
        self._areas = (A_c1, A_c2, p_a)

    # -- the hook ---------------------------------------------------------------
    def __call__(self, k: int, s: Any, cycle: Any, ctrls: dict[str, Any]) -> bool:
        sup = cycle.supervisor
        # the controllers' time base: their first sample is stamp 0
        events = self.decide(s.stamp_ns * 1e-9, s, sup is not None and sup.tripped)
        for e in events:
            if e.kind == "start":
                if e.loads and hasattr(cycle.plant, "set_load"):
                    cycle.plant.set_load(**e.loads)
                for axis, ref in references(e.trajectory).items():
                    if axis in ctrls:
                        ctrls[axis].set_reference(ref, start_s=e.trajectory.t_start)
            elif e.kind == "aborted" and sup is not None:
                sup.estop(f"task aborted: {e.reason}")  # both valves safe (5 V)
        return any(e.kind == "end" for e in events)

    # -- the decisions ----------------------------------------------------------------
    def decide(self, t: float, s: Any, tripped: bool) -> list[TaskEvent]:
        """What happens at sample ``s`` (time ``t`` s on the task's time base; ``tripped``:
        the supervisor holds an axis safe)."""
        if self.t_stop is not None:  # aborted: the safe tail, then the end
            if t >= self.t_stop:
                self.t_stop = math.inf
                return [TaskEvent("end", self.i)]
            return []
        if self.outcome != "running":
            return []
        if tripped and self.i >= 0:
            return self._abort(t, "safety: the supervisor took an axis safe")
        if self.i < 0:
            return [self._start(0, t)]
        seg = self.program.segments[self.i]
        if self._done(seg, t, s):
            self._finish(seg, t, s, "reached")
            return [TaskEvent("reached", seg.index), *self._next(t)]
        if t - self.t_seg >= seg.timeout_s:
            self._finish(seg, t, s, "timeout")
            if seg.on_timeout == "abort":
                return [
                    TaskEvent("timeout", seg.index),
                    *self._abort(t, f"{seg.label}: timeout after {seg.timeout_s:g} s"),
                ]
            return [TaskEvent("timeout", seg.index), *self._next(t)]
        return []

    def abort(self, t: float, reason: str) -> list[TaskEvent]:
        """Abort a running task now (a user's request): both valves safe, the safe tail."""
        if self.t_stop is not None or self.outcome != "running":
            return []
        return self._abort(t, reason)

    def interrupted(self, t: float) -> None:
        """The run stopped on a signal: the running segment ends there."""
        if self.outcome == "running":
            self.outcome = "interrupted"
            if 0 <= self.i < len(self.results) and self.results[self.i].status == "running":
                self.results[self.i].status = "interrupted"
                self.results[self.i].t_end_s = t

    # -- segments ---------------------------------------------------------------
    def _next(self, t: float) -> list[TaskEvent]:
        if self.i + 1 >= len(self.program.segments):
            self.outcome = "completed"
            return [TaskEvent("end", self.i)]
        return [self._start(self.i + 1, t)]

    def _start(self, i: int, t: float) -> TaskEvent:
        from pneu_control.task.plan import segment_trajectory

        seg = self.program.segments[i]
        self.i, self.t_seg, self.t_settled = i, t, None
        res = self.results[i]
        res.status, res.t_start_s = "running", t
        # on the integer-ns grid a ROS message carries, so over ROS the bits are the same
        traj = from_stamped(*to_stamped(segment_trajectory(seg, t + START_DELAY_S), 0), 0)
        return TaskEvent("start", i, traj, _load_kwargs(seg.load))

    def _done(self, seg: Segment, t: float, s: Any) -> bool:
        u = seg.until
        kind = u["kind"]
        if kind == "time":
            return t - self.t_seg >= seg.duration_s + START_DELAY_S
        if kind == "pressure":
            v = getattr(s, u["sensor"])
            return v > u["value"] if u["side"] == "above" else v < u["value"]
        if kind == "force":
            f = rod_force(s.p_c1, s.p_c2, *self._areas)
            return f > u["value"] if u["side"] == "above" else f < u["value"]
        # settled: both joints within tolerance of the targets, for for_s, after the motion
        if t - self.t_seg < seg.duration_s + START_DELAY_S:
            return False
        ok = abs(seg.x_end - s.x) * MM_PER_M <= u["tol_mm"] and (
            abs(seg.theta_end - s.theta) * DEG_PER_RAD <= u["tol_deg"]
        )
        if not ok:
            self.t_settled = None
            return False
        if self.t_settled is None:
            self.t_settled = t
        return t - self.t_settled >= u["for_s"]

    def _finish(self, seg: Segment, t: float, s: Any, status: str) -> None:
        res = self.results[seg.index]
        res.status, res.reached, res.t_end_s = status, status == "reached", t
        res.error_mm = (seg.x_end - s.x) * MM_PER_M
        res.error_deg = (seg.theta_end - s.theta) * DEG_PER_RAD

    def _abort(self, t: float, reason: str) -> list[TaskEvent]:
        if 0 <= self.i < len(self.results) and self.results[self.i].status == "running":
            self.results[self.i].status = "aborted"
            self.results[self.i].t_end_s = t
        self.outcome, self.reason = "aborted", reason
        self.t_stop = t + SAFE_TAIL_S
        return [TaskEvent("aborted", self.i, reason=reason)]


def _load_kwargs(load: dict[str, Any]) -> dict[str, Any]:
    """Load names (``T_bk`` or ``load.T_bk``, checked by the task session) as the plant's
    set_load keywords."""
    return {key.rsplit(".", 1)[-1]: value for key, value in load.items()}


def segment_references(seg: Segment, t0: float) -> dict[str, Any]:
    """Each joint's reference (SI: m, rad; t on the controllers' time base) for ``seg``."""
    from pneu_control.task.plan import segment_trajectory

    return dict(references(segment_trajectory(seg, t0 + START_DELAY_S)))
