"""``pneu paper``: every experiment of the paper on the twin, table and figures."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from pathlib import Path

from pneu_msgs_py.lifecycle import signals
from pneu_msgs_py.lifecycle.outputs import OutputDir
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.paths import config_dir
from pneu_msgs_py.params.yaml_file import from_option

from pneu_control.analysis.plots import Series, plot_runs
from pneu_control.cli.progress import counted, progress_bar
from pneu_control.controller.params import load_controller_params
from pneu_control.experiment import paper, session
from pneu_control.experiment.catalog import PAPER_EXPERIMENTS, Experiment, experiment_by_id

NAME = "paper"
HELP = (
    "reproduce the paper's experiments on the twin: results table beside the paper's, figures, bags"
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu paper`` options on ``p``."""
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="new or empty directory (or --overwrite): table, figures, one directory per run",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the outputs of a previous pneu paper in DIR (other files are left alone)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the runs in the table (and bags)")
    p.add_argument(
        "--seeds",
        type=int,
        default=5,
        metavar="N",
        help="also run seeds seed+1..seed+N-1 (no bags) for mean/worst columns (1: off)",
    )
    p.add_argument("--plant", default=None, metavar="FILE", help="plant.yaml (default: config/)")
    p.add_argument(
        "--config-dir",
        default=None,
        metavar="DIR",
        help="directory with controllers.yaml and controllers_retuned.yaml (default: config/)",
    )
    p.add_argument("--no-plots", action="store_true")
    p.add_argument(
        "--only",
        action="append",
        default=[],
        metavar="ID",
        help="run only these experiments (repeatable): "
        + ", ".join(e.id for e in PAPER_EXPERIMENTS),
    )
    p.add_argument(
        "--uncertainty",
        type=int,
        default=0,
        metavar="N",
        help="also run every row over N plant samples drawn from plant.yaml's ranges, "
        "[0, 10000]: "
        "median and 5-95 %% band beside each figure, the paper's ranking odds, "
        "sensitivities, band figures (uncertainty/ in --out)",
    )
    from pneu_control.cli.sweep import add_executor_arguments

    add_executor_arguments(p)


def _series(result, exp: Experiment, label: str, m) -> Series:
    from pneu_control.experiment.runner import MEASURED

    cols = result.axes[exp.axis]
    return Series(
        label=label,
        axis=exp.axis,
        t=result.t,
        reference=cols["reference"],
        measured=result.samples[MEASURED[exp.axis]],
        u=cols["u"],
        window_s=(m.window_start_s, m.window_end_s),
    )


MAX_SEEDS = 100


def _artefacts(experiments, uncertainty: int = 0) -> tuple[str, ...]:
    names = ["paper_table.json", "paper_table.md", *(["uncertainty"] if uncertainty else [])]
    names += [f"{exp.id}__{g}.png" for exp in experiments for g in paper.PAPER_GAIN_SETS]
    return tuple(names)


def run(args: argparse.Namespace) -> int:
    """``pneu paper``: every experiment, the table and the figures into ``--out``; the exit code."""
    from pneu_sim.physics.plant_file import load_plant

    # everything checked before anything is written
    if not 1 <= args.seeds <= MAX_SEEDS:
        raise ParamError("--seeds", args.seeds, f"an integer in [1, {MAX_SEEDS}]")
    session.check_seed(args.seed)
    session.check_seed(args.seed + args.seeds - 1, "--seed + --seeds - 1")
    from pneu_control.cli.sweep import MAX_SAMPLES, check_executor_args

    if not 0 <= args.uncertainty <= MAX_SAMPLES:
        raise ParamError(
            "--uncertainty",
            args.uncertainty,
            f"an integer in [0, {MAX_SAMPLES}] (0: off; the plant-sample cap of pneu sweep)",
        )
    if args.uncertainty:  # sample s runs with seed + s
        session.check_seed(args.seed + args.uncertainty - 1, "--seed + --uncertainty - 1")

    check_executor_args(args, runs="" if args.uncertainty else "--uncertainty N")
    experiments = [experiment_by_id(i) for i in args.only] or list(PAPER_EXPERIMENTS)
    cfg = Path(args.config_dir) if args.config_dir else config_dir()
    if not cfg.is_dir():
        raise ParamError("--config-dir", str(cfg), "a directory holding controllers*.yaml")
    with from_option("--plant" if args.plant else None):
        plant = load_plant(args.plant)
    for gains in paper.GAIN_SETS.values():  # every controllers file, strictly, before any run
        for axis in ("linear", "rotary"):
            with from_option("--config-dir" if args.config_dir else None):
                load_controller_params(axis, cfg / gains)
    claim = OutputDir(
        args.out,
        _artefacts(experiments, args.uncertainty),
        overwrite=args.overwrite,
        inputs=[args.plant],
    ).check()
    with claim:
        return _run(args, claim, plant, cfg, experiments)


