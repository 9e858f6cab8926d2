"""``pneu bench angle``: rotary angle positioning measured on the twin, both plumbings.

What project issue 20 asks to measure ("Measured, not guessed"), on the nominal twin and
on N plants drawn from the ranges of ``config/plant.yaml`` (:mod:`pneu_control.sweep.sampling`,
a seeded Latin hypercube; sample s runs with noise seed ``seed + s``):

- **moves**: steps of 90°, 360° and 3600° (10 turns) from rest, with the law a task uses
  for the plumbing (:func:`pneu_control.task.session.rotary_defaults`: ``coast`` with the
  paper's plumbing, ``pva`` with the bidirectional one), the supervisor of
  ``config/safety.yaml`` on (as a user runs it) and off. Per run, from the encoder angle
  θ (the twin's sensor samples): the final error r − θ at the run's end, the settling time
  (the first time after which |r − θ| ≤ 1° to the end; none if never), the overshoot (the
  farthest past the target, in the move's direction), the supervisor's first trip;
- **targets** (issue 20): bidirectional 90°: |final error| ≤ 0.5° and settled ≤ 0.3 s;
  paper: |final error| ≤ 2°; the share of the sampled plants meeting them, with its 95 %
  Wilson interval;
- **tasks** (``config/tasks/``, each on its plumbing): completed or not and when (the
  last segment's end), on the nominal twin and over the plants; ``screw_in``'s helix
  (1.5 mm pitch at 1 turn/s): the largest path error of its thread segment, in mm of the
  thread (target ≤ 1 mm).

The runs are independent (the compiled loop for the moves, the in-process runner with
the task logic for the tasks) and go through the sweep's executors (local processes by
default). Same config, N and seed: the same table bytes.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "MOVES_DEG",
    "AngleBench",
    "MoveRow",
    "TaskRow",
    "angle_bench",
    "move_metrics",
    "plan_angle_bench",
    "render_markdown",
    "run_bench",
    "run_item",
    "summarise",
]

MOVES_DEG = (90.0, 360.0, 3600.0)
DURATION_S = {90.0: 1.0, 360.0: 1.2, 3600.0: 2.5}  # each move settles well inside (nominal)
PLUMBINGS = ("bidirectional", "paper")
BAND_DEG = 1.0  # the settling band (issue 20)
# the targets of issue 20: (|final error| ≤ e, settling ≤ t) per plumbing, at 90° for both ways
TARGET = {"bidirectional": (0.5, 0.3), "paper": (2.0, math.inf)}
SCREW_TASK = "screw_in"
SCREW_SEGMENT = "thread"
SCREW_TARGET_MM = 1.0


def move_metrics(t: np.ndarray, theta_deg: np.ndarray, target_deg: float) -> dict[str, float]:
    """Final error, settling time to ±1° and overshoot of a move from 0 to ``target_deg``.

    ``t`` (s) from the step; settling: the first sample time after which |e| ≤ 1° to the end
    (inf when the last sample is outside); overshoot ≥ 0, in the move's direction.
    """
    e = target_deg - theta_deg
    outside = np.flatnonzero(np.abs(e) > BAND_DEG)
    if not len(outside):
        settle = 0.0
    elif outside[-1] == len(e) - 1:
        settle = math.inf
    else:
        settle = float(t[outside[-1] + 1])
    sign = 1.0 if target_deg >= 0.0 else -1.0
    over = max(0.0, float(np.max(sign * (theta_deg - target_deg))))
    return {"final_error_deg": float(e[-1]), "settling_s": settle, "overshoot_deg": over}


# ------------------------------------------------------------------ the runs
@dataclass(frozen=True)
class MoveItem:
    """One move: its place, plant sample (-1: nominal), plumbing, target, supervisor, spec."""

    index: int
    sample: int
    plumbing: str
    target_deg: float
    supervisor: bool
    spec: Any


@dataclass(frozen=True)
class TaskItem:
    """One task run: its place, plant sample (-1: nominal), task file, the prepared task."""

    index: int
    sample: int
    task: str
    prepared: Any


@dataclass(frozen=True)
class MoveRow:
    index: int
    sample: int
    plumbing: str
    algorithm: str
    target_deg: float
    supervisor: bool
    final_error_deg: float
    settling_s: float
    overshoot_deg: float
    trip: str  # the supervisor's first ERROR on the rotary axis, "rule at t s"; "" if none


@dataclass(frozen=True)
class TaskRow:
    index: int
    sample: int
    task: str
    plumbing: str
    completed: bool
    completion_s: float  # the last segment's end (NaN if not completed)
    outcome: str
    path_error_max_mm: float  # the screw task's thread segment (NaN for the others)


def run_item(item: MoveItem | TaskItem) -> MoveRow | TaskRow:
    """Run one item (in whichever process) and reduce it to its row."""
    if isinstance(item, TaskItem):
        return _run_task(item)
    from pneu_control.experiment.paper import first_trip
    from pneu_control.sweep.tasks import simulate

    result = simulate(item.spec)
    theta = np.degrees(result.samples["theta"])
    m = move_metrics(result.t, theta, item.target_deg)
    return MoveRow(
        index=item.index,
        sample=item.sample,
        plumbing=item.plumbing,
        algorithm=item.spec.controllers["rotary"].algorithm,
        target_deg=item.target_deg,
        supervisor=item.supervisor,
        trip=first_trip(result, "rotary") or "",
        **m,
    )


def _run_task(item: TaskItem) -> TaskRow:
    from pneu_control.experiment.runner import run
    from pneu_control.task.report import path_errors
    from pneu_control.task.runner import TaskDriver

    prepared = item.prepared
    p = prepared.spec.plant
    driver = TaskDriver(prepared.program, A_c1=p.linear.A_c1, A_c2=p.linear.A_c2, p_a=p.ambient.p_a)
    result = run(prepared.spec, hook=driver)
    path_errors(driver, result)
    done = driver.outcome == "completed"
    last = driver.results[-1] if driver.results else None
    pe = math.nan
    for seg, r in zip(prepared.program.segments, driver.results):
        if seg.kind == "screw" and r.name == SCREW_SEGMENT:
            pe = r.path_error_max_mm
    return TaskRow(
        index=item.index,
        sample=item.sample,
        task=prepared.program.name,
        plumbing=prepared.spec.safety.rotary_plumbing,
        completed=done,
        completion_s=float(last.t_end_s) if done and last is not None else math.nan,
        outcome=driver.outcome,
        path_error_max_mm=float(pe),
    )


# ------------------------------------------------------------------ the plan
@dataclass
class AngleBench:
    """Everything drawn and built before a run starts (picklable items)."""

    samples: int
    seed: int
    factors: list[Any]
    points: list[dict[str, Any]]
    items: list[MoveItem | TaskItem]
    tasks: list[str]


def _task_files(config_dir: Path) -> list[Path]:
    return sorted((config_dir / "tasks").glob("*.yaml"))


def plan_angle_bench(
    *,
    samples: int,
    seed: int = 0,
    plant_file: str | Path | None = None,
    controllers_file: str | Path | None = None,
    safety_file: str | Path | None = None,
    moves: Sequence[float] = MOVES_DEG,
    tasks: bool = True,
) -> AngleBench:
    """Draw ``samples`` plants and build every run (moves, and the shipped tasks if ``tasks``)."""
    from pneu_driver.safety import load_safety_params
    from pneu_msgs_py.params.core import with_updates
    from pneu_msgs_py.params.paths import config_dir
    from pneu_sim.physics.plant_file import load_plant_file

    from pneu_control.experiment import session
    from pneu_control.sweep.sampling import draw_points, factors_of, plant_of
    from pneu_control.sweep.tasks import spec_seed
    from pneu_control.task import session as task_session

    if samples < 1:
        raise ValueError(f"samples: {samples} refused; allowed: an integer >= 1")
    nominal, ranges = load_plant_file(plant_file)
    factors = factors_of(ranges, nominal)
    points = draw_points(factors, samples, seed)
    plants = [nominal] + [plant_of(nominal, factors, p) for p in points]
    safety = load_safety_params(safety_file)
    items: list[MoveItem | TaskItem] = []
    for plumbing in PLUMBINGS:
        sp = with_updates(safety, {"rotary_plumbing": plumbing})
        defaults = task_session.rotary_defaults(plumbing)
        sets = [f"{k}={v}" for k, v in defaults.items() if k != "algorithm"]
        for target in moves:
            for supervisor in (True, False):
                base = session.build_spec(
                    axes=("rotary",),
                    controller=defaults["algorithm"],
                    sets=[*sets, "reference.kind=constant", f"reference.value={target:g}"],
                    duration_s=DURATION_S.get(target, 2.5),
                    plant=with_updates(nominal, {"rotary.plumbing": plumbing}),
                    controllers_file=controllers_file,
                    safety=sp if supervisor else False,
                    name=f"angle/{plumbing}/{target:g}",
                )
                for s, plant in enumerate(plants):
                    spec = dataclasses.replace(
                        base,
                        plant=with_updates(plant, {"rotary.plumbing": plumbing}),
                        seed=spec_seed(seed, s),
                    )
                    items.append(MoveItem(len(items), s - 1, plumbing, target, supervisor, spec))
    names: list[str] = []
    if tasks:
        for f in _task_files(config_dir()):
            for s, plant in enumerate(plants):
                prepared = task_session.prepare(
                    f,
                    plant_file=plant_file,
                    controllers_file=controllers_file,
                    safety_file=safety_file,
                    seed=spec_seed(seed, s),
                )
                program_plumbing = prepared.spec.plant.rotary.plumbing
                spec = dataclasses.replace(
                    prepared.spec,
                    plant=with_updates(
                        plant,
                        {
                            "rotary.plumbing": program_plumbing,
                            **_loads(prepared.spec.plant),
                        },
                    ),
                )
                items.append(
                    TaskItem(len(items), s - 1, f.stem, dataclasses.replace(prepared, spec=spec))
                )
            names.append(f.stem)
    return AngleBench(samples, seed, factors, points, items, names)


def _loads(plant: Any) -> dict[str, float]:
    """The task's loads at its start (its ``loads:``), to put on a sampled plant."""
    return {f"load.{k}": v for k, v in dataclasses.asdict(plant.load).items()}


