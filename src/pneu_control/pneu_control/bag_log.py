"""Open the MCAP bag of an in-process run, with the run's config as metadata."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from pneu_msgs_py.bag import BagWriter

from .axis import STATE_FIELDS

__all__ = ["RUN_METADATA", "open_run_bag"]

RUN_METADATA = "pneu.run"  # metadata record holding the run's full config


def run_metadata(echo: dict[str, Any]) -> dict[str, dict[str, str]]:
    """MCAP metadata records (string maps) describing a run; see pneu_control.analysis."""
    return {
        RUN_METADATA: {
            "config_json": json.dumps(echo, sort_keys=True),
            "seed": str(echo.get("seed", "")),
            "version": str(echo.get("version", "")),
            "axes": ",".join(echo.get("axes", [])),
            "source": "pneu in-process runner (lockstep)",
            # wall-clock start of the run: informative only, never used by analysis
            "start_time": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        }
    }


def open_run_bag(path: str | Path, spec: Any, echo: dict[str, Any]) -> BagWriter:
    return BagWriter(
        path,
        metadata=run_metadata(echo),
        controller_state_fields=STATE_FIELDS,
        qos="lockstep",
    )