def _run(args, claim: OutputDir, plant, cfg: Path, experiments) -> int:
    out = claim.path
    results: dict[tuple[str, str], object] = {}

    plant_abs = paper.absolute_supply_plant(plant)

    def plant_for(gains: str):
        return plant_abs if gains == paper.ABSOLUTE_SUPPLY_SET else plant

    def options(exp: Experiment, controller: str, gains: str) -> session.RunOptions:
        return session.RunOptions(
            axes=(exp.axis,),
            controller=controller,
            reference=dict(exp.reference),
            duration_s=exp.duration_s,
            controllers_file=cfg / paper.GAIN_SETS[gains],
            plant=plant_for(gains),
        )

    def runner(exp: Experiment, controller: str, gains: str, run_dir: Path):
        spec = session.build_spec(
            options(exp, controller, gains), seed=args.seed, name=f"{exp.id}/{controller}/{gains}"
        )
        spec = _with_window(spec, exp)
        result = session.execute(spec, run_dir, bag=True, overwrite=args.overwrite)
        if result.interrupted:  # that run is finished (interrupted: true); stop here
            raise signals.Interrupted(signals.pending() or signal.SIGINT)
        m = session.metrics_from_bag(run_dir / "run.mcap", exp.axis)
        results[(exp.id, controller, gains)] = (result, m)
        return result, m

    def seed_runner(exp: Experiment, controller: str, gains: str, seed: int):
        from pneu_control.experiment.runner import run as run_spec

        spec = session.build_spec(options(exp, controller, gains), seed=seed)
        result = run_spec(_with_window(spec, exp))
        if result.interrupted:
            raise signals.Interrupted(signals.pending() or signal.SIGINT)
        return result.metrics[exp.axis]

    t0 = time.perf_counter()
    print(f"pneu paper: experiments of the paper on the twin (seed {args.seed})")
    n_runs = sum(len(paper.runs_for(e)) for e in experiments) * args.seeds
    bar = progress_bar(n_runs, "pneu paper", unit="run")  # one step per run, seeds included
    rows = paper.run_paper(
        out,
        seed=args.seed,
        runner=counted(runner, bar),
        experiments=experiments,
        seed_runner=counted(seed_runner, bar),
        seeds=args.seeds,
        log=bar.write,
    )
    bar.close()
    with signals.deferred():
        paper.write_table(rows, out, extra={"seed": args.seed, "seeds": args.seeds})
    if not args.no_plots:  # the nominal figures first: an interrupted band stage keeps them
        _figures(claim, experiments, results)
    band_md = ""
    if args.uncertainty:
        try:
            band_md = _uncertainty(args, rows, experiments, cfg, out)
        except signals.Interrupted as err:  # the nominal table is complete: it says the rest is not
            with signals.deferred():
                _mark_interrupted(out, args.uncertainty, err.signum)
            raise
    print()
    print(paper.render_markdown(rows))
    if band_md:
        print(band_md)
    print(
        f"wrote {out}/paper_table.json, paper_table.md, figures and one bag per run "
        f"in {time.perf_counter() - t0:.1f} s",
        file=sys.stderr,
    )
    return 0


