"""``linear_controller`` / ``rotary_controller``: an AxisController as an rclpy node.

Event-driven: raw (CDR bytes) subscriptions to the axis' input topics only
feed :class:`~pneu_control.nodes.controller_core.ControllerShellCore`, which
computes when a tick is complete; the command (stamped with the sample it
answers) is published from that callback as pre-serialised bytes -- no timer
in the loop, no message conversion. ``/pneu/joint_trajectory``
(``trajectory_msgs/JointTrajectory``, joint names ``linear``/``rotary``, as
joint_trajectory_controller takes it) sets the axis' reference from the next
sample on; a refused one is logged in one line and counted in ``/diagnostics``. The controller state follows every
``state_every`` ticks (parameter ``state_rate_hz``: every tick in lockstep,
100 Hz in realtime by default). Every field of :class:`AxisControllerParams`
is a parameter with a descriptor (description, range, read-only); defaults
come from ``controllers_file`` (config/controllers.yaml), ROS overrides win.
A change is validated as one set before rclpy stores it (on-set callback),
applied after (post-set), and takes effect at the next sample, bumplessly.

Realtime: the node listens to ``/diagnostics`` for the supervisor's word on its axis
(the sim's or the driver's safety statuses): while the valve is held safe it commands
the held 5 V, released it rejoins bumplessly (one log line each way; see
:meth:`~pneu_control.nodes.controller_core.ControllerShellCore.on_supervisor`). Lockstep
runs keep the in-process runner's semantics (deterministic: no such feedback).

``hosted=True`` (the one-process deployment, :mod:`.controller_manager`):
no sensor subscriptions; the host's 1 kHz loop calls :meth:`ControllerNode.compute`
with each sample and publishes the command and state for monitoring from its publishing
thread, while the node's parameters stay live (``ros2 param set /linear_controller ...``).
"""

from __future__ import annotations

import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from pneu_msgs_py.contract.convert import (
    diag_statuses_from_msg,
    fill_diagnostic_array,
    joint_trajectory_from_msg,
)
from pneu_msgs_py.contract.qos import DIAGNOSTICS, to_rclpy
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import (
    CONTROLLER_STATE_TOPIC,
    DIAGNOSTICS_TOPIC,
    TRAJECTORY_TOPIC,
    VALVE_COMMAND_TOPIC,
    qos_for,
    sub_qos_for,
)
from pneu_msgs_py.nodes.run import ShellDefaults, run_node
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.ros import coerce_value, declarations, specs_by_name, validate_updates
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy import qos as rq
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import FluidPressure, JointState
from trajectory_msgs.msg import JointTrajectory

from pneu_control.controller.axis import AxisController
from pneu_control.controller.params import load_controller_params
from pneu_control.nodes.controller_core import ControllerShellCore

#: Controller-state rate when ``state_rate_hz`` is 0: every tick in lockstep (the runner's
#: layout), 100 Hz in realtime (for people and plots; the bag keeps every command).
STATE_RATE_AUTO_HZ = {"lockstep": 0.0, "realtime": 100.0}
#: ``rt_priority`` -1 in realtime: one below the loop's (the launch files' ``rt_priority`` 50)
REALTIME_PRIORITY = 49


