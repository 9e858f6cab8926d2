"""``pneu excite``: an excitation experiment on the twin (in-process), a bag for ``pneu identify``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

NAME = "excite"
HELP = (
    "run the excitation experiment of an axis on the twin (supervisor on) and write its bag "
    "for pneu identify; on the rig: ros2 launch pneu_control excite.launch.py"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--axis", choices=("linear", "rotary", "both"), default="both")
    p.add_argument("--out", required=True, metavar="DIR", help="directory of run.mcap")
    p.add_argument("--plant", default=None, metavar="FILE", help="plant.yaml (default: config/)")
    p.add_argument("--seed", type=int, default=0, help="design and noise seed")
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
    from pneu_sim.physics.plant_file import load_plant

    from pneu_control.sysid.excite import excitation_spec, run_excitation

    axes = ("linear", "rotary") if args.axis == "both" else (args.axis,)
    plant = load_plant(args.plant)
    spec = excitation_spec(axes, plant, seed=args.seed, level=args.level, safety_file=args.safety)
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
    result = run_excitation(spec, args.out, progress=True, hide_plant=args.hide_plant)
    trips = [e for e in result.safety_events if e.level != "OK"]
    for e in trips:
        print(
            f"  supervisor: {e.axis} {e.rule} at {e.stamp_ns * 1e-9:.3f} s: {e.message}",
            file=sys.stderr,
        )
    out = Path(args.out) / "run.mcap"
    print(
        f"wrote {out} ({spec.duration_s:.1f} s simulated in {time.perf_counter() - t0:.1f} s"
        f"{', interrupted' if result.interrupted else ''}; {len(trips)} supervisor events)"
    )
    return 130 if result.interrupted else 0
