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

Same spec and seed -> the in-process runner's numbers (tested); a ROS
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
    fill_diagnostic_array,
    typestore_messages,
)
from pneu_msgs_py.contract.topics import (
    CLOCK_TOPIC,
    CONTROLLER_STATE_TOPIC,
    DIAGNOSTICS_TOPIC,
    TOPIC_BY_NAME,
    VALVE_COMMAND_TOPIC,
)
from pneu_msgs_py.contract.wire import CommandWire, SensorWire, clock_bytes
from pneu_sim.cycle.rig_cycle import RigCycle
from pneu_sim.nodes.sim_core import safety_statuses
from pneu_sim.physics.plant import Plant

from pneu_control.analysis.metrics import WindowSpec
from pneu_control.controller.axis import STATE_FIELDS
from pneu_control.experiment.runner import (
    SAMPLE_FIELDS,
    RunResult,
    RunSpec,
    axis_metrics,
    fault_intervals_of,
)
from pneu_control.nodes.controller_core import ControllerShellCore

__all__ = ["run_loopback"]

_MEASURED = {"linear": "x", "rotary": "omega"}
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
    ts = typestore_messages()
    messages = [0, 0]  # count, bytes

    def send(topic: str, data: bytes) -> bytes:
        messages[0] += 1
        messages[1] += len(data)
        if tap is not None:
            tap(topic, TOPIC_BY_NAME[topic].ros_type, data)
        return data

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
    shells = {axis: ControllerShellCore(axis, spec.controllers[axis]) for axis in spec.axes}
    commands = {axis: CommandWire(axis) for axis in spec.axes}
    sensors = SensorWire()
    n = int(round(spec.duration_s / plant.T))
    drain = getattr(supervisor, "events", None)

    rec_samples = []
    rec_state: dict[str, list[tuple[float, ...]]] = {a: [] for a in spec.axes}
    rec_u: dict[str, list[float]] = {a: [] for a in spec.axes}
    rec_out: list[tuple[float, float]] = []
    events_all: list[Any] = []
    algorithms: dict[str, str] = {}
    t_wall = time.perf_counter()
    s = core.reset()
    for _ in range(n):
        if tap is not None:  # /clock first, as the sim node publishes it (nobody here reads it)
            send(CLOCK_TOPIC, clock_bytes(s.stamp_ns))
        wired = [(topic, send(topic, data)) for topic, data in sensors.encode(s)]
        for axis, shell in shells.items():
            for topic, data in wired:  # one publication order; the assembler copes with any
                if topic not in shell.topics:
                    continue
                out = shell.step_raw(topic, data)
                if out is None:
                    continue
                stamp, u = commands[axis].decode(send(VALVE_COMMAND_TOPIC[axis], out[0]))
                status = core.offer(axis, stamp, u)
                if status not in ("accepted", "silent", "invalid"):
                    raise RuntimeError(f"{axis}: answer to {stamp} ns {status}")
                state = ts.deserialize_cdr(
                    send(CONTROLLER_STATE_TOPIC[axis], out[1]), "sensor_msgs/msg/JointState"
                )
                st_stamp, alg, values = controller_state_from_msg(state)
                if st_stamp != stamp:
                    raise RuntimeError(f"{axis}: state stamped {st_stamp}, command {stamp}")
                rec_state[axis].append(tuple(values[f] for f in STATE_FIELDS))
                rec_u[axis].append(u)
                algorithms[axis] = alg
        rec_samples.append(s)
        if not core.complete:
            raise RuntimeError(f"lockstep: no answer from {core.waiting_for} to sample {s.k}")
        if drain is not None:
            events = drain()
            events_all.extend(events)
            if events and tap is not None:  # the sim node's /diagnostics for them
                send(DIAGNOSTICS_TOPIC, _diag_bytes(ts, s.stamp_ns, events))
        rec_out.append(core.held_pair)
        s = core.advance()
    wall = time.perf_counter() - t_wall

    t = np.array([r.stamp_ns for r in rec_samples], dtype=np.int64) * 1e-9
    samples = {
        f: np.array([getattr(r, f) for r in rec_samples], dtype=float) for f in SAMPLE_FIELDS
    }
    intervals = fault_intervals_of(spec, events_all, plant.T)
    axes: dict[str, dict[str, np.ndarray]] = {}
    metrics = {}
    m = len(rec_samples)
    for axis in spec.axes:
        block = np.array(rec_state[axis], dtype=float).reshape(m, len(STATE_FIELDS))
        cols = {name: block[:, i] for i, name in enumerate(STATE_FIELDS)}
        cols["u"] = np.array(rec_u[axis], dtype=float)
        axes[axis] = cols
        window = spec.windows.get(axis, WindowSpec(kind="fixed"))
        if m > 1:
            metrics[axis] = axis_metrics(
                axis,
                t,
                cols["reference"],
                samples[_MEASURED[axis]],
                window,
                intervals,
                spec.include_faults,
            )
    applied = np.array(rec_out, dtype=float).reshape(m, 2)
    result = RunResult(
        spec,
        t,
        samples,
        axes,
        algorithms,
        metrics,
        wall,
        applied={"linear": applied[:, 0], "rotary": applied[:, 1]},
        safety_events=events_all,
        fault_intervals=intervals,
        safety_counters=dict(getattr(supervisor, "counters", {}) or {}),
    )
    result.wire = {"messages": messages[0], "bytes": messages[1], **core.counters()}  # type: ignore[attr-defined]
    return result
