"""``pneu rig``: the driver's 1 kHz loop with the controllers in it, on the rig or the simulated card."""

from __future__ import annotations

import argparse
import signal
import sys

from pneu_msgs_py.lifecycle import exits, signals
from pneu_msgs_py.lifecycle.duration import MAX_DURATION_S, check_duration
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.yaml_file import from_option

from pneu_control.experiment import session

NAME = "rig"
HELP = (
    "run the driver loop with the controllers in it, no ROS: --backend nidaqmx (the PCI-6221) "
    "or sim[:seed=,card=,stall_at_s=,stall_ms=] (the twin as a simulated card, a rehearsal)"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu rig`` options on ``p``."""
    p.add_argument(
        "--backend",
        required=True,
        metavar="KIND[:key=value,...]",
        help="nidaqmx (the rig: valves move!) or sim, e.g. sim:seed=1,stall_at_s=2,stall_ms=3",
    )
    p.add_argument("--axis", choices=("linear", "rotary", "both"), default="linear")
    p.add_argument("--controller", default=None, help="pid, ladrc, eso_smc, eso_smc_plus")
    p.add_argument("--reference", default=None, metavar="KIND[:key=value,...]")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--controllers", default=None, metavar="FILE", help="controllers.yaml")
    p.add_argument(
        "--duration",
        type=float,
        default=10.0,
        metavar="S",
        help="seconds, [0.01, 600] (the duration cap of every command); 0: until Ctrl-C "
        "(at most 600 s)",
    )
    p.add_argument("--rig", default=None, metavar="FILE", help="rig.yaml (default: config/)")
    p.add_argument("--safety", default=None, metavar="FILE", help="safety.yaml")
    p.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="new or empty directory (or --overwrite): run.mcap and loop.json",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the outputs of a previous pneu rig in DIR (other files are left alone)",
    )
    p.add_argument(
        "--hold",
        default="",
        metavar="AXIS=V[,AXIS=V]",
        help="command these valves a constant voltage instead of a controller (bring-up: "
        "neutral trim), e.g. linear=5.05",
    )


def parse_hold(text: str) -> dict[str, float]:
    """``linear=5.05,rotary=5`` -> ``{"linear": 5.05, "rotary": 5.0}`` (0-10 V, each axis once)."""
    from pneu_msgs_py.contract.samples import AXES, U_MAX_V, U_MIN_V
    from pneu_msgs_py.params.spec import parse_spec

    if not text:
        return {}
    try:
        _, values = parse_spec("hold:" + text, "--hold", keys=AXES)
    except ParamError as err:  # named as the user wrote it (no "hold:" kind of theirs)
        raise ParamError("--hold", err.value, err.allowed) from None
    out = {}
    for axis, v in values.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not U_MIN_V <= v <= U_MAX_V:
            raise ParamError(f"--hold {axis}", v, f"[{U_MIN_V:g}, {U_MAX_V:g}] V")
        out[axis] = float(v)
    return out


def _refuse_controller_options(args: argparse.Namespace) -> None:
    """No controller runs (--hold holds every axis): its options would be silently ignored."""
    for option, value in (("--controller", args.controller), ("--reference", args.reference),
                          ("--set", args.set), ("--controllers", args.controllers)):  # fmt: skip
        if value:
            raise ParamError(
                option,
                value[0] if isinstance(value, list) else value,
                f"only for an axis a controller runs on (--hold holds every axis of "
                f"--axis {args.axis})",
            )


def run(args: argparse.Namespace) -> int:
    """``pneu rig``: the controllers in the driver's loop on ``--backend`` until the duration or a
    signal; the exit code."""
    from pneu_driver.daq.backends import check_backend
    from pneu_driver.daq.rig import load_rig_params

    from pneu_control.experiment.rig_run import rig_dir, run_rig

    # everything checked before anything is written: options, the output, every file
    check_backend(args.backend)
    until_stopped = args.duration == 0
    duration_s = MAX_DURATION_S if until_stopped else check_duration(args.duration)
    axes = ("linear", "rotary") if args.axis == "both" else (args.axis,)
    hold = parse_hold(args.hold)
    active = tuple(a for a in axes if a not in hold)
    if not active:
        _refuse_controller_options(args)
    claim = None
    if args.out is not None:
        claim = rig_dir(
            args.out, overwrite=args.overwrite, inputs=(args.controllers, args.rig, args.safety)
        ).check()
    spec = session.build_spec(
        axes=active or axes,
        controller=args.controller,
        reference=args.reference,
        sets=args.set,
        duration_s=duration_s,
        controllers_file=args.controllers,
        name="rig",
        safety_file=args.safety,
    )
    with from_option("--rig" if args.rig else None):
        rig = load_rig_params(args.rig)
    echo = session.config_echo(spec) | {"backend": args.backend}
    print(
        f"pneu rig: backend {args.backend}, axes {', '.join(axes)}"
        + (f", until Ctrl-C (at most {MAX_DURATION_S:g} s)" if until_stopped else ""),
        file=sys.stderr,
    )
    result = run_rig(
        args.backend,
        spec,
        rig,
        duration_s=duration_s,
        out_dir=claim,
        echo=echo | {"hold": hold},
        hold=hold,
    )
    d = result.diagnostics
    if result.error is not None and d["cycles"] == "0":  # the DAQ never opened
        print(f"pneu rig: error: {result.error}", file=sys.stderr)
        return exits.RUNTIME_ERROR
    print(
        f"cycles {d['cycles']}  samples {result.cycles_logged}  late {d['late_cycles']}  missed ticks {d['missed_ticks']}  "
        f"DAQmx late {d['daq_late_errors']} ({d['daq_late_codes'] or '-'})  "
        f"cost p50 {float(d['cost_us_p50']):.0f} us  p99 {float(d['cost_us_p99']):.0f} us  "
        f"heartbeats {d['heartbeats']}"
    )
    for axis in dict.fromkeys((*axes, *hold)):
        print(f"safety  {axis:7s} {d[f'{axis}.state']} {d[f'{axis}.causes']}")
    if result.bag is not None:
        print(f"wrote {result.bag}", file=sys.stderr)
    if result.interrupted:
        end = result.end
        print(
            f"interrupted by {end['signal'] or 'SIGINT'} at {end['last_sample_s']:.3f} s: "
            "the valves are safe; the bag and loop.json of what ran are complete "
            "(interrupted: true)",
            file=sys.stderr,
        )
        return exits.interrupted_code(signals.pending() or signal.SIGINT)
    if result.error is not None:
        print(f"pneu rig: error: {result.error}", file=sys.stderr)
        return exits.RUNTIME_ERROR
    return exits.OK
