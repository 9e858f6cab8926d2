"""Analysis of recorded runs: the paper's metrics and figures from a bag alone.

A run's bag (ours, or one recorded with ``ros2 bag record -s mcap`` from the
node graph) holds per axis the controller state (reference, measured, ...),
the sensor topics and the valve commands. The metadata record ``pneu.run``
(written by the in-process runner and by the logger node) says which axes
ran, with which reference and steady-state window, so nothing is guessed; a
bag without it can still be analysed with an explicit window.

The arrays handed to :func:`pneu_control.analysis.metrics.compute_metrics` are the
very ones the runner used (float64 values round-trip exactly through CDR,
times are the sample stamps), so ``pneu analyze`` reproduces the runner's
metrics bit for bit.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pneu_msgs_py.bag.errors import BagError, MissingTopicError
from pneu_msgs_py.bag.reader import RunData, read_run
from pneu_msgs_py.contract.topics import (
    CONTROLLER_STATE_TOPIC,
    DIAGNOSTICS_TOPIC,
    JOINT_STATE_TOPIC,
    VALVE_COMMAND_TOPIC,
)

from pneu_control.analysis.fault_marks import (
    FaultInterval,
    injected_intervals,
    parse_safety_status,
    safe_intervals,
)
from pneu_control.analysis.metrics import AxisMetrics, WindowSpec, axis_metrics
from pneu_control.analysis.records import END_METADATA, FAULTS_METADATA, RUN_METADATA

__all__ = [
    "AxisTrace",
    "RunAnalysis",
    "analyze",
    "axes_in",
    "axis_traces",
    "fault_intervals",
    "run_config",
    "safety_events",
]

_PRESSURES = {
    "linear": ("/pneu/pressure/cylinder_1", "/pneu/pressure/cylinder_2"),
    "rotary": ("/pneu/pressure/motor_in",),
}


@dataclass
class AxisTrace:
    """One axis of a recorded run, SI arrays on the controller's sample grid."""

    axis: str
    algorithm: str
    t: np.ndarray  # s since the first sample of the run
    reference: np.ndarray
    measured: np.ndarray  # the sensor value (x in m, ω in rad/s)
    u: np.ndarray  # valve command, V
    state: dict[str, np.ndarray]  # every controller-state field
    pressures: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass
class RunAnalysis:
    """What :func:`analyze` found in one bag: config echo, metrics and traces per axis, warnings."""

    path: str
    config: dict[str, Any]
    metrics: dict[str, AxisMetrics]
    traces: dict[str, AxisTrace]
    warnings: list[str]
    faults: list[FaultInterval] = field(default_factory=list)  # marked intervals
    include_faults: bool = False  # metrics include the fault intervals
    end: dict[str, str] = field(default_factory=dict)  # the pneu.end record ({} if none)

    @property
    def interrupted(self) -> bool:
        """Did the run end on a signal (its ``pneu.end`` record says so)?"""
        return self.end.get("interrupted") == "true"

    def status_line(self) -> str:
        """How the recorded run ended, in one line ("" for a run that completed)."""
        e = self.end
        status = e.get("status", "")
        if status == "interrupted":
            planned = int(e.get("planned_samples", "0") or 0) * _period_s(self.config)
            return (
                f"run interrupted by {e.get('signal') or 'a signal'} at "
                f"{float(e.get('last_sample_s', 'nan')):.3f} s of {planned:g} s"
                f"{' (' + e['interrupted_utc'] + ')' if e.get('interrupted_utc') else ''}: "
                "the metrics are over what ran"
            )
        if status == "failed":
            return f"run failed: {e.get('error', '?')}; the bag holds what ran"
        return ""

    def to_dict(self) -> dict[str, Any]:
        """The analysis as plain data (``pneu analyze --json``); traces left out."""
        return {
            "path": self.path,
            "interrupted": self.interrupted,
            "end": self.end,
            "metrics": {a: m.to_dict() for a, m in self.metrics.items()},
            "fault_intervals": [iv.to_dict() for iv in self.faults],
            "faults_excluded": not self.include_faults,
            "algorithms": {a: tr.algorithm for a, tr in self.traces.items()},
            "seed": self.config.get("seed"),
            "warnings": self.warnings,
        }


