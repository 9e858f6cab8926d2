"""``pneu analyze``: the paper's metrics of a recorded run, from the bag alone."""

from __future__ import annotations

import argparse
import json
import math

from pneu_msgs_py.params.core import ParamError

from pneu_control.analysis.metrics import WindowSpec
from pneu_control.analysis.run_analysis import analyze

NAME = "analyze"
HELP = "metrics (e_max, RMSE per axis, DESIGN §7) of a run bag (.mcap file or rosbag2 directory)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu analyze`` options on ``p``."""
    p.add_argument("run", metavar="RUN", help=".mcap file or rosbag2 directory")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument(
        "--window-start",
        type=float,
        default=None,
        metavar="S",
        help="steady-state window start (default: from the bag's metadata)",
    )
    p.add_argument(
        "--include-faults",
        action="store_true",
        help="compute the metrics over the fault intervals too (default: they are left out)",
    )


def check_window_start(value: float | None) -> None:
    """``--window-start``: a finite time ≥ 0 (one line naming the option otherwise)."""
    if value is not None and not (math.isfinite(value) and value >= 0.0):
        raise ParamError("--window-start", value, "a finite time [0, inf) s from the run's start")


def run(args: argparse.Namespace) -> int:
    """``pneu analyze``: print the metrics of the run (JSON with ``--json``); the exit code."""
    check_window_start(args.window_start)
    window = (
        None if args.window_start is None else WindowSpec(kind="fixed", t_start_s=args.window_start)
    )
    res = analyze(args.run, window=window, include_faults=args.include_faults)
    ends = [float(tr.t[-1]) for tr in res.traces.values() if len(tr.t)]
    if args.window_start is not None and ends and args.window_start > max(ends):
        raise ParamError(  # a window after the last sample measures nothing
            "--window-start",
            args.window_start,
            f"[0, {max(ends):g}] s: inside the run (its last sample is at {max(ends):g} s)",
        )
    if args.json:
        print(json.dumps(res.to_dict(), indent=2, sort_keys=True, default=_json_safe))
        return 0
    for w in res.warnings:
        print(f"warning: {w}")
    if res.status_line():
        print(res.status_line())
    for iv in res.faults:
        end = "end" if math.isinf(iv.end_s) else f"{iv.end_s:.3f} s"
        what = "fault injected" if iv.kind == "injected" else "valve held safe"
        note = "included in" if res.include_faults else "excluded from"
        print(f"{iv.axis:7s} {what}: {iv.start_s:.3f} s – {end} ({iv.cause}); {note} the metrics")
    for axis, m in res.metrics.items():
        print(m.line(res.traces[axis].algorithm))
    return 0


def _json_safe(o):
    return str(o)
