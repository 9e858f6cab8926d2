"""``pneu sweep``: experiments × gain sets over N plant samples, one tidy table and a summary."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from pneu_msgs_py.lifecycle import signals
from pneu_msgs_py.lifecycle.duration import check_duration
from pneu_msgs_py.lifecycle.outputs import OutputDir
from pneu_msgs_py.params.core import ParamError

from pneu_control.cli.progress import progress_bar, progress_to
from pneu_control.experiment import session
from pneu_control.experiment.catalog import PAPER_EXPERIMENTS, experiment_by_id

NAME = "sweep"
HELP = (
    "run experiments over N plant samples drawn from plant.yaml's ranges (Latin hypercube or "
    "Sobol, seeded), in parallel processes or on a Dask cluster: sweep.csv, summary, figures"
)


def add_executor_arguments(p: argparse.ArgumentParser) -> None:
    """Where the runs execute (shared with ``pneu paper --uncertainty``)."""
    p.add_argument(
        "--executor",
        choices=EXECUTORS,
        default=None,
        help="local: one process per core (default); serial: this process; "
        "dask: a Dask cluster (--address) or a local one",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="processes started, with --executor local or a local Dask cluster (default: the "
        "cores)",
    )
    p.add_argument(
        "--address",
        default=None,
        metavar="tcp://HOST:8786",
        help="Dask scheduler to run on (with --executor dask)",
    )
    p.add_argument(
        "--sampler", choices=SAMPLERS, default=None, help="plant-sample design (default: lhs)"
    )


EXECUTORS = ("local", "serial", "dask")
SAMPLERS = ("lhs", "sobol")


MAX_SAMPLES = 10_000  # plant samples: bounded resources (the rows and envelopes stay in memory)
MAX_WORKERS = 1024


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu sweep`` options on ``p``."""
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="new or empty directory (or --overwrite): sweep.csv, envelopes.npz, summary.json, "
        "summary.md, band figures",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the outputs of a previous pneu sweep in DIR (other files are left alone)",
    )
    p.add_argument(
        "--samples",
        type=int,
        required=True,
        metavar="N",
        help=f"plant samples, [1, {MAX_SAMPLES}]",
    )
    p.add_argument(
        "--seed", type=int, default=0, help="seed of the design; sample s runs with seed+s"
    )
    p.add_argument(
        "--experiment",
        action="append",
        default=[],
        metavar="ID",
        help="paper experiments to run (repeatable; default: all): "
        + ", ".join(e.id for e in PAPER_EXPERIMENTS),
    )
    p.add_argument(
        "--reference",
        default=None,
        metavar="KIND[:key=value,...]",
        help="instead, one pneu run experiment with this reference (with --axis, --duration)",
    )
    p.add_argument(
        "--axis",
        choices=("linear", "rotary"),
        default=None,
        help="with --reference (default linear)",
    )
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="with --reference: simulated seconds per run, [0.01, 600] (the duration cap; "
        "default 20)",
    )
    p.add_argument(
        "--window-start",
        type=float,
        default=None,
        metavar="S",
        help="with --reference: the steady-state window's start, inside the run",
    )
    _add_run_options(p)


def _add_run_options(p: argparse.ArgumentParser) -> None:
    """What each run of the sweep takes: parameters, plant, supervisor, figures."""
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument(
        "--controller",
        action="append",
        default=[],
        help="keep only these controllers (repeatable): pid, ladrc, eso_smc, eso_smc_plus",
    )
    p.add_argument(
        "--gains",
        action="append",
        default=[],
        help="keep only these gain sets (repeatable): paper, retuned, design",
    )
    p.add_argument("--plant", default=None, metavar="FILE", help="plant.yaml with ranges")
    p.add_argument(
        "--config-dir",
        default=None,
        metavar="DIR",
        help="directory with controllers.yaml and controllers_retuned.yaml (default: config/)",
    )
    p.add_argument("--no-safety", action="store_true", help="runs without the supervisor")
    p.add_argument("--no-plots", action="store_true")
    add_executor_arguments(p)


def run_plan(plan, args: argparse.Namespace, desc: str, label: str):
    """``run_sweep(plan)`` on the executor the options name (``add_executor_arguments``), with
    a progress bar (``desc``; off a terminal, lines starting ``label``)."""
    from pneu_control.sweep.engine import run_sweep

    bar = progress_bar(len(plan.tasks), desc, unit="run")
    try:
        return run_sweep(
            plan,
            executor=args.executor,
            workers=args.workers,
            address=args.address,
            progress=progress_to(bar, label),
        )
    finally:
        bar.close()


ADDRESS_SCHEMES = ("tcp", "tls")
PROBE_S = 5.0  # the wait for a scheduler's port to answer, before anything is written


def check_address(address: str, field: str = "--address") -> tuple[str, int]:
    """``[tcp|tls://]HOST:PORT`` -> (host, port), and something answers there (a TCP connect
    within :data:`PROBE_S`): else one ParamError line, before anything is written."""
    import socket
    from urllib.parse import urlsplit

    allowed = "a Dask scheduler address tcp://HOST:PORT (or tls://), PORT in [1, 65535]"
    text = address.strip()
    url = urlsplit(text if "://" in text else f"tcp://{text}")
    try:
        host, port = url.hostname, url.port
    except ValueError:
        host, port = None, None
    if url.scheme not in ADDRESS_SCHEMES or not host or not port or url.path not in ("", "/"):
        raise ParamError(field, address, allowed)
    try:
        with socket.create_connection((host, port), timeout=PROBE_S):
            pass
    except TimeoutError:
        raise ParamError(
            field, address, f"a running Dask scheduler (nothing answered within {PROBE_S:g} s)"
        ) from None
    except OSError as err:
        why = err.strerror or type(err).__name__
        raise ParamError(
            field, address, f"a running Dask scheduler ({host}:{port}: {why})"
        ) from None
    return host, port


