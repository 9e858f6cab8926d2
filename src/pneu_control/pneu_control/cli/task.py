"""``pneu task FILE``: a motion program of both joints on the twin (bag, report, figure)."""

from __future__ import annotations

import argparse
import signal
import sys

from pneu_msgs_py.lifecycle import exits, signals

NAME = "task"
HELP = "run a task (a motion program of both joints: move, rotate, spin, screw, ...) on the twin"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu task`` options on ``p``."""
    p.add_argument(
        "file", help="task file (YAML; config/tasks/ has the paper's three applications)"
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="run directory: new or empty (or --overwrite); gets run.mcap, metrics.json, "
        "timeseries.npz, task_report.json|md, task.png",
    )
    p.add_argument(
        "--overwrite", action="store_true", help="replace a previous task's outputs in DIR"
    )
    p.add_argument("--plant", default=None, help="plant parameters (default config/plant.yaml)")
    p.add_argument(
        "--plumbing",
        choices=("paper", "bidirectional"),
        default=None,
        help="the twin's rotary plumbing (default: the task's, else the plant file's)",
    )
    p.add_argument(
        "--controllers",
        default=None,
        help="controller parameters (default config/controllers.yaml)",
    )
    p.add_argument(
        "--safety", default=None, help="supervisor parameters (default config/safety.yaml)"
    )
    p.add_argument("--seed", type=int, default=0, help="noise seed (same seed, same bytes)")


def run(args: argparse.Namespace) -> int:
    """``pneu task``: check everything, run, write; the exit code (3: a segment aborted the task
    or the supervisor took an axis safe)."""
    from pneu_msgs_py.lifecycle.outputs import OutputDir

    from pneu_control.task.session import ARTEFACTS, REPORTS, execute_task, prepare

    OutputDir(args.out, (*ARTEFACTS, *REPORTS), overwrite=args.overwrite).check()
    prepared = prepare(
        args.file,
        plant_file=args.plant,
        controllers_file=args.controllers,
        safety_file=args.safety,
        seed=args.seed,
        plumbing=args.plumbing,
    )
    driver, result, rep = execute_task(prepared, args.out, overwrite=args.overwrite, progress=True)
    from pneu_control.task.report import report_markdown

    print(report_markdown(rep), end="")
    print(f"wrote {args.out}/task_report.md, task.png, run.mcap", file=sys.stderr)
    if result.interrupted:
        return exits.interrupted_code(signals.pending() or signal.SIGINT)
    if driver.outcome != "completed" or result.safety_stopped:
        return exits.SAFETY_STOP
    return exits.OK
