"""``ros2 run pneu_driver driver_node``: the rig through nidaqmx, or the twin as a simulated card (rclpy shell).

The 1 kHz loop (:class:`pneu_driver.loop.driver_loop.DriverLoop` around
:class:`pneu_driver.daq.nidaqmx_backend.NidaqmxBackend` and the
:class:`pneu_driver.safety.supervisor.SafetySupervisor`) runs in its own thread and
paces itself on the DAQ's sample clock; this node only publishes its
samples, hands the controllers' commands to it, serves ``~/estop`` and
``~/reset`` and reports ``/diagnostics``. The backend writes 5 V (valves
closed) before the tasks start; the loop's ``finally`` writes it again on
stop or on any exception. No DAQ -> one line naming the device and the
devices visible, exit status 1. ``backend: sim`` runs the same loop on the
twin as a simulated PCI-6221 (:mod:`pneu_sim.daq_sim`, found by name): a
rehearsal of the rig without hardware.
"""

from __future__ import annotations

import collections
import sys
import threading

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from pneu_msgs_py.contract.convert import (
    DiagStatus,
    diag_statuses_from_msg,
    fill_diagnostic_array,
    stamp_to_ns,
)
from pneu_msgs_py.contract.qos import DIAGNOSTICS, to_rclpy
from pneu_msgs_py.contract.samples import AXES
from pneu_msgs_py.contract.topics import (
    DIAGNOSTICS_TOPIC,
    PRESSURE_TOPICS,
    TASK_PROGRESS_TOPIC,
    VALVE_COMMAND_TOPIC,
    qos_for,
    sub_qos_for,
)
from pneu_msgs_py.contract.wire import SENSOR_TOPICS, CommandWire, SensorWire
from pneu_msgs_py.nodes.handoff import Handoff
from pneu_msgs_py.nodes.hosted import answer_hosts
from pneu_msgs_py.nodes.run import ShellDefaults, run_node
from pneu_msgs_py.params.core import ParamError, with_updates
from rcl_interfaces.msg import IntegerRange, ParameterDescriptor
from rclpy import qos as rq
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import FluidPressure, JointState
from std_srvs.srv import Trigger

from pneu_driver.daq.backends import backend_kind, make_backend
from pneu_driver.daq.nidaqmx_backend import visible_devices
from pneu_driver.daq.rig import load_rig_params
from pneu_driver.loop.driver_loop import DriverLoop
from pneu_driver.safety import load_safety_params

_LEVEL = {"OK": 0, "WARN": 1, "ERROR": 2}


