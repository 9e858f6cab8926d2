"""``pneu bench``: speed figures of the stack (rates and ratios, machine noted).

Benchmarks, not tests: nothing here asserts a time. Each figure is computed
by the package that owns the code it measures; this module only collects.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

NAME = "bench"
HELP = (
    "measure plant, closed-loop (Python and compiled), sweep, logging, analysis, shell and "
    "loop-pacing speed (JSON with --json)"
)

FIGURES = (
    "plant_rtf",
    "closed_loop_rtf",
    "compiled_closed_loop_rtf",
    "compiled_closed_loop_cpu_rtf",
    "closed_loop_logged_rtf",
    "sweep_runs_per_s",
    "analyze_msgs_per_s",
    "baseline_msgs_per_s",
    "shell_us_per_sample",
    "loop_on_time_ratio",
    "loop_jitter_us_p99",
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu bench`` options on ``p``."""
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--only",
        action="append",
        default=[],
        choices=(
            "plant",
            "closed_loop",
            "compiled",
            "sweep",
            "logging",
            "analysis",
            "shell",
            "loop",
        ),
        help="run only these groups (repeatable)",
    )
    p.add_argument("--quick", action="store_true", help="shorter runs (smoke check of the bench)")


def machine() -> dict[str, Any]:
    """The machine the figures were taken on: CPU model, cores, Python, platform, load average."""
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        load = [round(x, 2) for x in os.getloadavg()]  # other work on a shared machine
    except OSError:
        load = None
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "load_avg_1_5_15_min": load,
    }


def closed_loop_rtf(duration_s: float = 20.0, *, logged: bool = False) -> float:
    """Both axes under ESO-SMC with the twin, in-process lockstep (safety supervisor on),
    timed over the closed loop itself; ``logged`` adds writing the MCAP bag (closed included)."""
    from pneu_control.bench.closed_loop import bench_spec
    from pneu_control.experiment import session
    from pneu_control.experiment.bag_log import open_run_bag
    from pneu_control.experiment.runner import run

    spec = bench_spec(duration_s)
    echo = session.config_echo(spec)
    with tempfile.TemporaryDirectory(prefix="pneu-bench-") as tmp:
        best = math.inf
        for i in range(3):  # best of 3; the first pass also warms the JIT cache
            t0 = time.perf_counter()
            if logged:
                with open_run_bag(Path(tmp) / f"run{i}.mcap", spec, echo) as bag:
                    run(spec, bag=bag)
            else:
                run(spec)
            best = min(best, time.perf_counter() - t0)
    return duration_s / best


def _groups(quick: bool) -> dict[str, Callable[[], dict[str, Any]]]:
    d = 4.0 if quick else 20.0

    def plant() -> dict[str, Any]:
        from pneu_sim.bench.plant import plant_rtf

        return {"plant_rtf": plant_rtf(duration_s=d)}

    def closed_loop() -> dict[str, Any]:
        return {"closed_loop_rtf": closed_loop_rtf(d)}

    def compiled() -> dict[str, Any]:
        from pneu_control.bench.closed_loop import compiled_rtf

        return compiled_rtf(d)

    def sweep() -> dict[str, Any]:
        from pneu_control.bench.sweep import sweep_runs_per_s

        # 20 s runs in either case; --quick: 2 per worker instead of 4
        from pneu_control.sweep.executors import default_workers

        return sweep_runs_per_s((2 if quick else 4) * default_workers())

    def logging() -> dict[str, Any]:
        return {"closed_loop_logged_rtf": closed_loop_rtf(d, logged=True)}

    def analysis() -> dict[str, Any]:
        from pneu_msgs_py.bench import bag as bag_bench

        minutes = 1.0 if quick else 10.0
        return bag_bench.analysis_figures(minutes=minutes)

    def shell() -> dict[str, Any]:
        from pneu_control.bench.shell import bench_shell_us_per_sample

        return {"shell_us_per_sample": bench_shell_us_per_sample()}

    def loop() -> dict[str, Any]:
        from pneu_driver.bench.loop import loop_pacing

        return loop_pacing(duration_s=2.0 if quick else 10.0)

    return {
        "plant": plant,
        "closed_loop": closed_loop,
        "compiled": compiled,
        "sweep": sweep,
        "logging": logging,
        "analysis": analysis,
        "shell": shell,
        "loop": loop,
    }


def run(args: argparse.Namespace) -> int:
    """``pneu bench``: run the benchmark groups, print their figures (JSON with ``--json``); the
    exit code."""
    results: dict[str, Any] = {"machine": machine()}
    groups = _groups(args.quick)
    for name, fn in groups.items():
        if args.only and name not in args.only:
            continue
        print(f"  bench {name} ...", file=sys.stderr)
        try:
            results.update(fn())
        except ImportError as err:
            results.setdefault("skipped", {})[name] = f"not available: {err}"
    if args.json:
        print(json.dumps(results, indent=2, sort_keys=True))
    else:
        for key in FIGURES:
            if key in results:
                print(f"{key:28s} {results[key]:.4g}")
        for key, why in results.get("skipped", {}).items():
            print(f"{key:28s} skipped ({why})")
    return 0
