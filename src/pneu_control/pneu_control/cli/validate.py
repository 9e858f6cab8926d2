"""``pneu validate``: replay bags through a twin and report the fit per signal, with overlays."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from pneu_msgs_py.lifecycle import signals
from pneu_msgs_py.lifecycle.duration import MAX_DURATION_S, MIN_DURATION_S
from pneu_msgs_py.lifecycle.outputs import OutputDir
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.yaml_file import from_option

NAME = "validate"
HELP = "replay bags through a twin (open loop on the recorded voltages, or closed loop) and report the fit %% per signal"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu validate`` options on ``p``."""
    p.add_argument("bags", nargs="+", metavar="BAG")
    p.add_argument("--plant", default=None, metavar="FILE", help="plant.yaml (default: config/)")
    p.add_argument("--mode", choices=("open", "closed", "auto"), default="open",
                   help="open: the recorded voltages (default); closed: the recorded controller "
                   "or excitation again; auto: closed where the bag says what ran")  # fmt: skip
    p.add_argument("--horizon", type=float, default=math.inf, metavar="S",
                   help="open loop: restart from the measured state every S seconds, "
                   "[0.01, 600] (default: never)")  # fmt: skip
    p.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="new or empty directory (or --overwrite): overlay figures and validate.json",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the outputs of a previous pneu validate in DIR",
    )
    p.add_argument("--min-fit", type=float, default=None, metavar="PCT",
                   help="exit 1 if a held-out bag's signal fits below PCT (<= 100)")  # fmt: skip


MIN_HORIZON_S = MIN_DURATION_S  # ten samples: the fewest a signal is scored on


def _used_by_identify(plant_file: str | None) -> set[str]:
    """Bags the plant was identified from (its .identify.json), to mark the others held out."""
    if not plant_file:
        return set()
    rep = Path(plant_file).with_suffix(".identify.json")
    if not rep.is_file():
        return set()
    try:
        doc = json.loads(rep.read_text(encoding="utf-8"))
        return {str(Path(b).resolve()) for b in doc.get("bags", [])}
    except (OSError, ValueError, TypeError, AttributeError) as err:
        raise ParamError(
            "--plant", str(rep), f"a report of pneu identify beside the plant file ({err})"
        ) from None


def _figure(i: int, bag: str) -> str:
    return f"validate_{i:02d}_{Path(bag).parent.name}.png"


def _check_options(args: argparse.Namespace) -> None:
    """Refuse a --horizon or --min-fit outside its range."""
    if not (args.horizon == math.inf or MIN_HORIZON_S <= args.horizon <= MAX_DURATION_S):
        raise ParamError(
            "--horizon",
            args.horizon,
            f"[{MIN_HORIZON_S:g}, {MAX_DURATION_S:g}] s (ten samples to the duration cap), "
            "or inf: never restart",
        )
    if args.min_fit is not None and not (math.isfinite(args.min_fit) and args.min_fit <= 100.0):
        raise ParamError(
            "--min-fit", args.min_fit, "a finite percentage <= 100 (a fit is at most 100 %)"
        )


def _validation(bag: str, plant, used: set[str], args: argparse.Namespace):
    """The validation of one bag; refused (before anything is written) if nothing of it
    could be compared."""
    from pneu_control.sysid.record import load_record
    from pneu_control.sysid.validate import validate_record

    rec = load_record(bag)
    held = str(Path(rec.path).resolve()) not in used
    v = validate_record(rec, plant, mode=args.mode, horizon_s=args.horizon, held_out=held)
    if not v.fits:  # refused before anything is written: nothing of it could be compared
        raise ParamError(
            "BAG",
            bag,
            f"a bag with a stretch to compare (mode {v.mode}: none here, "
            + (next((n for n in rec.notes if "not used" in n), "") or "too few valid samples")
            + (
                "); try --horizon S (restart from the measured state every S s)"
                if math.isinf(args.horizon) and v.mode == "open"
                else ")"
            ),
        )
    return v


def run(args: argparse.Namespace) -> int:
    """``pneu validate``: replay each bag through the twin, write the report and overlays; the exit
    code."""
    from pneu_sim.physics.plant_file import load_plant

    from pneu_control.cli.identify import resolve_bags
    from pneu_control.sysid.validate import plot_validation, write_report

    # everything checked before anything is written: options, the output, the plant file
    _check_options(args)
    bags = resolve_bags(args.bags)
    claim = None
    if args.out:
        names = ["validate.json", *(_figure(i, b) for i, b in enumerate(bags))]
        claim = OutputDir(
            args.out, names, overwrite=args.overwrite, inputs=[*bags, args.plant]
        ).check()
    with from_option("--plant" if args.plant else None):
        plant = load_plant(args.plant)
    used = _used_by_identify(args.plant)
    results = [_validation(bag, plant, used, args) for bag in bags]
    if claim is not None:
        with claim, signals.deferred():  # every file finished, whatever signal comes
            for i, (v, bag) in enumerate(zip(results, bags)):
                name = _figure(i, bag)
                plot_validation(v, claim.partial(name))
                claim.publish(name)
                v.figure = str(claim.final(name))
            write_report(results, claim.partial("validate.json"))
            claim.publish("validate.json")
    names = ["x", "p_c1", "p_c2", "p_m1", "omega"]
    print(
        "| bag | held out | mode | "
        + " | ".join(f"fit {n} %" for n in names)
        + " | offsets (kPa) |"
    )
    print("|---|---|---|" + "---|" * len(names) + "---|")
    worst = math.inf
    for v in results:
        cells = [f"{v.fits[n]:.1f}" if n in v.fits else "—" for n in names]
        offs = ", ".join(f"{k} {x / 1e3:+.2f}" for k, x in v.offsets.items())
        print(
            f"| {v.bag} | {'yes' if v.held_out else 'no (identify)'} | {v.mode} | "
            + " | ".join(cells)
            + f" | {offs} |"
        )
        if v.held_out and v.fits:
            worst = min(worst, min(v.fits.values()))
    if not any(v.held_out for v in results):
        print(
            "warning: every bag was used by identify; a validation needs held-out bags",
            file=sys.stderr,
        )
    if claim is not None:
        print(
            f"wrote {claim.path}/validate.json and {len(results)} overlay figure(s)",
            file=sys.stderr,
        )
    if args.min_fit is not None and worst < args.min_fit:
        print(
            f"pneu validate: a held-out fit is {worst:.1f} % < {args.min_fit:g} %", file=sys.stderr
        )
        return 1
    return 0
