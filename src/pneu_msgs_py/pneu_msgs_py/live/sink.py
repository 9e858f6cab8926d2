"""Where a run's messages go: the declared interface, and a fan-out to several sinks."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

from pneu_msgs_py.contract.convert import DiagStatus
from pneu_msgs_py.contract.samples import SensorSample

__all__ = ["RunSink", "Tee"]

#: ``(axis, u [V], controller state values, algorithm)`` per axis that answered a sample
Answer = tuple[str, float, Sequence[float], str]


class RunSink(Protocol):
    """What the in-process runner writes one control cycle and its diagnostics to.

    :class:`pneu_msgs_py.bag.BagWriter` and :class:`pneu_msgs_py.live.server.LiveServer`
    implement it; times are int nanoseconds (the sample stamps).
    """

    def write_cycle(self, s: SensorSample, answers: Sequence[Answer]) -> None: ...

    def write_diagnostics(self, stamp_ns: int, statuses: Sequence[DiagStatus]) -> None: ...


class Tee:
    """Write every cycle and diagnostics to each sink in turn (e.g. the bag, then the live view)."""

    def __init__(self, *sinks: Any) -> None:
        self.sinks = tuple(s for s in sinks if s is not None)

    def write_cycle(self, s: SensorSample, answers: Sequence[Answer]) -> None:
        for sink in self.sinks:
            sink.write_cycle(s, answers)

    def write_diagnostics(self, stamp_ns: int, statuses: Sequence[DiagStatus]) -> None:
        for sink in self.sinks:
            sink.write_diagnostics(stamp_ns, statuses)
