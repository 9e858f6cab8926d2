"""``pneu excite``: an excitation experiment on the twin (in-process), a bag for ``pneu identify``."""

from __future__ import annotations

import argparse
import signal
import sys
import time

from pneu_msgs_py.lifecycle import exits, signals
from pneu_msgs_py.params.yaml_file import from_option

from pneu_control.cli.run import add_run_dir_arguments
from pneu_control.experiment import session

NAME = "excite"
HELP = (
    "run the excitation experiment of an axis on the twin (supervisor on) and write its bag "
    "for pneu identify; on the rig: ros2 launch pneu_control excite.launch.py"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu excite`` options on ``p``."""
    p.add_argument("--axis", choices=("linear", "rotary", "both"), default="both")
    add_run_dir_arguments(p)
    p.add_argument("--plant", default=None, metavar="FILE", help="plant.yaml (default: config/)")
    p.add_argument(
        "--seed", type=int, default=0, help="design and noise seed, an integer in [0, 2^32 - 1]"
    )
    p.add_argument(
        "--level",
        choices=("full", "quick"),
        default="full",
        help="full: <= 2 min per axis (both axes run together); quick: ~45 s",
    )
    p.add_argument("--safety", default=None, metavar="FILE", help="config/safety.yaml by default")
    p.add_argument(
        "--hide-plant",
        action="store_true",
        help="blind study: the bag's recorded config names no plant parameters",
    )


def run(args: argparse.Namespace) -> int:
    """``pneu excite``: run the excitation design on the twin into a bag; the exit code."""
    from pneu_driver.safety import load_safety_params
    from pneu_msgs_py.lifecycle.duration import check_duration
    from pneu_sim.physics.plant_file import load_plant

    from pneu_control.sysid.excite import excitation_spec, run_excitation

    # everything checked before anything is written: the output, the seed, every file
    axes = ("linear", "rotary") if args.axis == "both" else (args.axis,)
    claim = session.run_dir(
        args.out, overwrite=args.overwrite, inputs=(args.plant, args.safety)
    ).check()
    session.check_seed(args.seed)
    with from_option("--plant" if args.plant else None):
        plant = load_plant(args.plant)
    with from_option("--safety" if args.safety else None):
        load_safety_params(args.safety)
    spec = excitation_spec(axes, plant, seed=args.seed, level=args.level, safety_file=args.safety)
    check_duration(spec.duration_s, "--level")  # the designs stay under the one cap
    for axis, d in spec.controllers.items():
        kinds = {}
        for s in d.segments:
            kinds[s.kind] = kinds.get(s.kind, 0) + 1
        print(
            f"{axis}: {len(d.segments)} segments, {d.duration_s:.1f} s "
            f"({', '.join(f'{n} {k}' for k, n in kinds.items())})",
            file=sys.stderr,
        )
    t0 = time.perf_counter()
    result = run_excitation(spec, claim, progress=True, hide_plant=args.hide_plant)
    trips = [e for e in result.safety_events if e.level != "OK"]
    for e in trips:
        print(
            f"  supervisor: {e.axis} {e.rule} at {e.stamp_ns * 1e-9:.3f} s: {e.message}",
            file=sys.stderr,
        )
    out = claim.final("run.mcap")
    print(
        f"wrote {out} ({result.end['last_sample_s']:.1f} of {spec.duration_s:.1f} s simulated "
        f"in {time.perf_counter() - t0:.1f} s"
        f"{', interrupted' if result.interrupted else ''}; {len(trips)} supervisor events)"
    )
    if result.interrupted:
        return exits.interrupted_code(signals.pending() or signal.SIGINT)
    return exits.OK
