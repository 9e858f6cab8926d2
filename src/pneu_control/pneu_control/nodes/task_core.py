"""Per-sample work of the task runner node, without ROS: sensor CDR in, trajectories and
progress out.

The task logic is :class:`pneu_control.task.runner.TaskDriver` -- the one ``pneu task``
runs in process. Here it is fed from the topics and its decisions go out as messages:

1. :meth:`TaskShellCore.on_raw` -- the five sensor payloads of a tick rebuild the
   :class:`SensorSample` (:class:`~pneu_control.nodes.controller_core.TickDecoder`);
2. :meth:`TaskShellCore.step` -- ``TaskDriver.decide`` at that sample; a segment's
   start becomes a ``JointTrajectory`` of both joints
   (:func:`~pneu_control.controller.trajectory.to_stamped`: stamp = its start on the
   samples' clock) for the controllers, and every event a
   :class:`~pneu_msgs_py.contract.task_progress.TaskProgress` for the sim / driver
   (loads, e-stop) and people. In lockstep every sample is answered (``tick`` when
   nothing happened): the sim waits for it, so the task switches at the same samples
   as in process.

The task's time base starts at the first sample after ``start`` (autostart: the first
sample): t = (stamp − that stamp)·1e-9 s, as the runner's (its first sample is stamp 0).
A trip of the supervisor is seen on ``/diagnostics`` (a ``<node>: safety <axis> <rule>``
transition at level ERROR) and aborts the task, as in process -- over ROS a few samples later, since
``/diagnostics`` is not part of the lockstep.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pneu_msgs_py.contract.convert import DiagStatus
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.task_progress import TaskProgress
from pneu_msgs_py.contract.wire import SENSOR_TOPICS

from pneu_control.controller.trajectory import to_stamped
from pneu_control.nodes.controller_core import TickDecoder
from pneu_control.task.runner import TaskDriver, TaskEvent

__all__ = ["TaskShellCore", "is_trip"]

_OUTCOME = {"running": "running", "completed": "completed", "aborted": "aborted"}


def is_trip(status: DiagStatus) -> bool:
    """A supervisor transition that takes an axis safe: ERROR, named ``<node>: safety <axis>
    <rule>`` (:func:`pneu_sim.nodes.sim_core.safety_statuses`; the driver's alike). The
    nodes' 1 Hz state statuses (``<node>: safety <axis>``) are not transitions: before the
    first command an axis reads SAFE there, which no task must take for a trip."""
    if status.level != 2 or ": safety " not in status.name:
        return False
    return len(status.name.split(": safety ", 1)[1].split()) == 2


class _Recorded:
    """What the task node saw, as much of a run result as the report reads."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, float, float]] = []
        self.safety_events: list[Any] = []

    @property
    def t(self) -> np.ndarray:
        return np.array([r[0] for r in self.rows], dtype=float)

    @property
    def samples(self) -> dict[str, np.ndarray]:
        a = np.array(self.rows, dtype=float).reshape(-1, 3)
        return {"x": a[:, 1], "theta": a[:, 2]}


class _Event:  # a /diagnostics safety status as the report lists it
    def __init__(self, st: DiagStatus) -> None:
        self.level = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}[st.level]
        self.message = st.message or st.name


