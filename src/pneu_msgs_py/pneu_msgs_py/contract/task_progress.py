"""The task runner's progress on ``/pneu/task/progress``: one status per event, as plain data.

A ``diagnostic_msgs/msg/DiagnosticArray`` with one status (``header.stamp`` = the stamp
of the sample the event answers): name ``task: <name>``, level 0 (running, reached,
completed), 1 (a segment timed out and the task goes on) or 2 (aborted), a one-line
message, and the values below. The sim node and the driver read it
(:meth:`TaskProgress.from_status`): ``aborted`` latches their supervisor's e-stop (both
valves at 5 V), the sim sets the twin's ``load.*`` values a segment names. In lockstep
the task runner answers every sample with one (``event: tick`` when nothing happened)
and the sim waits for it before it advances, as it waits for the controllers' commands:
so a task over ROS switches segments, loads and the e-stop at the same samples as
``pneu task`` in process.

Values (all str): ``event`` (:data:`EVENTS`), ``index`` (the segment, 0-based; -1 before
the first), ``segment`` (its label), ``outcome`` (:data:`OUTCOMES`), ``reason`` (why it
was aborted), ``load.<field>`` (the twin's ``load.*`` values set at a segment's start,
SI, ``repr`` of the float: exact both ways).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from pneu_msgs_py.contract.convert import DiagStatus

__all__ = ["EVENTS", "OUTCOMES", "TaskProgress"]

#: tick: nothing happened at this sample (lockstep's per-sample answer); idle: loaded,
#: waiting for ~/start; start: a segment starts; reached / timeout: a segment ends;
#: aborted: the task stopped with both valves safe; end: the task is over (``outcome``).
EVENTS = ("tick", "idle", "start", "reached", "timeout", "aborted", "end")
OUTCOMES = ("idle", "running", "completed", "aborted", "interrupted")
_PREFIX = "task: "
_LEVEL = {"timeout": 1, "aborted": 2}


@dataclass(frozen=True)
class TaskProgress:
    """One progress event of a task (see the module docstring)."""

    stamp_ns: int
    task: str
    event: str
    index: int = -1
    segment: str = ""
    outcome: str = "running"
    reason: str = ""
    loads: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.event not in EVENTS:
            raise ValueError(f"task progress event: {self.event!r}; allowed: {', '.join(EVENTS)}")
        if self.outcome not in OUTCOMES:
            raise ValueError(
                f"task progress outcome: {self.outcome!r}; allowed: {', '.join(OUTCOMES)}"
            )
        for k, v in self.loads.items():
            if not isinstance(v, float) or not math.isfinite(v):
                raise ValueError(f"task progress load.{k}: {v!r}; allowed: a finite float (SI)")

    @property
    def final(self) -> bool:
        """The last event of a task: nothing follows it."""
        return self.event == "end"

    def to_status(self) -> DiagStatus:
        values = {
            "event": self.event,
            "index": str(self.index),
            "segment": self.segment,
            "outcome": self.outcome,
            "reason": self.reason,
        }
        values.update({f"load.{k}": repr(v) for k, v in self.loads.items()})
        where = f"segment {self.index + 1} {self.segment}" if self.index >= 0 else "no segment"
        message = f"{self.event}: {where}" + (f" ({self.reason})" if self.reason else "")
        if self.event == "end":
            message = f"end: {self.outcome}" + (f" ({self.reason})" if self.reason else "")
        return DiagStatus(_LEVEL.get(self.event, 0), _PREFIX + self.task, message, "pneu", values)

    @classmethod
    def from_status(cls, stamp_ns: int, status: DiagStatus) -> TaskProgress:
        """The event of a status :meth:`to_status` made; ValueError on anything else."""
        if not status.name.startswith(_PREFIX):
            raise ValueError(f"task progress: status {status.name!r} is not 'task: <name>'")
        v = status.values
        try:
            loads = {k[5:]: float(x) for k, x in v.items() if k.startswith("load.")}
            return cls(
                int(stamp_ns),
                status.name[len(_PREFIX) :],
                v["event"],
                int(v.get("index", "-1")),
                v.get("segment", ""),
                v.get("outcome", "running"),
                v.get("reason", ""),
                loads,
            )
        except KeyError as err:
            raise ValueError(f"task progress: no {err.args[0]!r} value") from None
