"""A task from file to results: checks, the run spec, the run, the report and the figure.

:func:`prepare` checks everything before anything is written (the task file, the
plant, the controllers with the task's overrides, the supervisor's parameters);
:func:`execute_task` runs it on the twin through the experiment session (one bag,
``metrics.json``, ``timeseries.npz``) and writes ``task_report.json``,
``task_report.md`` and ``task.png`` beside them.

The rotary axis of a task is always in ``rotary_control: angle``. Its algorithm, when
the task names none: ``coast`` with the paper's plumbing (one-way drive), the angle
laws of :data:`BIDIRECTIONAL_ROTARY` with the bidirectional one. The linear axis's, when
the task names none: :data:`LINEAR` (ESO-SMC+ through the valve chart's inverse), the law
that holds a position against a load step (:func:`linear_defaults`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pneu_msgs_py.lifecycle import signals
from pneu_msgs_py.lifecycle.duration import MAX_DURATION_S
from pneu_msgs_py.lifecycle.outputs import OutputDir
from pneu_msgs_py.params.core import ParamError, unknown_key, with_updates
from pneu_msgs_py.params.yaml_file import from_option

from pneu_control.controller.params import load_controller_params
from pneu_control.experiment.runner import RunResult, RunSpec
from pneu_control.task.program import TaskProgram, load_task
from pneu_control.task.runner import SAFE_TAIL_S, TaskDriver

__all__ = [
    "ARTEFACTS",
    "BIDIRECTIONAL_ROTARY",
    "LINEAR",
    "PAPER_ROTARY",
    "PreparedTask",
    "execute_task",
    "linear_defaults",
    "prepare",
    "rotary_defaults",
]

ARTEFACTS = ("run.mcap", "metrics.json", "timeseries.npz")
REPORTS = ("task_report.json", "task_report.md", "task.png")

# the rotary angle loop with the bidirectional plumbing (the valve drives and brakes both
# ways): pva (algorithms/pva.py), with its gains from controllers.yaml; with the paper's
# plumbing: coast. docs/composite-motion.md has the figures (pneu bench angle).
BIDIRECTIONAL_ROTARY: dict[str, Any] = {"algorithm": "pva"}
PAPER_ROTARY: dict[str, Any] = {"algorithm": "coast"}
# the rod's law: a task holds positions against loads (a stem's pull, a spring, a thrust).
# The MPYE's flow chart is progressive (1 % of the flow at 0.36 V from centre, 7 % at 1 V,
# 40 % at 2.1 V: a local slope 3-5x the 1 V secant beyond 1.2 V), so a law with one b0
# (identified with ±1 V steps) has several times its design gain once a load step drives
# the command out, where the loop with its 1 ms transport delay and the valve's and the
# laser's lags does not settle: after the task's 60 N step every law of controllers.yaml
# and controllers_retuned.yaml (PID, LADRC, ESO-SMC; ESO-SMC+ without the chart) rings on
# between 0 and 10 V (PID ±3 mm at 30 Hz, LADRC and ESO-SMC ±10-17 mm at 11-15 Hz),
# though each holds 0-150 N applied in 5 N steps. ESO-SMC+ commanding the flow through
# the chart's inverse (algorithms/eso_smc_plus.py, item 2) keeps its design gain at every
# opening and holds 20-150 N steps. Measured: docs/composite-motion.md.
LINEAR: dict[str, Any] = {"algorithm": "eso_smc_plus", "eso_smc_plus.valve_linearisation": True}


def rotary_defaults(plumbing: str) -> dict[str, Any]:
    """The rotary axis's overrides of a task (and of ``pneu bench angle``) with ``plumbing``,
    when the task names no algorithm: ``rotary_control: angle`` and the plumbing's law."""
    law = PAPER_ROTARY if plumbing == "paper" else BIDIRECTIONAL_ROTARY
    return {**law, "rotary_control": "angle", "rotary_model": "speed"}


def linear_defaults() -> dict[str, Any]:
    """The linear axis's overrides of a task when the task names no algorithm (:data:`LINEAR`);
    a task naming one keeps the rest (a field of another law's block changes nothing)."""
    return dict(LINEAR)


@dataclass(frozen=True)
class PreparedTask:
    """A checked task and the run that carries it out."""

    program: TaskProgram
    spec: RunSpec


