"""``pneu validate``: replay bags through a twin and report the fit per signal and horizon, the
residual diagnostics and a structural-mismatch warning, with an overlay figure per axis."""

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
HELP = (
    "replay bags through a twin (open loop on the recorded voltages, restarted from the measured "
    "state at several horizons; or closed loop) and report the fit %% per signal, the residual "
    "diagnostics and a structural-mismatch warning"
)
MIN_HORIZON_S = MIN_DURATION_S  # ten samples: the fewest a signal is scored on
HORIZON_S = 1.0  # = pneu_control.sysid.validate.HORIZON_S (not imported: the CLI loads fast)
AXES = ("linear", "rotary")
SIGNALS = ("x", "p_c1", "p_c2", "p_m1", "omega")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu validate`` options on ``p``."""
    p.add_argument("bags", nargs="+", metavar="BAG")
    p.add_argument("--plant", default=None, metavar="FILE", help="plant.yaml (default: config/)")
    p.add_argument("--mode", choices=("open", "closed", "auto"), default="open",
                   help="open (default): the recorded voltages, restarted from the measured "
                   "state every 0.2, 1 and 5 s and never; closed: besides, the recorded "
                   "controller or excitation again, judged; auto: closed where the bag says "
                   "what ran")  # fmt: skip
    p.add_argument("--horizon", type=float, default=HORIZON_S, metavar="S",
                   help="the open-loop horizon judged (--min-fit, figures, diagnostics): "
                   f"[0.01, 600] s, or inf: never restart (default: {HORIZON_S:g})")  # fmt: skip
    p.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="new or empty directory (or --overwrite): an overlay figure per bag and axis, "
        "validate.json",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the outputs of a previous pneu validate in DIR",
    )
    p.add_argument("--min-fit", type=float, default=None, metavar="PCT",
                   help="exit 1 if a held-out bag's signal fits below PCT (<= 100) at the "
                   "judged horizon")  # fmt: skip


def _used_by_identify(plant_file: str | None) -> set[str]:
    """Bags the plant was identified from (its .identify.json), to mark the others held out."""
    if not plant_file:
        return set()
    rep = Path(plant_file).with_suffix(".identify.json")
    if not rep.is_file():
        return set()
    try:
        doc = json.loads(rep.read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        why = f"not JSON: {err}" if isinstance(err, ValueError) else (err.strerror or str(err))
        raise ParamError(
            "--plant", str(rep), f"a report of pneu identify beside the plant file ({why})"
        ) from None
    bags = doc.get("bags", []) if isinstance(doc, dict) else None
    if not isinstance(bags, list) or not all(isinstance(b, str) for b in bags):
        raise ParamError(
            "--plant",
            str(rep),
            "a report of pneu identify beside the plant file (a JSON object whose 'bags' "
            "lists the bags' paths)",
        )
    return {str(Path(b).resolve()) for b in bags}


def _figure(i: int, bag: str, axis: str) -> str:
    return f"validate_{i:02d}_{Path(bag).parent.name}_{axis}.png"


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
    if args.overwrite and not args.out:  # nothing to replace: it would be silently ignored
        raise ParamError("--overwrite", True, "only with --out")


def _validation(bag: str, plant, used: set[str], args: argparse.Namespace):
    """The validation of one bag; refused (before anything is written) if no axis of it could
    be compared."""
    from pneu_control.sysid.record import load_record
    from pneu_control.sysid.validate import validate_record

    rec = load_record(bag)
    held = str(Path(rec.path).resolve()) not in used
    v = validate_record(rec, plant, mode=args.mode, horizon_s=args.horizon, held_out=held)
    if not v.fits:  # refused before anything is written: nothing of it could be compared
        why = "; ".join(_why_not(a, av, v.headline) for a, av in v.axes.items())
        raise ParamError(
            "BAG", bag, f"a bag with a stretch to compare, as long as --horizon (none here: {why})"
        )
    return v


def _why_not(axis: str, av, headline: str) -> str:
    """Why ``axis`` has no fit at the judged horizon: not validated at all, or valid only for
    shorter horizons (then the horizons it has)."""
    from pneu_control.sysid.validate import horizon_label

    if av.reason:
        return f"{axis}: {av.reason}"
    heads = "; ".join(n.removeprefix(f"{axis}: ").split(": ")[0] for n in av.notes)
    has = ", ".join(horizon_label(h) for h in av.fits)
    return (
        f"{axis}: no valid stretch of {horizon_label(headline)}"
        + (f" ({heads})" if heads else "")
        + (f"; it has {has}: try --horizon" if has else "")
    )


def _print_report(results) -> None:
    """The fits per bag and horizon; the axes not validated and why; the diagnostics; last, the
    structural-mismatch warnings, one line each."""
    from pneu_control.sysid.validate import horizon_label

    print(
        "| bag | held out | horizon | "
        + " | ".join(f"fit {n} %" for n in SIGNALS)
        + " | offsets (kPa) |"
    )
    print("|---|---|---|" + "---|" * len(SIGNALS) + "---|")
    for v in results:
        held = "yes" if v.held_out else "no (identify)"
        for h in v.horizons:
            fits, offs = {}, {}
            for av in v.axes.values():
                fits.update(av.fits.get(h, {}))
                offs.update(av.offsets.get(h, {}))
            cells = [f"{fits[n]:.1f}" if n in fits else "—" for n in SIGNALS]
            label = horizon_label(h) + (" (judged)" if h == v.headline else "")
            o = ", ".join(f"{k} {x / 1e3:+.2f}" for k, x in offs.items())
            print(f"| {v.bag} | {held} | {label} | " + " | ".join(cells) + f" | {o} |")
    for v in results:
        for a, av in v.axes.items():
            if not av.validated:
                print(f"{v.bag}: {a} not validated: {av.reason}")
                continue
            for note in av.notes:
                print(f"{v.bag}: {note}")
            if av.diagnostics is not None:
                print(f"\n{v.bag}, " + "\n".join(av.diagnostics.lines(warning=False)))
    for v in results:
        for w in v.warnings:
            print(f"{v.bag}: {w}")


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
        figs = [_figure(i, b, a) for i, b in enumerate(bags) for a in AXES]
        claim = OutputDir(
            args.out, ["validate.json", *figs], overwrite=args.overwrite, inputs=[*bags, args.plant]
        ).check()
    with from_option("--plant" if args.plant else None):
        plant = load_plant(args.plant)
    used = _used_by_identify(args.plant)
    results = [_validation(bag, plant, used, args) for bag in bags]
    if claim is not None:
        with claim, signals.deferred():  # every file finished, whatever signal comes
            for i, (v, bag) in enumerate(zip(results, bags)):
                for a in AXES:
                    name = _figure(i, bag, a)
                    plot_validation(v, a, claim.partial(name))
                    claim.publish(name)
                    v.axes[a].figure = str(claim.final(name))
            write_report(results, claim.partial("validate.json"))
            claim.publish("validate.json")
    _print_report(results)
    worst = min((min(v.fits.values()) for v in results if v.held_out and v.fits), default=math.inf)
    if not any(v.held_out for v in results):
        print(
            "warning: every bag was used by identify; a validation needs held-out bags",
            file=sys.stderr,
        )
    if claim is not None:
        print(
            f"wrote {claim.path}/validate.json and {len(AXES) * len(results)} overlay figures",
            file=sys.stderr,
        )
    if args.min_fit is not None and worst < args.min_fit:
        print(
            f"pneu validate: a held-out fit is {worst:.1f} % < {args.min_fit:g} %", file=sys.stderr
        )
        return 1
    return 0
