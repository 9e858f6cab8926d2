"""``pneu bench``: speed figures of the stack (rates and ratios, machine noted); ``pneu bench
angle``: rotary angle positioning on the twin, both plumbings (:mod:`pneu_control.bench.angle`).

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
    "loop-pacing speed (JSON with --json); 'pneu bench angle': angle moves, the screw path "
    "and the shipped tasks on the nominal twin and over the plant band, both plumbings"
)
ANGLE_ARTEFACTS = ("angle_bench.json", "angle_bench.md")
MAX_ANGLE_SAMPLES = 1000

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
    "identify_s_structural",
    "identify_cpu_s_structural",
    "identify_s_in_model",
    "identify_cpu_s_in_model",
)
SLOW_GROUPS = ("identify",)  # minutes: only with --only


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The ``pneu bench`` options on ``p``."""
    p.add_argument(
        "what",
        nargs="?",
        choices=("speed", "angle"),
        default="speed",
        help="speed (default): the speed figures; angle: the angle positioning benchmark",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    angle = p.add_argument_group("pneu bench angle")
    angle.add_argument(
        "--samples", type=int, default=None, metavar="N",
        help="plants drawn from the plant band besides the nominal one (default 40)",
    )  # fmt: skip
    angle.add_argument("--seed", type=int, default=None, help="plant draws and noise (default 0)")
    angle.add_argument(
        "--workers", type=int, default=None, metavar="N", help="processes (default: the cores)"
    )
    angle.add_argument(
        "--serial", action="store_true", help="every run in this process (no worker processes)"
    )
    angle.add_argument("--no-tasks", action="store_true", help="the moves only")
    angle.add_argument("--plant", default=None, metavar="FILE", help="plant.yaml with ranges")
    angle.add_argument("--controllers", default=None, metavar="FILE", help="controllers.yaml")
    angle.add_argument("--safety", default=None, metavar="FILE", help="safety.yaml")
    angle.add_argument(
        "--out", default=None, metavar="DIR", help="also write angle_bench.json and .md there"
    )
    angle.add_argument("--overwrite", action="store_true", help="replace an earlier --out")
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
            "identify",
        ),
        help="run only these groups (repeatable); identify (minutes: one quick excitation "
        "identified, two plants) runs only when named",
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

    def identify() -> dict[str, Any]:
        from pneu_control.bench.identify import identify_figures

        return identify_figures(("structural",) if quick else ("structural", "in_model"))

    return {
        "plant": plant,
        "closed_loop": closed_loop,
        "compiled": compiled,
        "sweep": sweep,
        "logging": logging,
        "analysis": analysis,
        "shell": shell,
        "loop": loop,
        "identify": identify,
    }


_ANGLE_ONLY = (
    ("samples", "--samples"), ("seed", "--seed"), ("workers", "--workers"),
    ("serial", "--serial"), ("no_tasks", "--no-tasks"), ("plant", "--plant"),
    ("controllers", "--controllers"), ("safety", "--safety"), ("out", "--out"),
    ("overwrite", "--overwrite"),
)  # fmt: skip


def _angle_options(args: argparse.Namespace) -> tuple[int, int]:
    """(samples, seed) of ``pneu bench angle``, every option checked."""
    from pneu_msgs_py.params.core import ParamError

    from pneu_control.experiment.session import SEED_MAX, check_seed

    if args.only:
        raise ParamError(
            "--only", ",".join(args.only), "not with 'pneu bench angle' (speed groups)"
        )
    if args.quick:
        raise ParamError("--quick", True, "not with 'pneu bench angle'")
    samples = 40 if args.samples is None else args.samples
    seed = 0 if args.seed is None else args.seed
    if not 1 <= samples <= MAX_ANGLE_SAMPLES:
        raise ParamError("--samples", samples, f"an integer in [1, {MAX_ANGLE_SAMPLES}]")
    check_seed(seed)
    if seed + samples > SEED_MAX:  # the plants draw seeds seed .. seed + samples
        raise ParamError(
            "--seed",
            seed,
            f"an integer in [0, {SEED_MAX - samples}] (with --samples {samples}: "
            f"the draws' seeds up to --seed + {samples} stay within 2^32 - 1)",
        )
    if args.workers is not None and not 1 <= args.workers <= 1024:
        raise ParamError("--workers", args.workers, "an integer in [1, 1024]")
    if args.serial and args.workers is not None:
        raise ParamError("--workers", args.workers, "not with --serial (one process)")
    return samples, seed


def run_angle(args: argparse.Namespace) -> int:
    """``pneu bench angle``: plan, run and print the angle benchmark (JSON with ``--json``),
    ``--out DIR``: also its files; the exit code."""
    from pneu_msgs_py.lifecycle import signals
    from pneu_msgs_py.lifecycle.outputs import OutputDir
    from pneu_msgs_py.params.core import ParamError
    from pneu_msgs_py.params.yaml_file import from_option

    from pneu_control.bench import angle
    from pneu_control.cli.progress import progress_bar, progress_to
    from pneu_control.sweep.executors import default_workers

    samples, seed = _angle_options(args)
    claim = None
    if args.out is not None:
        claim = OutputDir(
            args.out,
            ANGLE_ARTEFACTS,
            overwrite=args.overwrite,
            inputs=[args.plant, args.controllers, args.safety],
        ).check()
    elif args.overwrite:
        raise ParamError("--overwrite", True, "only with --out")
    from pneu_driver.safety import load_safety_params

    with from_option("--safety" if args.safety else None):  # its errors name it, not the plant
        load_safety_params(args.safety)
    with from_option("--plant" if args.plant else None):
        bench = angle.plan_angle_bench(
            samples=samples,
            seed=seed,
            plant_file=args.plant,
            controllers_file=args.controllers,
            safety_file=args.safety,
            tasks=not args.no_tasks,
        )
    executor = "serial" if args.serial else "local"
    workers = args.workers or default_workers()
    print(
        f"pneu bench angle: {len(bench.items)} runs (nominal + {samples} plants, "
        f"{len(bench.factors)} factors, seed {seed}) on {executor}"
        + ("" if args.serial else f" ({workers} workers)"),
        file=sys.stderr,
    )
    bar = progress_bar(len(bench.items), "pneu bench angle", unit="run")
    try:
        summary = angle.run_bench(
            bench, executor=executor, workers=workers, progress=progress_to(bar, "bench angle")
        )
    finally:
        bar.close()
    md = angle.render_markdown(summary)
    text = json.dumps(summary, indent=2, sort_keys=True) + "\n"
    if claim is not None:
        with claim, signals.deferred():
            claim.partial("angle_bench.json").write_text(text, encoding="utf-8")
            claim.partial("angle_bench.md").write_text(md, encoding="utf-8")
            claim.publish(*ANGLE_ARTEFACTS)
    print(text if args.json else md, end="")
    return 0


def run(args: argparse.Namespace) -> int:
    """``pneu bench``: run the benchmark groups, print their figures (JSON with ``--json``); the
    exit code."""
    if args.what == "angle":
        return run_angle(args)
    for field, flag in _ANGLE_ONLY:
        v = getattr(args, field)
        if v not in (None, False):
            from pneu_msgs_py.params.core import ParamError

            raise ParamError(flag, v, "only with 'pneu bench angle'")
    results: dict[str, Any] = {"machine": machine()}
    groups = _groups(args.quick)
    for name, fn in groups.items():
        if (args.only and name not in args.only) or (not args.only and name in SLOW_GROUPS):
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
