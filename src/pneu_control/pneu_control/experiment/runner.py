"""The in-process experiment runner: twin and controller cores in lockstep.

One control cycle (DESIGN §3, k = sample index, T = 1 ms) is
:class:`pneu_sim.cycle.rig_cycle.RigCycle`'s:

1. the plant is sampled at tick k → sample s_k (faults, supervisor check);
2. each active controller computes u_k from s_k (here, in process);
3. u_k is written at tick k+1 and held until k+2 (one-sample transport delay),
   so the plant steps from k to k+1 under u_{k−1}.

The sim node steps the same class with the controllers' answers coming over
ROS, so a lockstep ROS run gives the same numbers for the same config and
seed. Inactive axes hold the neutral 5 V.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pneu_msgs_py.contract.samples import AXES
from pneu_msgs_py.lifecycle import signals
from pneu_msgs_py.lifecycle.duration import check_duration
from pneu_sim.cycle.rig_cycle import RigCycle
from pneu_sim.physics.plant import Plant

from pneu_control.analysis.metrics import AxisMetrics, WindowSpec, axis_metrics
from pneu_control.controller.axis import STATE_FIELDS, AxisController

__all__ = [
    "ANGLE_UNITS",
    "MEASURED",
    "SAMPLE_FIELDS",
    "measured_of",
    "RunResult",
    "RunSpec",
    "result_of",
    "run",
]

SAMPLE_FIELDS = ("p_c1", "p_c2", "p_m1", "x", "theta", "omega", "counts")
#: axis -> the sample field its metrics are taken on (rotary angle control: see measured_of)
MEASURED = {"linear": "x", "rotary": "omega"}
ANGLE_UNITS = ("°", 180.0 / math.pi)  # rotary_control: angle reports in degrees


def measured_of(axis: str, params: Any) -> tuple[str, tuple[str, float] | None]:
    """(sample field, report units or None for the axis's own) of what ``params`` controls."""
    if axis == "rotary" and getattr(params, "rotary_control", "speed") == "angle":
        return "theta", ANGLE_UNITS
    return MEASURED[axis], None


def _default_safety() -> Any:
    from pneu_driver.safety import SafetyParams

    return SafetyParams()


@dataclass(frozen=True)
class RunSpec:
    """Everything that sets a run: with the same spec the results are byte-identical."""

    axes: tuple[str, ...]
    controllers: dict[str, Any]  # axis -> AxisControllerParams (or an ExcitationDesign)
    plant: Any  # PlantParams
    duration_s: float
    seed: int = 0
    windows: dict[str, WindowSpec] = field(default_factory=dict)
    x0: float = 0.0
    name: str = "run"
    faults: tuple[Any, ...] = ()  # pneu_sim.faults.injection.FaultSpec
    safety: Any = field(default_factory=_default_safety)  # SafetyParams; None = no supervisor
    include_faults: bool = False  # metrics over the fault intervals too

    def __post_init__(self):
        for axis in self.axes:
            if axis not in AXES:
                raise ValueError(f"axis: {axis!r} refused; allowed: one of {AXES}")
            if axis not in self.controllers:
                raise ValueError(f"controllers: no controller parameters for axis {axis!r}")
        check_duration(self.duration_s, "duration_s")


@dataclass
class RunResult:
    """Time series and metrics of one run (SI arrays, metrics in report units)."""

    spec: RunSpec
    t: np.ndarray  # (N,) s, sample times
    samples: dict[str, np.ndarray]  # SAMPLE_FIELDS -> (N,)
    axes: dict[str, dict[str, np.ndarray]]  # axis -> STATE_FIELDS + "u" -> (N,)
    algorithms: dict[str, str]
    metrics: dict[str, AxisMetrics]
    wall_s: float
    interrupted: bool = False
    applied: dict[str, np.ndarray] = field(default_factory=dict)  # axis -> V held during each step
    truth: dict[str, np.ndarray] = field(default_factory=dict)  # x, omega (true; runs with faults)
    safety_events: list[Any] = field(default_factory=list)  # SafetyEvent, in order
    fault_intervals: list[Any] = field(default_factory=list)  # fault_marks.FaultInterval
    safety_counters: dict[str, int] = field(default_factory=dict)
    end: dict[str, Any] = field(default_factory=dict)  # how it ended (session.end_record)

    @property
    def safety_stopped(self) -> bool:
        """Did the supervisor take an axis safe, or detect a fault (an ERROR event)?"""
        return any(e.level == "ERROR" for e in self.safety_events)

    @property
    def rtf(self) -> float:
        """Simulated seconds per wall-clock second."""
        simulated = len(self.t) * self.spec.plant.sim.T
        return simulated / self.wall_s if self.wall_s > 0 else math.inf

    def metrics_dict(self) -> dict[str, Any]:
        """The metrics of each axis as plain data."""
        return {axis: m.to_dict() for axis, m in self.metrics.items()}

    def save(self, out_dir: str | Path, config_echo: dict[str, Any] | None = None) -> Path:
        """Write ``metrics.json`` and ``timeseries.npz`` into ``out_dir`` (as ``.partial``, renamed
        when complete)."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        doc = {
            "name": self.spec.name,
            "axes": list(self.spec.axes),
            "algorithms": self.algorithms,
            "duration_s": self.spec.duration_s,
            "seed": self.spec.seed,
            "interrupted": self.interrupted,
            "end": self.end,
            "safety_stopped": self.safety_stopped,
            "metrics": self.metrics_dict(),
            "units": {"linear": "mm", "rotary": "rpm"},
            "config": config_echo or {},
            "fault_intervals": [iv.to_dict() for iv in self.fault_intervals],
            "safety_counters": self.safety_counters,
        }
        part = out / "metrics.json.partial"
        part.write_text(json.dumps(doc, indent=2, sort_keys=True) + "\n")
        arrays = {"t": self.t}
        arrays.update({f"sample.{k}": v for k, v in self.samples.items()})
        for axis, cols in self.axes.items():
            arrays.update({f"{axis}.{k}": v for k, v in cols.items()})
        with open(out / "timeseries.npz.partial", "wb") as fh:
            np.savez(fh, **arrays)
        os.replace(part, out / "metrics.json")
        os.replace(out / "timeseries.npz.partial", out / "timeseries.npz")
        return out


RUNNER_NODE = "pneu_runner"  # the node name in /diagnostics status names


class _Rows:
    """Rows of floats recorded per cycle into an array preallocated for the whole run.

    Rows are gathered in a short list and copied in blocks (a numpy row write
    per cycle costs far more than a list append), so memory is the array plus one
    block, and :meth:`rows` always returns whole rows only.
    """

    BLOCK = 4096

    def __init__(self, n: int, width: int) -> None:
        self.arr = np.empty((n, width), dtype=float)
        self.buf: list[tuple[float, ...]] = []
        self.n = 0  # rows copied into arr
        self.append = self.buf.append

    def flush(self) -> None:
        if self.buf:
            k = len(self.buf)
            self.arr[self.n : self.n + k] = self.buf
            self.n += k
            self.buf.clear()

    def rows(self, m: int) -> np.ndarray:
        """The first ``m`` rows (``m`` ≤ rows appended)."""
        self.flush()
        return self.arr[:m]

    def __len__(self) -> int:
        return self.n + len(self.buf)


def _diag(events: list[Any]) -> list[Any]:
    from pneu_msgs_py.bag import DiagStatus

    from pneu_control.analysis.fault_marks import diag_name

    level = {"OK": 0, "WARN": 1, "ERROR": 2}
    return [
        DiagStatus(
            level[e.level],
            diag_name(RUNNER_NODE, e.axis, e.rule),
            e.message,
            "twin",
            dict(e.values),
        )
        for e in events
    ]


def run(
    spec: RunSpec,
    *,
    bag: Any | None = None,
    progress: Callable[[float], None] | None = None,
    hook: Callable[[int, Any, RigCycle, dict[str, Any]], bool] | None = None,
) -> RunResult:
    """Run ``spec`` in lockstep. ``bag``: an open ``BagWriter`` to log into.

    ``hook(k, s_k, cycle, controllers)``: called at the start of every cycle, before
    the controllers answer s_k (a task switches references and loads there); True
    ends the run after the cycles so far (a task that finished or aborted).

    With ``spec.safety`` (the default) every command passes through a
    :class:`pneu_driver.safety.supervisor.SafetySupervisor` before it reaches the plant,
    and every sample (with the raw AI volts the twin's sensors put out) is
    checked; transitions go to ``/diagnostics`` in the bag. ``spec.faults``
    are injected by a :class:`pneu_sim.faults.injection.FaultInjector`.

    Per cycle k: sample s_k (faults applied) → supervisor checks s_k →
    output for tick k (= u_{k−1} after the rules) → controllers answer s_k with
    u_k → plant steps k → k+1 under the tick-k output. No exception from a
    controller escapes: the controller is treated as crashed (silent) from
    then on and the supervisor's watchdog takes its axis safe.

    A signal recorded by :mod:`pneu_msgs_py.lifecycle.signals` (polled once per
    cycle) or a KeyboardInterrupt stops the loop cleanly: the result holds the
    cycles that ran completely (``interrupted=True``) and the caller still
    closes the bag. Memory is preallocated for the run's duration (capped by
    :mod:`pneu_msgs_py.lifecycle.duration`).
    """
    plant = Plant(spec.plant, seed=spec.seed)
    period = plant.T
    n = int(round(spec.duration_s / period))
    ctrls = {axis: _controller(axis, spec.controllers[axis], period) for axis in spec.axes}
    sup = None
    if spec.safety is not None:
        from pneu_driver.safety import SafetySupervisor

        sup = SafetySupervisor(spec.safety, sample_time_s=period)
    cycle = RigCycle(
        plant, axes=spec.axes, x0=spec.x0, supervisor=sup, faults=spec.faults, seed=spec.seed
    )
    rec = _Recording(n, ctrls, faulty=cycle.injector is not None)
    algorithms = {axis: c.algorithm for axis, c in ctrls.items()}  # as the run starts
    t_wall = time.perf_counter()
    m, interrupted = _cycles(cycle, ctrls, rec, n, bag, progress, hook)
    wall = time.perf_counter() - t_wall
    t, samples, axes, held, truth = rec.arrays(m)
    return result_of(
        spec,
        t,
        samples,
        axes,
        held,
        rec.events,
        dict(sup.counters) if sup is not None else {},
        period,
        wall,
        interrupted=interrupted,
        truth=truth,
        algorithms=algorithms,
    )


class _Recording:
    """What :func:`run` records per cycle, preallocated for its ``n`` cycles."""

    def __init__(self, n: int, ctrls: dict[str, Any], faulty: bool) -> None:
        # per cycle: (stamp, SAMPLE_FIELDS...); per axis: (STATE_FIELDS..., u); what the DAQ held
        self.samples = _Rows(n, 1 + len(SAMPLE_FIELDS))
        self.axis = {axis: _Rows(n, len(STATE_FIELDS) + 1) for axis in ctrls}
        self.out = _Rows(n, 2)  # what the DAQ held during each step
        self.faulty = faulty
        self.truth = _Rows(n if faulty else 0, 2)  # (x, omega) true, only with faults
        self.events: list[Any] = []  # SafetyEvent, in order
        self.crashed: dict[str, str] = {}  # axis -> the exception its controller raised

    def flush(self) -> None:
        """Copy the gathered rows of every recorder into its array."""
        for r in (self.samples, self.out, self.truth, *self.axis.values()):
            r.flush()

    def controller_failed(self, axis: str, err: BaseException, stamp: int, bag: Any) -> None:
        """``axis``'s controller raised ``err``: crashed from now on, an ERROR event (and
        its ``/diagnostics`` in ``bag``)."""
        self.crashed[axis] = f"{type(err).__name__}: {err}"
        from pneu_driver.safety import ERROR, SafetyEvent

        ev = SafetyEvent(
            stamp,
            axis,
            "controller_exception",
            ERROR,
            f"{axis} controller raised {self.crashed[axis]}; treated as crashed (no more commands)",
            (("exception", type(err).__name__),),
        )
        self.events.append(ev)
        if bag is not None:
            bag.write_diagnostics(stamp, _diag([ev]))

    def arrays(self, m: int) -> tuple[np.ndarray, dict, dict, np.ndarray, dict[str, np.ndarray]]:
        """(t, samples, axes, held, truth) of the first ``m`` cycles that were recorded whole."""
        # whole cycles only (an exception between two records of a cycle drops that cycle)
        m = min(m, len(self.samples), len(self.out), *(len(r) for r in self.axis.values()))
        srows = self.samples.rows(m)
        t = srows[:, 0].astype(np.int64) * 1e-9
        samples = {name: srows[:, 1 + i].copy() for i, name in enumerate(SAMPLE_FIELDS)}
        axes: dict[str, dict[str, np.ndarray]] = {}
        for axis, rows in self.axis.items():
            block = rows.rows(m)
            cols = {name: block[:, i].copy() for i, name in enumerate(STATE_FIELDS)}
            cols["u"] = block[:, len(STATE_FIELDS)].copy()
            axes[axis] = cols
        held = self.out.rows(m)
        truth = {}
        if self.faulty and m:
            tr = self.truth.rows(min(m, len(self.truth)))
            truth = {"x": tr[:, 0].copy(), "omega": tr[:, 1].copy()}
        return t, samples, axes, held, truth


def _cycles(
    cycle: RigCycle,
    ctrls: dict[str, Any],
    rec: _Recording,
    n: int,
    bag: Any | None,
    progress: Callable[[float], None] | None,
    hook: Callable[..., bool] | None = None,
) -> tuple[int, bool]:
    """Up to ``n`` cycles of :func:`run` (its docstring gives the order within one):
    (cycles recorded completely, interrupted?)."""
    plant, sup = cycle.plant, cycle.supervisor
    period = plant.T
    # (axis, core, its records), fixed order
    active = [(axis, ctrls[axis], rec.axis[axis].append) for axis in AXES if axis in ctrls]
    nan_row = (math.nan,) * (len(STATE_FIELDS) + 1)
    sig = signals.STATE
    faulty, crashed = rec.faulty, rec.crashed
    s = cycle.reset()
    interrupted = False
    report_every = max(1, int(round(1.0 / period)))  # once per simulated second
    m = 0  # cycles recorded completely
    append_sample, append_out, append_truth = rec.samples.append, rec.out.append, rec.truth.append
    try:
        for k in range(n):
            if sig.pending is not None:  # SIGINT/SIGTERM/SIGHUP under signals.deferred()
                interrupted = True
                break
            if hook is not None and hook(k, s, cycle, ctrls):
                break
            stamp = s.stamp_ns
            if faulty:
                st = plant.state
                append_truth((st.x, st.omega))
            append_sample((stamp, s.p_c1, s.p_c2, s.p_m1, s.x, s.theta, s.omega, s.counts))
            answers = []  # (axis, u, state values, algorithm) for the bag, in axis order
            for axis, ctrl, append_axis in active:
                u = None
                if not (axis in crashed or cycle.silent(axis)):
                    try:
                        u = ctrl.update(s)
                    except Exception as err:  # a crashed controller must not stop the rig
                        rec.controller_failed(axis, err, stamp, bag)
                if u is None:  # silent or crashed: no command this cycle
                    append_axis(nan_row)
                else:
                    values = ctrl.state_values()
                    u = cycle.command(axis, u)
                    append_axis((*values, u))
                    if bag is not None:
                        answers.append((axis, u, values, ctrl.algorithm))
            if bag is not None:
                bag.write_cycle(s, answers)
            if sup is not None:
                events = sup.events()
                if events:
                    rec.events.extend(events)
                    if bag is not None:
                        bag.write_diagnostics(stamp, _diag(events))
            append_out(cycle.held_pair)
            m = k + 1
            if not m % _Rows.BLOCK:
                rec.flush()
            s = cycle.advance()  # tick k -> k+1 under u_{k-1}
            if progress is not None and k % report_every == 0:
                progress(k * period)
    except KeyboardInterrupt as err:
        if isinstance(err, signals.Interrupted) and sig.defer == 0:
            raise  # the caller did not defer signals (tune, paper's extra seeds): it stops too
        interrupted = True
    return m, interrupted


def result_of(
    spec: RunSpec,
    t: np.ndarray,
    samples: dict[str, np.ndarray],
    axes: dict[str, dict[str, np.ndarray]],
    held: np.ndarray,
    events: list[Any],
    counters: dict[str, int],
    period_s: float,
    wall_s: float,
    *,
    interrupted: bool = False,
    truth: dict[str, np.ndarray] | None = None,
    algorithms: dict[str, str] | None = None,
) -> RunResult:
    """The :class:`RunResult` of recorded arrays (``held``: (N, 2) V, linear and rotary):
    fault and safe intervals, then the DESIGN §7 metrics per axis (shared by the runner
    and the compiled loop, :mod:`pneu_control.experiment.compiled`)."""
    m = t.shape[0]
    faults = fault_intervals_of(spec, events, period_s)
    metrics: dict[str, AxisMetrics] = {}
    for axis, cols in axes.items():
        window = spec.windows.get(axis, WindowSpec(kind="fixed"))
        name, units = measured_of(axis, spec.controllers[axis])
        if m > 1:
            metrics[axis] = axis_metrics(
                axis, t, cols["reference"], samples[name], window, faults, spec.include_faults,
                units,
            )  # fmt: skip
    return RunResult(
        spec,
        t,
        samples,
        axes,
        algorithms
        if algorithms is not None
        else {axis: spec.controllers[axis].algorithm for axis in axes},
        metrics,
        wall_s,
        interrupted,
        applied={"linear": held[:, 0], "rotary": held[:, 1]},
        truth=truth or {},
        safety_events=events,
        fault_intervals=faults,
        safety_counters=counters,
    )


def _controller(axis: str, params: Any, period_s: float) -> Any:
    """The per-sample core of ``axis``: an AxisController, or what ``params`` makes itself
    (``params.make_controller(axis, period_s)``: e.g. an excitation design's exciter, which
    answers samples like a controller: ``update``, ``state_values``, ``algorithm``)."""
    make = getattr(params, "make_controller", None)
    return make(axis, period_s) if make is not None else AxisController(axis, params)


def fault_intervals_of(spec: RunSpec, events: list[Any], period_s: float) -> list[Any]:
    """Injected-fault and safe intervals of a run (see :mod:`pneu_control.analysis.fault_marks`)."""
    from pneu_control.analysis.fault_marks import injected_intervals, safe_intervals

    out = injected_intervals([f.to_dict() for f in spec.faults], spec.axes, period_s)
    out += safe_intervals((e.stamp_ns, e.axis, e.rule, e.level, e.message) for e in events)
    return out
