"""``pneu plot``: paper-style figure of a recorded run."""

from __future__ import annotations

import argparse
from pathlib import Path

from pneu_control.analysis.plots import Series, plot_runs
from pneu_control.analysis.run_analysis import analyze

NAME = "plot"
HELP = "paper-style figure of a run bag: reference vs measured, error, valve voltage, pressures"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", metavar="RUN", help=".mcap file or rosbag2 directory")
    p.add_argument("--out", default=None, metavar="PNG", help="default: RUN with .png")


def series_of(res, label_prefix: str = "") -> list[Series]:
    out = []
    for axis, tr in res.traces.items():
        m = res.metrics[axis]
        out.append(
            Series(
                label=f"{label_prefix}{axis} · {tr.algorithm}  e_max {m.e_max:.3f} {m.unit}",
                axis=axis,
                t=tr.t,
                reference=tr.reference,
                measured=tr.measured,
                u=tr.u,
                pressures=tr.pressures,
                window_s=(m.window_start_s, m.window_end_s),
            )
        )
    return out


def run(args: argparse.Namespace) -> int:
    res = analyze(args.run)
    src = Path(args.run)
    out = Path(args.out) if args.out else src.with_suffix(".png") if src.suffix else src / "run.png"
    plot_runs(series_of(res), str(src), out, pressures=True)
    print(f"wrote {out}")
    return 0
