"""``ros2 run pneu_sim sim_node``: the twin on the driver's topics (rclpy shell).

One :class:`pneu_sim.cycle.rig_cycle.RigCycle` (plant, injected faults,
supervisor; the in-process runner's one-sample delay) behind the topics.
Every sample goes out as five pre-serialised CDR payloads
(:class:`pneu_msgs_py.contract.wire.SensorWire`), commands come in raw
(:class:`~pneu_msgs_py.contract.wire.CommandWire`): no message conversion on
the hot path.

Lockstep: publishes ``/clock`` and sample k (reliable), waits for every
active controller's valve command stamped with sample k (or
``lockstep.timeout_s``, counted), then advances -- driven by the command
callbacks. Realtime: :class:`pneu_sim.nodes.sim_core.SimLoop` paces the
cycle at 1/T on the wall clock in its own thread and applies the newest
answer at each tick (a period without one is counted as missed). Both wait
for their subscribers first (``startup.*``). ``~/estop`` and ``~/reset``
(std_srvs/Trigger) go to the SafetySupervisor. Exits when ``duration_s`` of
simulated time has been published.

``hosted=True`` (the one-process deployment, ``pneu_control``'s
``controller_manager``): no command subscriptions; the manager sets
:attr:`SimNode.hosts` -- objects with ``axis`` and ``compute(sample) -> (u, messages)``
-- before the node starts; the realtime loop calls them with each sample and hands the
topics (the sample, the commands, the states) to its publishing thread
(:mod:`pneu_msgs_py.nodes.hosted`).

Realtime: the loop thread at SCHED_FIFO ``realtime.rt_priority``, every other thread of the
process one below (``process_rt_priority``, :func:`pneu_msgs_py.nodes.run.run_node`).
"""

from __future__ import annotations

import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from pneu_driver.safety import SafetySupervisor, load_safety_params
from pneu_msgs_py.contract.convert import (
    DiagStatus,
    diag_statuses_from_msg,
    fill_diagnostic_array,
    stamp_to_ns,
)
from pneu_msgs_py.contract.qos import DIAGNOSTICS, to_rclpy
from pneu_msgs_py.contract.topics import (
    CLOCK_TOPIC,
    DIAGNOSTICS_TOPIC,
    PRESSURE_TOPICS,
    TASK_PROGRESS_TOPIC,
    VALVE_COMMAND_TOPIC,
    qos_for,
    sub_qos_for,
)
from pneu_msgs_py.contract.wire import SENSOR_TOPICS, CommandWire, SensorWire, clock_bytes
from pneu_msgs_py.nodes.handoff import Handoff
from pneu_msgs_py.nodes.hosted import answer_hosts
from pneu_msgs_py.nodes.run import ShellDefaults, run_node
from pneu_msgs_py.params.core import ParamError, from_dict, with_updates
from pneu_msgs_py.params.ros import declarations
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.task import Future
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import FluidPressure, JointState
from std_srvs.srv import Trigger

from pneu_sim.cycle.rig_cycle import RigCycle
from pneu_sim.nodes.sim_core import (
    SimLoop,
    SimNodeParams,
    TaskGate,
    active_axes,
    load_faults,
    safety_statuses,
)
from pneu_sim.physics.plant import Plant
from pneu_sim.physics.plant_file import load_plant


def declare_from_dataclass(node: Node, params) -> dict:
    """Declare every field of ``params`` (descriptor: description, range, read-only); values back."""
    decls = declarations(params, ParameterDescriptor, FloatingPointRange, IntegerRange)
    node.declare_parameters("", decls)
    return {name: node.get_parameter(name).value for name, _, _ in decls}


