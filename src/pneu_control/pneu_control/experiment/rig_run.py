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
``/diagnostics``, how the run ended in ``pneu.end``) is written when the loop
has stopped, so the file never stalls a cycle. The output directory is
claimed before the loop starts (:class:`pneu_msgs_py.lifecycle.outputs.OutputDir`:
``run.mcap`` and ``loop.json``, written as ``.partial`` and renamed). SIGINT,
SIGTERM and SIGHUP stop the loop (the main thread polls
:func:`pneu_msgs_py.lifecycle.signals.pending`; the driver's ``finally`` leaves
the valves safe) and the files are then finished inside
:func:`~pneu_msgs_py.lifecycle.signals.deferred`, marked interrupted: a second
signal cannot cut them. A killed process leaves no bag (and, on the rig, the
valves as they were: docs/rig.md, "Safety on the real rig").
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pneu_driver.daq.backends import make_backend
from pneu_driver.loop.driver_loop import DriverLoop, LoopStats
from pneu_driver.safety import SafetySupervisor
from pneu_msgs_py.bag import DiagStatus
from pneu_msgs_py.lifecycle import signals
from pneu_msgs_py.lifecycle.outputs import OutputDir

from pneu_control.controller.axis import AxisController

__all__ = ["RIG_ARTEFACTS", "RigRunResult", "rig_dir", "run_rig"]

RIG_ARTEFACTS = ("run.mcap", "loop.json")

_LEVEL = {"OK": 0, "WARN": 1, "ERROR": 2}
NODE = "pneu_rig"


@dataclass
class RigRunResult:
    """What a rig run left: the loop's statistics and diagnostics, its error, the cycles logged, the
    bag."""

    stats: LoopStats
    diagnostics: dict[str, str]  # the loop's /diagnostics key-values at the end
    error: BaseException | None
    cycles_logged: int
    bag: Path | None
    end: dict[str, Any] = field(default_factory=dict)  # how the run ended (pneu.end)

    @property
    def interrupted(self) -> bool:
        """Did a signal (or Ctrl-C) end the run?"""
        return bool(self.end.get("interrupted"))

    def to_dict(self) -> dict[str, Any]:
        """The result as plain data (loop.json)."""
        return {
            "loop": self.diagnostics,
            "error": None if self.error is None else str(self.error),
            "cycles_logged": self.cycles_logged,
            "bag": None if self.bag is None else str(self.bag),
            "end": self.end,
        }


def rig_dir(out_dir: str | Path, *, overwrite: bool = False, inputs: Any = ()) -> OutputDir:
    """The claim on ``pneu rig``'s output directory; ``.check()`` it with the other inputs."""
    return OutputDir(out_dir, RIG_ARTEFACTS, overwrite=overwrite, inputs=inputs)


def run_rig(
    backend: str,
    spec: Any,
    rig: Any,
    *,
    duration_s: float | None,
    out_dir: str | Path | OutputDir | None = None,
    echo: dict[str, Any] | None = None,
    stop: threading.Event | None = None,
    hold: dict[str, float] | None = None,
) -> RigRunResult:
    """Run ``spec``'s controllers (a :class:`~pneu_control.experiment.runner.RunSpec`) on
    ``backend`` for ``duration_s`` (None: until ``stop`` is set, a signal or Ctrl-C).

    ``out_dir``: a directory (claimed here) or its claim (:func:`rig_dir`, checked by the
    caller). ``hold``: axes commanded a constant voltage instead (bring-up: valve neutral trim).
    """
    hold = hold or {}
    claim = None
    if out_dir is not None:
        claim = out_dir if isinstance(out_dir, OutputDir) else rig_dir(out_dir)
        claim.check()
    daq = make_backend(backend, rig)  # a bad backend spec is refused here, before any file
    sup = SafetySupervisor(spec.safety, sample_time_s=rig.period_s)
    cycles: list[tuple[Any, list[tuple[str, float, tuple[float, ...], str]]]] = []
    events: list[Any] = []
    loop = _controlled_loop(daq, rig, sup, spec, hold, cycles, events)
    n = None if duration_s is None else max(1, round(duration_s * rig.loop.rate_hz))
    stats_marks: list[tuple[int, dict[str, str]]] = []

    def target() -> None:
        try:
            loop.run(n)
        except BaseException as err:  # reported by the caller (one line), valves already safe
            loop.error = err

    with signals.deferred():  # a signal stops the loop; the files are finished after it
        signals.raise_if_pending()  # one during start-up: nothing claimed, nothing written
        if claim is not None:
            claim.__enter__()
        try:
            keyboard = _run_loop(loop, target, stop, stats_marks)
            diag = loop.diagnostics()
            sig = signals.pending()
            end = _end_record(cycles, n, sig is not None or keyboard, sig, loop.error)
            bag_path = None
            if claim is not None and loop.error is not None and not cycles:
                claim.discard()  # the DAQ never opened: nothing ran, nothing to keep
            elif claim is not None:
                bag_path = claim.final("run.mcap")
                _write_bag(bag_path, cycles, events, stats_marks, diag, echo or {}, end)
                _write_loop_json(claim, diag, loop.error, end)
        except BaseException:
            if claim is not None:
                claim.discard()
            raise
        finally:
            if claim is not None:
                claim.__exit__(None, None, None)
    return RigRunResult(loop.stats, diag, loop.error, len(cycles), bag_path, end)


