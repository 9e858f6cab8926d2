"""Reference signals with analytic first and second derivatives.

A :class:`Reference` is a callable ``ref(t) -> (r, r_dot, r_ddot)`` in SI:
m, m/s, m/s² on the linear axis (position), rad/s, rad/s², rad/s³ on the
rotary axis (speed). :func:`make_reference` takes :class:`ReferenceParams`
in the paper's units (mm, rpm) and converts once.

Kinds (``u`` = scale: mm → m or rpm → rad/s, τ = max(t − t0, 0)):

- sine: r = offset + A sin(2π f τ)
- smooth_step (Eq. 38 generalised): with D = duration, Δr = target − offset,
  r = offset + Δr (τ/D − sin(2π τ/D)/(2π)) for τ ≤ D, target after.
  D = 4 s, offset 0, target 120/π mm gives Eq. 38 exactly; ṙ and r̈ are 0 at
  both ends (C² everywhere).
- constant: r = value
- ramp: r = offset + slope·τ, held after ``duration_s`` (0 = endless)
- waypoints: quintic Hermite through (t_i, r_i) from a CSV or YAML file,
  knot velocities by the Fritsch–Carlson monotone rule (no overshoot between
  knots of a monotone run, zero at the ends and at extrema) and knot
  accelerations by central differences of those velocities (zero at the ends):
  r, ṙ and r̈ are continuous; the value holds before the first and after the
  last knot.
"""

from __future__ import annotations

import bisect
import csv
import math
from pathlib import Path
from typing import Protocol

from pneu_msgs_py.contract.units import MM_PER_M, RPM_PER_RAD_S
from pneu_msgs_py.params.core import ParamError

from pneu_control.controller.params import ReferenceParams

__all__ = [
    "Reference",
    "make_reference",
    "Sine",
    "SmoothStep",
    "Constant",
    "Ramp",
    "Waypoints",
    "load_waypoints",
    "axis_scale",
]

_TWO_PI = 2.0 * math.pi


def axis_scale(axis: str) -> float:
    """Paper units per SI unit: 1000 (mm per m) linear, 9.549 (rpm per rad/s) rotary."""
    if axis == "linear":
        return MM_PER_M
    if axis == "rotary":
        return RPM_PER_RAD_S
    raise ParamError("axis", axis, "one of linear, rotary")


class Reference(Protocol):
    def __call__(self, t: float) -> tuple[float, float, float]: ...


class Sine:
    """offset + amplitude·sin(2π f (t − t0)) (SI)."""

    def __init__(self, amplitude: float, frequency_hz: float, offset: float, t0: float = 0.0):
        self.a, self.w, self.c, self.t0 = amplitude, _TWO_PI * frequency_hz, offset, t0

    def __call__(self, t: float) -> tuple[float, float, float]:
        tau = t - self.t0
        if tau <= 0.0:
            return self.c, 0.0, 0.0
        a, w = self.a, self.w
        sn, cs = math.sin(w * tau), math.cos(w * tau)
        return self.c + a * sn, a * w * cs, -a * w * w * sn


class SmoothStep:
    """Eq. 38 generalised: start → target over ``duration`` s (SI)."""

    def __init__(self, start: float, target: float, duration: float, t0: float = 0.0):
        self.r0, self.dr, self.d, self.t0 = start, target - start, duration, t0

    def __call__(self, t: float) -> tuple[float, float, float]:
        tau = t - self.t0
        if tau <= 0.0:
            return self.r0, 0.0, 0.0
        d = self.d
        if tau >= d:
            return self.r0 + self.dr, 0.0, 0.0
        ph = _TWO_PI * tau / d
        g = self.dr / d
        # Eq. 38: x = 30t/π − (60/π²) sin(πt/2) with D = 4, Δr = 120/π
        return (
            self.r0 + self.dr * (tau / d - math.sin(ph) / _TWO_PI),
            g * (1.0 - math.cos(ph)),
            g * (_TWO_PI / d) * math.sin(ph),
        )


class Constant:
    def __init__(self, value: float):
        self.v = value

    def __call__(self, t: float) -> tuple[float, float, float]:
        return self.v, 0.0, 0.0


