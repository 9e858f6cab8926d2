"""A bag as identification data: the voltages on the valves in each period and the samples.

:func:`load_record` reads a pneu bag (``pneu excite`` in-process, the ROS
exciter through the logger, or any ``pneu run`` / rig bag) and returns a
:class:`Record`:

- the samples k = 0..N-1 on the sample clock's grid (SI, pressures
  absolute): ``p_c1``, ``p_c2``, ``p_m1``, ``x``, ``theta``, ``omega``, NaN
  where a message is missing;
- ``u[axis][k]``: the voltage held on the valve over period k (sample k to
  k+1). DESIGN §3: the command answering sample k−1 (its header stamp) is
  written at tick k, so ``u[k]`` = command(stamp_{k−1}); the neutral 5 V before
  the first command; a missing command keeps the previous one (the DAQ holds
  its output);
- ``valid[axis]``: False from the first safety event of that axis on
  (``/diagnostics``): while the supervisor overrides the command, the
  voltage on the valve is not the recorded one;
- the excitation design of each axis if the bag has one (metadata
  ``pneu.excite``, or the exciter node's parameters as the logger records
  them), used to cut the replays and find the quiet segments.

Besides, for ``pneu validate``'s closed-loop replay, the controllers a
``pneu run`` bag ran (``pneu.run``'s ``controllers`` entry). Nothing else from
the metadata is read: a bag of a twin run carries the twin's parameters, and
the identifier must not see them.
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pneu_msgs_py.bag.errors import BagError, MissingTopicError
from pneu_msgs_py.bag.reader import read_run
from pneu_msgs_py.contract.samples import AXES, NEUTRAL_V
from pneu_msgs_py.contract.topics import (
    JOINT_STATE_TOPIC,
    PRESSURE_TOPICS,
    VALVE_COMMAND_TOPIC,
)

from pneu_control.experiment.bag_log import EXCITE_METADATA
from pneu_control.sysid.design import ExcitationDesign, design_from_json

__all__ = ["SIGNALS", "AXIS_SIGNALS", "Record", "load_record"]

EXCITER_PARAMS = "pneu.params/pneu_exciter"  # the logger's record of the exciter node

SIGNALS = ("p_c1", "p_c2", "p_m1", "x", "theta", "omega")
# the signals each axis's identification and validation compare
AXIS_SIGNALS = {"linear": ("x", "p_c1", "p_c2"), "rotary": ("omega", "p_m1")}
_PRESSURE_FIELD = {"p_c1": "cylinder_1", "p_c2": "cylinder_2", "p_m1": "motor_in"}


@dataclass
class Record:
    """One bag, ready for replay (see the module docstring)."""

    path: str
    name: str
    stamp_ns: np.ndarray  # (N,) int64
    y: dict[str, np.ndarray]  # SIGNALS -> (N,)
    u: dict[str, np.ndarray]  # axis -> (N,) V held over period k
    commanded: tuple[str, ...]  # axes with recorded commands
    valid: dict[str, np.ndarray]  # axis -> (N,) bool
    designs: dict[str, ExcitationDesign] = field(default_factory=dict)
    controllers: dict[str, dict] = field(default_factory=dict)  # a pneu run's controller params
    period_s: float = 1e-3
    notes: list[str] = field(default_factory=list)
    # values derived from this record alone, kept for the replays (spools, measured segment
    # starts: see pneu_control.sysid.shooting); never changes a result
    memo: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def n(self) -> int:
        """Samples on the record's grid."""
        return len(self.stamp_ns)

    @property
    def t(self) -> np.ndarray:
        """Sample times, s from the first sample."""
        return (self.stamp_ns - self.stamp_ns[0]) * 1e-9

    def quiet_mask(self, axis: str, min_s: float = 0.5) -> np.ndarray:
        """Samples where ``axis``'s valve voltage has not changed for ``min_s`` s (and stays so).

        With a design: its ``hold`` segments (after their first ``min_s``);
        else any run of an unchanged voltage at least 2·``min_s`` long.
        """
        t = self.t
        mask = np.zeros(self.n, dtype=bool)
        d = self.designs.get(axis)
        if d is not None:
            for s in d.segments:
                if s.kind == "hold":
                    mask |= (t >= s.t0_s + min_s) & (t < s.t1_s)
            return mask & self.valid[axis]
        u = self.u[axis]
        n_min = int(round(2 * min_s / self.period_s))
        change = np.flatnonzero(np.diff(u) != 0.0) + 1
        bounds = np.concatenate(([0], change, [self.n]))
        skip = int(round(min_s / self.period_s))
        for a, b in itertools.pairwise(bounds):
            if b - a >= n_min:
                mask[a + skip : b] = True
        return mask & self.valid[axis]


