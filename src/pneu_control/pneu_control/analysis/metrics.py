"""The paper's steady-state error metrics (DESIGN §7, paper Eq. 37).

e = reference − measured;  e_max = max |e(t)| for t ≥ T_s;
RMSE = sqrt(mean e²) over the same window.

The steady-state window T_s depends on the experiment kind:

- ``sine``: from the end of the second reference period to the end;
- ``speed`` (constant speed): from 2 s after the speed first comes within 1 %
  of the reference;
- ``positioning`` (Eq. 38 smooth step): from t = 5 s;
- ``fixed``: from a given start time.

Rotary speed is measured from encoder counts per 1 ms, quantised to 15 rpm
(1000 P/R, X4), and the vane motor's torque ripple (Eq. 8, four vanes: 53 Hz
at 800 rpm) modulates the true speed by about ±15 rpm on the twin. The paper's
±2 rpm cannot be read off such samples (errata: "the reported ±2 rpm implies
filtering"). Our choice, stated wherever a figure is printed: the constant-
speed metrics use the mean speed over one revolution at the reference speed
(``average_s`` = 60/n_ref: 75 ms at 800 rpm) -- what a tachometer counting
once per revolution reads; it is a causal moving average of reference and
measured alike, i.e. encoder edges counted over that window. The paper is
silent on its speed filter.

Everything here works on SI arrays; :class:`AxisMetrics` converts to the
report units (mm, rpm) once, at the edge.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from pneu_msgs_py.contract.units import MM_PER_M, RPM_PER_RAD_S

from pneu_control.analysis.fault_marks import exclusion_mask

__all__ = [
    "UNITS",
    "WINDOW_KINDS",
    "AxisMetrics",
    "WindowSpec",
    "axis_metrics",
    "compute_metrics",
    "moving_average",
    "window_start",
]

WINDOW_KINDS = ("sine", "speed", "positioning", "fixed")

#: axis -> (report unit, factor from SI)
UNITS = {"linear": ("mm", MM_PER_M), "rotary": ("rpm", RPM_PER_RAD_S)}


@dataclass(frozen=True)
class WindowSpec:
    """How the steady-state window starts (DESIGN §7); ``t_end_s`` None = run end."""

    kind: str = "fixed"
    frequency_hz: float = 0.0  # sine: the reference frequency
    settle_band: float = 0.01  # speed: |e| <= band·|r| counts as "within 1 %"
    settle_delay_s: float = 2.0  # speed: window opens this long after first within band
    t_start_s: float = 0.0  # positioning / fixed: window start
    t_end_s: float | None = None
    average_s: float = 0.0  # causal moving average of r and y before e (0 = none)

    def __post_init__(self):
        if self.kind not in WINDOW_KINDS:
            raise ValueError(f"window.kind: {self.kind!r} refused; allowed: one of {WINDOW_KINDS}")
        if self.kind == "sine" and not self.frequency_hz > 0.0:
            raise ValueError(
                f"window.frequency_hz: {self.frequency_hz!r} refused; allowed: (0, inf) Hz"
            )

    def to_dict(self) -> dict:
        """The window as plain data (metrics.json, the bag's ``pneu.run`` record)."""
        return asdict(self)

    @staticmethod
    def from_dict(d: dict) -> WindowSpec:
        """The window of :meth:`to_dict`'s output."""
        return WindowSpec(**d)


def moving_average(y: np.ndarray, n: int) -> np.ndarray:
    """Causal moving average over the last ``n`` samples (fewer at the start)."""
    if n <= 1:
        return y
    c = np.cumsum(np.concatenate(([0.0], y)))
    k = np.arange(1, y.size + 1)
    lo = np.maximum(k - n, 0)
    return (c[k] - c[lo]) / (k - lo)


def window_start(
    t: np.ndarray, reference: np.ndarray, measured: np.ndarray, spec: WindowSpec
) -> float:
    """Start time T_s of the steady-state window (s); NaN if it never opens."""
    if spec.kind == "sine":
        return 2.0 / spec.frequency_hz
    if spec.kind == "speed":
        band = spec.settle_band * np.abs(reference)
        inside = np.flatnonzero(np.abs(reference - measured) <= band)
        if inside.size == 0:
            return math.nan
        return float(t[inside[0]]) + spec.settle_delay_s
    return spec.t_start_s


@dataclass(frozen=True)
class AxisMetrics:
    """Steady-state metrics of one axis, in report units (mm or rpm)."""

    axis: str
    unit: str
    e_max: float
    rmse: float
    window_start_s: float
    window_end_s: float
    n_samples: int

    @property
    def window_s(self) -> list[float]:
        """``[window start, window end]`` in s."""
        return [self.window_start_s, self.window_end_s]

    def why_empty(self) -> str:
        """Why there is no figure (an empty window), with what to pass; "" if there is one."""
        if self.n_samples > 0:
            return ""
        t0, t1 = self.window_start_s, self.window_end_s
        if math.isnan(t0):
            return (
                "no steady-state window: the speed never came within 1 % of the reference; "
                f"pass --window-start S (below {t1:.2f} s) to measure anyway"
            )
        if t0 > t1:
            return (
                f"no steady-state window: it opens at {t0:.2f} s, after the run's end at "
                f"{t1:.2f} s; run longer, or pass --window-start S (below {t1:.2f} s)"
            )
        return (
            f"no sample in the window {t0:.2f}–{t1:.2f} s outside the fault intervals; "
            "pass --include-faults to measure over them"
        )

    def line(self, algorithm: str) -> str:
        """One report line: the figures and the window, or why there are none."""
        why = self.why_empty()
        if why:
            return f"{self.axis:7s} {algorithm:12s} {why}"
        return (
            f"{self.axis:7s} {algorithm:12s} e_max = {self.e_max:8.4f} {self.unit}   "
            f"RMSE = {self.rmse:8.4f} {self.unit}   window {self.window_start_s:.2f}–"
            f"{self.window_end_s:.2f} s ({self.n_samples} samples)"
        )

    def to_dict(self) -> dict:
        """The metrics as plain data, with ``window_s``."""
        d = asdict(self)
        d["window_s"] = self.window_s
        return d


def compute_metrics(
    axis: str,
    t: np.ndarray,
    reference: np.ndarray,
    measured: np.ndarray,
    spec: WindowSpec,
    exclude: np.ndarray | None = None,
    units: tuple[str, float] | None = None,
) -> AxisMetrics:
    """e_max and RMSE (Eq. 37) of ``reference − measured`` over the window.

    Arrays are SI (m, rad/s or rad) sampled at the control period. ``exclude`` is a
    boolean mask of samples to leave out (e.g. fault intervals). ``units``: (unit,
    scale) of the report (default the axis's: mm, rpm; ``ANGLE_UNITS`` for an angle).
    """
    if axis not in UNITS:
        raise ValueError(f"axis: {axis!r} refused; allowed: linear, rotary")
    unit, scale = UNITS[axis] if units is None else units
    t = np.asarray(t, dtype=float)
    reference = np.asarray(reference, dtype=float)
    measured = np.asarray(measured, dtype=float)
    if spec.average_s > 0.0 and t.size > 1:
        n_avg = max(1, int(round(spec.average_s / float(t[1] - t[0]))))
        reference = moving_average(reference, n_avg)
        measured = moving_average(measured, n_avg)
    e = (reference - measured) * scale
    t0 = window_start(t, reference, measured, spec)
    t1 = float(t[-1]) if spec.t_end_s is None else spec.t_end_s
    # half a sample of tolerance so that "t >= T_s" is exact on a k·T grid
    half = 0.5 * float(t[1] - t[0]) if t.size > 1 else 0.0
    mask = (t >= t0 - half) & (t <= t1 + half) if math.isfinite(t0) else np.zeros(t.shape, bool)
    if exclude is not None:
        mask &= ~np.asarray(exclude, dtype=bool)
    n = int(mask.sum())
    if n == 0:
        return AxisMetrics(axis, unit, math.nan, math.nan, t0, t1, 0)
    ew = e[mask]
    return AxisMetrics(
        axis=axis,
        unit=unit,
        e_max=float(np.max(np.abs(ew))),
        rmse=float(np.sqrt(np.mean(ew * ew))),
        window_start_s=float(t0),
        window_end_s=float(t1),
        n_samples=n,
    )


def axis_metrics(axis, t, reference, measured, window, intervals, include_faults=False, units=None):
    """DESIGN §7 metrics without the fault intervals (unless ``include_faults``) and non-finite samples."""
    bad = ~(np.isfinite(measured) & np.isfinite(reference))
    exclude = bad if bad.any() else None
    if not include_faults and intervals:
        fm = exclusion_mask(t, intervals, axis)
        if fm is not None:
            exclude = fm if exclude is None else (exclude | fm)
    return compute_metrics(axis, t, reference, measured, window, exclude=exclude, units=units)
