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
from typing import Any

from pneu_msgs_py.contract.convert import (
    DiagStatus,
    fill_controller_state,
    fill_valve_command,
    sample_from_msgs,
)
from pneu_msgs_py.contract.samples import AXES, SensorSample

from pneu_control.controller.axis import STATE_FIELDS
from pneu_control.nodes.controller_core import _P_TOPICS, SENSOR_TOPICS, SampleAssembler
from pneu_control.sysid.design import design_for
from pneu_control.sysid.exciter import Exciter

__all__ = ["ExciterShellCore"]


class ExciterShellCore:
    """The designs of ``axes`` for ``seed`` and ``level``, answering ticks of sensor messages."""

    def __init__(self, axes: tuple[str, ...], seed: int, level: str, sample_time_s: float = 1e-3):
        self.designs = {a: design_for(a, seed, level) for a in AXES if a in axes}
        self.exciters = {a: Exciter(d, sample_time_s) for a, d in self.designs.items()}
        self.assembler = SampleAssembler()
        self.n_samples = 0
        self.last_stamp_ns = -1

    @property
    def duration_s(self) -> float:
        return max(d.duration_s for d in self.designs.values())

    def designs_json(self) -> str:
        """``{axis: design}`` as JSON (the bag's ``pneu.excite`` record; a node parameter)."""
        return json.dumps({a: d.to_dict() for a, d in self.designs.items()}, sort_keys=True)

    def on_message(self, topic: str, msg: Any) -> SensorSample | None:
        tick = self.assembler.add(topic, msg)
        if tick is None:
            return None
        p = _P_TOPICS
        s = sample_from_msgs(
            self.n_samples,
            tick[p[0]],
            tick[p[1]],
            tick[p[2]],
            tick[SENSOR_TOPICS[3]],
            tick[SENSOR_TOPICS[4]],
        )
        self.n_samples += 1
        self.last_stamp_ns = s.stamp_ns
        return s

    def answer(self, sample: SensorSample, msgs: dict[str, tuple[Any, Any]]) -> list[str]:
        """Fill ``msgs[axis] = (command, state)`` for every active axis; returns the axes filled."""
        for axis, ex in self.exciters.items():
            u = ex.update(sample)
            cmd, state = msgs[axis]
            fill_valve_command(cmd, axis, sample.stamp_ns, u)
            fill_controller_state(
                state, sample.stamp_ns, STATE_FIELDS, ex.state_values(), ex.algorithm
            )
        return list(self.exciters)

    def segment(self, axis: str) -> str:
        ex = self.exciters[axis]
        i = ex.segment
        return self.designs[axis].segments[i].label if i >= 0 else "waiting"

    def diagnostics(self, node_name: str) -> list[DiagStatus]:
        a = self.assembler
        out = []
        for axis, ex in self.exciters.items():
            level = 1 if (a.incomplete or a.late) else 0
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
                    },
                )
            )
        return out
