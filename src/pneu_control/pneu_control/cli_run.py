"""``pneu run``: one closed-loop experiment on the twin, in-process."""

from __future__ import annotations

import argparse
import sys

from . import session

NAME = "run"
HELP = "run one closed-loop experiment on the twin (in-process lockstep) and write metrics"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--axis", choices=("linear", "rotary", "both"), default="linear")
    p.add_argument(
        "--controller",
        default=None,
        help="algorithm for the active axes (pid, ladrc, eso_smc, ...); default: controllers.yaml",
    )
    p.add_argument(
        "--reference",
        default=None,
        metavar="KIND[:key=value,...]",
        help="reference for the active axes in paper units, e.g. sine:amplitude=20,frequency_hz=0.25 "
        "or constant:value=800 or smooth_step:target=38.2,duration_s=4",
    )
    p.add_argument("--duration", type=float, default=20.0, metavar="S", help="simulated seconds")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", required=True, metavar="DIR")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="controller parameter override, e.g. eso_smc.epsilon=900 or rotary.pid.kp=0.3 "
        "(repeatable; validated as one set)",
    )
    p.add_argument("--plant", default=None, metavar="FILE", help="plant.yaml (default: config/)")
    p.add_argument("--controllers", default=None, metavar="FILE", help="controllers.yaml")
    p.add_argument("--window-start", type=float, default=None, metavar="S", help="override T_s")
    p.add_argument("--no-bag", action="store_true", help="do not write run.mcap")
    p.add_argument("--fault", action="append", default=[], metavar="NAME[:k=v,...]")


def run(args: argparse.Namespace) -> int:
    axes = ("linear", "rotary") if args.axis == "both" else (args.axis,)
    spec = session.build_spec(
        axes=axes,
        controller=args.controller,
        reference=args.reference,
        sets=args.set,
        duration_s=args.duration,
        seed=args.seed,
        plant_file=args.plant,
        controllers_file=args.controllers,
        window_start_s=args.window_start,
        faults=args.fault,
        name="run",
    )
    result = session.execute(spec, args.out, bag=not args.no_bag, progress=True)
    for axis, m in result.metrics.items():
        print(
            f"{axis:7s} {result.algorithms[axis]:10s} e_max = {m.e_max:8.4f} {m.unit}   "
            f"RMSE = {m.rmse:8.4f} {m.unit}   window {m.window_start_s:.2f}–{m.window_end_s:.2f} s"
        )
    print(f"wrote {args.out}/metrics.json  (rtf {result.rtf:.0f}x)", file=sys.stderr)
    return 130 if result.interrupted else 0
