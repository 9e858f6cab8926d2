"""``run_compiled(spec)``: the runner's results from the compiled closed loop.

:func:`run_compiled` gives the same :class:`~pneu_control.experiment.runner.RunResult`
as :func:`pneu_control.experiment.runner.run` (no bag) -- every array bit for bit,
the metrics, the safety events and counters -- from one call of
:func:`pneu_control.fastloop.loop.closed_loop` (see :mod:`pneu_control.fastloop`).
The Python runner stays the slow, obvious reference it is tested against
(test/control/experiment/test_compiled.py).

Events: the compiled loop mirrors the supervisor's *decisions* and reports the last
cycle at which the Python supervisor emits an event or counts something; the
events (messages, values, order) and counters are then produced by the Python
:class:`~pneu_driver.safety.supervisor.SafetySupervisor` itself, replayed over the
recorded samples and commands up to that cycle. In a run without trips that is
cycle 0 ("commands arriving"). The replay also checks the compiled outputs against
the Python supervisor's over those cycles (:class:`CompiledLoopMismatch` if not).

Not compiled (the Python runner runs these, see :func:`compiled_support`):
injected faults; a run where the plant gives a non-finite sample or a controller
answers NaN (found while running: the run is redone in Python). No bag, no
progress callback, no Ctrl-C inside the compiled call.

Many runs: the first call in a process loads the loop from numba's cache (or
compiles it: about a minute, once per source change); :func:`warm_up` does that up
front. For a pool of worker processes, call :func:`warm_up` in the parent first (the
cache is then on disk: each worker loads it in under a second instead of compiling
it), then ``warm_up()`` in each worker's initializer; every later call costs the
simulation only. The result's arrays are views of one (N, 33) record array
(≈ 5 MB for 20 s): keep the metrics, not the results, across thousands of runs.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from pneu_msgs_py.contract.samples import AXES, SensorSample
from pneu_sim.physics.plant import Plant

from pneu_control.controller.axis import STATE_FIELDS, AxisController
from pneu_control.experiment.runner import SAMPLE_FIELDS, RunResult, RunSpec, result_of, run

__all__ = ["CompiledLoopMismatch", "compiled_support", "run_compiled", "warm_up"]


class CompiledLoopMismatch(RuntimeError):
    """The compiled loop's output differs from the Python supervisor's (a bug)."""

    def __init__(self, k: int, compiled: tuple[float, float], python: tuple[float, float]):
        super().__init__(
            f"compiled closed loop diverged from the Python supervisor at cycle {k}: "
            f"held {compiled} V, Python {python} V"
        )


def compiled_support(spec: RunSpec) -> str | None:
    """Why :func:`run_compiled` would run ``spec`` in Python (None: it runs it compiled)."""
    from pneu_control.fastloop.pack import unsupported

    return unsupported(spec)


def _python(
    spec: RunSpec, reason: str, fallback: bool, on_fallback: Callable[[str], None] | None
) -> RunResult:
    if not fallback:
        raise ValueError(f"run_compiled: {reason}; allowed: fallback=True (the Python runner)")
    if on_fallback is not None:
        on_fallback(reason)
    return run(spec)


def run_compiled(
    spec: RunSpec,
    *,
    fallback: bool = True,
    on_fallback: Callable[[str], None] | None = None,
) -> RunResult:
    """:func:`pneu_control.experiment.runner.run` (no bag), compiled; same results.

    What the compiled loop does not cover runs in the Python runner
    (``fallback=True``; ``on_fallback(reason)`` is told why) or raises
    ValueError naming the reason (``fallback=False``).
    """
    from pneu_control.fastloop import layout as L
    from pneu_control.fastloop.loop import closed_loop
    from pneu_control.fastloop.pack import pack_spec
    from pneu_control.fastloop.supervisor import sup_new

    reason = compiled_support(spec)
    if reason is not None:
        return _python(spec, reason, fallback, on_fallback)
    # the runner's objects, in its order (same validation, same errors)
    plant = Plant(spec.plant, seed=spec.seed)
    period = plant.T
    n = int(round(spec.duration_s / period))
    for axis in spec.axes:
        AxisController(axis, spec.controllers[axis])
    sup = scaling = None
    if spec.safety is not None:
        from pneu_driver.safety import SafetySupervisor, check_plumbing
        from pneu_sim.faults.injection import SensorScaling

        check_plumbing(spec.safety, plant.params.rotary.plumbing, "the twin's rotary.plumbing")
        sup = SafetySupervisor(spec.safety, sample_time_s=period)
        scaling = SensorScaling(plant.params)
    packed = pack_spec(spec, sup, scaling)
    plant.reset(x0=spec.x0)  # sample s_0 (RigCycle.reset)
    noise = plant.noise_rows(n)
    st, prm, out = plant.kernel_arrays()
    rec = np.empty((n, L.N_REC))
    t_ns = round(period * 1e9)
    p = packed
    t_wall = time.perf_counter()
    status, k_stop, last_event = closed_loop(
        n, t_ns, st, prm, noise, out, p.axes, p.algs, p.sup_on, p.scale,
        (*sup_new(p.sf), np.empty(4)), rec,
    )  # fmt: skip
    wall = time.perf_counter() - t_wall
    if status != L.OK:
        return _python(spec, f"{L.STATUS_TEXT[status]} (cycle {k_stop})", fallback, on_fallback)
    events: list[Any] = []
    counters: dict[str, int] = {}
    if spec.safety is not None:
        events, counters = _replay(sup, spec.axes, rec, out, n, last_event, t_ns, scaling)
    t = (np.arange(n, dtype=np.int64) * t_ns) * 1e-9
    samples = {name: rec[:, L.REC_SAMPLE + i] for i, name in enumerate(SAMPLE_FIELDS)}
    axes: dict[str, dict[str, np.ndarray]] = {}
    for axis in spec.axes:
        base = L.REC_AXIS + L.N_REC_AXIS * AXES.index(axis)
        cols = {name: rec[:, base + i] for i, name in enumerate(STATE_FIELDS)}
        cols["u"] = rec[:, base + len(STATE_FIELDS)]
        axes[axis] = cols
    held = rec[:, L.REC_HELD : L.REC_HELD + 2]
    return result_of(spec, t, samples, axes, held, events, counters, period, wall)


def _replay(sup, axes, rec, last_out, n, last_event, t_ns, scaling):
    """The fresh supervisor ``sup`` over cycles 0..last_event: (events, counters).

    Checks the compiled outputs against it on the way.
    """
    from pneu_control.fastloop import layout as L

    active = [
        (axis, L.REC_AXIS + L.N_REC_AXIS * a + len(STATE_FIELDS)) for a, axis in enumerate(AXES)
    ]
    active = [(axis, col) for axis, col in active if axis in axes]
    events: list[Any] = []
    for k in range(min(max(last_event, 0), n) + 1):
        row = rec[k] if k < n else last_out  # s_n: the runner's final advance checks it
        s = SensorSample(k, k * t_ns, *row[L.REC_SAMPLE : L.REC_SAMPLE + 6].tolist(), int(row[6]))
        sup.check_sample(s, scaling.volts(s))
        held = sup.outputs(s.stamp_ns)
        if k == n:
            break
        compiled = (float(row[L.REC_HELD]), float(row[L.REC_HELD + 1]))
        if held != compiled:
            raise CompiledLoopMismatch(k, compiled, held)
        for axis, col in active:
            sup.command(axis, float(row[col]), s.stamp_ns)
        events.extend(sup.events())
    return events, dict(sup.counters)


def warm_up() -> float:
    """Load (or compile) the compiled loop in this process; returns the seconds it took."""
    from pneu_sim.physics.params import PlantParams

    from pneu_control.controller.params import AxisControllerParams

    t0 = time.perf_counter()
    spec = RunSpec(
        axes=AXES,
        controllers={axis: AxisControllerParams() for axis in AXES},
        plant=PlantParams(),
        duration_s=0.01,  # the shortest run the duration cap allows (lifecycle.duration)
    )
    run_compiled(spec, fallback=False)
    return time.perf_counter() - t0