# ------------------------------------------------------------------ the summary
def _finite(values: Sequence[float]) -> list[float]:
    return [v for v in values if math.isfinite(v)]


def _band(values: Sequence[float]) -> dict[str, Any]:
    from pneu_control.sweep.summary import band

    b = band(values)
    return {"q05": b.q05, "median": b.median, "q95": b.q95, "failed": b.failed}


def _share(k: int, n: int) -> dict[str, Any]:
    from pneu_control.sweep.summary import wilson

    lo, hi = wilson(k, n)
    return {"k": k, "n": n, "share": k / n if n else math.nan, "ci95": [lo, hi]}


def summarise(bench: AngleBench, rows: Sequence[MoveRow | TaskRow]) -> dict[str, Any]:
    """The figures of the bench, JSON-ready (floats as numbers, inf/NaN as None)."""
    moves = [r for r in rows if isinstance(r, MoveRow)]
    groups: list[dict[str, Any]] = []
    for plumbing in PLUMBINGS:
        for supervisor in (True, False):
            for target in sorted({r.target_deg for r in moves}):
                g = [
                    r
                    for r in moves
                    if r.plumbing == plumbing and r.supervisor == supervisor
                    and r.target_deg == target
                ]  # fmt: skip
                if not g:
                    continue
                nom = next(r for r in g if r.sample < 0)
                sam = [r for r in g if r.sample >= 0]
                e_tgt, t_tgt = TARGET[plumbing]
                abs_e = [abs(r.final_error_deg) for r in sam]
                groups.append(
                    {
                        "plumbing": plumbing,
                        "algorithm": nom.algorithm,
                        "supervisor": supervisor,
                        "target_deg": target,
                        "nominal": {
                            "final_error_deg": nom.final_error_deg,
                            "settling_s": nom.settling_s,
                            "overshoot_deg": nom.overshoot_deg,
                            "trip": nom.trip,
                        },
                        "abs_final_error_deg": _band(abs_e),
                        "settling_s": _band([r.settling_s for r in sam]),
                        "overshoot_deg": _band([r.overshoot_deg for r in sam]),
                        "within_0p5_deg": _share(sum(e <= 0.5 for e in abs_e), len(sam)),
                        "within_1_deg": _share(sum(e <= 1.0 for e in abs_e), len(sam)),
                        "within_2_deg": _share(sum(e <= 2.0 for e in abs_e), len(sam)),
                        "meets_target": _share(
                            sum(
                                abs(r.final_error_deg) <= e_tgt and r.settling_s <= t_tgt
                                for r in sam
                            ),
                            len(sam),
                        ),
                        "target": {"final_error_deg": e_tgt, "settling_s": t_tgt},
                        "trips": sorted({r.trip.split(" at ")[0] for r in sam if r.trip}),
                        "n_trips": sum(1 for r in sam if r.trip),
                    }
                )
    task_rows = [r for r in rows if isinstance(r, TaskRow)]
    tasks = [_task_entry(name, [r for r in task_rows if r.task == name]) for name in bench.tasks]
    return _clean(
        {
            "samples": bench.samples,
            "seed": bench.seed,
            "factors": [f.name for f in bench.factors],
            "moves": groups,
            "tasks": tasks,
        }
    )


