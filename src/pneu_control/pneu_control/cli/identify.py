"""``pneu identify``: fit the twin's uncertain parameters to bags; write a calibrated plant.yaml."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from pneu_msgs_py.lifecycle import signals
from pneu_msgs_py.params.core import ParamError

from pneu_control.cli.progress import progress_bar, progress_to

NAME = "identify"
HELP = (
    "output-error fit of the twin to bags (valve flow curve, leakage, friction, motor inertia, "
    "volumes, exhaust, polytropic index, supply, sensor noise) -> plant.yaml with 95 %% intervals"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu identify`` options on ``p``."""
    p.add_argument("bags", nargs="+", metavar="BAG", help=".mcap files or rosbag2 directories")
    p.add_argument(
        "--out",
        required=True,
        metavar="YAML",
        help="the identified plant.yaml (and beside it NAME.identify.json): new files, or "
        "--overwrite",
    )
    p.add_argument("--base", default=None, metavar="YAML", help="start values (config/plant.yaml)")
    p.add_argument("--axis", choices=("linear", "rotary", "both"), default=None,
                   help="axes to identify (default: every excited axis in the bags)")  # fmt: skip
    p.add_argument(
        "--overwrite", action="store_true", help="replace --out (and its .identify.json)"
    )
    p.add_argument("--force", dest="overwrite", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--max-steps", type=int, default=40, metavar="N",
                   help=f"cap on the least-squares function evaluations of each stage, [1, {MAX_STEPS}]")  # fmt: skip


MAX_STEPS = 10_000  # bounded: each evaluation replays every bag


def resolve_bag(bag: str) -> str:
    """``bag``, or the ``run.mcap`` inside it when it is an output directory of a run."""
    p = Path(bag)
    if p.is_dir() and not (p / "metadata.yaml").exists() and (p / "run.mcap").exists():
        return str(p / "run.mcap")  # an output directory of pneu excite / pneu run
    return bag


def resolve_bags(bags: list[str]) -> list[str]:
    """Each bag resolved (:func:`resolve_bag`); the same bag twice (by any path) is refused:
    it would count twice in a fit, or be scored twice."""
    from pneu_msgs_py.lifecycle.outputs import is_same_path

    out: list[str] = []
    for bag in bags:
        b = resolve_bag(bag)
        for seen in out:
            if is_same_path(b, seen):
                raise ParamError("BAG", bag, f"each bag once (the same bag as {seen})")
        out.append(b)
    return out


def _axes(axis: str | None, records: list, bags: list[str]) -> tuple[str, ...] | None:
    """The axes to fit (None: every excited one); an axis the bags do not excite is refused
    (it was found after the other axes' whole fit, or as 'fitting ... to 0 bag(s)')."""
    from pneu_control.sysid.identify import excited_axes

    found = excited_axes(records)
    if not found:
        raise ParamError(
            "BAG",
            ", ".join(bags),
            "bags that excite an axis (a design or a valve command that varies: pneu excite)",
        )
    if axis is None:
        return None
    axes = ("linear", "rotary") if axis == "both" else (axis,)
    for a in axes:
        if a not in found:
            raise ParamError("--axis", axis, f"an axis the bags excite ({', '.join(found)})")
    return axes


def run(args: argparse.Namespace) -> int:
    """``pneu identify``: fit the plant to the bags, write the plant.yaml and its report; the exit
    code."""
    from pneu_msgs_py.params.paths import config_file
    from pneu_msgs_py.params.yaml_file import from_option, load_yaml, located
    from pneu_sim.physics.plant_file import params_from_tree

    from pneu_control.sysid.fit import FitOptions
    from pneu_control.sysid.identify import identify, output_claims, write_plant
    from pneu_control.sysid.record import load_record

    # everything checked before anything is written: options, the output, the base file, bags
    if not 1 <= args.max_steps <= MAX_STEPS:
        raise ParamError("--max-steps", args.max_steps, f"an integer in [1, {MAX_STEPS}]")
    bags = resolve_bags(args.bags)
    base_path = Path(args.base) if args.base else config_file("plant.yaml")
    out_claims = output_claims(args.out, overwrite=args.overwrite, inputs=[*bags, base_path])
    with from_option("--base" if args.base else None):
        base_tree = load_yaml(base_path)
        with located(base_path, base_tree):
            base = params_from_tree(base_tree if base_tree is not None else {})
    t0 = time.perf_counter()
    records, lines = [], []
    for bag in bags:
        rec = load_record(bag)
        lines.append(f"read {rec.path}: {rec.n} samples, axes {', '.join(rec.commanded) or '-'}")
        lines += [f"  {note}" for note in rec.notes]
        records.append(rec)
    axes = _axes(args.axis, records, bags)  # refused before a line is printed
    for line in lines:
        print(line, file=sys.stderr)
    bar = progress_bar(1, "pneu identify", unit="stage")  # total set by identify's first call
    try:
        ident = identify(
            records,
            base,
            axes=axes,
            options=FitOptions(max_nfev=args.max_steps),
            log=lambda m: bar.write(m, file=sys.stderr),
            progress=progress_to(
                bar, "identify", unit="stage", every_s=1e9
            ),  # the stage lines say it
        )
    finally:
        bar.close()
    with signals.deferred():  # both files finished (or neither), whatever signal comes
        path = write_plant(ident, base_tree, out_claims)
    print(ident.report())
    for note in ident.notes:
        print(f"note: {note}")
    print(
        f"wrote {path} and {path.with_suffix('.identify.json')} in {time.perf_counter() - t0:.0f} s"
    )
    return 0
