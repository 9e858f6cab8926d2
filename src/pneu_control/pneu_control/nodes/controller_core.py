"""Per-sample work of a controller node, without ROS: messages in, core, messages out.

The rclpy node (:mod:`pneu_control.nodes.controller_node`) only subscribes,
publishes and declares parameters; everything it does per sample is here, so
it is tested and benchmarked without rclpy (with rosbags' Jazzy message
classes, which have rclpy's fields):

1. :meth:`ControllerShellCore.on_message` -- collect the five sensor messages
   of one tick (three FluidPressure, two JointState, published separately and
   possibly interleaved across topics) by stamp; when a tick is complete,
   rebuild the :class:`SensorSample` (:func:`pneu_msgs_py.contract.convert.sample_from_msgs`);
2. :meth:`ControllerShellCore.update` -- ``AxisController.update``;
3. :meth:`ControllerShellCore.fill_outputs` -- the valve command (stamped with
   the sample it answers) and the controller state (every sample).

The controller sees the whole sample, as in the in-process runner, so a
lockstep ROS run gives the runner's numbers.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pneu_msgs_py.contract.convert import (
    DiagStatus,
    fill_controller_state,
    fill_valve_command,
    sample_from_msgs,
    stamp_to_ns,
)
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import JOINT_STATE_TOPIC, PRESSURE_TOPICS

from pneu_control.controller.axis import STATE_FIELDS, AxisController

__all__ = [
    "SENSOR_TOPICS",
    "SampleAssembler",
    "ControllerShellCore",
]

#: The five topics one sample is published on, in the order the sim and driver publish them.
SENSOR_TOPICS: tuple[str, ...] = (
    *PRESSURE_TOPICS,
    JOINT_STATE_TOPIC["linear"],
    JOINT_STATE_TOPIC["rotary"],
)
_P_TOPICS = tuple(PRESSURE_TOPICS)


class SampleAssembler:
    """Groups the sensor messages of one tick by ``header.stamp``.

    A tick is emitted once all five topics have a message with its stamp.
    A message with a newer stamp abandons an incomplete older tick (counted in
    :attr:`incomplete`: a lost best-effort message); a message older than the
    tick being collected is dropped (:attr:`late`).
    """

    __slots__ = ("_msgs", "_stamp", "emitted", "incomplete", "late")

    def __init__(self) -> None:
        self._stamp = -1
        self._msgs: dict[str, Any] = {}
        self.emitted = 0
        self.incomplete = 0
        self.late = 0

    def add(self, topic: str, msg: Any) -> dict[str, Any] | None:
        """Add one message; returns ``{topic: msg}`` of a complete tick, else None."""
        stamp = stamp_to_ns(msg.header.stamp)
        if stamp != self._stamp:
            if stamp < self._stamp:
                self.late += 1
                return None
            if self._msgs:
                self.incomplete += 1
            self._stamp = stamp
            self._msgs = {}
        self._msgs[topic] = msg
        if len(self._msgs) < len(SENSOR_TOPICS):
            return None
        done, self._msgs = self._msgs, {}
        self.emitted += 1
        return done


class ControllerShellCore:
    """Everything a controller node does per sample (see the module docstring)."""

    def __init__(self, axis: str, params: Any):
        self.axis = axis
        self.controller = AxisController(axis, params)
        self.assembler = SampleAssembler()
        self.n_samples = 0
        self.n_saturated = 0
        self.last_stamp_ns = -1
        self.last_u = float("nan")
        self.param_changes = 0

    @property
    def params(self) -> Any:
        return self.controller.params

    def set_params(self, params: Any) -> None:
        """Validated new set; takes effect at the next sample (bumpless, by the core)."""
        self.controller.set_params(params)
        self.param_changes += 1

    # -- per sample -------------------------------------------------------
    def on_message(self, topic: str, msg: Any) -> SensorSample | None:
        """One sensor message in; the rebuilt sample when its tick is complete."""
        tick = self.assembler.add(topic, msg)
        if tick is None:
            return None
        p = _P_TOPICS
        return sample_from_msgs(
            self.n_samples,
            tick[p[0]],
            tick[p[1]],
            tick[p[2]],
            tick[SENSOR_TOPICS[3]],
            tick[SENSOR_TOPICS[4]],
        )

    def update(self, sample: SensorSample) -> float:
        """``AxisController.update``; returns the valve command (V)."""
        u = self.controller.update(sample)
        self.n_samples += 1
        self.last_stamp_ns = sample.stamp_ns
        self.last_u = u
        lim = self.controller.params.limits
        if u <= lim.u_min or u >= lim.u_max:
            self.n_saturated += 1
        return u

    def fill_outputs(self, cmd_msg: Any, state_msg: Any, stamp_ns: int, u: float) -> None:
        """Valve command (stamp = the answered sample) and controller state, in place."""
        fill_valve_command(cmd_msg, self.axis, stamp_ns, u)
        fill_controller_state(
            state_msg,
            stamp_ns,
            STATE_FIELDS,
            self.controller.state_values(),
            self.controller.algorithm,
        )

    def step(self, topic: str, msg: Any, cmd_msg: Any, state_msg: Any) -> bool:
        """The whole per-message path; True when a command was computed into ``cmd_msg``."""
        s = self.on_message(topic, msg)
        if s is None:
            return False
        u = self.update(s)
        self.fill_outputs(cmd_msg, state_msg, s.stamp_ns, u)
        return True

    # -- reports ----------------------------------------------------------
    def diagnostics(self, node_name: str) -> list[DiagStatus]:
        """One ``/diagnostics`` status: OK, or WARN when ticks were lost or inputs non-finite."""
        a = self.assembler
        nonfinite = self.controller.n_nonfinite
        level = 1 if (a.incomplete or a.late or nonfinite) else 0
        msg = "running" if self.n_samples else "waiting for samples"
        if level:
            msg = f"{a.incomplete} incomplete / {a.late} late ticks, {nonfinite} non-finite inputs"
        return [
            DiagStatus(
                level=level,
                name=f"{node_name}: {self.axis} controller",
                message=msg,
                hardware_id="pneu",
                values={
                    "algorithm": self.controller.algorithm,
                    "samples": str(self.n_samples),
                    "incomplete_ticks": str(a.incomplete),
                    "late_messages": str(a.late),
                    "nonfinite_inputs": str(nonfinite),
                    "saturated_samples": str(self.n_saturated),
                    "last_stamp_ns": str(self.last_stamp_ns),
                    "last_command_v": f"{self.last_u:.6g}",
                    "parameter_changes": str(self.param_changes),
                },
            )
        ]


def new_sensor_messages(types: Mapping[str, Any]) -> dict[str, Any]:
    """Empty FluidPressure/JointState messages per sensor topic from a ``{ros_type: class}`` map."""
    return {
        topic: _new(
            types,
            "sensor_msgs/msg/FluidPressure"
            if topic in PRESSURE_TOPICS
            else "sensor_msgs/msg/JointState",
        )
        for topic in SENSOR_TOPICS
    }


def _new(types: Mapping[str, Any], name: str) -> Any:
    """A default-constructed message of a rosbags typestore class (all fields required there)."""
    import numpy as np

    cls = types[name]
    Time = types["builtin_interfaces/msg/Time"]
    Header = types["std_msgs/msg/Header"]
    header = Header(stamp=Time(sec=0, nanosec=0), frame_id="")
    if name == "sensor_msgs/msg/FluidPressure":
        return cls(header=header, fluid_pressure=0.0, variance=0.0)
    empty = np.zeros(0)
    return cls(header=header, name=[], position=empty, velocity=empty, effort=empty)
