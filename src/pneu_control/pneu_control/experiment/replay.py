"""Open-loop replay: recorded sensor streams through a controller core, offline.

The recorded samples are fed, in stamp order, to a fresh
:class:`~pneu_control.controller.axis.AxisController`; what it would have estimated and
commanded is written to a new bag beside the recorded sensor topics. The
plant does NOT respond to the new commands (open loop): the replay shows an
observer's estimates and a law's commands on real data, e.g. new ESO gains on
a bag recorded on the rig. Every replay bag says so in its metadata.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from pneu_msgs_py.bag.errors import MissingTopicError
from pneu_msgs_py.bag.reader import RunData, read_run
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import JOINT_STATE_TOPIC, PRESSURE_TOPICS, ROTARY_COUNTS_JOINT
from pneu_msgs_py.params.core import ParamError, from_dict

from pneu_control.analysis.run_analysis import axes_in, run_config
from pneu_control.controller.axis import STATE_FIELDS, AxisController
from pneu_control.controller.params import AxisControllerParams, load_controller_params
from pneu_control.experiment.bag_log import RUN_METADATA

__all__ = ["OPEN_LOOP_NOTE", "recorded_samples", "replay"]

OPEN_LOOP_NOTE = (
    "open-loop replay: recorded sensor samples fed to a controller core offline; the plant "
    "did not respond to these commands"
)


def recorded_samples(data: RunData) -> list[SensorSample]:
    """Rebuild the :class:`SensorSample` stream of a bag (stamp-aligned; NaN where absent)."""
    lin = data[JOINT_STATE_TOPIC["linear"]]
    stamps = lin.stamp_ns
    cols: dict[str, np.ndarray] = {"x": lin["position"]}
    rot = data.topics.get(JOINT_STATE_TOPIC["rotary"])
    for name, (attr, _) in zip(PRESSURE_TOPICS, PRESSURE_TOPICS.values()):
        cols[attr] = _at(data, name, "fluid_pressure", stamps)
    if rot is not None and np.array_equal(rot.stamp_ns, stamps):
        cols["theta"] = rot["rotary.position"]
        cols["omega"] = rot["rotary.velocity"]
        cols["counts"] = (
            rot[f"{ROTARY_COUNTS_JOINT}.position"]
            if f"{ROTARY_COUNTS_JOINT}.position" in rot
            else np.zeros(len(stamps))
        )
    else:
        nan = np.full(len(stamps), np.nan)
        cols["theta"], cols["omega"], cols["counts"] = nan, nan, np.zeros(len(stamps))
    out = []
    for i, st in enumerate(stamps):
        out.append(
            SensorSample(
                k=i,
                stamp_ns=int(st),
                p_c1=float(cols["p_c1"][i]),
                p_c2=float(cols["p_c2"][i]),
                p_m1=float(cols["p_m1"][i]),
                x=float(cols["x"][i]),
                theta=float(cols["theta"][i]),
                omega=float(cols["omega"][i]),
                counts=int(cols["counts"][i]),
            )
        )
    return out


def _at(data: RunData, topic: str, field: str, stamps: np.ndarray) -> np.ndarray:
    arr = data.topics.get(topic)
    if arr is None:
        return np.full(len(stamps), np.nan)
    if np.array_equal(arr.stamp_ns, stamps):
        return arr[field]
    idx = np.clip(np.searchsorted(arr.stamp_ns, stamps), 0, len(arr) - 1)
    out = np.where(arr.stamp_ns[idx] == stamps, arr[field][idx], np.nan)
    return out


def base_params(
    config: Mapping[str, Any], axis: str, controllers_file=None
) -> AxisControllerParams:
    """The controller parameters the run used (from the bag), else the config file's."""
    recorded = config.get("controllers", {}).get(axis)
    if recorded:
        return from_dict(AxisControllerParams, recorded, strict=False)
    return load_controller_params(axis, controllers_file)


def replay(
    run: str | Path,
    out: str | Path,
    *,
    axes: list[str] | None = None,
    overrides: Mapping[str, Mapping[str, Any]] | None = None,
    controllers_file=None,
) -> dict[str, AxisControllerParams]:
    """Replay ``run`` through controller cores into the bag ``out``; returns the params used."""
    from pneu_msgs_py.bag import BagWriter
    from pneu_msgs_py.params.core import with_updates

    data = read_run(run)
    config = run_config(data)
    axes = axes or axes_in(data, config) or ["linear"]
    if JOINT_STATE_TOPIC["linear"] not in data.topics:
        raise MissingTopicError(
            run, f"replay needs {JOINT_STATE_TOPIC['linear']} (the sample clock)"
        )
    samples = recorded_samples(data)
    ctrls: dict[str, AxisController] = {}
    used: dict[str, AxisControllerParams] = {}
    for axis in axes:
        params = base_params(config, axis, controllers_file)
        upd = dict((overrides or {}).get(axis, {}))
        if upd:
            try:
                params = with_updates(params, upd)
            except ParamError as err:  # named as the user wrote it: --set linear.td.r=...
                raise ParamError(f"{axis}.{err.key}", err.value, err.allowed) from None
        used[axis] = params
        ctrls[axis] = AxisController(axis, params)
    from pneu_msgs_py.params.core import to_dict

    meta = {
        RUN_METADATA: {
            "config_json": json.dumps(
                {**config, "controllers": {a: to_dict(p) for a, p in used.items()}, "axes": axes},
                sort_keys=True,
            ),
            "source": OPEN_LOOP_NOTE,
            "replay_of": str(run),
            "open_loop": "true",
        }
    }
    from pneu_msgs_py.lifecycle import signals

    w = BagWriter(out, metadata=meta, controller_state_fields=STATE_FIELDS)
    sig = signals.STATE
    try:
        with signals.deferred():  # a signal stops at the next sample; no half-written bag
            for s in samples:
                if sig.pending is not None:
                    raise signals.Interrupted(sig.pending)
                w.write_sample(s)
                for axis, c in ctrls.items():
                    u = c.update(s)
                    w.write_command(axis, s.stamp_ns, u)
                    w.write_controller_state(axis, s.stamp_ns, c.state_values(), c.algorithm)
    except BaseException:
        w.discard()  # an offline product: remade by running the command again
        raise
    w.close()
    return used
