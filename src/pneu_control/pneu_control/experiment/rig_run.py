"""The driver loop with the controllers hosted in it: the rig (or its rehearsal) without ROS.

``pneu rig --backend nidaqmx|sim[:...]`` runs :class:`pneu_driver.loop.driver_loop.DriverLoop`
on a DAQ backend (:func:`pneu_driver.daq.backends.make_backend`) with one
:class:`~pneu_control.controller.axis.AxisController` per active axis called
in the loop thread, as ros2_control's controller manager does (DESIGN §10):
sample k → controllers → commands → supervisor → written at clock k+1. The
safety supervisor, the late-cycle accounting and the heartbeat are the
driver's; on the ``sim`` backend the twin is a simulated PCI-6221 on its own
1 kHz clock, so this is the rig's code path end to end, rehearsed.

The loop thread only appends to lists; the MCAP bag (samples, commands,
controller states, safety events, the loop's statistics once a second on
``/diagnostics``) is written when the loop has stopped, so the file never
stalls a cycle. A killed process leaves no bag (and, on the rig, the valves
as they were: README, "Safety on the real rig").
"""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pneu_driver.daq.backends import make_backend
from pneu_driver.loop.driver_loop import DriverLoop, LoopStats
from pneu_driver.safety import SafetySupervisor
from pneu_msgs_py.bag import DiagStatus

from pneu_control.controller.axis import AxisController

__all__ = ["RigRunResult", "run_rig"]

_LEVEL = {"OK": 0, "WARN": 1, "ERROR": 2}
NODE = "pneu_rig"


@dataclass
class RigRunResult:
    stats: LoopStats
    diagnostics: dict[str, str]  # the loop's /diagnostics key-values at the end
    error: BaseException | None
    cycles_logged: int
    bag: Path | None

    def to_dict(self) -> dict[str, Any]:
        return {
            "loop": self.diagnostics,
            "error": None if self.error is None else str(self.error),
            "cycles_logged": self.cycles_logged,
            "bag": None if self.bag is None else str(self.bag),
        }


def run_rig(
    backend: str,
    spec: Any,
    rig: Any,
    *,
    duration_s: float | None,
    out_dir: str | Path | None = None,
    echo: dict[str, Any] | None = None,
    stop: threading.Event | None = None,
    hold: dict[str, float] | None = None,
) -> RigRunResult:
    """Run ``spec``'s controllers (a :class:`~pneu_control.experiment.runner.RunSpec`) on
    ``backend`` for ``duration_s`` (None: until ``stop`` is set or Ctrl-C).

    ``hold``: axes commanded a constant voltage instead (bring-up: valve neutral trim).
    """
    hold = hold or {}
    daq = make_backend(backend, rig)
    sup = SafetySupervisor(spec.safety, sample_time_s=rig.period_s)
    ctrls = [(a, AxisController(a, spec.controllers[a])) for a in spec.axes if a not in hold]
    held = tuple(hold.items())
    cycles: list[tuple[Any, list[tuple[str, float, tuple[float, ...], str]]]] = []
    events: list[Any] = []
    loop: DriverLoop

    def on_sample(s: Any) -> None:
        answers = []
        for axis, u in held:
            loop.put_command(axis, u, s.stamp_ns)
        for axis, c in ctrls:
            u = c.update(s)
            loop.put_command(axis, u, s.stamp_ns)
            answers.append((axis, u, c.state_values(), c.algorithm))
        cycles.append((s, answers))

    loop = DriverLoop(
        daq,
        rig,
        sup,
        on_sample=on_sample,
        on_events=events.extend,
        expected_axes=tuple(dict.fromkeys((*spec.axes, *hold))),
    )
    n = None if duration_s is None else max(1, round(duration_s * rig.loop.rate_hz))
    stats_marks: list[tuple[int, dict[str, str]]] = []

    def target() -> None:
        try:
            loop.run(n)
        except BaseException as err:  # reported by the caller (one line), valves already safe
            loop.error = err

    th = threading.Thread(target=target, name="pneu_rig_loop", daemon=True)
    th.start()
    try:
        while th.is_alive():
            th.join(timeout=1.0)
            if loop.last_sample is not None:
                stats_marks.append((loop.last_sample.stamp_ns, loop.diagnostics()))
            if stop is not None and stop.is_set():
                loop.stop()
    except KeyboardInterrupt:
        loop.stop()
        th.join()
    diag = loop.diagnostics()
    bag_path = None
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        bag_path = out / "run.mcap"
        _write_bag(bag_path, cycles, events, stats_marks, diag, echo or {})
        (out / "loop.json").write_text(
            json.dumps({"loop": diag, "error": str(loop.error or "")}, indent=2) + "\n"
        )
    return RigRunResult(loop.stats, diag, loop.error, len(cycles), bag_path)


def _write_bag(path, cycles, events, stats_marks, final, echo) -> None:
    from pneu_control.controller.axis import STATE_FIELDS
    from pneu_control.experiment.bag_log import run_metadata

    meta = run_metadata(echo)
    meta["pneu.run"]["source"] = (
        f"pneu rig (driver loop, hosted controllers): {echo.get('backend')}"
    )
    from pneu_msgs_py.bag import BagWriter

    with BagWriter(
        path, metadata=meta, controller_state_fields=STATE_FIELDS, qos="realtime"
    ) as bag:
        for s, answers in cycles:
            bag.write_cycle(s, answers)
        for e in events:
            status = DiagStatus(
                _LEVEL[e.level], f"{NODE}: safety {e.axis} {e.rule}", e.message, "", dict(e.values)
            )
            bag.write_diagnostics(e.stamp_ns, [status])
        for stamp, values in [*stats_marks, (stats_marks[-1][0] if stats_marks else 0, final)]:
            bag.write_diagnostics(stamp, [DiagStatus(0, f"{NODE}: loop", "", "", values)])
