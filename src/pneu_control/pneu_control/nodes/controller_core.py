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

Hosted (one-process) deployments call :meth:`update` and :meth:`answer` with
a whole sample instead of step 1. Same sample, same numbers: a lockstep ROS
run gives the in-process runner's results.
"""

from __future__ import annotations

import math
from typing import Any

from pneu_msgs_py.contract.convert import DiagStatus
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import JOINT_STATE_TOPIC, PRESSURE_TOPICS
from pneu_msgs_py.contract.wire import CommandWire, SensorWire, StateWire

from pneu_control.controller.axis import STATE_FIELDS, AxisController

__all__ = ["INPUT_TOPICS", "SampleAssembler", "TickDecoder", "ControllerShellCore"]

_P = tuple(PRESSURE_TOPICS)
#: The sensor topics each axis' controller takes (its algorithms read nothing else).
INPUT_TOPICS: dict[str, tuple[str, ...]] = {
    "linear": (_P[0], _P[1], JOINT_STATE_TOPIC["linear"]),
    "rotary": (JOINT_STATE_TOPIC["rotary"],),
}
_NAN = math.nan


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
        self.n_saturated = 0
        self.last_stamp_ns = -1
        self.last_u = _NAN
        self.param_changes = 0

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
        level = 1 if (a.incomplete or a.late or nonfinite or self.n_bad) else 0
        msg = "running" if self.n_samples else "waiting for samples"
        if level:
            msg = (
                f"{a.incomplete} incomplete / {a.late} late ticks, {nonfinite} non-finite "
                f"inputs, {self.n_bad} malformed payloads"
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
                    "input_topics": ",".join(self.topics),
                    "state_every": str(self.state_every),
                },
            )
        ]