class TaskShellCore:
    """Everything the task runner node does per sample (see the module docstring)."""

    def __init__(self, prepared: Any, *, lockstep: bool, autostart: bool = True) -> None:
        p = prepared.spec.plant
        self.program = prepared.program
        self.driver = TaskDriver(
            prepared.program, A_c1=p.linear.A_c1, A_c2=p.linear.A_c2, p_a=p.ambient.p_a
        )
        self.lockstep = lockstep
        self.decoder = TickDecoder(SENSOR_TOPICS)
        self.state = "running" if autostart else "idle"
        self.base_ns: int | None = None  # the task's t = 0
        self.last: SensorSample | None = None
        self.tripped = False
        self._abort_reason = ""
        self.recorded = _Recorded()
        self.n_trajectories = 0

    @property
    def name(self) -> str:
        return self.program.name

    @property
    def finished(self) -> bool:
        return self.state == "finished"

    # -- requests ---------------------------------------------------------------
    def start(self) -> tuple[bool, str]:
        """``~/start``: the task starts at the next sample."""
        if self.state != "idle":
            return False, f"task {self.name} is {self.state}, not idle"
        self.state = "running"
        return True, f"task {self.name} starts at the next sample"

    def abort(self, reason: str = "service ~/abort") -> tuple[bool, str]:
        """``~/abort``: at the next sample the task ends with both valves safe."""
        if self.state == "finished":
            return False, f"task {self.name} already ended ({self.driver.outcome})"
        self._abort_reason = reason
        return True, f"task {self.name}: aborting ({reason}); both valves go safe"

    def on_diagnostics(self, statuses: list[DiagStatus]) -> None:
        """``/diagnostics``: a trip aborts a running task at the next sample."""
        for st in statuses:
            if not (": safety " in st.name and len(st.name.split(": safety ", 1)[1].split()) == 2):
                continue  # not a transition
            if st.level >= 1:
                self.recorded.safety_events.append(_Event(st))
            if is_trip(st):
                self.tripped = True

    # -- per sample -------------------------------------------------------------
    def on_raw(self, topic: str, data: bytes) -> tuple[list, list[TaskProgress]] | None:
        """One sensor payload; when its tick is complete, :meth:`step`'s answer."""
        s = self.decoder.on_raw(topic, data)
        return None if s is None else self.step(s)

    def step(self, s: SensorSample) -> tuple[list, list[TaskProgress]]:
        """The task at sample ``s``: (trajectories as (stamp_ns, joint names, points),
        progress events). Lockstep: at least one progress event (the sample's answer)."""
        self.last = s
        trajs: list = []
        progress: list[TaskProgress] = []
        if self.state == "running":
            if self.base_ns is None:
                self.base_ns = s.stamp_ns
            t = (s.stamp_ns - self.base_ns) * 1e-9
            self.recorded.rows.append((t, s.x, s.theta))
            d = self.driver
            events = d.abort(t, self._abort_reason) if self._abort_reason else []
            events = events or d.decide(t, s, self.tripped)
            for e in events:
                if e.kind == "start":
                    trajs.append(to_stamped(e.trajectory, self.base_ns))
                    self.n_trajectories += 1
                progress.append(self._progress(s.stamp_ns, e))
                if e.kind == "end":
                    self.state = "finished"
        elif self.state == "idle" and self.lockstep:
            progress.append(TaskProgress(s.stamp_ns, self.name, "idle", outcome="idle"))
        if self.lockstep and not progress and self.state != "finished":
            progress.append(self._progress(s.stamp_ns, None))
        return trajs, progress

    def _progress(self, stamp_ns: int, e: TaskEvent | None) -> TaskProgress:
        d = self.driver
        i = d.i if e is None else e.index
        label = self.program.segments[i].label if 0 <= i < len(self.program.segments) else ""
        kind = "tick" if e is None else ("end" if e.kind == "end" else e.kind)
        return TaskProgress(
            stamp_ns,
            self.name,
            kind,
            i,
            label,
            _OUTCOME.get(d.outcome, "interrupted"),
            e.reason if e is not None else "",
            {k: float(v) for k, v in e.loads.items()} if e is not None else {},
        )

    def status(self, stamp_ns: int) -> TaskProgress:
        """The task's state now (the node's periodic progress in realtime)."""
        return self._progress(stamp_ns, None)

    # -- the end ----------------------------------------------------------------
    def interrupted(self) -> None:
        """Shut down before the task ended: the running segment ends at the last sample."""
        if self.finished:
            return
        started = self.base_ns is not None and self.last is not None
        self.driver.interrupted((self.last.stamp_ns - self.base_ns) * 1e-9 if started else 0.0)

    def report(self) -> dict[str, Any]:
        """The task report (:func:`pneu_control.task.report.report_dict`) of what ran."""
        from pneu_control.task.report import path_errors, report_dict

        rec = self.recorded
        if rec.rows:
            path_errors(self.driver, rec)
        rep = report_dict(self.driver, rec)
        rep["source_of_record"] = "task runner node (the samples it received)"
        rep["trajectories_published"] = self.n_trajectories
        return rep
