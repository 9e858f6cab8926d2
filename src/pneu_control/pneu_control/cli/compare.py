"""``pneu compare``: one table and overlay plots across runs."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from pneu_msgs_py.lifecycle import signals
from pneu_msgs_py.lifecycle.outputs import OutputDir

from pneu_control.analysis.plots import plot_runs
from pneu_control.analysis.run_analysis import analyze
from pneu_control.cli.plot import series_of

NAME = "compare"
HELP = "compare runs: one metrics table (markdown + JSON) and a figure with a column per run"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu compare`` options on ``p``."""
    p.add_argument("runs", nargs="+", metavar="RUN")
    p.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="write compare.md, compare.json, compare.png (a new or empty DIR, or --overwrite)",
    )
    p.add_argument("--overwrite", action="store_true", help="replace those three files in DIR")


ARTEFACTS = ("compare.md", "compare.json", "compare.png")


def run(args: argparse.Namespace) -> int:
    """``pneu compare``: one metrics table across the runs (overlay plots with ``--out``); the exit
    code."""
    claim = None
    if args.out:
        claim = OutputDir(args.out, ARTEFACTS, overwrite=args.overwrite, inputs=args.runs).check()
    rows = []
    series = []
    for path in args.runs:
        res = analyze(path)
        for axis, m in res.metrics.items():
            rows.append(
                {
                    "run": str(path),
                    "axis": axis,
                    "algorithm": res.traces[axis].algorithm,
                    "e_max": m.e_max,
                    "rmse": m.rmse,
                    "unit": m.unit,
                    "window_s": m.window_s,
                    # compare has no window option: the hint points at analyze's
                    "why": m.why_empty().replace(
                        "pass --window-start", "pneu analyze --window-start"
                    ),
                }
            )
        series.extend(series_of(res, label_prefix=f"{Path(path).parent.name}/{Path(path).name}: "))
    lines = ["| run | axis | algorithm | e_max | RMSE | window (s) |", "|---|---|---|---|---|---|"]
    notes = []
    for r in rows:
        if r["why"]:  # no figure: say why once, below the table
            notes.append(f"- {r['run']} {r['axis']}: {r['why']}")
            lines.append(f"| {r['run']} | {r['axis']} | {r['algorithm']} | — | — | — |")
            continue
        lines.append(
            f"| {r['run']} | {r['axis']} | {r['algorithm']} | {r['e_max']:.4f} {r['unit']} | "
            f"{r['rmse']:.4f} {r['unit']} | {r['window_s'][0]:.2f}–{r['window_s'][1]:.2f} |"
        )
    table = "\n".join(lines + (["", *notes] if notes else [])) + "\n"
    print(table)
    if claim is not None:
        with signals.deferred(), claim:
            try:
                claim.partial("compare.md").write_text(table)
                claim.partial("compare.json").write_text(
                    json.dumps({"runs": rows}, indent=2, default=str) + "\n"
                )
                plot_runs(series, "pneu compare", claim.partial("compare.png"), fmt="png")
                claim.publish(*ARTEFACTS)
            except BaseException:
                claim.discard()
                raise
        print(f"wrote {claim.path}/compare.md, compare.json, compare.png")
    return 0