def run_config(data: RunData) -> dict[str, Any]:
    """The run's config echo from the ``pneu.run`` metadata record ({} if absent).

    A damaged record (not JSON, not a mapping) is left out with a warning in
    ``data.warnings``: the messages are still analysed, over the whole run.
    """
    rec = data.metadata.get(RUN_METADATA)
    if not rec or "config_json" not in rec:
        return {}
    try:
        config = json.loads(rec["config_json"])
        if not isinstance(config, dict):
            raise ValueError("not a mapping")
        return config
    except ValueError as err:
        data.warnings.append(
            f"{data.path}: metadata {RUN_METADATA}.config_json is damaged ({err}); "
            "analysed without it (windows: the whole run)"
        )
        return {}


def axes_in(data: RunData, config: dict[str, Any]) -> list[str]:
    """The run's axes: the config echo's ``axes`` if intact, else those with a controller state."""
    axes = config.get("axes")
    if axes:
        if isinstance(axes, list) and all(a in CONTROLLER_STATE_TOPIC for a in axes):
            return list(axes)
        data.warnings.append(f"{data.path}: metadata axes {axes!r} damaged: axes from the topics")
    return [a for a, topic in CONTROLLER_STATE_TOPIC.items() if topic in data.topics]


def axis_traces(data: RunData, axes: list[str]) -> dict[str, AxisTrace]:
    """Join controller state, sensor and command topics of each axis by stamp."""
    traces: dict[str, AxisTrace] = {}
    t0_ns: int | None = None
    for axis in axes:
        cs = data[CONTROLLER_STATE_TOPIC[axis]]
        js = data[JOINT_STATE_TOPIC[axis]]
        stamps = cs.stamp_ns
        first = int(js.stamp_ns[0]) if len(js) else int(stamps[0])
        t0_ns = first if t0_ns is None else min(t0_ns, first)
        col = "position" if axis == "linear" else "velocity"
        measured = _align(stamps, js.stamp_ns, js[col], data.path, JOINT_STATE_TOPIC[axis])
        u = np.full(stamps.shape, math.nan)
        if VALVE_COMMAND_TOPIC[axis] in data.topics:
            cmd = data.topics[VALVE_COMMAND_TOPIC[axis]]
            u = _align(stamps, cmd.stamp_ns, cmd["effort"], data.path, VALVE_COMMAND_TOPIC[axis])
        pressures = {}
        for topic in _PRESSURES[axis]:
            if topic in data.topics:
                fp = data.topics[topic]
                pressures[topic.rsplit("/", 1)[-1]] = _align(
                    stamps, fp.stamp_ns, fp["fluid_pressure"], data.path, topic
                )
        frames = cs.frame_id
        algorithm = str(frames[-1]) if len(frames) else ""
        state = {name: cs[name] for name in cs.keys() if name not in ("position",)}
        traces[axis] = AxisTrace(
            axis, algorithm, stamps, state["reference"], measured, u, state, pressures
        )
    for tr in traces.values():
        tr.t = (tr.t - t0_ns) * 1e-9
    return traces


def _align(stamps: np.ndarray, src_stamps: np.ndarray, values: np.ndarray, path: str, topic: str):
    """``values`` (stamped ``src_stamps``) at ``stamps``; exact-stamp match required."""
    if src_stamps.shape == stamps.shape and np.array_equal(src_stamps, stamps):
        return np.asarray(values, dtype=float)
    idx = np.searchsorted(src_stamps, stamps)
    idx = np.clip(idx, 0, len(src_stamps) - 1)
    ok = src_stamps[idx] == stamps
    if not ok.any():
        raise MissingTopicError(path, f"topic {topic} has no message at the controller's stamps")
    out = np.full(stamps.shape, math.nan)
    out[ok] = np.asarray(values, dtype=float)[idx[ok]]
    return out


def safety_events(data: RunData) -> list[tuple[int, str, str, int, str]]:
    """Supervisor transitions ``(stamp_ns, axis, rule, level, message)`` from ``/diagnostics``."""
    topic = data.topics.get(DIAGNOSTICS_TOPIC)
    if topic is None or topic.objects is None:
        return []
    out = []
    for stamp, statuses in zip(topic.stamp_ns.tolist(), topic.objects):
        for st in statuses or ():
            parsed = parse_safety_status(st.name)
            if parsed is not None:
                out.append((int(stamp), parsed[0], parsed[1], int(st.level), st.message))
    return out


