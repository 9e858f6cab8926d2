"""The in-process experiment runner: twin and controller cores in lockstep.

One control cycle (DESIGN §3, k = sample index, T = 1 ms):

1. the plant is sampled at tick k → sample s_k;
2. each active controller computes u_k from s_k;
3. u_k is written at tick k+1 and held until k+2 (one-sample transport delay),
   so the plant steps from k to k+1 under u_{k−1}.

The ROS graph in lockstep mode does exactly the same, so both give the same
numbers for the same config and seed. Inactive axes hold the neutral 5 V.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pneu_msgs_py.samples import AXES, NEUTRAL_V, SensorSample
from pneu_sim.plant import Plant

from .axis import STATE_FIELDS, AxisController
from .metrics import AxisMetrics, WindowSpec, compute_metrics

__all__ = ["SAMPLE_FIELDS", "RunResult", "RunSpec", "run"]

SAMPLE_FIELDS = ("p_c1", "p_c2", "p_m1", "x", "theta", "omega", "counts")
_MEASURED = {"linear": "x", "rotary": "omega"}


@dataclass(frozen=True)
class RunSpec:
    """Everything that sets a run: with the same spec the results are byte-identical."""

    axes: tuple[str, ...]
    controllers: dict[str, Any]  # axis -> AxisControllerParams
    plant: Any  # PlantParams
    duration_s: float
    seed: int = 0
    windows: dict[str, WindowSpec] = field(default_factory=dict)
    x0: float = 0.0
    name: str = "run"

    def __post_init__(self):
        for axis in self.axes:
            if axis not in AXES:
                raise ValueError(f"axis: {axis!r} refused; allowed: one of {AXES}")
            if axis not in self.controllers:
                raise ValueError(f"controllers: no controller parameters for axis {axis!r}")
        if not (self.duration_s > 0.0 and math.isfinite(self.duration_s)):
            raise ValueError(f"duration: {self.duration_s!r} refused; allowed: (0, inf) s")


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

    @property
    def rtf(self) -> float:
        """Simulated seconds per wall-clock second."""
        return (
            float(self.t[-1] + self.t[1] - self.t[0]) / self.wall_s if self.wall_s > 0 else math.inf
        )

    def metrics_dict(self) -> dict[str, Any]:
        return {axis: m.to_dict() for axis, m in self.metrics.items()}

    def save(self, out_dir: str | Path, config_echo: dict[str, Any] | None = None) -> Path:
        """Write ``metrics.json`` and ``timeseries.npz`` into ``out_dir``."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        doc = {
            "name": self.spec.name,
            "axes": list(self.spec.axes),
            "algorithms": self.algorithms,
            "duration_s": self.spec.duration_s,
            "seed": self.spec.seed,
            "interrupted": self.interrupted,
            "metrics": self.metrics_dict(),
            "units": {"linear": "mm", "rotary": "rpm"},
            "config": config_echo or {},
        }
        (out / "metrics.json").write_text(json.dumps(doc, indent=2, sort_keys=True) + "\n")
        arrays = {"t": self.t}
        arrays.update({f"sample.{k}": v for k, v in self.samples.items()})
        for axis, cols in self.axes.items():
            arrays.update({f"{axis}.{k}": v for k, v in cols.items()})
        with open(out / "timeseries.npz", "wb") as fh:
            np.savez(fh, **arrays)
        return out


def run(
    spec: RunSpec,
    *,
    bag: Any | None = None,
    progress: Callable[[float], None] | None = None,
) -> RunResult:
    """Run ``spec`` in lockstep. ``bag``: an open ``BagWriter`` to log into.

    A KeyboardInterrupt stops the loop cleanly: the result holds what ran
    (``interrupted=True``) and the caller still closes the bag.
    """
    plant = Plant(spec.plant, seed=spec.seed)
    period = plant.T
    n = int(round(spec.duration_s / period))
    ctrls = {axis: AxisController(axis, spec.controllers[axis]) for axis in spec.axes}
    lin = ctrls.get("linear")
    rot = ctrls.get("rotary")
    rec_samples: list[SensorSample] = []
    rec_state: dict[str, list[tuple[float, ...]]] = {axis: [] for axis in ctrls}
    rec_u: dict[str, list[float]] = {axis: [] for axis in ctrls}
    rec_lin, rec_rot = rec_state.get("linear", []), rec_state.get("rotary", [])
    u_lin, u_rot = rec_u.get("linear", []), rec_u.get("rotary", [])
    algorithms = {axis: c.params.algorithm for axis, c in ctrls.items()}

    s = plant.reset(x0=spec.x0)
    u_hold_l = u_hold_r = NEUTRAL_V  # what the DAQ holds during the coming period
    interrupted = False
    report_every = max(1, int(round(1.0 / period)))  # once per simulated second
    t_wall = time.perf_counter()
    k = 0
    try:
        for k in range(n):
            stamp = s.stamp_ns
            rec_samples.append(s)
            if bag is not None:
                bag.write_sample(s)
            if lin is not None:
                u_l = lin.update(s)
                values = lin.state_values()
                rec_lin.append(values)
                u_lin.append(u_l)
                if bag is not None:
                    bag.write_command("linear", stamp, u_l)
                    bag.write_controller_state("linear", stamp, values, lin.algorithm)
            else:
                u_l = NEUTRAL_V
            if rot is not None:
                u_r = rot.update(s)
                values = rot.state_values()
                rec_rot.append(values)
                u_rot.append(u_r)
                if bag is not None:
                    bag.write_command("rotary", stamp, u_r)
                    bag.write_controller_state("rotary", stamp, values, rot.algorithm)
            else:
                u_r = NEUTRAL_V
            s = plant.step(u_hold_l, u_hold_r)  # tick k -> k+1 under u_{k-1}
            u_hold_l, u_hold_r = u_l, u_r
            if progress is not None and k % report_every == 0:
                progress(k * period)
    except KeyboardInterrupt:
        interrupted = True
    wall = time.perf_counter() - t_wall

    m = len(rec_samples)
    t = np.array([rs.stamp_ns for rs in rec_samples], dtype=np.int64) * 1e-9
    samples = {
        name: np.array([getattr(rs, name) for rs in rec_samples], dtype=float)
        for name in SAMPLE_FIELDS
    }
    axes: dict[str, dict[str, np.ndarray]] = {}
    metrics: dict[str, AxisMetrics] = {}
    for axis in ctrls:
        block = np.array(rec_state[axis][:m], dtype=float).reshape(m, len(STATE_FIELDS))
        cols = {name: block[:, i] for i, name in enumerate(STATE_FIELDS)}
        cols["u"] = np.array(rec_u[axis][:m], dtype=float)
        axes[axis] = cols
        window = spec.windows.get(axis, WindowSpec(kind="fixed"))
        measured = samples[_MEASURED[axis]]
        if m > 1:
            metrics[axis] = compute_metrics(axis, t, cols["reference"], measured, window)
    return RunResult(spec, t, samples, axes, algorithms, metrics, wall, interrupted)
