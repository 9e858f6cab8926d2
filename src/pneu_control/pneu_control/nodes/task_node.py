"""``ros2 run pneu_control task_runner``: a task file carried out over ROS (rclpy shell).

The task is checked at start as ``pneu task`` checks it (:func:`pneu_control.task.session.
prepare`: one line naming the segment and field, exit status 1). Everything per sample is
:class:`~pneu_control.nodes.task_core.TaskShellCore`: raw subscriptions to the five
sensor topics feed it; it publishes each segment's ``trajectory_msgs/JointTrajectory`` on
``/pneu/joint_trajectory`` (the controllers follow it) and its progress on
``/pneu/task/progress`` (the sim / driver: loads, e-stop; lockstep: one per sample, the sim
waits for it). ``/diagnostics`` tells it of a supervisor trip (the task aborts).

Services (``std_srvs/Trigger``): ``~/start`` (``autostart:=false``: the task waits for
it), ``~/abort`` (both valves safe: the e-stop through the progress topic, then the safe
tail). When the task has ended the node writes ``<out>/task_report.json`` and
``task_report.md`` (if ``out`` is set) and exits, which ends a ``task.launch.py`` run.
"""

from __future__ import annotations

import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from pneu_msgs_py.contract.convert import diag_statuses_from_msg, fill_diagnostic_array
from pneu_msgs_py.contract.convert import fill_joint_trajectory as fill_trajectory
from pneu_msgs_py.contract.qos import DIAGNOSTICS, to_rclpy
from pneu_msgs_py.contract.topics import (
    DIAGNOSTICS_TOPIC,
    PRESSURE_TOPICS,
    TASK_PROGRESS_TOPIC,
    TRAJECTORY_TOPIC,
    qos_for,
    sub_qos_for,
)
from pneu_msgs_py.contract.wire import SENSOR_TOPICS
from pneu_msgs_py.nodes.run import ShellDefaults, run_node
from pneu_msgs_py.params.core import ParamError
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy import qos as rq
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import FluidPressure, JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from pneu_control.nodes.task_core import TaskShellCore

# lockstep: how long a trajectory may take to reach every subscriber's reader (a machine
# far slower than that has other problems; the run goes on, warned and counted)
ACK_TIMEOUT_S = 5.0


