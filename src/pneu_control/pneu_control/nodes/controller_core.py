"""Per-sample work of a controller, without ROS: raw CDR in, the core, raw CDR out.

The rclpy node (:mod:`pneu_control.nodes.controller_node`) only subscribes,
publishes and declares parameters; everything it does per sample is here, so
it is tested and benchmarked without rclpy. Every message is raw CDR bytes
(:mod:`pneu_msgs_py.contract.wire`): rclpy's message conversion is skipped
both ways (DESIGN §10).

1. :meth:`ControllerShellCore.on_raw` -- collect, by stamp, the sensor
   payloads of one tick on the axis' input topics only (:data:`INPUT_TOPICS`:
   linear -- its joint state and the two chamber pressures; rotary -- its
   joint state); when a tick is complete, rebuild the
   :class:`SensorSample` (fields of topics not taken are NaN: no algorithm of
   that axis reads them);
2. :meth:`ControllerShellCore.update` -- ``AxisController.update``;
3. :meth:`ControllerShellCore.answer` -- the valve command (stamped with the
   sample it answers) and, every ``state_every`` ticks, the controller state.

A ``trajectory_msgs/JointTrajectory`` on ``/pneu/joint_trajectory``
(:meth:`ControllerShellCore.on_trajectory`, as joint_trajectory_controller takes it:
joint names ``linear``/``rotary``, each controller its own joint; times from
``header.stamp``, 0 = the next sample) becomes the axis' reference from the next
sample on (:func:`~pneu_control.controller.trajectory.joint_reference`, the
in-process task runner's reference, with the same bits: times in integer ns).

The supervisor's word on the axis (:meth:`ControllerShellCore.on_supervisor`: the
sim's or the driver's ``/diagnostics``, :func:`supervisor_hold` reads them): while
it holds the valve safe (a latched fault, the e-stop) the controller commands the
neutral 5 V it holds and feeds that to its observers; released (``~/reset``), it
restarts from its estimates, bumplessly from 5 V (``AxisController.hold``). A
controller restarted while its axis is latched so rejoins without a jump, after the
operator's acknowledge only (the supervisor's latch).

Hosted (one-process) deployments call :meth:`update` and :meth:`answer` with
a whole sample instead of step 1. Same sample, same numbers: a lockstep ROS
run gives the in-process runner's results.
"""

from __future__ import annotations

import math
import re
import threading
from typing import Any

from pneu_msgs_py.contract.convert import DiagStatus
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import JOINT_STATE_TOPIC, PRESSURE_TOPICS
from pneu_msgs_py.contract.wire import CommandWire, SensorWire, StateWire
from pneu_msgs_py.params.core import ParamError

from pneu_control.controller.axis import STATE_FIELDS, AxisController
from pneu_control.controller.trajectory import from_stamped, joint_reference

__all__ = [
    "INPUT_TOPICS",
    "SampleAssembler",
    "TickDecoder",
    "ControllerShellCore",
    "supervisor_hold",
]

_P = tuple(PRESSURE_TOPICS)
#: The sensor topics each axis' controller takes (its algorithms read nothing else).
INPUT_TOPICS: dict[str, tuple[str, ...]] = {
    "linear": (_P[0], _P[1], JOINT_STATE_TOPIC["linear"]),
    "rotary": (JOINT_STATE_TOPIC["rotary"],),
}
_NAN = math.nan
# the sim's and the driver's safety statuses (pneu_sim.nodes.sim_core.safety_statuses, the
# driver node): "<node>: safety <axis>" (1 Hz: state, causes) or "<node>: safety <axis> <rule>"
# (a transition, stamped with its sample); axis "all" for the e-stop and the reset
_SAFETY_STATUS = re.compile(r"^(?:pneu_sim|pneu_driver): safety (linear|rotary|all)(?: (\S+))?$")
_NOT_HELD = ("no_command", "no_sample")  # causes of a SAFE axis that hold nothing latched


