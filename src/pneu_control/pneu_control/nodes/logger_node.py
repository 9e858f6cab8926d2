"""``ros2 run pneu_control logger``: every pneu topic into one MCAP, as the runner writes it.

Subscriptions are ``raw=True``: the CDR bytes go straight to
:class:`~pneu_control.nodes.logger_core.LoggerCore` (``BagWriter.write_serialized``),
nothing is decoded on the hot path. The parameters of every node in the
graph are fetched once each node appears (parameter services) and followed on
``/parameter_events``; they become the bag's metadata when the logger shuts
down (SIGINT/SIGTERM from ``ros2 launch`` included), which also finishes the
file. Output: ``<out>/<bag_name>``.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from pneu_msgs_py.contract.convert import DiagStatus, fill_diagnostic_array
from pneu_msgs_py.contract.qos import DIAGNOSTICS, to_rclpy
from pneu_msgs_py.contract.topics import DIAGNOSTICS_TOPIC, qos_for
from pneu_msgs_py.nodes.run import ShellDefaults, run_node
from rcl_interfaces.msg import ParameterDescriptor, ParameterEvent
from rclpy import qos as rq
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import FluidPressure, JointState
from trajectory_msgs.msg import JointTrajectory

from pneu_control.nodes.logger_core import LOGGED_TOPICS, SIDECAR, LoggerCore

_TYPES = {
    "sensor_msgs/msg/FluidPressure": FluidPressure,
    "sensor_msgs/msg/JointState": JointState,
    "diagnostic_msgs/msg/DiagnosticArray": DiagnosticArray,
    "rosgraph_msgs/msg/Clock": ClockMsg,
    "trajectory_msgs/msg/JointTrajectory": JointTrajectory,
}


class LoggerNode(ShellDefaults, Node):
    """The logger as an rclpy node: raw subscriptions to every pneu topic into the core; the graph's
    parameters into the run metadata."""

    def __init__(self, **node_kwargs):
        super().__init__("logger", **node_kwargs)
        self._declare_parameters()
        mode = self.get_parameter("mode").value
        if mode not in ("lockstep", "realtime"):
            raise ValueError(f"mode: {mode!r} refused; allowed: one of lockstep, realtime")
        recorder = self.get_parameter("recorder").value
        if recorder not in ("pneu", "rosbag2"):
            raise ValueError(f"recorder: {recorder!r} refused; allowed: one of pneu, rosbag2")
        out = Path(self.get_parameter("out").value).expanduser()
        out.mkdir(parents=True, exist_ok=True)
        self.path = out / self.get_parameter("bag_name").value
        record = recorder == "pneu"
        self.core = LoggerCore(
            self.path,
            mode=mode,
            compression=self.get_parameter("compression").value,
            record=record,
        )
        if record:
            self._subscribe_logged(mode)
        self.create_subscription(
            ParameterEvent,
            "/parameter_events",
            self._on_param_event,
            rq.qos_profile_parameter_events,
        )
        self.diag_pub = self.create_publisher(
            DiagnosticArray, DIAGNOSTICS_TOPIC, to_rclpy(DIAGNOSTICS, rq)
        )
        self._param_clients: dict[str, AsyncParameterClient] = {}  # (Node.clients is rclpy's)
        self._pending: set[str] = set()
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(0.25, self._discover, clock=steady)  # parameters of every node, early
        self.create_timer(1.0, self._diagnostics, clock=steady)
        self.get_logger().info(
            f"logging to {self.path} ({mode})"
            if record
            else f"run metadata for the rosbag2 bag {self.path} ({mode})"
        )

    def _declare_parameters(self) -> None:
        """out, bag_name, recorder, mode, compression: read-only, read once at start."""
        ro = {"read_only": True}
        self.declare_parameter(
            "out", ".", ParameterDescriptor(description="output directory", **ro)
        )
        self.declare_parameter(
            "bag_name",
            "run.mcap",
            ParameterDescriptor(
                description="the bag in 'out': the .mcap this node writes (recorder pneu), or "
                "the rosbag2 directory ros2 bag record writes (recorder rosbag2)",
                **ro,
            ),
        )
        self.declare_parameter(
            "recorder",
            "pneu",
            ParameterDescriptor(
                description="pneu: record every pneu topic and the run metadata into one .mcap; "
                "rosbag2: ros2 bag record records the topics, this node writes only the run "
                f"metadata ({SIDECAR}) into its bag directory",
                additional_constraints="one of pneu, rosbag2",
                **ro,
            ),
        )
        self.declare_parameter(
            "mode",
            "lockstep",
            ParameterDescriptor(
                description="lockstep (reliable QoS, log time = message stamp) or realtime (receive time)",
                additional_constraints="one of lockstep, realtime",
                **ro,
            ),
        )
        self.declare_parameter(
            "compression",
            "zstd",
            ParameterDescriptor(
                description="MCAP chunk compression",
                additional_constraints="one of zstd, lz4, none",
                **ro,
            ),
        )

    def _subscribe_logged(self, mode: str) -> None:
        """One raw subscription per logged topic, into the core."""
        for topic, ros_type in LOGGED_TOPICS:
            prof = qos_for(topic, mode)
            prof = dataclasses.replace(
                prof, depth=max(prof.depth, 1000)
            )  # a slow disk loses nothing
            # raw bytes, one-argument callback (rclpy 7.1.9's EventsExecutor fails on callbacks
            # that also take a MessageInfo); realtime log time = receive time on the system
            # clock, as rosbag2 records it
            self.create_subscription(
                _TYPES[ros_type],
                topic,
                lambda data, t=topic, r=ros_type: self.core.on_message(
                    t, r, data, *((time.time_ns(),) * 2)
                ),
                to_rclpy(prof, rq),
                raw=True,
            )

    def safe_shutdown(self) -> None:
        """Close the bag (metadata, summary, footer) and say where it is."""
        written = self.core.close()  # metadata, summary, footer: the bag is complete
        print(f"logger: wrote {written}", file=sys.stderr)

    # -- parameters of the graph -------------------------------------------
    def _discover(self) -> None:
        me = self.get_fully_qualified_name()
        for name, ns in self.get_node_names_and_namespaces():
            full = (ns.rstrip("/") + "/" + name) if ns != "/" else "/" + name
            if full == me or full in self.core.node_params:
                continue
            client = self._param_clients.get(full)
            if client is None:
                client = self._param_clients[full] = AsyncParameterClient(self, full)
            if client.services_are_ready() and full not in self._pending:
                self._pending.add(full)
                client.list_parameters(
                    callback=lambda f, c=client, n=full: self._got_names(f, c, n)
                )

    def _got_names(self, future, client, node: str) -> None:
        names = list(future.result().result.names)
        client.get_parameters(names, callback=lambda f: self._got_values(f, client, node, names))

    def _got_values(self, future, client, node: str, names: list[str]) -> None:
        values = [parameter_value_to_python(v) for v in future.result().values]
        self.core.set_node_params(node, dict(zip(names, values)))
        self._pending.discard(node)

    def _on_param_event(self, msg: ParameterEvent) -> None:
        changed = {
            p.name: parameter_value_to_python(p.value)
            for p in (*msg.new_parameters, *msg.changed_parameters)
        }
        if changed and msg.node != self.get_fully_qualified_name():
            stamp = msg.stamp.sec * 1_000_000_000 + msg.stamp.nanosec
            self.core.on_parameter_event(stamp, msg.node, changed)

    def _diagnostics(self) -> None:
        c = self.core
        values = {t: str(n) for t, n in sorted(c.counts.items())}
        values.update(
            bag=str(self.path), nodes=",".join(sorted(c.node_params)), unreadable=str(c.bad)
        )
        st = DiagStatus(
            1 if c.bad else 0, "logger: bag", "recording" if c.counts else "waiting", "pneu", values
        )
        now = self.get_clock().now().nanoseconds
        self.diag_pub.publish(
            fill_diagnostic_array(DiagnosticArray(), DiagnosticStatus, KeyValue, now, [st])
        )


def main(args=None) -> int:
    """``logger``: the exit code."""
    return run_node("logger", LoggerNode, args)


if __name__ == "__main__":
    sys.exit(main())
