"""One sweep run: a fully built :class:`RunSpec` in, one table row out.

This module is what workers import (local processes and Dask workers alike):
task and result are plain picklable dataclasses, and the task function lives
in the installed package so a worker started from the same environment finds
it by name. A worker never reads a config file: the driver ships the whole
spec (plant sample, controller gains, safety thresholds).

:func:`simulate` is the one closed-loop call of every sweep run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pneu_control.experiment.catalog import Experiment
from pneu_control.experiment.compiled import run_compiled
from pneu_control.experiment.runner import MEASURED, RunResult, RunSpec

__all__ = ["ENVELOPE_S", "RunRow", "SweepTask", "run_task", "simulate"]

ENVELOPE_S = 0.05  # bin of the |e| envelope kept per run for the band figures


def simulate(spec: RunSpec) -> RunResult:
    """THE closed loop of a sweep run (without a bag): the compiled loop.

    :func:`pneu_control.experiment.compiled.run_compiled` gives ``runner.run(spec)``'s
    result bit for bit (tested); what it does not cover (injected faults, a
    non-finite value mid-run) it runs in the Python runner itself.
    """
    return run_compiled(spec)


@dataclass(frozen=True)
class SweepTask:
    """One run of a sweep: its place in the table, plant sample, experiment, controller, gain set
    and spec."""

    index: int  # position in the table
    sample: int
    experiment: Experiment
    controller: str
    gains: str
    spec: RunSpec


@dataclass(frozen=True)
class RunRow:
    """One run's results (report units), and its |e| envelope for the figures."""

    index: int
    sample: int
    seed: int
    experiment: str
    axis: str
    controller: str
    gains: str
    e_max: float
    rmse: float
    unit: str
    window_start_s: float
    window_end_s: float
    in_band: bool | None  # the paper's stated band (700 rpm), where it gives one
    safety_trip: str  # the supervisor's first ERROR on the axis, "rule at t s"; "" if none
    safety_errors: int  # ERROR events on the axis
    envelope: np.ndarray  # max |e| per ENVELOPE_S bin over the whole run (report units)


def run_task(task: SweepTask) -> RunRow:
    """Run one task (in whichever process) and reduce it to its row."""
    from pneu_control.experiment.paper import first_trip, in_band

    exp, spec = task.experiment, task.spec
    result = simulate(spec)
    m = result.metrics[exp.axis]
    band = None
    if exp.band is not None and math.isfinite(m.e_max):
        band = in_band(result, exp, m)
    errors = [e for e in result.safety_events if e.level == "ERROR" and e.axis in (exp.axis, "all")]
    return RunRow(
        index=task.index,
        sample=task.sample,
        seed=spec.seed,
        experiment=exp.id,
        axis=exp.axis,
        controller=task.controller,
        gains=task.gains,
        e_max=m.e_max,
        rmse=m.rmse,
        unit=m.unit,
        window_start_s=m.window_start_s,
        window_end_s=m.window_end_s,
        in_band=band,
        safety_trip=first_trip(result, exp.axis) or "",
        safety_errors=len(errors),
        envelope=error_envelope(result, exp),
    )


def error_envelope(result: RunResult, exp: Experiment) -> np.ndarray:
    """max |reference − measured| per ENVELOPE_S bin, with the metric's averaging
    (one revolution on the rotary axis), in report units; NaN where nothing finite."""
    from pneu_control.analysis.metrics import UNITS, moving_average

    t = result.t
    ref = result.axes[exp.axis]["reference"]
    y = result.samples[MEASURED[exp.axis]]
    dt = float(t[1] - t[0])
    if exp.window.average_s > 0.0:
        n_avg = max(1, int(round(exp.window.average_s / dt)))
        ref, y = moving_average(ref, n_avg), moving_average(y, n_avg)
    e = np.abs(ref - y) * UNITS[exp.axis][1]
    per = max(1, int(round(ENVELOPE_S / dt)))
    n_bins = math.ceil(e.size / per)
    padded = np.full(n_bins * per, np.nan)
    padded[: e.size] = np.where(np.isfinite(e), e, np.nan)
    block = padded.reshape(n_bins, per)
    out = np.full(n_bins, np.nan)
    ok = np.isfinite(block).any(axis=1)
    out[ok] = np.nanmax(block[ok], axis=1)
    return out


def spec_seed(base_seed: int, sample: int) -> int:
    """Seed of sample ``sample`` (noise and sensor offsets): one per plant sample,
    the same for every controller on it (common random numbers for the ranking)."""
    return base_seed + sample