def _period_s(config: dict[str, Any]) -> float:
    try:
        return float(config["plant"]["sim"]["T"])
    except (KeyError, TypeError, ValueError):
        return 1e-3


def fault_intervals(
    data: RunData, config: dict[str, Any], axes: list[str], t0_ns: int
) -> list[FaultInterval]:
    """Injected faults (config echo or ``pneu.faults``) and safe intervals (``/diagnostics``)."""
    faults = config.get("faults")
    if faults is None:
        rec = data.metadata.get(FAULTS_METADATA) or {}
        try:
            faults = json.loads(rec.get("faults_json", "[]"))
        except json.JSONDecodeError as err:
            raise BagError(data.path, f"metadata {FAULTS_METADATA} is not JSON: {err}") from None
    out = injected_intervals(faults, axes, _period_s(config))
    out += safe_intervals(safety_events(data), t0_ns)
    return out


def analyze(
    path: str | Path,
    *,
    window: WindowSpec | None = None,
    axes: list[str] | None = None,
    include_faults: bool = False,
) -> RunAnalysis:
    """The paper's metrics (DESIGN §7) of each axis of the run at ``path``.

    Fault intervals (injected faults, and where the safety supervisor held an
    axis safe) are marked in :attr:`RunAnalysis.faults` and left out of the
    metrics unless ``include_faults``.
    """
    data = read_run(path)
    config = run_config(data)
    axes = axes or axes_in(data, config)
    if not axes:
        raise MissingTopicError(path, _not_a_run(data))
    for axis in axes:
        for topic in (CONTROLLER_STATE_TOPIC[axis], JOINT_STATE_TOPIC[axis]):
            if topic not in data.topics or not len(data.topics[topic]):
                raise MissingTopicError(
                    path,
                    f"the {axis} axis has no {topic} messages to analyse "
                    f"(axes recorded: {', '.join(axes_in(data, {})) or 'none'})",
                )
    traces = axis_traces(data, axes)
    t0_ns = min(
        (
            int(data[JOINT_STATE_TOPIC[a]].stamp_ns[0])
            for a in axes
            if len(data[JOINT_STATE_TOPIC[a]])
        ),
        default=0,
    )
    try:
        intervals = fault_intervals(data, config, axes, t0_ns)
    except BagError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        data.warnings.append(
            f"{path}: fault records damaged ({type(err).__name__}); no fault marked"
        )
        intervals = []
    metrics: dict[str, AxisMetrics] = {}
    warnings = list(data.warnings)
    end = dict(data.metadata.get(END_METADATA) or {})
    source = (data.metadata.get(RUN_METADATA) or {}).get("source", "")
    if not end and source.startswith("pneu in-process runner"):
        warnings.append(
            f"{path}: no end record: the run was cut short (process killed?); "
            "the metrics are over the messages that were written"
        )
    for axis, tr in traces.items():
        spec = window
        if spec is None:
            windows = config.get("windows")
            wdict = windows.get(axis) if isinstance(windows, dict) else None
            spec = WindowSpec(kind="fixed")
            if wdict is None:
                warnings.append(f"{path}: no window in metadata for {axis}; using the whole run")
            else:
                try:
                    spec = WindowSpec.from_dict(wdict)
                except (TypeError, ValueError):
                    warnings.append(
                        f"{path}: window of {axis} in the metadata damaged; using the whole run"
                    )
        metrics[axis] = axis_metrics(
            axis, tr.t, tr.reference, tr.measured, spec, intervals, include_faults
        )
    return RunAnalysis(str(path), config, metrics, traces, warnings, intervals, include_faults, end)


def _not_a_run(data: RunData) -> str:
    """ "not a pneu run: no /pneu topics; found /chatter (std_msgs/msg/String)" and the like."""
    from pneu_msgs_py.bag.reader import iter_topic_names

    try:
        found = sorted(set(iter_topic_names(data.path)))
    except BagError:
        found = [(t, a.ros_type) for t, a in data.topics.items()]
    listed = ", ".join(f"{t} ({ty})" for t, ty in found[:8]) + (", ..." if len(found) > 8 else "")
    pneu = [t for t, _ in found if t.startswith("/pneu/")]
    if not pneu:
        return f"not a pneu run: no /pneu topics; found {listed or 'no topics'}"
    return f"not a pneu run: no /pneu/<axis>/controller_state topic; found {listed}"
