"""``ros2 run pneu_sim sim_node``: the twin on the driver's topics (rclpy shell).

Lockstep: publishes ``/clock`` and sample k (reliable), waits for every active
controller's valve command stamped with sample k (or ``lockstep.timeout_s``,
counted), then advances -- :class:`pneu_sim.cycle.rig_cycle.RigCycle` does the
bookkeeping, with the in-process runner's one-sample delay. Realtime: the
same core advanced by a 1/T wall-clock timer. ``~/estop`` and ``~/reset``
(std_srvs/Trigger) go to the SafetySupervisor. Exits when ``duration_s`` of
simulated time has been published.
"""

from __future__ import annotations

import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from pneu_driver.safety import SafetySupervisor, load_safety_params
from pneu_msgs_py.contract.convert import (
    DiagStatus,
    command_from_msg,
    fill_diagnostic_array,
    fill_stamp,
)
from pneu_msgs_py.contract.qos import COMMAND_SUB_REALTIME, DIAGNOSTICS, to_rclpy
from pneu_msgs_py.contract.topics import (
    CLOCK_TOPIC,
    DIAGNOSTICS_TOPIC,
    JOINT_STATE_TOPIC,
    PRESSURE_TOPICS,
    VALVE_COMMAND_TOPIC,
    qos_for,
)
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
    SimNodeParams,
    active_axes,
    fill_sample_messages,
    load_faults,
    safety_statuses,
)
from pneu_sim.physics.plant import Plant
from pneu_sim.physics.plant_file import load_plant

SENSOR_TOPICS = (*PRESSURE_TOPICS, JOINT_STATE_TOPIC["linear"], JOINT_STATE_TOPIC["rotary"])


def declare_from_dataclass(node: Node, params) -> dict:
    """Declare every field of ``params`` (descriptor: description, range, read-only); values back."""
    decls = declarations(params, ParameterDescriptor, FloatingPointRange, IntegerRange)
    node.declare_parameters("", decls)
    return {name: node.get_parameter(name).value for name, _, _ in decls}


