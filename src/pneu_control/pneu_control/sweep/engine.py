"""A sweep: experiments × controller gain sets × N plant samples, run anywhere, one table.

The driver (this module) does everything that needs config files or
randomness: it loads plant.yaml with its ranges, draws the samples
(:mod:`.sampling`), and builds every run's complete :class:`RunSpec`
(nominal spec per experiment and gain set, then the sample's plant and seed
put in). Workers only run specs (:func:`.tasks.run_task`). Same plant file,
ranges, seed and options -> the same table bytes, on any executor.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pneu_control.controller.params import ALGORITHMS
from pneu_control.experiment import paper, session
from pneu_control.experiment.catalog import PAPER_CONTROLLERS, PAPER_EXPERIMENTS, Experiment
from pneu_control.experiment.compiled import warm_up
from pneu_control.sweep.executors import map_tasks
from pneu_control.sweep.sampling import Factor, draw_points, factors_of, plant_of
from pneu_control.sweep.tasks import ENVELOPE_S, RunRow, SweepTask, run_task, spec_seed

__all__ = [
    "SweepPlan",
    "SweepResult",
    "custom_experiment",
    "default_pairs",
    "plan_sweep",
    "run_sweep",
]


def default_pairs(exp: Experiment) -> tuple[tuple[str, str], ...]:
    """(controller, gain set) pairs: ``pneu paper``'s for its experiments; for any other,
    PID, LADRC and ESO-SMC with the paper's and the re-tuned gains, and ESO-SMC+ (design)."""
    if any(e.id == exp.id for e in PAPER_EXPERIMENTS):
        # not the nominal twin's supply-read-as-absolute rows: the plant samples draw the
        # reading (gauge or absolute) themselves
        return tuple(p for p in paper.runs_for(exp) if p[1] != paper.ABSOLUTE_SUPPLY_SET)
    pairs = [(c, g) for g in paper.PAPER_GAIN_SETS for c in exp.controllers]
    return (*pairs, ("eso_smc_plus", "design"))


def custom_experiment(
    *,
    axis: str,
    reference: str,
    duration_s: float,
    window_start_s: float | None = None,
    name: str = "custom",
    config_dir: Path | None = None,
) -> Experiment:
    """An experiment from ``pneu run``-style options (``--reference KIND:k=v``)."""
    ref = session.parse_reference(reference)
    spec = session.build_spec(
        axes=(axis,),
        reference=ref,
        duration_s=duration_s,
        window_start_s=window_start_s,
        controllers_file=_files(config_dir)["paper"],
    )
    params = spec.controllers[axis]
    unit = "mm" if axis == "linear" else "rpm"
    return Experiment(
        id=name,
        axis=axis,
        title=f"{name}: {reference} ({axis}, {duration_s:g} s)",
        reference=ref,
        duration_s=duration_s,
        window=session.window_for(axis, params.reference, window_start_s),
        controllers=PAPER_CONTROLLERS,
        unit=unit,
    )


def _files(config_dir: Path | None) -> dict[str, Path]:
    from pneu_msgs_py.params.paths import config_dir as default_dir

    cfg = Path(config_dir) if config_dir is not None else default_dir()
    # the supply reading is one of the sampled factors: no gain set fixes it
    return {g: cfg / f for g, f in paper.GAIN_SETS.items() if g != paper.ABSOLUTE_SUPPLY_SET}


@dataclass
class SweepPlan:
    """Everything drawn and built before a run starts (picklable tasks)."""

    factors: list[Factor]
    points: list[dict[str, Any]]
    experiments: list[Experiment]
    tasks: list[SweepTask]
    meta: dict[str, Any]


@dataclass
class SweepResult:
    """A sweep that ran: its plan, one row per run, the wall time and executor."""

    plan: SweepPlan
    rows: list[RunRow]
    wall_s: float
    executor: str
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def factor_names(self) -> list[str]:
        """The sampled factors' names, in plan order."""
        return [f.name for f in self.plan.factors]


