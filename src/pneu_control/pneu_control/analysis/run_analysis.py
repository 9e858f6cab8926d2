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
from pneu_control.analysis.metrics import AxisMetrics, WindowSpec
from pneu_control.experiment.bag_log import FAULTS_METADATA, RUN_METADATA

__all__ = [
    "AxisTrace",
    "RunAnalysis",
    "analyze",
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
    path: str
    config: dict[str, Any]
    metrics: dict[str, AxisMetrics]
    traces: dict[str, AxisTrace]
    warnings: list[str]
    faults: list[FaultInterval] = field(default_factory=list)  # marked intervals
    include_faults: bool = False  # metrics include the fault intervals

    def to_dict(self) -> dict[str, Any]:
        return {
            "path": self.path,
            "metrics": {a: m.to_dict() for a, m in self.metrics.items()},
            "fault_intervals": [iv.to_dict() for iv in self.faults],
            "faults_excluded": not self.include_faults,
            "algorithms": {a: tr.algorithm for a, tr in self.traces.items()},
            "seed": self.config.get("seed"),
            "warnings": self.warnings,
        }


def run_config(data: RunData) -> dict[str, Any]:
    """The run's config echo from the ``pneu.run`` metadata record ({} if absent)."""
    rec = data.metadata.get(RUN_METADATA)
    if not rec or "config_json" not in rec:
        return {}
    try:
        return json.loads(rec["config_json"])
    except json.JSONDecodeError as err:
        raise BagError(
            data.path, f"metadata {RUN_METADATA}.config_json is not JSON: {err}"
        ) from None


def _axes_in(data: RunData, config: dict[str, Any]) -> list[str]:
    if config.get("axes"):
        return list(config["axes"])
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
    from pneu_control.experiment.runner import axis_metrics

    data = read_run(path)
    config = run_config(data)
    axes = axes or _axes_in(data, config)
    if not axes:
        raise MissingTopicError(
            path, "no /pneu/<axis>/controller_state topic: nothing to analyse (is this a pneu run?)"
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
    intervals = fault_intervals(data, config, axes, t0_ns)
    metrics: dict[str, AxisMetrics] = {}
    warnings = list(data.warnings)
    for axis, tr in traces.items():
        spec = window
        if spec is None:
            wdict = config.get("windows", {}).get(axis)
            if wdict is None:
                warnings.append(f"{path}: no window in metadata for {axis}; using the whole run")
                spec = WindowSpec(kind="fixed")
            else:
                spec = WindowSpec.from_dict(wdict)
        metrics[axis] = axis_metrics(
            axis, tr.t, tr.reference, tr.measured, spec, intervals, include_faults
        )
    return RunAnalysis(str(path), config, metrics, traces, warnings, intervals, include_faults)
