"""Sweep throughput: 20 s closed-loop runs per wall second through ``pneu sweep``'s executor.

The paper's sine (20 mm, 0.25 Hz, 20 s) under the re-tuned ESO-SMC, safety on, each
run on its own plant sample drawn from plant.yaml's ranges, in local spawn processes
(one per core): what a sweep gets on this machine. The wall time includes starting
the processes (imports, numba cache load), as a sweep pays it.
"""

from __future__ import annotations

import time
from typing import Any

__all__ = ["sweep_runs_per_s"]


def sweep_runs_per_s(
    runs: int | None = None, *, workers: int | None = None, executor: str = "local"
) -> dict[str, Any]:
    """Sweep throughput: runs per wall-clock second of one small sweep (the sine experiment,
    ESO-SMC, ``runs`` plant samples) on ``workers`` processes."""
    from pneu_control.experiment.catalog import experiment_by_id
    from pneu_control.sweep.engine import plan_sweep, run_sweep
    from pneu_control.sweep.executors import default_workers

    n_workers = workers or default_workers()
    plan = plan_sweep(
        samples=runs or 4 * n_workers,
        seed=0,
        experiments=[experiment_by_id("sine_20mm_0p25hz")],
        controllers=["eso_smc"],
        gains=["retuned"],
    )
    t0 = time.perf_counter()
    run_sweep(plan, executor=executor, workers=n_workers)
    wall = time.perf_counter() - t0
    return {
        "sweep_runs_per_s": len(plan.tasks) / wall,
        "sweep_workers": n_workers,
        "sweep_runs": len(plan.tasks),
    }