def _controlled_loop(
    daq: Any, rig: Any, sup: Any, spec: Any, hold: dict[str, float], cycles: list, events: list
) -> DriverLoop:
    """The driver loop whose sample callback runs ``spec``'s controllers (and the held axes'
    constant commands) and records each cycle's answers into ``cycles``."""
    ctrls = [(a, AxisController(a, spec.controllers[a])) for a in spec.axes if a not in hold]
    held = tuple(hold.items())
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
    return loop


def _write_loop_json(claim: OutputDir, diag: Any, error: Any, end: dict[str, Any]) -> None:
    """``loop.json``: the loop's diagnostics, its error ("" if none) and the end record."""
    doc = {"loop": diag, "error": str(error or ""), "end": end}
    claim.partial("loop.json").write_text(json.dumps(doc, indent=2) + "\n")
    claim.publish("loop.json")


def _run_loop(loop: DriverLoop, target: Any, stop: Any, stats_marks: list) -> bool:
    """Run the loop thread until it ends, ``stop`` is set or a signal comes (polled every
    50 ms); the loop's statistics once a second. True if a KeyboardInterrupt stopped it
    (SIGINT where pneu's handlers are not installed)."""
    th = threading.Thread(target=target, name="pneu_rig_loop", daemon=True)
    th.start()
    next_mark = time.monotonic() + 1.0
    try:
        while th.is_alive():
            th.join(timeout=0.05)
            if time.monotonic() >= next_mark:
                next_mark += 1.0
                if loop.last_sample is not None:
                    stats_marks.append((loop.last_sample.stamp_ns, loop.diagnostics()))
            if (stop is not None and stop.is_set()) or signals.pending() is not None:
                loop.stop()
    except KeyboardInterrupt:
        loop.stop()
        th.join()
        return True
    return False


def _end_record(cycles, n, interrupted: bool, sig, error) -> dict[str, Any]:
    """``pneu.end`` as :func:`pneu_control.experiment.session.end_record` writes it."""
    status = "interrupted" if interrupted else ("failed" if error is not None else "completed")
    out = {
        "status": status,
        "interrupted": interrupted,
        "signal": signals.signal_name(sig) if (interrupted and sig) else "",
        "interrupted_utc": signals.pending_since() if interrupted else "",
        "last_sample_s": cycles[-1][0].stamp_ns * 1e-9 if cycles else 0.0,
        "samples": len(cycles),
        "planned_samples": n if n is not None else "until stopped",
    }
    if error is not None:
        out["error"] = f"{type(error).__name__}: {error}"
    return out


def _write_bag(path, cycles, events, stats_marks, final, echo, end) -> None:
    from pneu_control.controller.axis import STATE_FIELDS
    from pneu_control.experiment.bag_log import END_METADATA, end_metadata, run_metadata

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
        bag.add_metadata(END_METADATA, end_metadata(end))