class Ramp:
    """start + slope·(t − t0), held after ``duration`` (0 = endless)."""

    def __init__(self, start: float, slope: float, duration: float = 0.0, t0: float = 0.0):
        self.r0, self.k, self.d, self.t0 = start, slope, duration, t0

    def __call__(self, t: float) -> tuple[float, float, float]:
        tau = t - self.t0
        if tau <= 0.0:
            return self.r0, 0.0, 0.0
        if self.d > 0.0 and tau >= self.d:
            return self.r0 + self.k * self.d, 0.0, 0.0
        return self.r0 + self.k * tau, self.k, 0.0


def _pchip_slopes(t: list[float], y: list[float]) -> list[float]:
    """Fritsch–Carlson knot velocities; zero at the ends (the trajectory starts/ends at rest)."""
    n = len(t)
    h = [t[i + 1] - t[i] for i in range(n - 1)]
    d = [(y[i + 1] - y[i]) / h[i] for i in range(n - 1)]
    m = [0.0] * n
    for i in range(1, n - 1):
        if d[i - 1] * d[i] <= 0.0:
            m[i] = 0.0
        else:  # weighted harmonic mean (Fritsch & Butland 1984)
            w1 = 2.0 * h[i] + h[i - 1]
            w2 = h[i] + 2.0 * h[i - 1]
            m[i] = (w1 + w2) / (w1 / d[i - 1] + w2 / d[i])
    return m


class Waypoints:
    """Quintic Hermite through knots (t_i, r_i), C² (SI values)."""

    def __init__(self, t: list[float], r: list[float], t0: float = 0.0):
        self.t = [float(x) + t0 for x in t]
        self.r = [float(x) for x in r]
        n = len(self.t)
        v = _pchip_slopes(self.t, self.r)
        a = [0.0] * n
        for i in range(1, n - 1):
            a[i] = (v[i + 1] - v[i - 1]) / (self.t[i + 1] - self.t[i - 1])
        self.v, self.a = v, a

    def __call__(self, t: float) -> tuple[float, float, float]:
        ts = self.t
        if t <= ts[0]:
            return self.r[0], 0.0, 0.0
        if t >= ts[-1]:
            return self.r[-1], 0.0, 0.0
        i = bisect.bisect_right(ts, t) - 1
        h = ts[i + 1] - ts[i]
        s = (t - ts[i]) / h
        p0, p1 = self.r[i], self.r[i + 1]
        v0, v1 = self.v[i] * h, self.v[i + 1] * h
        a0, a1 = self.a[i] * h * h, self.a[i + 1] * h * h
        s2, s3 = s * s, s * s * s
        s4, s5 = s3 * s, s3 * s2
        # quintic Hermite basis and its derivatives in s
        h00 = 1 - 10 * s3 + 15 * s4 - 6 * s5
        h10 = s - 6 * s3 + 8 * s4 - 3 * s5
        h20 = 0.5 * (s2 - 3 * s3 + 3 * s4 - s5)
        h01 = 10 * s3 - 15 * s4 + 6 * s5
        h11 = -4 * s3 + 7 * s4 - 3 * s5
        h21 = 0.5 * (s3 - 2 * s4 + s5)
        d00 = -30 * s2 + 60 * s3 - 30 * s4
        d10 = 1 - 18 * s2 + 32 * s3 - 15 * s4
        d20 = 0.5 * (2 * s - 9 * s2 + 12 * s3 - 5 * s4)
        d11 = -12 * s2 + 28 * s3 - 15 * s4
        d21 = 0.5 * (3 * s2 - 8 * s3 + 5 * s4)
        e00 = -60 * s + 180 * s2 - 120 * s3
        e10 = -36 * s + 96 * s2 - 60 * s3
        e20 = 0.5 * (2 - 18 * s + 36 * s2 - 20 * s3)
        e11 = -24 * s + 84 * s2 - 60 * s3
        e21 = 0.5 * (6 * s - 24 * s2 + 20 * s3)
        r = h00 * p0 + h10 * v0 + h20 * a0 + h01 * p1 + h11 * v1 + h21 * a1
        rd = d00 * p0 + d10 * v0 + d20 * a0 - d00 * p1 + d11 * v1 + d21 * a1
        rdd = e00 * p0 + e10 * v0 + e20 * a0 - e00 * p1 + e11 * v1 + e21 * a1
        return r, rd / h, rdd / (h * h)


def _resolve(file: str) -> Path:
    p = Path(file).expanduser()
    if p.is_absolute() or p.is_file():
        return p
    try:
        from pneu_msgs_py.params.paths import config_dir

        cand = config_dir() / file
        if cand.is_file():
            return cand
    except FileNotFoundError:
        pass
    return p


