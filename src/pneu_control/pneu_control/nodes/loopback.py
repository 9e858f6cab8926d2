"""The ROS lockstep graph without ROS: the sim's cycle and the controller shell cores over CDR.

:func:`run_loopback` runs a :class:`~pneu_control.experiment.runner.RunSpec` exactly as
``ros2 launch pneu_sim sim.launch.py mode:=lockstep`` does, minus the
middleware: the sim node's :class:`pneu_sim.cycle.rig_cycle.RigCycle`
publishes each sample as the five sensor payloads of
:class:`pneu_msgs_py.contract.wire.SensorWire` (the bytes the sim node puts on
the wire), each active controller's
:class:`~pneu_control.nodes.controller_core.ControllerShellCore` takes the
payloads of its input topics, rebuilds the sample, computes and answers with
a valve command stamped with the sample's stamp, and the cycle advances when
every active axis has answered. The controller states are read back with
rosbags' Jazzy typestore (an independent decoder). What is recorded is what
the logger would see on the topics (``tap``).

With ``task`` (a :class:`~pneu_control.task.session.PreparedTask`) the task runner
node's core takes part as it does over ROS: it reads the five sensor payloads first,
its trajectories (``/pneu/joint_trajectory``, CDR) reach the controllers only after
they answered that sample (the worst order ROS can deliver them in; the trajectory's
start :data:`~pneu_control.task.runner.START_DELAY_S` later covers it), its progress
(``/pneu/task/progress``) goes to the sim's :class:`~pneu_sim.nodes.sim_core.TaskGate`
(loads, e-stop), the sim's ``/diagnostics`` back to it; the run ends at the task's end.

Same spec and seed -> the in-process runner's numbers (tested), a task's too; a ROS
lockstep run adds only transport, so it must give them too (the rclpy test
in ``test/ros`` checks that on a ROS machine).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from pneu_msgs_py.contract.convert import (
    controller_state_from_msg,
    diag_statuses_from_msg,
    diagnostics_to_typestore,
    fill_diagnostic_array,
    joint_trajectory_from_msg,
    joint_trajectory_to_typestore,
    typestore_messages,
)
from pneu_msgs_py.contract.topics import (
    CLOCK_TOPIC,
    CONTROLLER_STATE_TOPIC,
    DIAGNOSTICS_TOPIC,
    TASK_PROGRESS_TOPIC,
    TOPIC_BY_NAME,
    TRAJECTORY_TOPIC,
    VALVE_COMMAND_TOPIC,
)
from pneu_msgs_py.contract.wire import CommandWire, SensorWire, clock_bytes
from pneu_sim.cycle.rig_cycle import RigCycle
from pneu_sim.nodes.sim_core import TaskGate, TaskParams, safety_statuses
from pneu_sim.physics.plant import Plant

from pneu_control.controller.axis import STATE_FIELDS
from pneu_control.experiment.runner import SAMPLE_FIELDS, RunResult, RunSpec, result_of
from pneu_control.nodes.controller_core import ControllerShellCore

__all__ = ["run_loopback"]

_DIAG = "diagnostic_msgs/msg/DiagnosticArray"


def _diag_bytes(ts: Any, stamp_ns: int, events: list[Any]) -> bytes:
    """The DiagnosticArray the sim node publishes for supervisor transitions, as CDR."""
    types = ts.types
    Time, Header = types["builtin_interfaces/msg/Time"], types["std_msgs/msg/Header"]
    msg = types[_DIAG](header=Header(stamp=Time(sec=0, nanosec=0), frame_id=""), status=[])
    status = types["diagnostic_msgs/msg/DiagnosticStatus"]
    kv = types["diagnostic_msgs/msg/KeyValue"]
    fill_diagnostic_array(
        msg,
        lambda: status(level=0, name="", message="", hardware_id="", values=[]),
        lambda: kv(key="", value=""),
        stamp_ns,
        safety_statuses("pneu_sim", events),
    )
    return bytes(ts.serialize_cdr(msg, _DIAG))


def run_loopback(
    spec: RunSpec,
    *,
    supervisor: Any | None = None,
    tap: Callable[[str, str, bytes], None] | None = None,
    task: Any | None = None,
) -> RunResult:
    """Run ``spec`` through the shells' per-sample code and CDR (see module docstring).

    As the sim node does: the SafetySupervisor of ``spec.safety`` (unless
    ``supervisor`` is given) and ``spec.faults`` act in the runner's order.
    Controller faults are emulated where the sim sees them: a muted
    controller's answer is dropped, a NaN one replaced -- the controller core
    itself keeps running (the runner's skips the muted samples), so with
    ``controller_silent`` the two differ after the fault. ``tap(topic,
    ros_type, data)`` receives every message as published, in publication
    order, ``/clock`` included (e.g. a :class:`LoggerCore`).
    """
    plant = Plant(spec.plant, seed=spec.seed)
    if supervisor is None and spec.safety is not None:
        from pneu_driver.safety import SafetySupervisor

        supervisor = SafetySupervisor(spec.safety, sample_time_s=plant.T)
    core = RigCycle(
        plant,
        axes=tuple(spec.axes),
        x0=spec.x0,
        supervisor=supervisor,
        faults=spec.faults,
        seed=spec.seed,
    )
    loop = _Lockstep(spec, core, supervisor, tap)
    if task is not None:
        from pneu_control.nodes.task_core import TaskShellCore

        loop.task = TaskShellCore(task, lockstep=True)
        loop.gate = TaskGate(core, TaskParams(wait=True, ends_run=True))
    t_wall = time.perf_counter()
    loop.run(int(round(spec.duration_s / plant.T)))
    wall = time.perf_counter() - t_wall
    result = loop.result(plant.T, wall)
    result.wire = {"messages": loop.messages, "bytes": loop.bytes, **core.counters()}  # type: ignore[attr-defined]
    result.task = loop.task  # type: ignore[attr-defined]
    return result


class _Lockstep:
    """The sim's cycle and the controller shell cores of one loopback run, and what it recorded."""

    def __init__(
        self,
        spec: RunSpec,
        core: RigCycle,
        supervisor: Any | None,
        tap: Callable[[str, str, bytes], None] | None,
    ) -> None:
        self.spec, self.core, self.supervisor, self.tap = spec, core, supervisor, tap
        self.ts = typestore_messages()
        self.messages = 0
        self.bytes = 0
        self.shells = {
            axis: ControllerShellCore(axis, spec.controllers[axis]) for axis in spec.axes
        }
        self.commands = {axis: CommandWire(axis) for axis in spec.axes}
        self.sensors = SensorWire()
        self.drain = getattr(supervisor, "events", None)
        self.rec_samples: list[Any] = []
        self.rec_state: dict[str, list[tuple[float, ...]]] = {a: [] for a in spec.axes}
        self.rec_u: dict[str, list[float]] = {a: [] for a in spec.axes}
        self.rec_out: list[tuple[float, float]] = []
        self.events: list[Any] = []
        self.algorithms: dict[str, str] = {}
        self.task: Any = None  # a TaskShellCore
        self.gate: TaskGate | None = None

    def send(self, topic: str, data: bytes) -> bytes:
        """Publish ``data`` on ``topic``: count it and hand it to the tap."""
        self.messages += 1
        self.bytes += len(data)
        if self.tap is not None:
            self.tap(topic, TOPIC_BY_NAME[topic].ros_type, data)
        return data

    def run(self, n: int) -> None:
        """``n`` lockstep cycles from the cycle's reset."""
        core, send = self.core, self.send
        s = core.reset()
        for _ in range(n):
            if self.tap is not None:  # /clock first, as the sim node publishes it (nobody reads it)
                send(CLOCK_TOPIC, clock_bytes(s.stamp_ns))
            wired = [(topic, send(topic, data)) for topic, data in self.sensors.encode(s)]
            trajectories = self.task_answers(s, wired) if self.task is not None else []
            if self.gate is not None and self.gate.ended:
                break  # the task's end: this sample is not run (as the in-process runner)
            for axis, shell in self.shells.items():
                for topic, data in wired:  # one publication order; the assembler copes with any
                    if topic in shell.topics:
                        self.answer(axis, shell.step_raw(topic, data))
            for data in trajectories:  # after the controllers answered: the latest delivery
                stamp, names, points = joint_trajectory_from_msg(
                    self.ts.deserialize_cdr(data, "trajectory_msgs/msg/JointTrajectory")
                )
                for shell in self.shells.values():
                    shell.on_trajectory(stamp, names, points)
            self.rec_samples.append(s)
            if not core.complete:
                raise RuntimeError(f"lockstep: no answer from {core.waiting_for} to sample {s.k}")
            if self.drain is not None:
                events = self.drain()
                self.events.extend(events)
                if events and (self.tap is not None or self.task is not None):
                    data = _diag_bytes(self.ts, s.stamp_ns, events)  # the sim node's /diagnostics
                    send(DIAGNOSTICS_TOPIC, data)
                    if self.task is not None:
                        msg = self.ts.deserialize_cdr(data, _DIAG)
                        self.task.on_diagnostics(diag_statuses_from_msg(msg))
            self.rec_out.append(core.held_pair)
            s = core.advance()

    def task_answers(self, s: Any, wired: list[tuple[str, bytes]]) -> list[bytes]:
        """The task runner's answer to sample ``s``: its progress to the sim's gate (CDR both
        ways), its trajectories as CDR (returned: delivered after the controllers answered)."""
        out = None
        for topic, data in wired:
            out = self.task.on_raw(topic, data) or out
        trajs, progress = out
        msgs = [
            self.send(
                TRAJECTORY_TOPIC,
                bytes(
                    self.ts.serialize_cdr(
                        joint_trajectory_to_typestore(*t), "trajectory_msgs/msg/JointTrajectory"
                    )
                ),
            )
            for t in trajs
        ]
        arr = diagnostics_to_typestore(s.stamp_ns, [p.to_status() for p in progress])
        data = self.send(TASK_PROGRESS_TOPIC, bytes(self.ts.serialize_cdr(arr, _DIAG)))
        back = self.ts.deserialize_cdr(data, _DIAG)
        self.gate.on_progress(s.stamp_ns, diag_statuses_from_msg(back))
        if not self.gate.complete:
            raise RuntimeError(f"lockstep: no task progress for sample {s.k}")
        return msgs

    def answer(self, axis: str, out: tuple[bytes, bytes] | None) -> None:
        """A shell's (command, state) payloads, if it answered: offered to the cycle, recorded."""
        if out is None:
            return
        stamp, u = self.commands[axis].decode(self.send(VALVE_COMMAND_TOPIC[axis], out[0]))
        status = self.core.offer(axis, stamp, u)
        if status not in ("accepted", "silent", "invalid"):
            raise RuntimeError(f"{axis}: answer to {stamp} ns {status}")
        state = self.ts.deserialize_cdr(
            self.send(CONTROLLER_STATE_TOPIC[axis], out[1]), "sensor_msgs/msg/JointState"
        )
        st_stamp, alg, values = controller_state_from_msg(state)
        if st_stamp != stamp:
            raise RuntimeError(f"{axis}: state stamped {st_stamp}, command {stamp}")
        self.rec_state[axis].append(tuple(values[f] for f in STATE_FIELDS))
        self.rec_u[axis].append(u)
        self.algorithms[axis] = alg

    def result(self, period_s: float, wall_s: float) -> RunResult:
        """The recorded cycles as the runner's :class:`RunResult` (same intervals and metrics)."""
        rec = self.rec_samples
        m = len(rec)
        t = np.array([r.stamp_ns for r in rec], dtype=np.int64) * 1e-9
        samples = {f: np.array([getattr(r, f) for r in rec], dtype=float) for f in SAMPLE_FIELDS}
        axes: dict[str, dict[str, np.ndarray]] = {}
        for axis in self.spec.axes:
            block = np.array(self.rec_state[axis], dtype=float).reshape(m, len(STATE_FIELDS))
            cols = {name: block[:, i] for i, name in enumerate(STATE_FIELDS)}
            cols["u"] = np.array(self.rec_u[axis], dtype=float)
            axes[axis] = cols
        held = np.array(self.rec_out, dtype=float).reshape(m, 2)
        counters = dict(getattr(self.supervisor, "counters", {}) or {})
        return result_of(
            self.spec,
            t,
            samples,
            axes,
            held,
            self.events,
            counters,
            period_s,
            wall_s,
            algorithms=self.algorithms,
        )