def _figures(claim: OutputDir, experiments, results) -> None:
    """One figure per experiment and gain set (``EXP__GAINS.png``): the runs beside each other."""
    for exp in experiments:
        for gains in paper.PAPER_GAIN_SETS:
            keys = [
                (exp.id, c, g)
                for c, g in paper.runs_for(exp)
                if (g == gains)
                or (gains == "retuned" and g == "design")
                or (gains == "paper" and g == paper.ABSOLUTE_SUPPLY_SET)
            ]
            series = [
                _series(results[k][0], exp, f"{k[1]} ({k[2]} gains)", results[k][1]) for k in keys
            ]
            name = f"{exp.id}__{gains}.png"
            with signals.deferred():
                plot_runs(series, f"{exp.title}: {gains} gains", claim.partial(name), fmt="png")
                claim.publish(name)


def _uncertainty(args, rows, experiments, cfg: Path, out: Path) -> str:
    """The rows over ``--uncertainty`` plant samples: out/uncertainty/, and the band
    table appended to paper_table.md/json beside the nominal figures."""
    from pneu_control.cli.sweep import run_plan
    from pneu_control.sweep.engine import plan_sweep

    signals.raise_if_pending()  # one recorded while the table or figures were written
    plan = plan_sweep(
        samples=args.uncertainty,
        seed=args.seed,
        sampler=args.sampler,
        experiments=experiments,
        plant_file=args.plant,
        config_dir=cfg,
    )
    print(
        f"pneu paper: {len(plan.tasks)} runs over {args.uncertainty} plant samples "
        f"({len(plan.factors)} factors) on {args.executor}",
        file=sys.stderr,
    )
    result = run_plan(plan, args, "pneu paper --uncertainty", "uncertainty")
    nominal = {(r.id, r.controller, r.gains): (r.e_max, r.rmse) for r in rows}
    with signals.deferred():
        return _write_uncertainty(args, result, out, nominal, len(plan.tasks))


def _mark_interrupted(out: Path, samples: int, signum: int) -> None:
    """paper_table.json (``uncertainty``: status interrupted, the signal, when) and
    paper_table.md (a last section) say the band stage was interrupted; no band table."""
    import json

    name = signals.signal_name(signum)
    record = {
        "status": "interrupted",
        "interrupted": True,
        "signal": name,
        "interrupted_utc": signals.pending_since(),
        "samples": samples,
    }
    text = (
        f"\n## Over {samples} plant samples: interrupted\n\n"
        f"Interrupted by {name} before its runs finished: no band table. "
        "The nominal table above is complete.\n"
    )
    md, js = out / "paper_table.md", out / "paper_table.json"
    doc = json.loads(js.read_text(encoding="utf-8"))
    doc["uncertainty"] = record
    partial = js.with_name(js.name + ".partial")
    partial.write_text(json.dumps(doc, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(partial, js)
    with open(md, "a", encoding="utf-8") as fh:
        fh.write(text)
    print(f"pneu paper: uncertainty stage interrupted by {name}; {js} says so", file=sys.stderr)


def _write_uncertainty(args, result, out: Path, nominal, n_tasks: int) -> str:
    import json

    from pneu_control.sweep.report import write_sweep

    _, _, md = write_sweep(result, out / "uncertainty", plots=not args.no_plots, nominal=nominal)
    md = f"## Over {args.uncertainty} plant samples (uncertainty/)\n\n{md}"
    with open(out / "paper_table.md", "a", encoding="utf-8") as fh:
        fh.write("\n" + md)
    doc = json.loads((out / "paper_table.json").read_text())
    doc["uncertainty"] = json.loads((out / "uncertainty" / "summary.json").read_text())
    (out / "paper_table.json").write_text(json.dumps(doc, indent=2, sort_keys=True) + "\n")
    print(
        f"  uncertainty: {n_tasks} runs in {result.wall_s:.1f} s "
        f"({n_tasks / result.wall_s:.2f} runs/s)",
        file=sys.stderr,
    )
    return md


def _with_window(spec, exp: Experiment):
    from dataclasses import replace

    return replace(spec, windows={exp.axis: exp.window})
