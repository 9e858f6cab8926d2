"""Per-sample work of the exciter node, without ROS: sensor messages in, designed commands out.

The rclpy shell (:mod:`pneu_control.nodes.exciter_node`) subscribes to the
five sensor topics and publishes, per complete tick, each active axis's valve
command (stamped with the sample it answers) and its state on the axis's
controller-state topic -- the exciter stands where the controllers stand, so
the sim node (lockstep or realtime) and the driver take its answers as a
controller's. Everything it does per message is here:
:class:`~pneu_control.nodes.controller_core.SampleAssembler` for the tick,
:class:`~pneu_control.sysid.exciter.Exciter` per axis for the command.
"""

from __future__ import annotations

import json

from pneu_msgs_py.contract.convert import DiagStatus
from pneu_msgs_py.contract.samples import AXES, SensorSample
from pneu_msgs_py.contract.wire import SENSOR_TOPICS, CommandWire, StateWire

from pneu_control.controller.axis import STATE_FIELDS
from pneu_control.nodes.controller_core import TickDecoder
from pneu_control.sysid.design import design_for
from pneu_control.sysid.exciter import Exciter

__all__ = ["ExciterShellCore"]


class ExciterShellCore:
    """The designs of ``axes`` for ``seed`` and ``level``, answering ticks of raw sensor payloads."""

    def __init__(self, axes: tuple[str, ...], seed: int, level: str, sample_time_s: float = 1e-3):
        self.designs = {a: design_for(a, seed, level) for a in AXES if a in axes}
        self.exciters = {a: Exciter(d, sample_time_s) for a, d in self.designs.items()}
        self.topics = SENSOR_TOPICS  # all five: the bag of an excitation run keeps every sensor
        self.decoder = TickDecoder(self.topics)
        self.commands = {a: CommandWire(a) for a in self.exciters}
        self.states = StateWire(STATE_FIELDS)
        self.last_stamp_ns = -1

    @property
    def n_samples(self) -> int:
        """Complete sensor ticks so far."""
        return self.decoder.n_ticks

    @property
    def duration_s(self) -> float:
        """The longest design's duration (s): the experiment ends with it."""
        return max(d.duration_s for d in self.designs.values())

    def designs_json(self) -> str:
        """``{axis: design}`` as JSON (the bag's ``pneu.excite`` record; a node parameter)."""
        return json.dumps({a: d.to_dict() for a, d in self.designs.items()}, sort_keys=True)

    def on_raw(self, topic: str, data: bytes) -> SensorSample | None:
        """One sensor payload in; the sample when its tick is complete."""
        s = self.decoder.on_raw(topic, data)
        if s is not None:
            self.last_stamp_ns = s.stamp_ns
        return s

    def answer(self, sample: SensorSample) -> list[tuple[str, bytes, bytes]]:
        """``[(axis, command payload, state payload)]`` of every active axis for ``sample``."""
        out = []
        for axis, ex in self.exciters.items():
            u = ex.update(sample)
            cmd = self.commands[axis].encode(sample.stamp_ns, u)
            state = self.states.encode(sample.stamp_ns, ex.state_values(), ex.algorithm)
            out.append((axis, cmd, state))
        return out

    def neutral_commands(self, u_neutral: float) -> list[tuple[str, bytes]]:
        """The neutral command of every axis for the last answered sample (the last word)."""
        if self.last_stamp_ns < 0:
            return []
        return [(a, w.encode(self.last_stamp_ns, u_neutral)) for a, w in self.commands.items()]

    def segment(self, axis: str) -> str:
        """The label of ``axis``'s current design segment ("waiting" before the first)."""
        ex = self.exciters[axis]
        i = ex.segment
        return self.designs[axis].segments[i].label if i >= 0 else "waiting"

    def diagnostics(self, node_name: str) -> list[DiagStatus]:
        """One status per excited axis: its segment, samples and guard trips (WARN on incomplete,
        late or bad input)."""
        a = self.decoder.assembler
        out = []
        for axis, ex in self.exciters.items():
            level = 1 if (a.incomplete or a.late or self.decoder.n_bad) else 0
            out.append(
                DiagStatus(
                    level=level,
                    name=f"{node_name}: {axis} excitation",
                    message=self.segment(axis),
                    hardware_id="pneu",
                    values={
                        "samples": str(self.n_samples),
                        "segment": str(ex.segment),
                        "guard_trips": str(ex.guard_trips),
                        "incomplete_ticks": str(a.incomplete),
                        "late_messages": str(a.late),
                        "malformed_payloads": str(self.decoder.n_bad),
                    },
                )
            )
        return out