def check_executor_args(args: argparse.Namespace, runs: str = "") -> None:
    """Refuse an executor option that would be ignored (``runs``, when not empty: the option
    without which nothing runs on an executor, e.g. ``--uncertainty N``; ``--address`` without
    the dask executor; ``--workers`` where no workers are started), ``--workers`` out of
    range and an ``--address`` where no scheduler answers; then fill in the defaults
    (``local``, ``lhs``)."""
    options = {"--address": args.address, "--workers": args.workers,
               "--sampler": args.sampler, "--executor": args.executor}  # fmt: skip
    given = [(o, v) for o, v in options.items() if v is not None]
    if runs and given:
        raise ParamError(given[0][0], given[0][1], f"only with {runs} (nothing runs without it)")
    args.executor = args.executor or EXECUTORS[0]
    args.sampler = args.sampler or SAMPLERS[0]
    if args.address is not None and args.executor != "dask":
        raise ParamError("--address", args.address, "with --executor dask")
    if args.workers is not None:
        if args.executor == "serial" or args.address is not None:
            where = (
                "serial runs in this process"
                if args.executor == "serial"
                else ("the cluster at --address has its own")
            )
            raise ParamError(
                "--workers",
                args.workers,
                f"only where workers are started: --executor local, or dask without --address "
                f"({where})",
            )
        if not 1 <= args.workers <= MAX_WORKERS:
            raise ParamError("--workers", args.workers, f"an integer in [1, {MAX_WORKERS}]")
    if args.address is not None:
        check_address(args.address)


def _read_plant(plant_file: str | None) -> None:
    """The plant file read now, so that its errors name --plant (plan_sweep's do not)."""
    from pneu_msgs_py.params.yaml_file import from_option
    from pneu_sim.physics.plant_file import load_plant_file

    with from_option("--plant" if plant_file else None):
        load_plant_file(plant_file)


def run(args: argparse.Namespace) -> int:
    """``pneu sweep``: plan the sweep, run it, write the table, summary and figures; the exit
    code."""
    from pneu_control.sweep.engine import custom_experiment, plan_sweep
    from pneu_control.sweep.report import sweep_artefacts, write_sweep

    # everything checked before anything is written: options, the output, every file
    if not 1 <= args.samples <= MAX_SAMPLES:
        raise ParamError("--samples", args.samples, f"an integer in [1, {MAX_SAMPLES}]")
    session.check_seed(args.seed)
    session.check_seed(args.seed + args.samples - 1, "--seed + --samples - 1")
    if args.reference and args.experiment:
        raise ParamError("--reference", args.reference, "one or the other of it and --experiment")
    for option in ("--axis", "--duration", "--window-start"):  # of the one --reference run
        value = getattr(args, option[2:].replace("-", "_"))
        if value is not None and not args.reference:
            raise ParamError(
                option, value, "only with --reference (the paper's experiments fix their own)"
            )
    args.axis = args.axis or "linear"
    args.duration = check_duration(args.duration if args.duration is not None else 20.0)
    check_executor_args(args)
    if args.config_dir and not Path(args.config_dir).is_dir():
        raise ParamError("--config-dir", args.config_dir, "a directory holding controllers*.yaml")
    cfg = Path(args.config_dir) if args.config_dir else None
    ids = ["custom"] if args.reference else (args.experiment or [e.id for e in PAPER_EXPERIMENTS])
    exps = [] if args.reference else [experiment_by_id(i, "--experiment") for i in ids]
    claim = OutputDir(
        args.out, sweep_artefacts(ids), overwrite=args.overwrite, inputs=[args.plant]
    ).check()
    if args.reference:
        exps = [
            custom_experiment(
                axis=args.axis,
                reference=args.reference,
                duration_s=args.duration,
                window_start_s=args.window_start,
                config_dir=cfg,
            )
        ]
    _read_plant(args.plant)
    t0 = time.perf_counter()
    plan = plan_sweep(
        samples=args.samples,
        seed=args.seed,
        sampler=args.sampler,
        experiments=exps,
        controllers=args.controller,
        gains=args.gains,
        plant_file=args.plant,
        config_dir=cfg,
        sets=args.set,
        safety=not args.no_safety,
    )
    print(
        f"pneu sweep: {len(plan.tasks)} runs ({args.samples} plant samples × "
        f"{plan.meta['runs_per_sample']} runs, {len(plan.factors)} factors, {args.sampler}, "
        f"seed {args.seed}) on {args.executor}",
        file=sys.stderr,
    )
    with claim:
        try:
            # a signal here raises at once: the executor stops its workers, nothing is written
            result = run_plan(plan, args, "pneu sweep", "sweep")
        except BaseException:
            claim.discard()
            raise
        with signals.deferred():  # every file finished; a signal now ends the command after
            _, _, md = write_sweep(result, claim.path, plots=not args.no_plots)
    print(md)
    wall = time.perf_counter() - t0
    print(
        f"wrote {args.out}/sweep.csv, summary.json, summary.md in {wall:.1f} s "
        f"({len(plan.tasks) / result.wall_s:.2f} runs/s, "
        f"{plan.meta['simulated_s'] / result.wall_s:.0f} s simulated per s)",
        file=sys.stderr,
    )
    return 0