def supervisor_hold(statuses: Any, axis: str) -> str | None:
    """What the sim's or the driver's ``/diagnostics`` statuses say about ``axis``' valve:
    why the supervisor holds it safe (the latched causes or the rule that tripped, e.g.
    ``watchdog``, ``estop``), ``""`` released, None when they say nothing about it.

    A latch is an ERROR transition of the axis (or of ``all``: the e-stop); a release the
    ``reset`` (or this axis' ``acknowledge`` with no e-stop left); the 1 Hz status says
    either (SAFE with latched causes; waiting for a first command holds nothing)."""
    out = None
    for st in statuses:
        m = _SAFETY_STATUS.match(st.name)
        if m is None or m.group(1) not in (axis, "all"):
            continue
        rule = m.group(2)
        if rule is None:
            if m.group(1) == axis:
                causes = [c for c in st.values.get("causes", "").split(",") if c]
                causes = [c for c in causes if c not in _NOT_HELD]
                out = ",".join(causes) if st.message == "SAFE" and causes else ""
        elif st.level == 2:
            out = rule
        elif st.level == 0 and (
            rule == "reset" or (rule == "acknowledge" and "e-stop still" not in st.message)
        ):
            out = ""
    return out


class SampleAssembler:
    """Groups the decoded sensor payloads of one tick by stamp.

    A tick is emitted once every topic of ``topics`` has a payload with its
    stamp. A payload with a newer stamp abandons an incomplete older tick
    (counted in :attr:`incomplete`: a lost best-effort message); one older than
    the tick being collected is dropped (:attr:`late`).
    """

    __slots__ = ("_fields", "_got", "_n", "_stamp", "emitted", "incomplete", "late")

    def __init__(self, topics: tuple[str, ...]) -> None:
        self._n = len(topics)
        self._stamp = -1
        self._got: set[str] = set()
        self._fields: dict[str, float] = {}
        self.emitted = 0
        self.incomplete = 0
        self.late = 0

    def add(self, topic: str, stamp_ns: int, fields: dict[str, float]) -> tuple | None:
        """Add one topic's fields; ``(stamp_ns, fields)`` of a complete tick, else None."""
        if stamp_ns != self._stamp:
            if stamp_ns < self._stamp:
                self.late += 1
                return None
            if self._got:
                self.incomplete += 1
            self._stamp = stamp_ns
            self._got = set()
            self._fields = {}
        self._got.add(topic)
        self._fields.update(fields)
        if len(self._got) < self._n:
            return None
        done, self._fields, self._got = self._fields, {}, set()
        self.emitted += 1
        return stamp_ns, done


class TickDecoder:
    """Raw sensor payloads of ``topics`` in, the :class:`SensorSample` of each complete
    tick out (fields of topics not taken are NaN; samples indexed from 0)."""

    __slots__ = ("assembler", "n_bad", "n_ticks", "sensors", "topics")

    def __init__(self, topics: tuple[str, ...]) -> None:
        self.topics = topics
        self.assembler = SampleAssembler(topics)
        self.sensors = SensorWire()
        self.n_bad = 0  # malformed payloads
        self.n_ticks = 0

    def on_raw(self, topic: str, data: bytes) -> SensorSample | None:
        """One sensor payload in; the :class:`SensorSample` when its tick is complete, else None (a
        malformed payload counts in ``n_bad``)."""
        try:
            stamp, fields = self.sensors.decode(topic, data)
        except ValueError:
            self.n_bad += 1
            return None
        tick = self.assembler.add(topic, stamp, fields)
        if tick is None:
            return None
        stamp, f = tick
        g = f.get
        counts = g("counts", 0.0)
        self.n_ticks += 1
        return SensorSample(
            self.n_ticks - 1,
            stamp,
            g("p_c1", _NAN),
            g("p_c2", _NAN),
            g("p_m1", _NAN),
            g("x", _NAN),
            g("theta", _NAN),
            g("omega", _NAN),
            int(counts) if counts == counts else 0,
        )