class DriverNode(ShellDefaults, Node):
    """``hosted=True``: the one-process deployment; no command subscriptions, and the manager
    sets :attr:`hosts` (``axis``, ``compute(sample) -> (u, messages)``) before :meth:`start`:
    the loop thread calls them with each sample and hands the topics to its publishing
    thread (:mod:`pneu_msgs_py.nodes.hosted`). The loop thread runs at SCHED_FIFO
    ``rt_priority`` (the rig file's ``loop.rt_priority`` unless set), every other thread of
    the process one below."""

    def __init__(self, hosted: bool = False, **node_kwargs):
        super().__init__("pneu_driver", **node_kwargs)
        self.hosts: tuple = ()
        self.crashed: dict[str, str] = {}
        self._declare_shell_parameters()
        axes = self.get_parameter("axes").value
        choices = {"linear": ("linear",), "rotary": ("rotary",), "both": AXES, "none": ()}
        if axes not in choices:
            raise ParamError("axes", axes, "one of " + ", ".join(choices))
        rig = load_rig_params(self.get_parameter("rig_file").value or None)
        rt = self.get_parameter("rt_priority").value
        if rt >= 0:  # the launch's (or the user's) priority wins over the rig file's
            rig = with_updates(rig, {"loop.rt_priority": rt})
        rt = rig.loop.rt_priority
        self.process_rt_priority = rt - 1 if rt > 1 else 0
        self.outbox = Handoff(on_error=self._publish_failed) if hosted else None
        safety = load_safety_params(self.get_parameter("safety_file").value or None)
        backend = self.get_parameter("backend").value
        if backend_kind(backend) == "nidaqmx":
            seen = visible_devices(rig.device)  # DaqUnavailableError without the NI driver
            if rig.device not in seen:
                from pneu_driver.daq.errors import DaqUnavailableError

                raise DaqUnavailableError(rig.device, seen)
        from pneu_driver.safety import SafetySupervisor

        self._create_publishers()
        self.loop = DriverLoop(
            make_backend(backend, rig),
            rig,
            SafetySupervisor(safety, sample_time_s=rig.period_s),
            on_sample=self._publish_sample,  # loop thread
            on_events=self._queue_events,  # loop thread
            expected_axes=choices[axes],
            epoch_ns=self.get_clock().now().nanoseconds + rig.period_ns,  # stamps on the ROS clock
        )
        self.cmd_subs = {}
        for a in () if hosted else AXES:
            self.cmd_subs[a] = self.create_subscription(
                JointState,
                VALVE_COMMAND_TOPIC[a],
                lambda data, a=a: self._on_command(data, a),  # raw bytes, one argument
                to_rclpy(sub_qos_for(VALVE_COMMAND_TOPIC[a], "realtime"), rq),
                raw=True,
            )
        # a task runner's abort latches the e-stop (loads are the twin's business)
        self.create_subscription(
            DiagnosticArray,
            TASK_PROGRESS_TOPIC,
            self._on_task_progress,
            to_rclpy(qos_for(TASK_PROGRESS_TOPIC, "realtime"), rq),
        )
        self.create_service(Trigger, "~/estop", self._on_estop)
        self.create_service(Trigger, "~/reset", self._on_reset)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(1.0, self._diagnostics, clock=steady)
        self.create_timer(0.1, self._publish_events, clock=steady)
        self.done = Future()
        self.events: collections.deque = collections.deque(maxlen=10000)
        self.stamp_offset_ns: int | None = None
        self.second_io = ""
        self.thread: threading.Thread | None = None
        self.device = (
            rig.device if backend_kind(backend) == "nidaqmx" else f"{backend} ({rig.device})"
        )

    def _declare_shell_parameters(self) -> None:
        """rig_file, safety_file, backend, axes: read-only, read once at start."""
        ro = {"read_only": True}
        self.declare_parameter(
            "rig_file",
            "",
            ParameterDescriptor(
                description="rig YAML: DAQ map, scaling, loop ('' = installed config/rig.yaml)",
                **ro,
            ),
        )
        self.declare_parameter(
            "safety_file",
            "",
            ParameterDescriptor(
                description="safety YAML ('' = installed config/safety.yaml)", **ro
            ),
        )
        self.declare_parameter(
            "backend",
            "nidaqmx",
            ParameterDescriptor(
                description="the DAQ: nidaqmx (the PCI-6221) or sim[:seed=,plant=,card=,stall_at_s=,stall_ms=] "
                "(the twin as a simulated card, pneu_sim)",
                **ro,
            ),
        )
        self.declare_parameter(
            "rt_priority",
            -1,
            ParameterDescriptor(
                description="SCHED_FIFO priority of the 1 kHz loop thread, the process's other "
                "threads one below (0 = normal scheduling; -1 = the rig file's loop.rt_priority)",
                integer_range=[IntegerRange(from_value=-1, to_value=99, step=1)],
                **ro,
            ),
        )
        self.declare_parameter(
            "axes",
            "both",
            ParameterDescriptor(
                description="axes whose controller's command for sample k the loop waits for",
                additional_constraints="one of linear, rotary, both, none",
                **ro,
            ),
        )

    def _create_publishers(self) -> None:
        """The sensor topics (and their wire encoder) and /diagnostics."""
        self.wire = SensorWire()
        self.cmd_wire = {a: CommandWire(a) for a in AXES}
        self.pubs = {
            t: self.create_publisher(
                FluidPressure if t in PRESSURE_TOPICS else JointState,
                t,
                to_rclpy(qos_for(t, "realtime"), rq),
            )
            for t in SENSOR_TOPICS
        }
        self.diag_pub = self.create_publisher(
            DiagnosticArray, DIAGNOSTICS_TOPIC, to_rclpy(DIAGNOSTICS, rq)
        )

    def start(self) -> None:
        if self.outbox is not None:
            self.outbox.start()  # before the loop: it inherits this thread's priority
        self.thread = self.loop.start(name="pneu_driver_loop")
        self.get_logger().info(f"driver loop running on {self.device}")

    def exit_code(self) -> int:
        if self.loop.error is not None:
            print(f"driver_node: error: {self.loop.error}", file=sys.stderr)
            return 1
        return 0

    def safe_shutdown(self) -> None:
        self.loop.stop()  # the loop's finally writes 5 V and closes the tasks
        if self.thread is not None:
            self.thread.join(timeout=2.0)
        if self.outbox is not None:
            self.outbox.close()

    # -- loop thread ---------------------------------------------------------
    def _publish_sample(self, s) -> None:
        if (
            self.stamp_offset_ns is None
        ):  # ROS clock at the first sample vs its stamp (epoch estimate)
            self.stamp_offset_ns = self.get_clock().now().nanoseconds - s.stamp_ns
        pubs = self.pubs
        if self.outbox is not None:  # hosted: the controllers first, the topics after
            msgs = [(pubs[topic].publish, data) for topic, data in self.wire.encode(s)]
            msgs += answer_hosts(
                s,
                self.hosts,
                self.crashed,
                lambda axis, u: self.loop.put_command(axis, u, s.stamp_ns),
                self.get_logger().error,
            )
            self.outbox.put(msgs)
            return
        try:
            for topic, data in self.wire.encode(s):
                pubs[topic].publish(data)
        except Exception:
            if self.context.ok():
                raise
            self.loop.stop()  # Ctrl-C shut rclpy down first: stop quietly, the valves go safe

    def _publish_failed(self, err: BaseException) -> None:
        """The publishing thread's publish raised: an error while rclpy runs; at shutdown the
        loop stops quietly (the valves go safe)."""
        if not self.context.ok():
            self.loop.stop()
        elif self.outbox is not None and self.outbox.errors == 1:  # once; counted after
            self.get_logger().error(f"publishing failed: {type(err).__name__}: {err}")

    def _queue_events(self, events) -> None:
        self.events.extend(events)  # published from the executor thread (one publisher, one thread)

    # -- executor thread ------------------------------------------------------
    def _publish_events(self) -> None:
        """Supervisor transitions, one DiagnosticArray per sample stamp (``pneu analyze`` reads them)."""
        by_stamp: dict[int, list] = {}
        while self.events:
            e = self.events.popleft()
            by_stamp.setdefault(e.stamp_ns, []).append(
                DiagStatus(
                    _LEVEL[e.level],
                    f"pneu_driver: safety {e.axis} {e.rule}",
                    e.message,
                    self.device,
                    dict(e.values),
                )
            )
        for stamp, statuses in by_stamp.items():
            self._publish(statuses, stamp)

    def _on_command(self, data: bytes, axis: str) -> None:
        try:
            stamp_ns, u = self.cmd_wire[axis].decode(data)
        except ValueError as err:
            self.get_logger().warning(
                f"{axis} valve command ignored: {err}", throttle_duration_sec=1.0
            )
            return
        self.loop.put_command(axis, u, stamp_ns)

    def _on_task_progress(self, msg) -> None:
        from pneu_msgs_py.contract.task_progress import TaskProgress

        stamp = stamp_to_ns(msg.header.stamp)
        for st in diag_statuses_from_msg(msg):
            try:
                ev = TaskProgress.from_status(stamp, st)
            except ValueError as err:
                self.get_logger().warning(str(err), throttle_duration_sec=1.0)
                continue
            if ev.event == "aborted":
                self.loop.estop(f"task aborted: {ev.reason}")
                self.get_logger().error(f"task {ev.task} aborted ({ev.reason}): e-stop latched")

    def _on_estop(self, request, response):
        self.loop.estop("service ~/estop")
        response.success, response.message = (
            True,
            "e-stop latched: both valves at 5 V until ~/reset",
        )
        return response

    def _on_reset(self, request, response):
        response.success, response.message = self.loop.reset()
        return response

    def _diagnostics(self) -> None:
        stats = {
            k: f"{v:.6g}" if isinstance(v, float) else str(v)
            # percentiles over the last second: cheap on the executor thread taking the commands
            for k, v in self.loop.stats.as_dict(last=round(self.loop.rig.loop.rate_hz)).items()
        }
        self._watch_graph()
        counts = {a: sub.get_publisher_count() for a, sub in self.cmd_subs.items()}
        if counts:  # a second publisher is reported and, with publisher_trip, trips the axis
            self.loop.command_publishers(counts)
        stats.update({f"{a}.publishers": str(n) for a, n in counts.items()})
        stats.update(self.loop.command_counts())
        err = self.loop.error
        running = self.thread is not None and self.thread.is_alive()
        level = 2 if err is not None or not running else (1 if self.loop.stats.late_cycles else 0)
        msg = f"stopped: {err}" if err is not None else ("running" if running else "not running")
        statuses = [DiagStatus(level, "pneu_driver: loop", msg, self.device, stats)]
        for axis, st in self.loop.status().items():
            lvl = 0 if st.state == "OK" else (1 if st.state == "LIMITED" else 2)
            statuses.append(
                DiagStatus(
                    lvl,
                    f"pneu_driver: safety {axis}",
                    st.state,
                    self.device,
                    {"causes": ",".join(st.causes)},
                )
            )
        self._publish(statuses)
        if self.thread is not None and not running and not self.done.done():
            self.done.set_result(err)  # the loop ended (error or stop): leave spin

    def _watch_graph(self) -> None:
        """Another driver or sim publishing samples on this domain: e-stop, said once."""
        from pneu_msgs_py.contract.security import second_io

        msg = second_io({t: self.count_publishers(t) for t in SENSOR_TOPICS})
        if msg and not self.second_io:
            self.second_io = msg
            self.loop.estop(msg)
            self.get_logger().error(msg)

    def _publish(self, statuses, stamp_ns: int | None = None) -> None:
        now = self.get_clock().now().nanoseconds if stamp_ns is None else stamp_ns
        self.diag_pub.publish(
            fill_diagnostic_array(DiagnosticArray(), DiagnosticStatus, KeyValue, now, statuses)
        )


def main(args=None) -> int:
    return run_node("driver_node", DriverNode, args)


if __name__ == "__main__":
    sys.exit(main())