def _task_entry(name: str, g: Sequence[TaskRow]) -> dict[str, Any]:
    """One task over the nominal twin and the plants: completion, time, the screw's path."""
    nom = next(r for r in g if r.sample < 0)
    sam = [r for r in g if r.sample >= 0]
    entry = {
        "task": name,
        "plumbing": nom.plumbing,
        "nominal_completed": nom.completed,
        "nominal_completion_s": nom.completion_s,
        "completed": _share(sum(r.completed for r in sam), len(sam)),
        "completion_s": _band([r.completion_s if r.completed else math.inf for r in sam]),
        "outcomes": sorted({r.outcome for r in sam}),
    }
    if name == SCREW_TASK:
        pe = [r.path_error_max_mm for r in sam]
        entry["nominal_path_error_max_mm"] = nom.path_error_max_mm
        entry["path_error_max_mm"] = _band(pe)
        entry["path_within_target"] = _share(
            sum(v <= SCREW_TARGET_MM for v in _finite(pe)), len(sam)
        )
    return entry


def _clean(v: Any) -> Any:
    """JSON-ready: non-finite floats as None, floats rounded to 6 significant digits."""
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    if isinstance(v, float):
        return float(f"{v:.6g}") if math.isfinite(v) else None
    return v


def _q(b: dict[str, Any], fmt: str) -> str:
    def one(x: float | None) -> str:
        return "—" if x is None else format(x, fmt)

    return f"{one(b['median'])} [{one(b['q05'])}–{one(b['q95'])}]"


