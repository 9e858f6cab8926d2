"""``ros2 run pneu_control exciter``: the excitation experiment over ROS (rclpy shell).

Stands where the controller nodes stand: per complete tick of the five
sensor topics, each active axis's designed valve command (stamped with the
sample it answers) and its state (``/pneu/<axis>/controller_state``, frame
``excite``) -- :class:`~pneu_control.nodes.exciter_core.ExciterShellCore`.
Against the sim node (lockstep or realtime) or the driver (the rig). The
design goes into the read-only parameter ``design_json``, which the logger
records (``pneu.params/pneu_exciter``) for ``pneu identify``. After the
design it keeps answering with its last segment (the valves held at 5 V);
the sim's ``duration_s`` or Ctrl-C ends the run.
"""

from __future__ import annotations

import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from pneu_msgs_py.contract.convert import fill_diagnostic_array
from pneu_msgs_py.contract.qos import DIAGNOSTICS, to_rclpy
from pneu_msgs_py.contract.samples import NEUTRAL_V
from pneu_msgs_py.contract.topics import (
    CONTROLLER_STATE_TOPIC,
    DIAGNOSTICS_TOPIC,
    VALVE_COMMAND_TOPIC,
    qos_for,
    sub_qos_for,
)
from pneu_msgs_py.nodes.run import ShellDefaults, run_node
from pneu_msgs_py.params.core import ParamError
from rcl_interfaces.msg import ParameterDescriptor
from rclpy import qos as rq
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import FluidPressure, JointState

from pneu_control.nodes.exciter_core import ExciterShellCore

_AXES = {"linear": ("linear",), "rotary": ("rotary",), "both": ("linear", "rotary")}


class ExciterNode(ShellDefaults, Node):
    """The excitation experiment as an rclpy node: sensor payloads in, designed valve commands
    out."""

    def __init__(self, **node_kwargs):
        super().__init__("pneu_exciter", **node_kwargs)
        ro = {"read_only": True}
        self.declare_parameter("axes", "both", ParameterDescriptor(description="excited axes", additional_constraints="one of linear, rotary, both", **ro))  # fmt: skip
        self.declare_parameter("seed", 0, ParameterDescriptor(description="design seed (pulse order, amplitudes, PRBS)", **ro))  # fmt: skip
        self.declare_parameter("level", "full", ParameterDescriptor(description="full (<= 2 min per axis) or quick (~45 s)", additional_constraints="one of full, quick", **ro))  # fmt: skip
        self.declare_parameter("mode", "lockstep", ParameterDescriptor(description="QoS set: lockstep or realtime", additional_constraints="one of lockstep, realtime", **ro))  # fmt: skip
        axes = self.get_parameter("axes").value
        mode = self.get_parameter("mode").value
        if axes not in _AXES:
            raise ParamError("axes", axes, "one of linear, rotary, both")
        if mode not in ("lockstep", "realtime"):
            raise ParamError("mode", mode, "one of lockstep, realtime")
        self.core = ExciterShellCore(
            _AXES[axes], int(self.get_parameter("seed").value), self.get_parameter("level").value
        )
        self.declare_parameter("design_json", self.core.designs_json(), ParameterDescriptor(description="the designs run (JSON, for pneu identify)", **ro))  # fmt: skip
        self.cmd_pub = {}
        self.state_pub = {}
        for a in self.core.exciters:
            t = VALVE_COMMAND_TOPIC[a]
            self.cmd_pub[a] = self.create_publisher(JointState, t, to_rclpy(qos_for(t, mode), rq))
            t = CONTROLLER_STATE_TOPIC[a]
            self.state_pub[a] = self.create_publisher(JointState, t, to_rclpy(qos_for(t, mode), rq))
        self.diag_pub = self.create_publisher(
            DiagnosticArray, DIAGNOSTICS_TOPIC, to_rclpy(DIAGNOSTICS, rq)
        )
        for topic in self.core.topics:  # raw CDR, one-argument callbacks (as the controllers)
            self.create_subscription(
                FluidPressure if "pressure" in topic else JointState,
                topic,
                lambda data, t=topic: self._on_sensor(t, data),
                to_rclpy(sub_qos_for(topic, mode), rq),
                raw=True,
            )
        self.create_timer(1.0, self._diagnostics, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.done = None  # spin until stopped: after its design the exciter holds the last segment
        self.get_logger().info(
            f"excitation of {axes}, seed {self.get_parameter('seed').value}, "
            f"{self.core.duration_s:.1f} s, {mode} QoS"
        )

    def _on_sensor(self, topic: str, data: bytes) -> None:
        s = self.core.on_raw(topic, data)
        if s is None:
            return
        for a, cmd, state in self.core.answer(s):
            self.cmd_pub[a].publish(cmd)
            self.state_pub[a].publish(state)

    def _diagnostics(self) -> None:
        now = self.get_clock().now().nanoseconds
        self.diag_pub.publish(
            fill_diagnostic_array(
                DiagnosticArray(),
                DiagnosticStatus,
                KeyValue,
                now,
                self.core.diagnostics(self.get_name()),
            )
        )

    def safe_shutdown(self) -> None:
        """On the way out: 5 V for the last answered sample (ignored when the context is already
        gone)."""
        try:  # last word: 5 V for the last answered sample
            for a, data in self.core.neutral_commands(NEUTRAL_V):
                self.cmd_pub[a].publish(data)
        except Exception:  # context already shut down: the driver's watchdog acts
            pass


def main(args=None) -> int:
    """``exciter``: the exit code."""
    return run_node("exciter", ExciterNode, args)


if __name__ == "__main__":
    sys.exit(main())
