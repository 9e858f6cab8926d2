"""A sweep's files: the table, the envelopes, the summary (JSON + Markdown), the figures.

``<out>/sweep.csv`` (:mod:`.table`), ``<out>/envelopes.npz``,
``<out>/summary.json`` and ``summary.md`` (:mod:`.summary`), and
``<out>/<experiment>__bands.png`` (:mod:`.figures`). Everything but the wall
time in summary.json is a function of the plan: the same seed gives the same
bytes.

Every file is written as ``NAME.partial`` and the whole set renamed when the
last one is complete (:data:`pneu_msgs_py.lifecycle.outputs.PARTIAL`): the
directory holds a finished sweep, or partial files that say so. Callers write
inside :func:`pneu_msgs_py.lifecycle.signals.deferred`, so a signal never cuts
a file.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np
from pneu_msgs_py.lifecycle.outputs import PARTIAL

from pneu_control.sweep.engine import SweepResult
from pneu_control.sweep.summary import render_summary, summarise
from pneu_control.sweep.table import read_table, table_text, write_envelopes

__all__ = ["SWEEP_FILES", "sweep_artefacts", "write_sweep"]

SWEEP_FILES = ("sweep.csv", "envelopes.npz", "summary.md", "summary.json")


def sweep_artefacts(experiment_ids: list[str]) -> tuple[str, ...]:
    """Every file name a sweep of these experiments may write (for the output claim)."""
    return (*SWEEP_FILES, *(f"{e}__bands.png" for e in experiment_ids))


def _json_safe(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if isinstance(x, dict):
        return {k: _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    return x


def write_sweep(
    result: SweepResult,
    out_dir: str | Path,
    *,
    plots: bool = True,
    nominal: dict[tuple[str, str, str], tuple[float, float]] | None = None,
) -> tuple[list, list, str]:
    """Write the sweep's files; return (group summaries, rankings, summary markdown)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    plan = result.plan
    names = result.factor_names
    written: list[str] = []

    def partial(name: str) -> Path:
        written.append(name)
        return out / (name + PARTIAL)

    partial("sweep.csv").write_text(table_text(result.rows, plan.points, names), encoding="utf-8")
    write_envelopes(partial("envelopes.npz"), result.rows, plan.meta["envelope_dt_s"])
    _, rows = read_table(out / ("sweep.csv" + PARTIAL))  # the summary reads what was written
    summaries, rankings = summarise(rows, plan.factors, plan.experiments)
    md = render_summary(summaries, rankings, plan.meta["samples"], nominal)
    partial("summary.md").write_text(md, encoding="utf-8")
    doc = {
        **plan.meta,
        "executor": result.executor,
        "wall_s": result.wall_s,
        "runs": len(result.rows),
        "factors": [dataclasses.asdict(f) for f in plan.factors],
        "groups": [g.to_dict() for g in summaries],
        "rankings": [r.to_dict() for r in rankings],
    }
    partial("summary.json").write_text(
        json.dumps(_json_safe(doc), indent=2, sort_keys=True) + "\n", encoding="utf-8"
    )
    if plots:
        from pneu_control.sweep.figures import plot_bands

        env = np.load(out / ("envelopes.npz" + PARTIAL))
        for exp in plan.experiments:
            if any(r["experiment"] == exp.id for r in rows):
                plot_bands(
                    exp,
                    rows,
                    env["envelope"],
                    float(env["envelope_dt_s"]),
                    summaries,
                    partial(f"{exp.id}__bands.png"),
                )
    for name in written:  # complete: every file renamed (atomic each)
        os.replace(out / (name + PARTIAL), out / name)
    return summaries, rankings, md