def plan_sweep(
    *,
    samples: int,
    seed: int = 0,
    sampler: str = "lhs",
    experiments: Sequence[Experiment] | None = None,
    controllers: Sequence[str] = (),
    gains: Sequence[str] = (),
    plant_file: str | Path | None = None,
    config_dir: str | Path | None = None,
    sets: Sequence[str] = (),
    safety: bool = True,
    safety_file: str | Path | None = None,
) -> SweepPlan:
    """Draw ``samples`` plants from plant.yaml's ranges and build every run's spec.

    ``controllers`` / ``gains`` keep only those (controller, gain set) pairs of
    :func:`default_pairs`. Sample ``s`` runs with seed ``seed + s``.
    """
    from pneu_sim.physics.plant_file import load_plant_file

    nominal, ranges = load_plant_file(plant_file)
    if not ranges:
        raise ValueError(
            f"plant: {plant_file or 'config/plant.yaml'} has no range or alternatives to sweep"
        )
    factors = factors_of(ranges, nominal)
    points = draw_points(factors, samples, seed, sampler)
    exps = list(experiments or PAPER_EXPERIMENTS)
    files = _files(Path(config_dir) if config_dir is not None else None)
    for c in controllers:
        if c not in ALGORITHMS:
            raise ValueError(f"controller: {c!r} refused; allowed: one of {', '.join(ALGORITHMS)}")
    for g in gains:
        if g not in files:
            raise ValueError(f"gains: {g!r} refused; allowed: one of {', '.join(files)}")
    runs: list[tuple[Experiment, str, str, Any]] = []
    base = session.RunOptions(
        axes=(), sets=sets, plant=nominal, safety=safety, safety_file=safety_file
    )
    for exp in exps:
        for c, g in default_pairs(exp):
            if (controllers and c not in controllers) or (gains and g not in gains):
                continue
            spec = session.build_spec(
                base,
                axes=(exp.axis,),
                controller=c,
                reference=dict(exp.reference),
                duration_s=exp.duration_s,
                controllers_file=files[g],
                name=f"{exp.id}/{c}/{g}",
            )
            runs.append((exp, c, g, dataclasses.replace(spec, windows={exp.axis: exp.window})))
    if not runs:
        raise ValueError("sweep: no (experiment, controller, gains) run left after the filters")
    tasks: list[SweepTask] = []
    for s, point in enumerate(points):
        plant = plant_of(nominal, factors, point)
        for exp, c, g, spec in runs:
            run_spec = dataclasses.replace(spec, plant=plant, seed=spec_seed(seed, s))
            tasks.append(SweepTask(len(tasks), s, exp, c, g, run_spec))
    meta = {
        "samples": samples,
        "seed": seed,
        "sampler": sampler,
        "plant_file": str(plant_file) if plant_file else "config/plant.yaml",
        "gain_sets": {g: str(p) for g, p in files.items()},
        "runs_per_sample": len(runs),
        "simulated_s": sum(t.spec.duration_s for t in tasks),
        "envelope_dt_s": ENVELOPE_S,
    }
    return SweepPlan(factors, points, exps, tasks, meta)


def run_sweep(
    plan: SweepPlan,
    *,
    executor: str = "local",
    workers: int | None = None,
    address: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    client: Any | None = None,
    timeout_s: float = 24 * 3600.0,
) -> SweepResult:
    """Run every task of ``plan``; rows in table order whatever the executor."""
    t0 = time.monotonic()
    if executor != "dask" or address is None:
        # build (or load) the compiled loop once here: local workers then load numba's cache
        # in well under a second instead of each compiling it (a remote cluster compiles there)
        warm_up()
    rows = map_tasks(
        run_task,
        plan.tasks,
        executor=executor,
        workers=workers,
        address=address,
        progress=progress,
        client=client,
        timeout_s=timeout_s,
    )
    return SweepResult(plan, rows, time.monotonic() - t0, executor)
