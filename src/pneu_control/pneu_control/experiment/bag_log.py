"""Open the MCAP bag of an in-process run, with the run's config as metadata."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from pneu_msgs_py.bag import BagWriter

from pneu_control.analysis.records import (
    END_METADATA,
    EXCITE_METADATA,
    FAULTS_METADATA,
    INTERVALS_METADATA,
    RUN_METADATA,
    SAFETY_METADATA,
)
from pneu_control.controller.axis import STATE_FIELDS

__all__ = [
    "EXCITE_METADATA",
    "END_METADATA",
    "FAULTS_METADATA",
    "INTERVALS_METADATA",
    "RUN_METADATA",
    "SAFETY_METADATA",
    "intervals_metadata",
    "open_run_bag",
]


def end_metadata(end: dict[str, Any]) -> dict[str, str]:
    """``pneu.end`` (last record of a finished bag): the run's end as strings.

    A bag of a pneu run without it was cut short (process killed): ``pneu analyze``
    says so, ``pneu recover`` rebuilds its index.
    """
    out = {}
    for k, v in end.items():
        out[k] = ("true" if v else "false") if isinstance(v, bool) else str(v)
    return out


def safety_metadata(echo: dict[str, Any]) -> dict[str, str]:
    """``pneu.safety``: every bag says whether protections were on and whether any was weakened."""
    safety = echo.get("safety")
    if safety is None:
        return {
            "enabled": "false",
            "allow_unsafe": "false",
            "unsafe_overrides": "",
            "params_json": "",
        }
    from pneu_driver.safety import SafetyParams
    from pneu_msgs_py.params.core import from_dict

    overrides = from_dict(SafetyParams, safety, strict=False).unsafe_overrides()
    return {
        "enabled": "true",
        "allow_unsafe": "true" if safety.get("allow_unsafe") else "false",
        "unsafe_overrides": "; ".join(overrides),
        "params_json": json.dumps(safety, sort_keys=True),
    }


def intervals_metadata(intervals: list[Any], counters: dict[str, int]) -> dict[str, str]:
    """``pneu.fault_intervals`` (end of run): what the runner marked, as JSON."""
    return {
        "intervals_json": json.dumps([iv.to_dict() for iv in intervals], sort_keys=True),
        "counters_json": json.dumps(counters, sort_keys=True),
    }


def excite_metadata(echo: dict[str, Any]) -> dict[str, dict[str, str]]:
    """``pneu.excite`` when the run is an excitation experiment: each axis's design (JSON) and seed."""
    designs = {a: c for a, c in echo.get("controllers", {}).items() if "segments" in c}
    if not designs:
        return {}
    return {
        EXCITE_METADATA: {
            "designs_json": json.dumps(designs, sort_keys=True),
            "seed": str(echo.get("seed", "")),
            "axes": ",".join(designs),
            "duration_s": str(echo.get("duration_s", "")),
        }
    }


def run_metadata(echo: dict[str, Any]) -> dict[str, dict[str, str]]:
    """MCAP metadata records (string maps) describing a run; see pneu_control.analysis.run_analysis."""
    return {
        **excite_metadata(echo),
        RUN_METADATA: {
            "config_json": json.dumps(echo, sort_keys=True),
            "seed": str(echo.get("seed", "")),
            "version": str(echo.get("version", "")),
            "axes": ",".join(echo.get("axes", [])),
            "source": "pneu in-process runner (lockstep)",
            # wall-clock start of the run: informative only, never used by analysis
            "start_time": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        },
        SAFETY_METADATA: safety_metadata(echo),
        FAULTS_METADATA: {
            "faults_json": json.dumps(echo.get("faults", []), sort_keys=True),
            "count": str(len(echo.get("faults", []))),
        },
    }


def open_run_bag(path: str | Path, spec: Any, echo: dict[str, Any]) -> BagWriter:
    """A :class:`BagWriter` at ``path`` for an in-process run, with the run's metadata
    (``echo``)."""
    return BagWriter(
        path,
        metadata=run_metadata(echo),
        controller_state_fields=STATE_FIELDS,
        qos="lockstep",
    )
