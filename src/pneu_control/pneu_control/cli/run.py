"""``pneu run``: one closed-loop experiment on the twin, in-process."""

from __future__ import annotations

import argparse
import signal
import sys

from pneu_msgs_py.lifecycle import exits, signals
from pneu_sim.cli import live_options

from pneu_control.experiment import session

NAME = "run"
HELP = "run one closed-loop experiment on the twin (in-process lockstep) and write metrics"


def add_run_dir_arguments(p: argparse.ArgumentParser) -> None:
    """``--out DIR`` and ``--overwrite`` of a command that writes one run (run, excite)."""
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="run directory: new or empty (or --overwrite); gets run.mcap, metrics.json, "
        "timeseries.npz",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the pneu outputs of a previous run in DIR (other files are left alone)",
    )


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu run`` options on ``p``."""
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
    p.add_argument(
        "--duration",
        type=float,
        default=20.0,
        metavar="S",
        help="simulated seconds, [0.01, 600] (the duration cap of every command)",
    )
    p.add_argument("--seed", type=int, default=0, help="noise seed, an integer in [0, 2^32 - 1]")
    add_run_dir_arguments(p)
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
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="NAME[:k=v,...]",
        help="inject a fault (repeatable): sensor_dropout, stuck_sensor, noise_burst, broken_wire, "
        "encoder_missed, valve_stuck, supply_drop, added_mass, controller_silent, controller_nan; "
        "keys start_s, duration_s and the fault's own, e.g. controller_silent:axis=linear,start_s=1",
    )
    p.add_argument(
        "--safety",
        default=None,
        metavar="FILE",
        help="safety supervisor thresholds (default: config/safety.yaml)",
    )
    p.add_argument(
        "--no-safety",
        action="store_true",
        help="run without the safety supervisor (recorded in the bag's pneu.safety metadata)",
    )
    p.add_argument(
        "--include-faults",
        action="store_true",
        help="compute the metrics over the fault intervals too (default: left out)",
    )
    live_options.add_arguments(p)


def run(args: argparse.Namespace) -> int:
    """``pneu run``: one experiment on the twin into ``--out`` (bag, metrics, time series); the exit
    code."""
    axes = ("linear", "rotary") if args.axis == "both" else (args.axis,)
    # everything is checked before anything is written: the output first (cheap), then
    # every file and option, the references against the rig's limits, the faults
    claim = session.run_dir(
        args.out, overwrite=args.overwrite, inputs=(args.plant, args.controllers, args.safety)
    ).check()
    options = session.RunOptions(
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
        safety=not args.no_safety,
        safety_file=args.safety,
        include_faults=args.include_faults,
    )
    spec = session.build_spec(options)
    live = live_options.open_live(args, axes=axes, kind=args.axis)
    try:
        result = session.execute(spec, claim, bag=not args.no_bag, progress=True, live=live)
    finally:
        if live is not None:
            live.close()
    for axis, m in result.metrics.items():
        print(m.line(result.algorithms[axis]))
    for iv in result.fault_intervals:
        if iv.kind == "injected":
            print(f"fault   {iv.axis:7s} {iv.cause} injected {iv.start_s:.3f}–{iv.end_s:.3f} s")
    for axis, st in _final_status(result).items():
        print(f"safety  {axis:7s} {st}")
    end = result.end
    if result.interrupted:
        print(
            f"interrupted by {end.get('signal') or 'SIGINT'} at {end['last_sample_s']:.3f} s of "
            f"{spec.duration_s:g} s: the bag and the metrics of what ran are complete "
            "(interrupted: true)",
            file=sys.stderr,
        )
    print(f"wrote {args.out}/metrics.json  (rtf {result.rtf:.0f}x)", file=sys.stderr)
    if result.interrupted:
        return exits.interrupted_code(signals.pending() or signal.SIGINT)
    return exits.SAFETY_STOP if result.safety_stopped else exits.OK


def _final_status(result) -> dict[str, str]:
    """Per active axis: SAFE (since when, why), TRIPPED (a fault was detected) or OK."""
    out = {}
    for axis in result.spec.axes:
        safe = [iv for iv in result.fault_intervals if iv.kind == "safe" and iv.axis == axis]
        at_end = [iv for iv in safe if iv.end_s == float("inf")]
        if at_end:
            out[axis] = (
                f"SAFE at the end (valve 5 V since {at_end[0].start_s:.3f} s: {at_end[0].cause})"
            )
        elif safe:
            out[axis] = f"TRIPPED at {safe[0].start_s:.3f} s ({safe[0].cause}), recovered"
        else:
            out[axis] = "OK" if result.spec.safety is not None else "no supervisor"
    return out
