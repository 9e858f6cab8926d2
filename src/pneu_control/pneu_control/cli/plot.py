"""``pneu plot``: paper-style figure of a recorded run."""

from __future__ import annotations

import argparse
from pathlib import Path

from pneu_msgs_py.lifecycle import signals
from pneu_msgs_py.lifecycle.outputs import OutputFile

from pneu_control.analysis.plots import FORMATS, Series, plot_runs
from pneu_control.analysis.run_analysis import analyze

NAME = "plot"
HELP = "paper-style figure of a run bag: reference vs measured, error, valve voltage, pressures"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu plot`` options on ``p``."""
    p.add_argument("run", metavar="RUN", help=".mcap file or rosbag2 directory")
    p.add_argument(
        "--out",
        default=None,
        metavar="PNG",
        help="figure file (.png, .pdf or .svg; new, or --overwrite); default: RUN with .png",
    )
    p.add_argument("--overwrite", action="store_true", help="replace the figure if it exists")


def series_of(res, label_prefix: str = "") -> list[Series]:
    """One plot series per axis of an analysed run (``res``: a :class:`RunAnalysis`)."""
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
    """``pneu plot``: the figure of a recorded run; the exit code."""
    src = Path(args.run)
    out = Path(args.out) if args.out else src.with_suffix(".png") if src.suffix else src / "run.png"
    claim = OutputFile(out, overwrite=args.overwrite, inputs=[src], suffixes=FORMATS).check()
    res = analyze(args.run)
    with claim:
        try:
            with signals.deferred():
                plot_runs(
                    series_of(res), str(src), claim.partial, pressures=True, fmt=out.suffix[1:]
                )
                claim.publish()
        except BaseException:
            claim.discard()
            raise
    print(f"wrote {claim.path}")
    return 0