class SimNode(ShellDefaults, Node):
    def __init__(self, **node_kwargs):
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
        faults = load_faults(p.faults, p.faults_file)
        self.core = RigCycle(
            plant, axes=self.axes, mode=p.mode, x0=p.x0, supervisor=sup, faults=faults, seed=p.seed
        )
        self.n_end = round(p.duration_s / plant.T) if p.duration_s > 0 else 0
        self.done = Future()
        self.halted = ""  # e-stopped without a supervisor: time stands still
        from rclpy import qos as rq

        self.msgs = {
            t: FluidPressure() if t in PRESSURE_TOPICS else JointState() for t in SENSOR_TOPICS
        }
        self.pubs = {
            t: self.create_publisher(type(self.msgs[t]), t, to_rclpy(qos_for(t, p.mode), rq))
            for t in SENSOR_TOPICS
        }
        self.lockstep = p.mode == "lockstep"
        self.clock_msg = ClockMsg()
        self.clock_pub = (
            self.create_publisher(ClockMsg, CLOCK_TOPIC, to_rclpy(qos_for(CLOCK_TOPIC, p.mode), rq))
            if self.lockstep
            else None
        )
        cmd_qos = to_rclpy(
            qos_for(VALVE_COMMAND_TOPIC["linear"], "lockstep")
            if self.lockstep
            else COMMAND_SUB_REALTIME,
            rq,
        )
        self.cmd_subs = [
            self.create_subscription(
                JointState, VALVE_COMMAND_TOPIC[a], lambda m, a=a: self._on_command(m, a), cmd_qos
            )
            for a in self.axes
        ]
        self.diag_pub = self.create_publisher(
            DiagnosticArray, DIAGNOSTICS_TOPIC, to_rclpy(DIAGNOSTICS, rq)
        )
        self.create_service(Trigger, "~/estop", self._on_estop)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._apply)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(1.0, self._publish_diagnostics, clock=steady)
        self.started = False
        self.t_ready = None
        self.t_start = self.t_published = time.monotonic()
        if self.lockstep:
            self.create_timer(0.05, self._lockstep_watch, clock=steady)
        else:
            self.create_timer(plant.T, self._realtime_tick, clock=steady)
        self.get_logger().info(
            f"{p.mode} simulation, active axes: {', '.join(self.axes) or 'none'}, "
            f"duration {p.duration_s:g} s (0 = endless), safety supervisor {'on' if sup else 'off'}"
        )

    def safe_shutdown(self) -> None:
        self.core.safe_outputs()  # a real rig would now be at 5 V on both valves

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
    def _publish_sample(self) -> None:
        s = self.core.sample
        if self.clock_pub is not None:
            fill_stamp(self.clock_msg.clock, s.stamp_ns)
            self.clock_pub.publish(self.clock_msg)
        fill_sample_messages(self.msgs, s)
        for t in SENSOR_TOPICS:
            self.pubs[t].publish(self.msgs[t])
        self.t_published = time.monotonic()

    def _advance(self) -> None:
        if self.halted or self.done.done():
            return
        self._publish_safety_events()  # end of cycle k, stamped with sample k (the runner's layout)
        if self.n_end and self.core.sample.k + 1 >= self.n_end:
            self._finish()
            return
        self.core.advance()
        self._publish_sample()

    def _on_command(self, msg: JointState, axis: str) -> None:
        try:
            stamp_ns, u = command_from_msg(msg, axis)
        except ValueError as err:
            self.get_logger().warning(
                f"{axis} valve command ignored: {err}", throttle_duration_sec=1.0
            )
            return
        if not self.started:
            return
        self.core.offer(axis, stamp_ns, u)
        if self.lockstep and self.core.complete:
            self._advance()

    def _lockstep_watch(self) -> None:
        now = time.monotonic()
        lp = self.p.lockstep
        if not self.started:
            ready = all(
                pub.get_subscription_count() >= lp.min_subscribers for pub in self.pubs.values()
            )
            ready = ready and all(sub.get_publisher_count() >= 1 for sub in self.cmd_subs)
            if ready and self.t_ready is None:
                self.t_ready = now
            if ready and now - self.t_ready >= lp.settle_s:
                self._start()
            elif now - self.t_start > lp.startup_timeout_s:
                self.get_logger().warning("starting without every expected subscriber/controller")
                self._start()
        elif not self.axes:  # open loop (axes: none): nobody answers, so step in batches
            for _ in range(1000):
                if self.done.done() or self.halted:
                    break
                self._advance()
        elif now - self.t_published > lp.timeout_s and not self.done.done():
            self.get_logger().warning(
                f"lockstep timeout at sample {self.core.sample.k}: no answer from {', '.join(self.core.waiting_for)}",
                throttle_duration_sec=1.0,
            )
            self._advance()

    def _realtime_tick(self) -> None:
        if not self.started:
            self._start()
        else:
            self._advance()

    def _start(self) -> None:
        self.started = True
        self.core.reset()
        self._publish_sample()

    def _finish(self) -> None:
        self.core.safe_outputs()
        self._publish_safety_events()
        self._publish_diagnostics()
        c = self.core.counters()
        self.get_logger().info(f"finished after {self.core.sample.k + 1} samples; counters {c}")
        self.done.set_result(c)

    # -- services and diagnostics -----------------------------------------
    def _on_estop(self, request, response):
        if self.supervisor is not None:
            self.supervisor.estop("service ~/estop")
            response.message = "e-stop latched: both valves at 5 V until ~/reset"
        else:
            self.halted = "service ~/estop"
            response.message = "simulation halted (safety:=false, no supervisor) until ~/reset"
        response.success = True
        return response

    def _on_reset(self, request, response):
        if self.supervisor is not None:
            response.success, response.message = self.supervisor.reset()
        else:
            was, self.halted = self.halted, ""
            response.success, response.message = True, "resumed" if was else "nothing to reset"
            if was and self.lockstep and self.started:
                self._advance()
        return response

    def _publish_safety_events(self) -> None:
        if self.supervisor is None:
            return
        events = self.supervisor.events()
        if events:
            statuses = safety_statuses("pneu_sim", events)
            stamp = self.core.sample.stamp_ns
            self.diag_pub.publish(
                fill_diagnostic_array(
                    DiagnosticArray(), DiagnosticStatus, KeyValue, stamp, statuses
                )
            )

    def _publish_diagnostics(self) -> None:
        c = self.core.counters()
        lost = sum(v for k, v in c.items() if not k.startswith("steps"))
        elapsed = max(time.monotonic() - self.t_start, 1e-9)
        sim_s = (self.core.sample.stamp_ns * 1e-9) if self.core.sample is not None else 0.0
        values = {k: str(v) for k, v in c.items()}
        values.update(
            mode=self.p.mode, sim_time_s=f"{sim_s:.3f}", real_time_factor=f"{sim_s / elapsed:.3g}"
        )
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
        out = fill_diagnostic_array(
            DiagnosticArray(),
            DiagnosticStatus,
            KeyValue,
            now,
            statuses,
        )
        self.diag_pub.publish(out)


def main(args=None) -> int:
    return run_node("sim_node", SimNode, args)


if __name__ == "__main__":
    sys.exit(main())