class TaskRunnerNode(ShellDefaults, Node):
    """The task runner as an rclpy node (see the module docstring)."""

    def __init__(self, **node_kwargs):
        super().__init__("task_runner", **node_kwargs)
        self._declare_parameters()
        names = ("task_file", "plant_file", "controllers_file", "safety_file", "plumbing")
        g = {n: self.get_parameter(n).value for n in (*names, "out", "mode", "autostart")}
        if g["mode"] not in ("lockstep", "realtime"):
            raise ParamError("mode", g["mode"], "one of lockstep, realtime")
        if not g["task_file"]:
            raise ParamError("task_file", "''", "a task YAML file (config/tasks/*.yaml)")
        from pneu_control.task.session import prepare

        prepared = prepare(
            g["task_file"],
            plant_file=g["plant_file"] or None,
            controllers_file=g["controllers_file"] or None,
            safety_file=g["safety_file"] or None,
            plumbing=g["plumbing"] or None,
        )
        self.out = g["out"]
        if self.out:
            self._report_files()  # refused now, before anything runs, if one exists
        mode = g["mode"]
        self.core = TaskShellCore(prepared, lockstep=mode == "lockstep", autostart=g["autostart"])
        self.done = Future()
        self.n_unacked = 0
        self.traj_pub = self.create_publisher(
            JointTrajectory, TRAJECTORY_TOPIC, to_rclpy(qos_for(TRAJECTORY_TOPIC, mode), rq)
        )
        self.progress_pub = self.create_publisher(
            DiagnosticArray, TASK_PROGRESS_TOPIC, to_rclpy(qos_for(TASK_PROGRESS_TOPIC, mode), rq)
        )
        for topic in SENSOR_TOPICS:
            self.create_subscription(
                FluidPressure if topic in PRESSURE_TOPICS else JointState,
                topic,
                lambda data, t=topic: self._on_sensor(t, data),  # raw bytes, one argument
                to_rclpy(sub_qos_for(topic, mode), rq),
                raw=True,
            )
        self.create_subscription(
            DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_diagnostics, to_rclpy(DIAGNOSTICS, rq)
        )
        self.create_service(Trigger, "~/start", self._on_start)
        self.create_service(Trigger, "~/abort", self._on_abort)
        if mode == "realtime":
            period = 1.0 / self.get_parameter("status_rate_hz").value
            self.create_timer(period, self._status, clock=Clock(clock_type=ClockType.STEADY_TIME))
        p = prepared.program
        self.get_logger().info(
            f"task {p.name}: {len(p.segments)} segments, at most {p.planned_s:.3g} s; "
            + ("starts at the first sample" if g["autostart"] else "waits for ~/start")
        )

    def _declare_parameters(self) -> None:
        """Every parameter read-only: read once at start."""

        def ro(description: str, **kw) -> ParameterDescriptor:
            return ParameterDescriptor(description=description, read_only=True, **kw)

        self.declare_parameter(
            "task_file",
            "",
            ro("the task YAML (config/tasks/*.yaml; format: pneu_control/task/program.py)"),
        )
        self.declare_parameter(
            "plant_file", "", ro("plant YAML the task is checked against ('' = installed)")
        )
        self.declare_parameter(
            "controllers_file", "", ro("controllers YAML the task's overrides apply to")
        )
        self.declare_parameter(
            "safety_file", "", ro("safety YAML the task is checked against ('' = installed)")
        )
        self.declare_parameter(
            "plumbing", "", ro("paper or bidirectional ('' = the task's, else the plant's)")
        )
        self.declare_parameter(
            "out", "", ro("directory of task_report.json / task_report.md ('' = none)")
        )
        self.declare_parameter(
            "mode",
            "lockstep",
            ro(
                "lockstep (answer every sample; the sim waits) or realtime",
                additional_constraints="one of lockstep, realtime",
            ),
        )
        self.declare_parameter("autostart", True, ro("start at the first sample (else on ~/start)"))
        self.declare_parameter(
            "status_rate_hz",
            10.0,
            ro(
                "realtime: the task's state on the progress topic this often (events go out "
                "when they happen)",
                floating_point_range=[FloatingPointRange(from_value=0.1, to_value=100.0)],
            ),
        )

    # -- per sample -----------------------------------------------------------------
    def _on_sensor(self, topic: str, data: bytes) -> None:
        out = self.core.on_raw(topic, data)
        if out is not None:
            self._publish(*out)

    def _publish(self, trajectories, progress) -> None:
        for stamp, names, points in trajectories:  # before the progress that announces it
            self.traj_pub.publish(
                fill_trajectory(JointTrajectory(), JointTrajectoryPoint, stamp, names, points)
            )
        if trajectories and self.core.lockstep:
            self._wait_delivered()
        if progress:
            self.progress_pub.publish(
                fill_diagnostic_array(
                    DiagnosticArray(),
                    DiagnosticStatus,
                    KeyValue,
                    progress[0].stamp_ns,
                    [p.to_status() for p in progress],
                )
            )
            for p in progress:
                if p.event not in ("tick", "idle"):
                    self.get_logger().info(p.to_status().message)
        if self.core.finished and not self.done.done():
            self._finish()

    def _wait_delivered(self) -> None:
        """Lockstep: the trajectory in every subscriber's reader before the progress that lets
        the sim go on. A long trajectory is many DDS fragments; on a busy machine one lost
        and repaired by a NACK takes longer than START_DELAY_S of lockstep samples, and the
        controller would join it late (a run unlike ``pneu task``). The ack is the DDS
        reader's (reliable QoS), not the controller's callback: that runs before the next
        sample's (events in arrival order) or within START_DELAY_S (a wait set)."""
        if not self.traj_pub.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S)):
            self.n_unacked += 1
            self.get_logger().warning(
                f"trajectory not acknowledged by every subscriber in {ACK_TIMEOUT_S:g} s "
                f"({self.n_unacked} so far): a controller may join it late"
            )

    def _status(self) -> None:
        s = self.core.last
        if s is not None and not self.core.finished:
            self._publish([], [self.core.status(s.stamp_ns)])

    def _on_diagnostics(self, msg) -> None:
        self.core.on_diagnostics(diag_statuses_from_msg(msg))

    # -- services -------------------------------------------------------------------
    def _on_start(self, request, response):
        response.success, response.message = self.core.start()
        return response

    def _on_abort(self, request, response):
        response.success, response.message = self.core.abort()
        return response

    # -- the end ----------------------------------------------------------------------
    def _finish(self) -> None:
        self._write_report()
        self.done.set_result(self.core.driver.outcome)

    def _report_files(self) -> list:
        """The two report files as output claims (checked: a report is never overwritten)."""
        from pathlib import Path

        from pneu_msgs_py.lifecycle.outputs import OutputFile

        return [
            OutputFile(Path(self.out) / name, field="out").check()
            for name in ("task_report.json", "task_report.md")
        ]

    def _write_report(self) -> None:
        if not self.out:
            return
        from pneu_control.task.report import report_markdown, write_json

        rep = self.core.report()
        try:
            js, md = self._report_files()
            with js, md:
                write_json(js.partial, rep)
                md.partial.write_text(report_markdown(rep), encoding="utf-8")
                js.publish()
                md.publish()
        except (OSError, ParamError) as err:
            self.get_logger().error(f"task report not written: {err}")
            return
        self.get_logger().info(f"task {self.core.name}: {rep['outcome']}; wrote {self.out}")

    def safe_shutdown(self) -> None:
        """Stopped before the task ended (Ctrl-C, the launch ending): the report says so."""
        if not self.done.done():
            self.core.interrupted()
            self._write_report()


def main(args=None) -> int:
    return run_node("task_runner", TaskRunnerNode, args)


if __name__ == "__main__":
    sys.exit(main())