class ControllerShellCore:
    """Everything a controller node does per sample (see the module docstring)."""

    def __init__(self, axis: str, params: Any, state_every: int = 1):
        if state_every < 1:
            raise ValueError(f"state_every: {state_every!r} refused; allowed: an integer >= 1")
        self.axis = axis
        self.controller = AxisController(axis, params)
        self.topics = INPUT_TOPICS[axis]
        self.decoder = TickDecoder(self.topics)
        self.assembler = self.decoder.assembler
        self.commands = CommandWire(axis)
        self.states = StateWire(STATE_FIELDS)
        self.state_every = int(state_every)
        self._period_ns = round(params.sample_time_s * 1e9)
        self.n_samples = 0
        self._samples_seen = 0  # n_samples at the last diagnostics
        self.n_saturated = 0
        self.last_stamp_ns = -1
        self.last_u = _NAN
        self.param_changes = 0
        self._trajectory: tuple | None = None  # (stamp_ns, names, points) for the next sample
        self._traj_lock = threading.Lock()
        self.n_trajectories = 0  # taken (set as the reference)
        self.n_trajectories_refused = 0
        self.n_trajectories_late = 0  # started before the sample that took it (joined mid-way)
        self.trajectory_error = ""
        self.held_by = ""  # why the supervisor holds the valve safe ("" = it does not)
        self._hold_request: str | None = None  # from another thread, applied at the next sample

    @property
    def params(self) -> Any:
        """The controller's current parameter set."""
        return self.controller.params

    def set_params(self, params: Any) -> None:
        """Validated new set; takes effect at the next sample (bumpless, by the core)."""
        self.controller.set_params(params)
        self.param_changes += 1

    # -- per sample -------------------------------------------------------
    @property
    def n_bad(self) -> int:
        """Malformed payloads so far."""
        return self.decoder.n_bad

    def on_raw(self, topic: str, data: bytes) -> SensorSample | None:
        """One sensor payload in; the rebuilt sample when its tick is complete."""
        return self.decoder.on_raw(topic, data)

    def on_trajectory(self, stamp_ns: int, joint_names: tuple[str, ...], points: list) -> bool:
        """A JointTrajectory (:func:`pneu_msgs_py.contract.convert.joint_trajectory_from_msg`'s
        form): True if it names this axis' joint and is valid (it becomes the reference at the
        next sample, replacing one not yet taken); False if it does not name the joint; raises
        :class:`ParamError` (one line, counted) if it is refused."""
        if self.axis not in joint_names:
            return False
        try:
            if self.axis == "rotary" and self.controller.controls != "angle":
                raise ParamError(
                    "joint_names", "rotary", "a rotary joint under rotary_control: angle only "
                    "(this controller controls the speed)",
                )  # fmt: skip
            from_stamped(stamp_ns, joint_names, points, stamp_ns)  # the message alone
        except ParamError as err:
            self.n_trajectories_refused += 1
            self.trajectory_error = str(err)
            raise
        with self._traj_lock:  # hosted: the loop's thread takes it
            self._trajectory = (int(stamp_ns), tuple(joint_names), list(points))
        return True

    def _take_trajectory(self, sample: SensorSample) -> None:
        """The pending trajectory as the reference, on the controller's time base."""
        with self._traj_lock:
            pending, self._trajectory = self._trajectory, None
        if pending is None:
            return
        stamp, names, points = pending
        c = self.controller
        base = c.t0_ns if c.t0_ns is not None else sample.stamp_ns
        start = stamp if stamp else sample.stamp_ns  # 0: from this sample on
        try:
            traj = from_stamped(start, names, points, base)
        except ParamError as err:  # stamped before this controller's first sample
            self.n_trajectories_refused += 1
            self.trajectory_error = str(err)
            return
        if start < sample.stamp_ns:
            self.n_trajectories_late += 1
        # the reference followed so far goes on until the trajectory's start (as in process)
        c.set_reference(joint_reference(traj, self.axis), start_s=traj.t_start)
        self.n_trajectories += 1

    def on_supervisor(self, statuses: Any) -> str | None:
        """The sim's or driver's ``/diagnostics`` statuses (any thread): a line when they
        hold or release this axis (applied at the next sample), else None."""
        why = supervisor_hold(statuses, self.axis)
        if why is None or (why != "") == (self.held_by != ""):
            return None
        self.held_by = why
        self._hold_request = why
        u0 = self.params.limits.u_neutral
        if why:
            return (
                f"{self.axis}: valve held safe by the supervisor ({why}); commanding {u0:g} V "
                "until it is released (~/reset)"
            )
        return f"{self.axis}: released by the supervisor; rejoining bumplessly from {u0:g} V"

    def update(self, sample: SensorSample) -> float:
        """``AxisController.update``; returns the valve command (V)."""
        if self._hold_request is not None:
            why, self._hold_request = self._hold_request, None
            self.controller.hold(self.params.limits.u_neutral if why else None)
        if self._trajectory is not None:
            self._take_trajectory(sample)
        u = self.controller.update(sample)
        self.n_samples += 1
        self.last_stamp_ns = sample.stamp_ns
        self.last_u = u
        lim = self.controller.params.limits
        if u <= lim.u_min or u >= lim.u_max:
            self.n_saturated += 1
        return u

    def answer(self, stamp_ns: int, u: float) -> tuple[bytes, bytes | None]:
        """The command payload (stamp = the answered sample) and, every ``state_every``
        ticks (by the sample's index on the clock), the controller-state payload."""
        cmd = self.commands.encode(stamp_ns, u)
        if self.state_every != 1 and (stamp_ns // self._period_ns) % self.state_every:
            return cmd, None
        c = self.controller
        return cmd, self.states.encode(stamp_ns, c.state_values(), c.algorithm)

    def step_raw(self, topic: str, data: bytes) -> tuple[bytes, bytes | None] | None:
        """The whole per-payload path: (command, state or None) when a tick completed."""
        s = self.on_raw(topic, data)
        if s is None:
            return None
        return self.answer(s.stamp_ns, self.update(s))

    def neutral_command(self) -> bytes | None:
        """The neutral command for the last answered sample (the node's last word), or None."""
        if self.last_stamp_ns < 0:
            return None
        return self.commands.encode(self.last_stamp_ns, self.params.limits.u_neutral)

    # -- reports ----------------------------------------------------------
    def diagnostics(self, node_name: str) -> list[DiagStatus]:
        """One ``/diagnostics`` status: OK, or WARN when ticks were lost or inputs bad."""
        a = self.assembler
        nonfinite = self.controller.n_nonfinite
        refused = self.n_trajectories_refused
        level = 1 if (a.incomplete or a.late or nonfinite or self.n_bad or refused) else 0
        msg = "running" if self.n_samples else "waiting for samples"
        if self.held_by and not level:
            level = 1
            msg = (
                f"valve held safe by the supervisor ({self.held_by}): commanding "
                f"{self.params.limits.u_neutral:g} V until released"
            )
        # samples before, none since the last report (1 s): the driver or sim stopped or is gone
        stopped = self.n_samples and self.n_samples == self._samples_seen
        self._samples_seen = self.n_samples
        if stopped:
            level = 2
            msg = (
                f"no samples since the last report (last stamp {self.last_stamp_ns} ns): "
                "the driver or sim stopped or is gone; not commanding"
            )
        elif level:
            msg = (
                f"{a.incomplete} incomplete / {a.late} late ticks, {nonfinite} non-finite "
                f"inputs, {self.n_bad} malformed payloads, {refused} trajectories refused"
                + (f" (last: {self.trajectory_error})" if refused else "")
            )
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
                    "malformed_payloads": str(self.n_bad),
                    "saturated_samples": str(self.n_saturated),
                    "last_stamp_ns": str(self.last_stamp_ns),
                    "last_command_v": f"{self.last_u:.6g}",
                    "parameter_changes": str(self.param_changes),
                    "held_by_supervisor": self.held_by,
                    "rejoins": str(self.controller.n_rejoins),
                    "trajectories": str(self.n_trajectories),
                    "trajectories_refused": str(refused),
                    "trajectories_late": str(self.n_trajectories_late),
                    "input_topics": ",".join(self.topics),
                    "state_every": str(self.state_every),
                },
            )
        ]