class ControllerNode(ShellDefaults, Node):
    """One axis's controller as an rclpy node; ``hosted``: the driver's loop calls :meth:`compute`
    (no sensor subscriptions)."""

    def __init__(self, axis: str, hosted: bool = False, **node_kwargs):
        super().__init__(f"{axis}_controller", **node_kwargs)
        self.axis = axis
        self.hosted = hosted
        self._declare_shell_parameters()
        rt = self.get_parameter("rt_priority").value
        if rt < 0:
            rt = REALTIME_PRIORITY if self.get_parameter("mode").value == "realtime" else 0
        self.process_rt_priority = 0 if hosted else rt
        mode = self.get_parameter("mode").value
        if mode not in ("lockstep", "realtime"):
            raise ParamError("mode", mode, "one of lockstep, realtime")
        rate = self.get_parameter("state_rate_hz").value or STATE_RATE_AUTO_HZ[mode]
        base = load_controller_params(axis, self.get_parameter("controllers_file").value or None)
        decls = declarations(base, ParameterDescriptor, FloatingPointRange, IntegerRange)
        self.declare_parameters("", decls)
        ok, reason, params = validate_updates(
            base, [(n, self.get_parameter(n).value) for n, _, _ in decls], startup=True
        )
        if not ok:
            raise ValueError(reason)
        self.specs = specs_by_name(params)
        self.params = params  # the newest accepted set
        every = max(1, round(1.0 / (rate * params.sample_time_s))) if rate else 1
        self.core = ControllerShellCore(axis, params, state_every=every)
        self.add_pre_set_parameters_callback(self._coerce)
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._apply)

        self._said_gone = False  # "no samples" logged (once per stop)
        self._create_topics(mode, hosted)
        # diagnostics at 1 Hz of wall time (steady clock): works whether /clock runs or not,
        # and with executors whose timers do not follow sim time; stamps use the node clock
        self.create_timer(
            1.0, self._publish_diagnostics, clock=Clock(clock_type=ClockType.STEADY_TIME)
        )
        self.get_logger().info(
            f"{axis} controller ({params.algorithm}), {mode} QoS, "
            + ("hosted by the 1 kHz loop" if hosted else f"inputs {', '.join(self.core.topics)}")
            + f", state every {every} tick(s)"
        )

    def _declare_shell_parameters(self) -> None:
        """controllers_file, mode, state_rate_hz, rt_priority: read-only, read once at start."""
        ro = {"read_only": True}
        self.declare_parameter(
            "controllers_file",
            "",
            ParameterDescriptor(
                description="controllers YAML giving the defaults ('' = installed config/controllers.yaml)",
                **ro,
            ),
        )
        self.declare_parameter(
            "mode",
            "realtime",
            ParameterDescriptor(
                description="QoS set: realtime (best-effort sensors) or lockstep (reliable, nothing lost)",
                additional_constraints="one of lockstep, realtime",
                **ro,
            ),
        )
        self.declare_parameter(
            "state_rate_hz",
            0.0,
            ParameterDescriptor(
                description="controller_state rate (the command goes out every tick); 0 = every "
                "tick in lockstep, 100 Hz in realtime",
                floating_point_range=[FloatingPointRange(from_value=0.0, to_value=1000.0)],
                **ro,
            ),
        )
        self.declare_parameter(
            "rt_priority",
            -1,
            ParameterDescriptor(
                description="SCHED_FIFO priority of every thread of this process (it computes "
                "the axis on its executor thread); 0 = normal scheduling, -1 = 49 in realtime "
                "(one below the loop's default 50), 0 in lockstep; ignored when hosted",
                integer_range=[IntegerRange(from_value=-1, to_value=98, step=1)],
                **ro,
            ),
        )

    def _create_topics(self, mode: str, hosted: bool) -> None:
        """Command, state and diagnostics publishers; raw sensor subscriptions unless hosted."""
        axis = self.axis
        self.cmd_pub = self.create_publisher(
            JointState,
            VALVE_COMMAND_TOPIC[axis],
            to_rclpy(qos_for(VALVE_COMMAND_TOPIC[axis], mode), rq),
        )
        self.state_pub = self.create_publisher(
            JointState,
            CONTROLLER_STATE_TOPIC[axis],
            to_rclpy(qos_for(CONTROLLER_STATE_TOPIC[axis], mode), rq),
        )
        self.diag_pub = self.create_publisher(
            DiagnosticArray, DIAGNOSTICS_TOPIC, to_rclpy(DIAGNOSTICS, rq)
        )
        # a trajectory of both joints (the task runner's, or anyone's): this axis' joint from
        # the next sample on; a low-rate message, converted by rclpy
        self.create_subscription(
            JointTrajectory,
            TRAJECTORY_TOPIC,
            self._on_trajectory,
            to_rclpy(sub_qos_for(TRAJECTORY_TOPIC, mode), rq),
        )
        if mode == "realtime":  # the supervisor's holds and releases of this axis
            self.create_subscription(
                DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_diagnostics, to_rclpy(DIAGNOSTICS, rq)
            )
        for topic in () if hosted else self.core.topics:
            # raw=True: the callback gets the CDR bytes; one argument (rclpy 7.1.9's
            # EventsExecutor fails on callbacks that also take a MessageInfo)
            self.create_subscription(
                FluidPressure if "pressure" in topic else JointState,
                topic,
                lambda data, t=topic: self._on_sensor(t, data),
                to_rclpy(sub_qos_for(topic, mode), rq),
                raw=True,
            )

    # -- per sample: everything in the core ---------------------------------
    def _on_sensor(self, topic: str, data: bytes) -> None:
        out = self.core.step_raw(topic, data)
        if out is not None:
            self.cmd_pub.publish(out[0])
            if out[1] is not None:
                self.state_pub.publish(out[1])

    def _on_trajectory(self, msg) -> None:
        try:
            if self.core.on_trajectory(*joint_trajectory_from_msg(msg)):
                self.get_logger().info(f"{self.axis}: trajectory of {len(msg.points)} points taken")
        except ParamError as err:
            self.get_logger().warning(f"{self.axis}: trajectory refused: {err}")

    def _on_diagnostics(self, msg) -> None:
        line = self.core.on_supervisor(diag_statuses_from_msg(msg))
        if line is not None:
            self.get_logger().warning(line)

    def compute(self, s: SensorSample) -> tuple[float, list]:
        """Hosted mode: the host's loop hands over sample ``s``; returns u (V) and the command
        and state messages, ``(publish, payload)`` pairs for the loop's publishing thread
        (monitoring and bags: :mod:`pneu_msgs_py.nodes.hosted`)."""
        u = self.core.update(s)
        cmd, state = self.core.answer(s.stamp_ns, u)
        out = [(self.cmd_pub.publish, cmd)]
        if state is not None:
            out.append((self.state_pub.publish, state))
        return u, out

    # -- parameters ----------------------------------------------------------
    def _coerce(self, params: list[Parameter]) -> list[Parameter]:
        """``ros2 param set ... 900`` sends INTEGER to a DOUBLE parameter: make it 900.0."""
        out = []
        for p in params:
            spec = self.specs.get(p.name)
            value = coerce_value(spec, p.value) if spec is not None else p.value
            out.append(p if value is p.value else Parameter(p.name, value=value))
        return out

    def _validate(self, params: list[Parameter]) -> SetParametersResult:
        changes = [(p.name, p.value) for p in params]
        ok, reason, new = validate_updates(self.params, changes)
        if ok and new is not self.params:
            try:  # the core's own checks (reference and waypoint file, axis rules)
                AxisController(self.axis, new)
            except (ParamError, OSError) as err:
                ok, reason = False, str(err)
        if not ok:
            self.get_logger().warning(f"parameter change refused: {reason}")
        # validated once: the post-set callback applies this set (milliseconds of Python on
        # the thread that also answers the samples, in the separate-process deployment)
        self._validated = (self.params, changes, new) if ok else None
        return SetParametersResult(successful=ok, reason=reason)

    def _apply(self, params: list[Parameter]) -> None:
        changes = [(p.name, p.value) for p in params]
        done = getattr(self, "_validated", None)
        self._validated = None
        if done is not None and done[0] is self.params and done[1] == changes:
            ok, new = True, done[2]
        else:
            ok, _, new = validate_updates(self.params, changes)
        if ok and new is not self.params:
            self.params = new
            self.core.set_params(new)  # takes effect at the next sample

    # -- reports and shutdown ----------------------------------------------
    def _publish_diagnostics(self) -> None:
        statuses = self.core.diagnostics(self.get_name())
        gone = statuses[0].level == 2
        if gone and not self._said_gone:
            self.get_logger().warning(statuses[0].message)
        self._said_gone = gone
        now = self.get_clock().now().nanoseconds
        self.diag_pub.publish(
            fill_diagnostic_array(DiagnosticArray(), DiagnosticStatus, KeyValue, now, statuses)
        )

    def safe_shutdown(self) -> None:
        """On the way out: the neutral command (ignored when the context is already gone)."""
        try:
            self.publish_neutral()
        except Exception:  # context already shut down by the signal: the driver's watchdog acts
            pass

    def publish_neutral(self) -> None:
        """Last word: the neutral command for the last answered sample (driver writes 5 V now)."""
        data = self.core.neutral_command()
        if data is not None:
            self.cmd_pub.publish(data)


def main_linear(args=None) -> int:
    """``linear_controller``: the exit code."""
    return run_node("linear_controller", lambda: ControllerNode("linear"), args)


def main_rotary(args=None) -> int:
    """``rotary_controller``: the exit code."""
    return run_node("rotary_controller", lambda: ControllerNode("rotary"), args)


if __name__ == "__main__":
    sys.exit(main_linear())