def load_waypoints(file: str, key: str = "reference.file") -> tuple[list[float], list[float]]:
    """Read (t, value) rows from CSV (``t,value`` with optional header) or YAML.

    YAML forms: ``[[t, v], ...]``, ``{points: [[t, v], ...]}`` or
    ``{t: [...], value: [...]}``. Time must be strictly increasing, values
    finite, at least two rows; otherwise :class:`ParamError` naming the row.
    """
    path = _resolve(file)
    if not path.is_file():
        raise ParamError(key, file, "an existing CSV or YAML waypoint file")
    rows: list[tuple[object, object]] = []
    if path.suffix.lower() in (".yaml", ".yml"):
        from pneu_msgs_py.params.yaml_file import load_yaml

        data = load_yaml(path)
        if isinstance(data, dict) and "points" in data:
            data = data["points"]
        if isinstance(data, dict) and "t" in data and "value" in data:
            rows = list(zip(data["t"], data["value"]))
            if len(data["t"]) != len(data["value"]):
                raise ParamError(key, file, "t and value lists of equal length")
        elif isinstance(data, list):
            for i, row in enumerate(data):
                if not isinstance(row, (list, tuple)) or len(row) != 2:
                    raise ParamError(f"{key}[{i}]", row, "a [t, value] pair")
                rows.append((row[0], row[1]))
        else:
            raise ParamError(
                key, file, "YAML list of [t, value], {points: ...} or {t: [...], value: [...]}"
            )
    else:
        with open(path, encoding="utf-8", newline="") as fh:
            for i, row in enumerate(csv.reader(fh)):
                cells = [c.strip() for c in row if c.strip() != ""]
                if not cells or cells[0].startswith("#"):
                    continue
                if i == 0 and not _is_number(cells[0]):
                    continue  # header
                if len(cells) < 2:
                    raise ParamError(f"{key}[row {i + 1}]", row, "two columns t, value")
                rows.append((cells[0], cells[1]))
    t: list[float] = []
    r: list[float] = []
    for i, (ti, ri) in enumerate(rows):
        for name, val in (("t", ti), ("value", ri)):
            try:
                f = float(val)  # type: ignore[arg-type]
            except (TypeError, ValueError):
                raise ParamError(f"{key}[{i}].{name}", val, "a finite number") from None
            if not math.isfinite(f):
                raise ParamError(f"{key}[{i}].{name}", val, "a finite number (no NaN or inf)")
        tf_, rf_ = float(ti), float(ri)  # type: ignore[arg-type]
        if t and tf_ <= t[-1]:
            raise ParamError(
                f"{key}[{i}].t", tf_, f"strictly increasing time: > {t[-1]:g} s (previous row)"
            )
        if not t and tf_ < 0.0:
            raise ParamError(f"{key}[{i}].t", tf_, "[0, inf) s")
        t.append(tf_)
        r.append(rf_)
    if len(t) < 2:
        raise ParamError(key, file, "at least two waypoints")
    return t, r


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def make_reference(p: ReferenceParams, axis: str, sample_time_s: float = 0.001) -> Reference:
    """Build the reference of ``p`` (paper units) as an SI callable for ``axis``."""
    u = 1.0 / axis_scale(axis)
    if p.kind == "sine":
        f_nyq = 0.5 / sample_time_s
        if not 0.0 < p.frequency_hz < f_nyq:
            raise ParamError(
                "reference.frequency_hz",
                p.frequency_hz,
                f"(0, {f_nyq:g}) Hz (Nyquist at T = {sample_time_s:g} s)",
            )
        return Sine(p.amplitude * u, p.frequency_hz, p.offset * u, p.t0_s)
    if p.kind == "smooth_step":
        if p.duration_s <= 0.0:
            raise ParamError("reference.duration_s", p.duration_s, "(0, inf) s for a smooth_step")
        return SmoothStep(p.offset * u, p.target * u, p.duration_s, p.t0_s)
    if p.kind == "constant":
        return Constant(p.value * u)
    if p.kind == "ramp":
        return Ramp(p.offset * u, p.slope * u, p.duration_s, p.t0_s)
    if p.kind == "waypoints":
        t, r = load_waypoints(p.file)
        return Waypoints(t, [x * u for x in r], p.t0_s)
    raise ParamError(
        "reference.kind", p.kind, "one of sine, smooth_step, constant, ramp, waypoints"
    )