def prepare(
    task_file: str | Path,
    *,
    plant_file: str | Path | None = None,
    controllers_file: str | Path | None = None,
    safety_file: str | Path | None = None,
    seed: int = 0,
    plumbing: str | None = None,
    name: str | None = None,
) -> PreparedTask:
    """Check ``task_file`` against the plant, controllers and supervisor it will run with."""
    from pneu_driver.safety import load_safety_params
    from pneu_sim.physics.plant_file import load_plant

    from pneu_control.experiment.session import check_seed

    check_seed(seed)
    with from_option("--plant" if plant_file else None):
        plant = load_plant(plant_file)
    with from_option("--safety" if safety_file else None):
        safety = load_safety_params(safety_file)
    if plumbing is not None and plumbing not in ("paper", "bidirectional"):
        raise ParamError("--plumbing", plumbing, "paper or bidirectional")
    base_plumbing = plumbing or getattr(plant.rotary, "plumbing", "paper")
    program = load_task(task_file, safety=safety, plant_plumbing=base_plumbing)
    effective = plumbing or program.plumbing or base_plumbing
    safety = with_updates(safety, {"rotary_plumbing": effective})  # what the stall rule reads
    if program.angle_limits_deg is not None:  # the tool's range: the supervisor enforces it
        bound = 1.0e6  # SafetyParams.angle_min_deg/angle_max_deg's own range (one side open)
        lo, hi = (min(max(v, -bound), bound) for v in program.angle_limits_deg)
        safety = with_updates(
            safety, {"angle_limits": True, "angle_min_deg": lo, "angle_max_deg": hi}
        )
    updates: dict[str, Any] = (
        {"rotary.plumbing": effective} if hasattr(plant.rotary, "plumbing") else {}
    )
    plant = with_updates(plant, updates)
    plant = _with_loads(plant, program.loads, f"{program.source}: loads")
    loaded = plant
    for seg in program.segments:  # each segment's loads, from its start on: checked now
        loaded = _with_loads(loaded, seg.load, f"{program.source}: {seg.label}.load")
    controllers = {}
    for axis in ("linear", "rotary"):
        overrides = dict(program.controllers.get(axis, {}))
        defaults = rotary_defaults(effective) if axis == "rotary" else linear_defaults()
        if "algorithm" in overrides:
            defaults = {k: v for k, v in defaults.items() if k != "algorithm"}
        forced = {"rotary_control": "angle"} if axis == "rotary" else {}
        overrides = {**defaults, **overrides, **forced}
        overrides.setdefault("reference.kind", "constant")
        overrides.setdefault("reference.value", 0.0)
        with from_option("--controllers" if controllers_file else None):
            load_controller_params(axis, controllers_file)
        try:
            params = load_controller_params(axis, controllers_file, overrides)
            from pneu_control.controller.axis import AxisController

            AxisController(axis, params)  # what only the axis knows (angle-mode algorithms)
        except ParamError as err:
            raise ParamError(
                f"{program.source}: controllers.{axis}.{err.key}", err.value, err.allowed
            ) from None
        controllers[axis] = params
    # the timeouts fit the cap (parse_task): every segment runs to its end, then the tail
    duration = min(program.planned_s + SAFE_TAIL_S + 0.01, MAX_DURATION_S)
    spec = RunSpec(
        axes=("linear", "rotary"),
        controllers=controllers,
        plant=plant,
        duration_s=duration,
        seed=seed,
        name=name or program.name,
        safety=safety,
    )
    return PreparedTask(program, spec)


def _load_key(key: str) -> str:
    return key if key.startswith("load.") else f"load.{key}"


def _with_loads(plant: Any, loads: dict[str, Any], where: str) -> Any:
    """``plant`` with the loads ``T_bk: 0.06`` (or ``load.T_bk``) set; one line naming
    ``where`` and the load for a name or value refused."""
    from pneu_sim.physics.params import LOAD_FIELDS

    for key, value in loads.items():
        if _load_key(str(key))[len("load.") :] not in LOAD_FIELDS:
            allowed = unknown_key(key, LOAD_FIELDS).replace("no such parameter", "a load")
            raise ParamError(f"{where}.{key}", value, allowed)
    try:
        return with_updates(plant, {_load_key(k): v for k, v in loads.items()})
    except ParamError as err:
        raise ParamError(f"{where}.{err.key[len('load.') :]}", err.value, err.allowed) from None


def execute_task(
    prepared: PreparedTask, out_dir: str | Path, *, overwrite: bool = False, progress: bool = False
) -> tuple[TaskDriver, RunResult, dict[str, Any]]:
    """Run the task on the twin into ``out_dir``; returns (driver, result, report)."""
    from pneu_control.experiment import session
    from pneu_control.task.report import (
        path_errors,
        report_dict,
        report_markdown,
        task_figure,
        write_json,
    )

    claim = OutputDir(out_dir, (*ARTEFACTS, *REPORTS), overwrite=overwrite).check()
    spec = prepared.spec
    p = spec.plant
    driver = TaskDriver(prepared.program, A_c1=p.linear.A_c1, A_c2=p.linear.A_c2, p_a=p.ambient.p_a)
    result = session.execute(spec, claim, progress=progress, hook=driver)
    if result.interrupted:
        driver.interrupted(float(result.t[-1]) if len(result.t) else 0.0)
    path_errors(driver, result)
    rep = report_dict(driver, result)
    rep["end"] = result.end
    reports = OutputDir(out_dir, REPORTS, overwrite=True)
    with signals.deferred(), reports:
        write_json(reports.partial("task_report.json"), rep)
        reports.partial("task_report.md").write_text(report_markdown(rep), encoding="utf-8")
        task_figure(reports.partial("task.png"), driver, result)
        reports.publish(*REPORTS)
    return driver, result, rep


def with_seed(prepared: PreparedTask, seed: int) -> PreparedTask:
    """The same task on another seed (noise draws)."""
    return PreparedTask(prepared.program, dataclasses.replace(prepared.spec, seed=seed))