class SimNode(ShellDefaults, Node):
    def __init__(self, hosted: bool = False, **node_kwargs):
        super().__init__("pneu_sim", **node_kwargs)
        values = declare_from_dataclass(self, SimNodeParams())
        self.p = with_updates(from_dict(SimNodeParams, {}, strict=False), values)
        p = self.p
        plant = Plant(load_plant(p.plant_file or None), seed=p.seed)
        sup = None
        if p.safety:
            sup = SafetySupervisor(load_safety_params(p.safety_file or None), sample_time_s=plant.T)
        self.supervisor = sup
        self.axes = active_axes(p.axes)
        self.hosts: tuple = ()  # set by the one-process deployment before start
        if hosted and p.mode != "realtime":
            raise ParamError("mode", p.mode, "realtime for the one-process deployment")
        faults = load_faults(p.faults, p.faults_file)
        self.core = RigCycle(
            plant, axes=self.axes, mode=p.mode, x0=p.x0, supervisor=sup, faults=faults, seed=p.seed
        )
        self.n_end = round(p.duration_s / plant.T) if p.duration_s > 0 else 0
        self.done = Future()
        self.halted = ""  # e-stopped without a supervisor: time stands still
        self.second_io = ""  # another sim or driver seen on the domain
        self.crashed: dict[str, str] = {}  # hosted controllers that raised
        rt = p.realtime.rt_priority
        self.process_rt_priority = rt - 1 if p.mode == "realtime" and rt > 1 else 0
        self.outbox = Handoff(on_error=self._publish_failed) if hosted else None
        from rclpy import qos as rq

        self.wire = SensorWire()
        self.cmd_wire = {a: CommandWire(a) for a in self.axes}
        self.pubs = {
            t: self.create_publisher(
                FluidPressure if t in PRESSURE_TOPICS else JointState,
                t,
                to_rclpy(qos_for(t, p.mode), rq),
            )
            for t in SENSOR_TOPICS
        }
        self.lockstep = p.mode == "lockstep"
        self.clock_pub = (
            self.create_publisher(ClockMsg, CLOCK_TOPIC, to_rclpy(qos_for(CLOCK_TOPIC, p.mode), rq))
            if self.lockstep
            else None
        )
        self._create_subscriptions(hosted)
        self.diag_pub = self.create_publisher(
            DiagnosticArray, DIAGNOSTICS_TOPIC, to_rclpy(DIAGNOSTICS, rq)
        )
        self.create_service(Trigger, "~/estop", self._on_estop)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._apply)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(1.0, lambda: self._publish_diagnostics(periodic=True), clock=steady)
        self.loop: SimLoop | None = None
        if not self.lockstep:
            self.loop = SimLoop(
                self.core,
                on_sample=self._realtime_sample,
                on_events=self._publish_safety_events,
                n_end=self.n_end,
                params=p.realtime,
            )
        self.started = False
        self.t_ready = None
        self.t_start = self.t_published = time.monotonic()
        self.create_timer(0.05, self._watch, clock=steady)
        self.get_logger().info(
            f"{p.mode} simulation, active axes: {', '.join(self.axes) or 'none'}"
            + (" (controllers hosted in this process)" if hosted else "")
            + f", duration {p.duration_s:g} s (0 = endless), safety supervisor "
            + ("on" if sup else "off")
        )

    def _create_subscriptions(self, hosted: bool) -> None:
        """The controllers' commands (raw; none when hosted) and the task runner's progress
        (loads, e-stop; with ``task.wait`` part of the lockstep)."""
        from rclpy import qos as rq

        mode = self.p.mode
        cmd_qos = to_rclpy(sub_qos_for(VALVE_COMMAND_TOPIC["linear"], mode), rq)
        self.cmd_axes = () if hosted else tuple(self.axes)
        self.cmd_subs = [
            self.create_subscription(
                JointState,
                VALVE_COMMAND_TOPIC[a],
                lambda data, a=a: self._on_command(data, a),  # raw bytes, one argument
                cmd_qos,
                raw=True,
            )
            for a in (() if hosted else self.axes)
        ]
        self.gate = TaskGate(self.core, self.p.task)
        self.task_sub = self.create_subscription(
            DiagnosticArray,
            TASK_PROGRESS_TOPIC,
            self._on_task_progress,
            to_rclpy(qos_for(TASK_PROGRESS_TOPIC, mode), rq),
        )

    def safe_shutdown(self) -> None:
        if self.loop is not None:
            self.loop.stop_event.set()
            self.loop.finished.wait(timeout=2.0)
        if self.outbox is not None:
            self.outbox.close()
        self.core.safe_outputs()  # a real rig would now be at 5 V on both valves

    def exit_code(self) -> int:
        if self.loop is not None and self.loop.error is not None:
            print(f"sim_node: error: {self.loop.error}", file=sys.stderr)
            return 1
        return 0

    # -- parameters --------------------------------------------------------
    def _validate(self, params) -> SetParametersResult:
        try:
            with_updates(
                self.p, {q.name: q.value for q in params if q.name.startswith("lockstep.")}
            )
        except ParamError as err:
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _apply(self, params) -> None:
        self.p = with_updates(
            self.p, {q.name: q.value for q in params if q.name.startswith("lockstep.")}
        )

    # -- the cycle ---------------------------------------------------------
    def _publish_sample(self, s) -> None:
        if self.clock_pub is not None:
            self.clock_pub.publish(clock_bytes(s.stamp_ns))
        pubs = self.pubs
        for topic, data in self.wire.encode(s):
            pubs[topic].publish(data)
        self.t_published = time.monotonic()

    def _realtime_sample(self, s) -> None:
        """Realtime loop thread: publish sample k -- hosted: the controllers answer it first,
        and the sample, the commands and the states go to the publishing thread."""
        if self.outbox is not None:
            msgs = [(self.pubs[topic].publish, data) for topic, data in self.wire.encode(s)]
            msgs += answer_hosts(
                s,
                self.hosts,
                self.crashed,
                lambda axis, u: self.loop.offer(axis, s.stamp_ns, u),
                self.get_logger().error,
            )
            self.outbox.put(msgs)
            self.t_published = time.monotonic()
            return
        try:
            self._publish_sample(s)
        except Exception:
            if self.context.ok():
                raise
            self.loop.stop_event.set()  # Ctrl-C shut rclpy down first: stop quietly

    def _publish_failed(self, err: BaseException) -> None:
        """The publishing thread's publish raised: at shutdown (rclpy gone) the loop stops
        quietly; otherwise an error of the node's, said once (the publishing thread counts them)."""
        if not self.context.ok():
            if self.loop is not None:
                self.loop.stop_event.set()
        elif self.outbox is not None and self.outbox.errors == 1:  # once; counted after
            self.get_logger().error(f"publishing failed: {type(err).__name__}: {err}")

    def _advance(self) -> None:
        """Lockstep: end of cycle k (every answer in, or the timeout) -> sample k+1."""
        if self.halted or self.done.done():
            return
        self._publish_safety_events(self._drain(), self.core.sample.stamp_ns)
        if (self.n_end and self.core.sample.k + 1 >= self.n_end) or self._task_ended():
            self._finish()
            return
        self._publish_sample(self.core.advance())

    def _drain(self):
        return self.supervisor.events() if self.supervisor is not None else []

    def _on_command(self, data: bytes, axis: str) -> None:
        try:
            stamp_ns, u = self.cmd_wire[axis].decode(data)
        except ValueError as err:
            self.get_logger().warning(
                f"{axis} valve command ignored: {err}", throttle_duration_sec=1.0
            )
            return
        if not self.started:
            return
        if self.loop is not None:
            self.loop.offer(axis, stamp_ns, u)
            return
        self.core.offer(axis, stamp_ns, u)
        if self.core.complete and self.gate.complete:
            self._advance()

    def _on_task_progress(self, msg) -> None:
        """The task runner's progress: carried out on the cycle (under the realtime loop's
        lock); in lockstep its answer to the current sample may complete the cycle."""
        with self._locked():
            bad = self.gate.on_progress(stamp_to_ns(msg.header.stamp), diag_statuses_from_msg(msg))
        for line in bad:
            self.get_logger().warning(line, throttle_duration_sec=1.0)
        if self.lockstep and self.started and self.core.complete and self.gate.complete:
            self._advance()
        elif self.loop is not None and self._task_ended():
            self.loop.stop_event.set()

    def _task_ended(self) -> bool:
        return self.p.task.ends_run and self.gate.ended

    def _ready(self) -> bool:
        sp = self.p.startup
        ok = all(pub.get_subscription_count() >= sp.min_subscribers for pub in self.pubs.values())
        if sp.wait_for_logger:  # the logger is the one node listening to parameter events
            ok = ok and self.count_subscribers("/parameter_events") >= 1
        if self.p.task.wait or self.p.task.ends_run:
            ok = ok and self.task_sub.get_publisher_count() >= 1
        return ok and all(sub.get_publisher_count() >= 1 for sub in self.cmd_subs)

    def _watch(self) -> None:
        """Start-up (wait for the subscribers), lockstep timeouts, the realtime loop's end."""
        now = time.monotonic()
        if not self.started:
            ready = self._ready()
            if ready and self.t_ready is None:
                self.t_ready = now
            if ready and now - self.t_ready >= self.p.startup.settle_s:
                self._start()
            elif now - self.t_start > self.p.startup.timeout_s:
                self.get_logger().warning("starting without every expected subscriber/controller")
                self._start()
            return
        if self.loop is not None:
            if self.loop.finished.is_set() and not self.done.done():
                self._finish()
        elif not self.axes:  # open loop (axes: none): nobody answers, so step in batches
            for _ in range(1000):
                if self.done.done() or self.halted:
                    break
                self._advance()
        elif now - self.t_published > self.p.lockstep.timeout_s and not self.done.done():
            waiting = (*self.core.waiting_for, *(() if self.gate.complete else ("task",)))
            self.get_logger().warning(
                f"lockstep timeout at sample {self.core.sample.k}: no answer from "
                f"{', '.join(waiting)}",
                throttle_duration_sec=1.0,
            )
            self._advance()

    def _start(self) -> None:
        self.started = True
        if self.outbox is not None:
            self.outbox.start()  # before the loop: it inherits this thread's priority, not 50
        if self.loop is not None:
            self.loop.start()
        else:
            self._publish_sample(self.core.reset())

    def _finish(self) -> None:
        if self.outbox is not None:
            self.outbox.close()  # the last samples and commands out before the final status
        if self.loop is None:
            self.core.safe_outputs()
            self._publish_safety_events(self._drain(), self.core.sample.stamp_ns)
        self._publish_diagnostics()
        c = self.core.counters()
        k = self.core.sample.k + 1 if self.core.sample is not None else 0
        report = self.loop.stats() if self.loop is not None else c
        self.get_logger().info(f"finished after {k} samples; {report}")
        self.done.set_result(c)

    # -- services and diagnostics -----------------------------------------
    def _locked(self):
        """The realtime loop's lock (the supervisor is stepped by its thread), or a no-op."""
        import contextlib

        return self.loop.lock if self.loop is not None else contextlib.nullcontext()

    def _on_estop(self, request, response):
        if self.supervisor is not None:
            with self._locked():
                self.supervisor.estop("service ~/estop")
            response.message = "e-stop latched: both valves at 5 V until ~/reset"
        else:
            self.halted = "service ~/estop"
            response.message = "simulation halted (safety:=false, no supervisor) until ~/reset"
        response.success = True
        return response

    def _on_reset(self, request, response):
        if self.supervisor is not None:
            with self._locked():
                response.success, response.message = self.supervisor.reset()
        else:
            was, self.halted = self.halted, ""
            response.success, response.message = True, "resumed" if was else "nothing to reset"
            if was and self.lockstep and self.started:
                self._advance()
        return response

    def _watch_graph(self) -> None:
        """Another sim or driver publishing samples on this domain: e-stop (or halt), said once."""
        from pneu_msgs_py.contract.security import second_io

        msg = second_io({t: self.count_publishers(t) for t in self.pubs})
        if not msg or self.second_io:
            return
        self.second_io = msg
        self.get_logger().error(msg)
        if self.supervisor is not None:
            with self._locked():
                self.supervisor.estop(msg)
        else:
            self.halted = msg

    def _watch_publishers(self) -> dict[str, str]:
        """The publishers the graph shows on each command topic, to the supervisor (a second one
        is reported and, with ``publisher_trip``, trips that axis)."""
        counts = {a: sub.get_publisher_count() for a, sub in zip(self.cmd_axes, self.cmd_subs)}
        if self.supervisor is not None and counts:
            with self._locked():
                self.supervisor.command_publishers(counts)
            if self.loop is None:  # lockstep: the node drains the supervisor's events
                stamp = self.core.sample.stamp_ns if self.core.sample is not None else 0
                self._publish_safety_events(self._drain(), stamp)
        return {f"{a}.publishers": str(n) for a, n in counts.items()}

    def _publish_safety_events(self, events, stamp_ns: int) -> None:
        """Supervisor transitions on ``/diagnostics``, stamped with their sample."""
        if events:
            self.diag_pub.publish(
                fill_diagnostic_array(
                    DiagnosticArray(),
                    DiagnosticStatus,
                    KeyValue,
                    stamp_ns,
                    safety_statuses("pneu_sim", events),
                )
            )

    def _publish_diagnostics(self, periodic: bool = False) -> None:
        """The 1 Hz status (``periodic``: timing percentiles over the last second, cheap on the
        executor thread that also takes the commands) or the final one (the whole run)."""
        c = self.core.counters()
        lost = sum(v for k, v in c.items() if not k.startswith("steps"))
        elapsed = max(time.monotonic() - self.t_start, 1e-9)
        sim_s = (self.core.sample.stamp_ns * 1e-9) if self.core.sample is not None else 0.0
        last = round(1.0 / self.core.period_s) if periodic else None
        values = (
            self.loop.stats(last) if self.loop is not None else {k: str(v) for k, v in c.items()}
        )
        values.update(
            mode=self.p.mode, sim_time_s=f"{sim_s:.3f}", real_time_factor=f"{sim_s / elapsed:.3g}"
        )
        if self.outbox is not None:
            values.update(self.outbox.counters())
        if periodic:
            self._watch_graph()
            values.update(self._watch_publishers())
        msg = (
            "halted: " + self.halted
            if self.halted
            else ("running" if self.started else "waiting for controllers")
        )
        statuses = [
            DiagStatus(
                1 if (lost or self.halted) else 0, "pneu_sim: lockstep", msg, "pneu_sim", values
            )
        ]
        if self.supervisor is not None:
            for axis, st in self.supervisor.status.items():
                level = 0 if st.state == "OK" else (1 if st.state == "LIMITED" else 2)
                if st.causes == ("no_command",) and axis not in self.axes:
                    level = 0
                statuses.append(
                    DiagStatus(
                        level,
                        f"pneu_sim: safety {axis}",
                        st.state,
                        "pneu_sim",
                        {"causes": ",".join(st.causes)},
                    )
                )
        if self.lockstep:  # sim time, as every other node of a lockstep run stamps
            now = self.core.sample.stamp_ns if self.core.sample is not None else 0
        else:
            now = self.get_clock().now().nanoseconds
        self.diag_pub.publish(
            fill_diagnostic_array(DiagnosticArray(), DiagnosticStatus, KeyValue, now, statuses)
        )


def main(args=None) -> int:
    return run_node("sim_node", SimNode, args)


if __name__ == "__main__":
    sys.exit(main())