def _pct(s: dict[str, Any]) -> str:
    lo, hi = s["ci95"]
    return f"{100 * s['share']:.0f} % ({s['k']}/{s['n']}; {100 * lo:.0f}–{100 * hi:.0f})"


def render_markdown(summary: dict[str, Any]) -> str:
    """The bench's tables (Markdown): the moves per plumbing, then the tasks."""
    n = summary["samples"]
    lines = [
        f"Angle moves on the nominal twin and over {n} plants drawn from config/plant.yaml's "
        f"ranges (seed {summary['seed']}): nominal value, then median [5–95 %] over the plants; "
        "shares with their 95 % interval. Final error |r − θ| at the run's end; settling to "
        "±1° from the step; overshoot past the target.",
        "",
        "| plumbing | law | supervisor | move | nominal: error / settling / overshoot | "
        "abs(final error) (°) | settling (s) | overshoot (°) | ≤ 0.5° | ≤ 2° | target met | trips |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for g in summary["moves"]:
        nom = g["nominal"]
        t = nom["settling_s"]
        nominal = (
            f"{nom['final_error_deg']:+.2f}° / {'—' if t is None else f'{t:.3f} s'} / "
            f"{nom['overshoot_deg']:.2f}°" + (f" ({nom['trip']})" if nom["trip"] else "")
        )
        tgt = g["target"]
        target = (
            f"≤ {tgt['final_error_deg']:g}°"
            + ("" if tgt["settling_s"] is None else f", ≤ {tgt['settling_s']:g} s")
            + f": {_pct(g['meets_target'])}"
        )
        trips = f"{g['n_trips']}" + (f" ({', '.join(g['trips'])})" if g["trips"] else "")
        lines.append(
            f"| {g['plumbing']} | {g['algorithm']} | {'on' if g['supervisor'] else 'off'} | "
            f"{g['target_deg']:g}° | {nominal} | {_q(g['abs_final_error_deg'], '.2f')} | "
            f"{_q(g['settling_s'], '.3f')} | {_q(g['overshoot_deg'], '.2f')} | "
            f"{_pct(g['within_0p5_deg'])} | {_pct(g['within_2_deg'])} | {target} | {trips} |"
        )
    if summary["tasks"]:
        lines += [
            "",
            "| task | plumbing | nominal: completed in | completed over the plants | "
            "completion (s) | screw path error max (mm) |",
            "|---|---|---|---|---|---|",
        ]
        for tk in summary["tasks"]:
            c = tk["nominal_completion_s"]
            nominal = f"{c:.2f} s" if tk["nominal_completed"] and c is not None else "not completed"
            screw = "—"
            if "path_error_max_mm" in tk:
                v = tk["nominal_path_error_max_mm"]
                screw = (
                    f"nominal {'—' if v is None else f'{v:.3f}'}; "
                    f"{_q(tk['path_error_max_mm'], '.3f')}; ≤ {SCREW_TARGET_MM:g} mm: "
                    f"{_pct(tk['path_within_target'])}"
                )
            lines.append(
                f"| {tk['task']} | {tk['plumbing']} | {nominal} | {_pct(tk['completed'])} | "
                f"{_q(tk['completion_s'], '.2f')} | {screw} |"
            )
    return "\n".join(lines) + "\n"


def run_bench(
    bench: AngleBench,
    *,
    executor: str = "local",
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Run every item of ``bench`` on ``executor`` (:mod:`pneu_control.sweep.executors`); the
    summary (:func:`summarise`)."""
    from pneu_control.experiment.compiled import warm_up
    from pneu_control.sweep.executors import map_tasks

    warm_up()  # the compiled loop built (or loaded) once here; workers load numba's cache
    rows = map_tasks(run_item, bench.items, executor=executor, workers=workers, progress=progress)
    return summarise(bench, rows)


def angle_bench(
    *,
    samples: int = 40,
    seed: int = 0,
    executor: str = "local",
    workers: int | None = None,
    tasks: bool = True,
    moves: Sequence[float] = MOVES_DEG,
    plant_file: str | Path | None = None,
    controllers_file: str | Path | None = None,
    safety_file: str | Path | None = None,
) -> dict[str, Any]:
    """Plan and run the bench (see the module docstring); the summary."""
    bench = plan_angle_bench(
        samples=samples,
        seed=seed,
        plant_file=plant_file,
        controllers_file=controllers_file,
        safety_file=safety_file,
        moves=moves,
        tasks=tasks,
    )
    return run_bench(bench, executor=executor, workers=workers)
