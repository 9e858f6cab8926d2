"""A task's report: a table of its segments (JSON and Markdown) and a figure of both joints."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from pneu_msgs_py.contract.units import DEG_PER_RAD, MM_PER_M

from pneu_control.task.runner import SegmentResult, TaskDriver

__all__ = ["report_dict", "report_markdown", "task_figure", "REPORT_COLUMNS"]

REPORT_COLUMNS = (
    "segment", "kind", "status", "start (s)", "time (s)", "error (mm)", "error (°)",
    "path error max / RMS (mm)",
)  # fmt: skip


def _num(v: float) -> float | None:
    return None if not math.isfinite(v) else float(v)


def report_dict(driver: TaskDriver, result: Any) -> dict[str, Any]:
    """What the task did: outcome, every segment, the run's end and safety (JSON-ready)."""
    p = driver.program
    return {
        "task": p.name,
        "description": p.description,
        "source": p.source,
        "outcome": driver.outcome,
        "reason": driver.reason,
        "reached": sum(r.reached for r in driver.results),
        "segments_total": len(driver.results),
        "duration_s": float(result.t[-1]) if len(result.t) else 0.0,
        "safety_events": [e.message for e in result.safety_events if e.level != "INFO"],
        "segments": [_segment_dict(r) for r in driver.results],
    }


def _segment_dict(r: SegmentResult) -> dict[str, Any]:
    return {
        "index": r.index,
        "kind": r.kind,
        "name": r.name,
        "status": r.status,
        "reached": r.reached,
        "t_start_s": _num(r.t_start_s),
        "t_end_s": _num(r.t_end_s),
        "duration_s": _num(r.duration_s),
        "error_mm": _num(r.error_mm),
        "error_deg": _num(r.error_deg),
        "path_error_max_mm": _num(r.path_error_max_mm),
        "path_error_rms_mm": _num(r.path_error_rms_mm),
    }


def _f(v: float | None, fmt: str = ".3f") -> str:
    return "—" if v is None else format(v, fmt)


def report_markdown(rep: dict[str, Any]) -> str:
    """The report as a Markdown table (one row per segment)."""
    head = (
        f"# Task {rep['task']}: {rep['outcome']}"
        + (f" ({rep['reason']})" if rep["reason"] else "")
        + f"\n\n{rep['description']}\n\n{rep['reached']} of {rep['segments_total']} segments "
        f"reached in {rep['duration_s']:.3f} s.\n\n"
    )
    lines = ["| " + " | ".join(REPORT_COLUMNS) + " |", "|" + "---|" * len(REPORT_COLUMNS)]
    for s in rep["segments"]:
        label = f"{s['index']}" + (f" {s['name']}" if s["name"] else "")
        path = (
            "—"
            if s["path_error_max_mm"] is None
            else f"{s['path_error_max_mm']:.3f} / {s['path_error_rms_mm']:.3f}"
        )
        lines.append(
            f"| {label} | {s['kind']} | {s['status']} | {_f(s['t_start_s'])} | "
            f"{_f(s['duration_s'])} | {_f(s['error_mm'])} | {_f(s['error_deg'], '.2f')} | {path} |"
        )
    tail = ""
    if rep["safety_events"]:
        tail = "\n\nSafety: " + "; ".join(rep["safety_events"])
    return head + "\n".join(lines) + tail + "\n"


def write_json(path: Path, rep: dict[str, Any]) -> None:
    path.write_text(json.dumps(rep, indent=2, allow_nan=False) + "\n", encoding="utf-8")


def task_figure(path: Path, driver: TaskDriver, result: Any) -> None:
    """Both joints (reference, measured, error), the valve voltages and the pressures over the
    task, the segment boundaries marked (PNG)."""
    from pneu_control.analysis.plots import pyplot

    plt = pyplot()
    t = result.t
    fig, ax = plt.subplots(5, 1, figsize=(10, 12), sharex=True)
    lin, rot = result.axes.get("linear"), result.axes.get("rotary")
    x = result.samples["x"] * MM_PER_M
    th = result.samples["theta"] * DEG_PER_RAD
    if lin is not None:
        ax[0].plot(t, lin["reference"] * MM_PER_M, "k--", lw=1, label="reference")
    ax[0].plot(t, x, "C0", lw=1, label="measured")
    ax[0].set_ylabel("rod x (mm)")
    if rot is not None:
        ax[1].plot(t, rot["reference"] * DEG_PER_RAD, "k--", lw=1, label="reference")
    ax[1].plot(t, th, "C1", lw=1, label="measured")
    ax[1].set_ylabel("angle θ (°)")
    if lin is not None:
        ax[2].plot(t, (lin["reference"] * MM_PER_M) - x, "C0", lw=1, label="linear (mm)")
    if rot is not None:
        ax[2].plot(t, (rot["reference"] * DEG_PER_RAD) - th, "C1", lw=1, label="rotary (°)")
    ax[2].set_ylabel("error")
    for axis, c in (("linear", "C0"), ("rotary", "C1")):
        ax[3].plot(t, result.applied[axis][: len(t)], c, lw=1, label=f"{axis} valve")
    ax[3].set_ylabel("valve (V)")
    for name, c in (("p_c1", "C2"), ("p_c2", "C3"), ("p_m1", "C4")):
        ax[4].plot(t, result.samples[name] * 1e-3, c, lw=1, label=name)
    ax[4].set_ylabel("pressure (kPa abs)")
    ax[4].set_xlabel("t (s)")
    for r in driver.results:
        if math.isfinite(r.t_start_s):
            for a in ax:
                a.axvline(r.t_start_s, color="0.7", lw=0.8, ls=":")
            ax[0].annotate(
                f"{r.index} {r.kind}", (r.t_start_s, 1.0), xycoords=("data", "axes fraction"),
                fontsize=7, va="bottom", rotation=0,
            )  # fmt: skip
    for a in ax:
        a.grid(True, lw=0.3)
        a.legend(loc="upper right", fontsize=7)
    fig.suptitle(f"task {driver.program.name}: {driver.outcome}")
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)


def path_errors(driver: TaskDriver, result: Any) -> None:
    """The path error of each helix (screw) segment, from the recorded joints, into its result."""
    from pneu_control.analysis.path import path_distances
    from pneu_control.task.plan import segment_trajectory
    from pneu_control.task.runner import START_DELAY_S

    t = result.t
    for seg, r in zip(driver.program.segments, driver.results):
        if seg.kind != "screw" or not math.isfinite(r.t_start_s):
            continue
        traj = segment_trajectory(seg, r.t_start_s + START_DELAY_S)
        end = r.t_end_s if math.isfinite(r.t_end_s) else t[-1]
        m = (t >= r.t_start_s) & (t <= end)
        if m.sum() < 2:
            continue
        pe = path_distances(
            traj, result.samples["x"][m], result.samples["theta"][m],
            r_eq_m=abs(seg.args["pitch_mm"]) / MM_PER_M / (2.0 * math.pi),
            n_curve=max(4000, int(400 * abs(seg.args["turns"]))),
        )  # fmt: skip
        r.path_error_max_mm = float(np.max(pe)) * MM_PER_M
        r.path_error_rms_mm = float(np.sqrt(np.mean(pe * pe))) * MM_PER_M
