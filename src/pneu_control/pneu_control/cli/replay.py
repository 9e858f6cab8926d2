"""``pneu replay``: recorded sensors through a controller core, offline (open loop)."""

from __future__ import annotations

import argparse
import sys

from pneu_msgs_py.lifecycle.outputs import OutputFile
from pneu_msgs_py.params.core import ParamError

from pneu_control.analysis.run_analysis import analyze
from pneu_control.controller.params import ALGORITHMS
from pneu_control.experiment.replay import OPEN_LOOP_NOTE, replay
from pneu_control.experiment.session import parse_sets

NAME = "replay"
HELP = "feed a bag's recorded sensor stream through a controller core offline (OPEN LOOP)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu replay`` options on ``p``."""
    p.add_argument("run", metavar="RUN", help=".mcap file or rosbag2 directory")
    p.add_argument("--controller", default=None, help="algorithm (default: the one recorded)")
    p.add_argument(
        "--axis",
        choices=("linear", "rotary", "both"),
        default=None,
        help="axes to replay (default: those recorded)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="parameter override, e.g. eso_smc.omega_0=40.0 (validated as one set)",
    )
    p.add_argument("--out", required=True, metavar="NEW.mcap", help="new bag (never RUN itself)")
    p.add_argument("--overwrite", action="store_true", help="replace NEW.mcap if it exists")


def run(args: argparse.Namespace) -> int:
    """``pneu replay``: the recorded sensors through a controller core into a new bag (its commands
    and estimates); the exit code."""
    axes = None
    if args.axis:
        axes = ["linear", "rotary"] if args.axis == "both" else [args.axis]
    if args.controller is not None and args.controller not in ALGORITHMS:
        raise ParamError("--controller", args.controller, "one of " + ", ".join(ALGORITHMS))
    probe_axes = tuple(axes or ("linear", "rotary"))
    taken = {"algorithm": "--controller"} if args.controller else {}
    overrides = parse_sets(args.set, probe_axes, taken)
    for axis in overrides if args.controller else ():
        overrides[axis] = {"algorithm": args.controller, **overrides[axis]}
    claim = OutputFile(
        args.out, overwrite=args.overwrite, inputs=[args.run], suffixes=(".mcap",)
    ).check()
    with claim:  # the bag is written as NEW.mcap.partial and renamed over NEW.mcap when complete
        used = replay(args.run, claim.path, axes=axes, overrides=overrides)
    print(f"pneu replay: {OPEN_LOOP_NOTE}", file=sys.stderr)
    res = analyze(args.out)
    for axis, params in used.items():
        m = res.metrics[axis]
        print(
            f"{axis:7s} {params.algorithm:10s} (open loop) reference − recorded measurement: "
            f"e_max {m.e_max:.4f} {m.unit}, RMSE {m.rmse:.4f} {m.unit}; "
            f"commands and estimates in {args.out}"
        )
    return 0
