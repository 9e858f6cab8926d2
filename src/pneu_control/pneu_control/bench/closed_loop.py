"""Closed-loop speed: the bench run (both axes, ESO-SMC re-tuned, supervisor on), Python and compiled.

``bench_spec(d)`` is the one run both figures time, so they compare like with like.
``compiled_rtf(d)`` times :func:`pneu_control.experiment.compiled.run_compiled` (the
whole call: plant set-up, the compiled loop, result and metrics; JIT warm-up excluded)
on the wall clock and on this process's CPU clock: on a shared machine the CPU figure
is the one that does not depend on the others' load.
"""

from __future__ import annotations

import math
import time
from typing import Any

__all__ = ["bench_spec", "compiled_rtf"]


def bench_spec(duration_s: float = 20.0) -> Any:
    """Both axes under ESO-SMC with the re-tuned gains: sine 20 mm 0.25 Hz, 800 rpm."""
    from pneu_msgs_py.params.paths import config_file

    from pneu_control.experiment import session

    return session.build_spec(
        axes=("linear", "rotary"),
        controller="eso_smc",
        sets=[
            "linear.reference.kind=sine",
            "linear.reference.amplitude=20.0",
            "linear.reference.frequency_hz=0.25",
            "rotary.reference.kind=constant",
            "rotary.reference.value=800.0",
        ],
        duration_s=duration_s,
        controllers_file=config_file("controllers_retuned.yaml"),  # gains that work on the twin
        name="bench",
    )


def compiled_rtf(duration_s: float = 20.0, repeats: int = 3) -> dict[str, float]:
    """Simulated s per wall s and per CPU s of ``run_compiled(bench_spec(d))``, best of ``repeats``."""
    from pneu_control.experiment.compiled import run_compiled, warm_up

    warm_up()  # load or compile the loop: not part of the figure
    spec = bench_spec(duration_s)
    wall = cpu = math.inf
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        run_compiled(spec, fallback=False)
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return {
        "compiled_closed_loop_rtf": duration_s / wall,
        "compiled_closed_loop_cpu_rtf": duration_s / cpu,
    }