def _aligned(stamps: np.ndarray, src: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = np.full(stamps.shape, math.nan)
    if len(src) == 0:
        return out
    idx = np.clip(np.searchsorted(src, stamps), 0, len(src) - 1)
    ok = src[idx] == stamps
    out[ok] = np.asarray(values, dtype=float)[idx[ok]]
    return out


def _designs(metadata: dict[str, dict[str, str]], path: str) -> dict[str, ExcitationDesign]:
    """The designs of an in-process run (``pneu.excite``) or of the ROS exciter node (its
    ``design_json`` parameter, recorded by the logger as ``pneu.params/pneu_exciter``)."""
    rec = metadata.get(EXCITE_METADATA)
    text = rec.get("designs_json") if rec else None
    if text is None:
        node = metadata.get(EXCITER_PARAMS) or {}
        if "design_json" in node:
            try:
                text = json.loads(node["design_json"])  # the logger stores values as JSON
            except json.JSONDecodeError:
                text = None
    if not text:
        return {}
    try:
        doc = json.loads(text)
        return {axis: design_from_json(d) for axis, d in doc.items()}
    except (json.JSONDecodeError, KeyError, TypeError) as err:
        raise BagError(path, f"metadata {EXCITE_METADATA}.designs_json unreadable: {err}") from None


def _controllers(metadata: dict[str, dict[str, str]]) -> dict[str, dict]:
    """Only the ``controllers`` entry of the run's config (never its plant)."""
    from pneu_control.experiment.bag_log import RUN_METADATA

    try:
        ctrls = json.loads((metadata.get(RUN_METADATA) or {}).get("config_json", "{}"))
        ctrls = ctrls.get("controllers") or {}
    except (json.JSONDecodeError, AttributeError):
        return {}
    return {a: c for a, c in ctrls.items() if isinstance(c, dict) and "segments" not in c}


def _safety_start(data, axis: str, stamps: np.ndarray) -> int | None:
    """Sample index of the first supervisor event on ``axis`` (WARN or ERROR), if any."""
    from pneu_control.analysis.run_analysis import safety_events

    for stamp, ev_axis, _rule, level, _msg in sorted(safety_events(data)):
        if level >= 1 and ev_axis in (axis, "all"):
            return int(np.searchsorted(stamps, stamp))
    return None


def _measured(data, stamps: np.ndarray) -> dict[str, np.ndarray]:
    """The sensor values (p_c1, p_c2, p_m1, x, theta, omega) at ``stamps``; NaN where lost."""
    js_lin = data.topics.get(JOINT_STATE_TOPIC["linear"])
    js_rot = data.topics.get(JOINT_STATE_TOPIC["rotary"])
    y: dict[str, np.ndarray] = {}
    for name, frame in _PRESSURE_FIELD.items():
        topic = next(t for t, (_, fr) in PRESSURE_TOPICS.items() if fr == frame)
        fp = data.topics.get(topic)
        y[name] = (
            _aligned(stamps, fp.stamp_ns, fp["fluid_pressure"])
            if fp is not None
            else np.full(len(stamps), math.nan)
        )
    y["x"] = (
        _aligned(stamps, js_lin.stamp_ns, js_lin["position"])
        if js_lin is not None
        else np.full(len(stamps), math.nan)
    )
    if js_rot is not None:
        y["theta"] = _aligned(stamps, js_rot.stamp_ns, js_rot["rotary.position"])
        y["omega"] = _aligned(stamps, js_rot.stamp_ns, js_rot["rotary.velocity"])
    else:
        y["theta"] = y["omega"] = np.full(len(stamps), math.nan)
    return y


def _held_commands(data, stamps: np.ndarray, notes: list[str]):
    """Per axis the voltage held over each sample period (neutral before the first command),
    where it is unknown (a lost command), and the axes that were commanded."""
    u: dict[str, np.ndarray] = {}
    unknown: dict[str, np.ndarray] = {}
    commanded = []
    for axis in AXES:
        cmd = data.topics.get(VALVE_COMMAND_TOPIC[axis])
        held = np.full(len(stamps), NEUTRAL_V)
        if cmd is not None and len(cmd):
            commanded.append(axis)
            c = _aligned(stamps, cmd.stamp_ns, cmd["effort"])  # answer to sample k
            lost = ~np.isfinite(c)
            lost[-1] = False  # the last sample's answer is never applied
            if lost.any():
                notes.append(
                    f"{axis}: {int(lost.sum())} samples without a recorded command: the "
                    "periods after them are not used (the voltage on the valve is unknown)"
                )
                unknown[axis] = np.concatenate(([False], lost[:-1]))
            # held over period k+1 = the answer to sample k; a lost one: the previous held
            idx = np.where(np.isfinite(c), np.arange(len(c)), -1)
            idx = np.maximum.accumulate(idx)
            last = np.where(idx >= 0, c[np.maximum(idx, 0)], NEUTRAL_V)
            held[1:] = last[:-1]
        u[axis] = held
    return u, unknown, commanded


def load_record(path: str | Path) -> Record:
    """Read ``path`` (``.mcap`` or rosbag2 directory) into a :class:`Record`."""
    path = str(path)
    data = read_run(path)
    js_lin = data.topics.get(JOINT_STATE_TOPIC["linear"])
    js_rot = data.topics.get(JOINT_STATE_TOPIC["rotary"])
    base = js_lin if js_lin is not None and len(js_lin) else js_rot
    if base is None or not len(base):
        raise MissingTopicError(path, "no sensor samples (/pneu/<axis>/joint_state)")
    seen = np.asarray(base.stamp_ns, dtype=np.int64)
    notes: list[str] = []
    # the sample clock's grid from the first to the last stamp: a lost message is a NaN
    period_ns = int(np.median(np.diff(seen))) if len(seen) > 1 else 1_000_000
    stamps = np.arange(int(seen[0]), int(seen[-1]) + 1, period_ns, dtype=np.int64)
    if len(stamps) > len(seen):
        notes.append(f"{len(stamps) - len(seen)} of {len(stamps)} samples missing (lost messages)")
    y = _measured(data, stamps)
    u, unknown, commanded = _held_commands(data, stamps, notes)
    valid = {}
    for axis in AXES:
        v = np.ones(len(stamps), dtype=bool)
        if axis in unknown:
            v &= ~unknown[axis]
        i = _safety_start(data, axis, stamps)
        if i is not None:
            v[i:] = False
            notes.append(f"{axis}: supervisor event at sample {i}: data after it not used")
        valid[axis] = v
    period = period_ns * 1e-9
    return Record(
        path=path,
        name=Path(path).name,
        stamp_ns=stamps,
        y=y,
        u=u,
        commanded=tuple(commanded),
        valid=valid,
        designs=_designs(data.metadata, path),
        controllers=_controllers(data.metadata),
        period_s=period,
        notes=notes,
    )
