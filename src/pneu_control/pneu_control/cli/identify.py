"""``pneu identify``: fit the twin's uncertain parameters to bags; write a calibrated plant.yaml."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

NAME = "identify"
HELP = (
    "output-error fit of the twin to bags (valve flow curve, leakage, friction, motor inertia, "
    "volumes, exhaust, polytropic index, supply, sensor noise) -> plant.yaml with 95 %% intervals"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("bags", nargs="+", metavar="BAG", help=".mcap files or rosbag2 directories")
    p.add_argument("--out", required=True, metavar="YAML", help="the identified plant.yaml")
    p.add_argument("--base", default=None, metavar="YAML", help="start values (config/plant.yaml)")
    p.add_argument("--axis", choices=("linear", "rotary", "both"), default=None,
                   help="axes to identify (default: every excited axis in the bags)")  # fmt: skip
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    p.add_argument("--max-steps", type=int, default=40, metavar="N", help="cap on the least-squares function evaluations of each stage")  # fmt: skip


def _resolve(bag: str) -> str:
    p = Path(bag)
    if p.is_dir() and not (p / "metadata.yaml").exists() and (p / "run.mcap").exists():
        return str(p / "run.mcap")  # an output directory of pneu excite / pneu run
    return bag


def run(args: argparse.Namespace) -> int:
    import yaml
    from pneu_msgs_py.params.paths import config_file
    from pneu_sim.physics.plant_file import params_from_tree

    from pneu_control.sysid.fit import FitOptions
    from pneu_control.sysid.identify import identify, write_plant
    from pneu_control.sysid.record import load_record

    out = Path(args.out)
    if out.exists() and not args.force:
        raise FileExistsError(f"--out {out} exists; refusing to overwrite it (use --force)")
    base_path = Path(args.base) if args.base else config_file("plant.yaml")
    base_tree = yaml.safe_load(base_path.read_text())
    base = params_from_tree(base_tree)
    t0 = time.perf_counter()
    records = []
    for bag in args.bags:
        rec = load_record(_resolve(bag))
        print(
            f"read {rec.path}: {rec.n} samples, axes {', '.join(rec.commanded) or '-'}",
            file=sys.stderr,
        )
        for note in rec.notes:
            print(f"  {note}", file=sys.stderr)
        records.append(rec)
    axes = (
        None
        if args.axis is None
        else (("linear", "rotary") if args.axis == "both" else (args.axis,))
    )
    ident = identify(
        records,
        base,
        axes=axes,
        options=FitOptions(max_nfev=args.max_steps),
        log=lambda m: print(m, file=sys.stderr),
    )
    path = write_plant(ident, base_tree, out, force=args.force)
    print(ident.report())
    for note in ident.notes:
        print(f"note: {note}")
    print(
        f"wrote {path} and {path.with_suffix('.identify.json')} in {time.perf_counter() - t0:.0f} s"
    )
    return 0
