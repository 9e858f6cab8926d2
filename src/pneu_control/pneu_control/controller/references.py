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

import csv
import io
import math
from pathlib import Path
from typing import Protocol

from pneu_msgs_py.contract.units import DEG_PER_RAD, MM_PER_M, RPM_PER_RAD_S
from pneu_msgs_py.lifecycle.duration import MAX_DURATION_S
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.records import Record, RecordType, kernel

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
    "REFERENCE",
    "reference_at",
]

_TWO_PI = 2.0 * math.pi


def axis_scale(axis: str, rotary_control: str = "speed") -> float:
    """Paper units per SI unit: 1000 (mm per m) linear, 9.549 (rpm per rad/s) rotary speed,
    57.30 (degrees per rad) rotary angle (``rotary_control: angle``)."""
    if axis == "linear":
        return MM_PER_M
    if axis == "rotary":
        return DEG_PER_RAD if rotary_control == "angle" else RPM_PER_RAD_S
    raise ParamError("axis", axis, "one of linear, rotary")


class Reference(Protocol):
    def __call__(self, t: float) -> tuple[float, float, float]: ...


# Every kind is one record type (named fields; a kind uses its own) and one kernel
# (DESIGN §12): the classes below call it; the compiled loop calls it too.
REF_SINE, REF_SMOOTH_STEP, REF_CONSTANT, REF_RAMP, REF_WAYPOINTS = 0, 1, 2, 3, 4
REFERENCE = RecordType(
    "ReferenceConstants",
    [
        ("kind", "i"),
        ("a", "f", 0.0), ("w", "f", 0.0), ("c", "f", 0.0),  # sine
        ("r0", "f", 0.0), ("dr", "f", 0.0), ("d", "f", 0.0), ("k", "f", 0.0),  # steps, ramps
        ("v", "f", 0.0),  # constant
        ("t0", "f", 0.0),
        ("n", "i"),  # waypoints: knots in the table
    ],
)  # fmt: skip
NO_KNOTS: list[list[float]] = [[0.0], [0.0], [0.0], [0.0]]


@kernel
def sine_ref(c, t):
    """offset + amplitude·sin(ω (t − t0)), ω = 2π f."""
    tau = t - c.t0
    if tau <= 0.0:
        return c.c, 0.0, 0.0
    a = c.a
    w = c.w
    sn = math.sin(w * tau)
    cs = math.cos(w * tau)
    return c.c + a * sn, a * w * cs, -a * w * w * sn


@kernel
def smooth_step_ref(c, t):
    """Eq. 38 generalised: r0 → r0 + Δr over d s."""
    tau = t - c.t0
    if tau <= 0.0:
        return c.r0, 0.0, 0.0
    d = c.d
    if tau >= d:
        return c.r0 + c.dr, 0.0, 0.0
    ph = _TWO_PI * tau / d
    g = c.dr / d
    # Eq. 38: x = 30t/π − (60/π²) sin(πt/2) with D = 4, Δr = 120/π
    return (
        c.r0 + c.dr * (tau / d - math.sin(ph) / _TWO_PI),
        g * (1.0 - math.cos(ph)),
        g * (_TWO_PI / d) * math.sin(ph),
    )


@kernel
def ramp_ref(c, t):
    """r0 + k (t − t0), held after d s (d = 0: endless)."""
    tau = t - c.t0
    if tau <= 0.0:
        return c.r0, 0.0, 0.0
    if c.d > 0.0 and tau >= c.d:
        return c.r0 + c.k * c.d, 0.0, 0.0
    return c.r0 + c.k * tau, c.k, 0.0


@kernel
def waypoints_ref(knots, n, t):
    """Quintic Hermite through n knots: rows (t, r, v, a) of ``knots``."""
    ts = knots[0]
    rs = knots[1]
    if t <= ts[0]:
        return rs[0], 0.0, 0.0
    if t >= ts[n - 1]:
        return rs[n - 1], 0.0, 0.0
    lo = 0  # bisect.bisect_right(ts, t)
    hi = n
    while lo < hi:
        mid = (lo + hi) // 2
        if t < ts[mid]:
            hi = mid
        else:
            lo = mid + 1
    i = lo - 1
    h = ts[i + 1] - ts[i]
    s = (t - ts[i]) / h
    p0 = rs[i]
    p1 = rs[i + 1]
    vs = knots[2]
    acc = knots[3]
    v0 = vs[i] * h
    v1 = vs[i + 1] * h
    a0 = acc[i] * h * h
    a1 = acc[i + 1] * h * h
    s2 = s * s
    s3 = s * s * s
    s4 = s3 * s
    s5 = s3 * s2
    # quintic Hermite basis and its derivatives in s
    h00 = 1.0 - 10.0 * s3 + 15.0 * s4 - 6.0 * s5
    h10 = s - 6.0 * s3 + 8.0 * s4 - 3.0 * s5
    h20 = 0.5 * (s2 - 3.0 * s3 + 3.0 * s4 - s5)
    h01 = 10.0 * s3 - 15.0 * s4 + 6.0 * s5
    h11 = -4.0 * s3 + 7.0 * s4 - 3.0 * s5
    h21 = 0.5 * (s3 - 2.0 * s4 + s5)
    d00 = -30.0 * s2 + 60.0 * s3 - 30.0 * s4
    d10 = 1.0 - 18.0 * s2 + 32.0 * s3 - 15.0 * s4
    d20 = 0.5 * (2.0 * s - 9.0 * s2 + 12.0 * s3 - 5.0 * s4)
    d11 = -12.0 * s2 + 28.0 * s3 - 15.0 * s4
    d21 = 0.5 * (3.0 * s2 - 8.0 * s3 + 5.0 * s4)
    e00 = -60.0 * s + 180.0 * s2 - 120.0 * s3
    e10 = -36.0 * s + 96.0 * s2 - 60.0 * s3
    e20 = 0.5 * (2.0 - 18.0 * s + 36.0 * s2 - 20.0 * s3)
    e11 = -24.0 * s + 84.0 * s2 - 60.0 * s3
    e21 = 0.5 * (6.0 * s - 24.0 * s2 + 20.0 * s3)
    r = h00 * p0 + h10 * v0 + h20 * a0 + h01 * p1 + h11 * v1 + h21 * a1
    rd = d00 * p0 + d10 * v0 + d20 * a0 - d00 * p1 + d11 * v1 + d21 * a1
    rdd = e00 * p0 + e10 * v0 + e20 * a0 - e00 * p1 + e11 * v1 + e21 * a1
    return r, rd / h, rdd / (h * h)


@kernel
def reference_at(c, knots, t):
    """(r, ṙ, r̈) in SI at t s for any kind (the compiled loop's entry)."""
    kind = c.kind
    if kind == REF_CONSTANT:
        return c.v, 0.0, 0.0
    if kind == REF_SINE:
        return sine_ref(c, t)
    if kind == REF_SMOOTH_STEP:
        return smooth_step_ref(c, t)
    if kind == REF_RAMP:
        return ramp_ref(c, t)
    return waypoints_ref(knots, c.n, t)


class _Kernelled:
    """A reference held as a :data:`REFERENCE` record (``rc``) and its ``knots`` table."""

    knots: list[list[float]] = NO_KNOTS
    rc: Record

    def __call__(self, t: float) -> tuple[float, float, float]:
        return reference_at(self.rc, self.knots, t)


class Sine(_Kernelled):
    """offset + amplitude·sin(2π f (t − t0)) (SI)."""

    def __init__(self, amplitude: float, frequency_hz: float, offset: float, t0: float = 0.0):
        self.a, self.w, self.c, self.t0 = amplitude, _TWO_PI * frequency_hz, offset, t0
        self.rc = REFERENCE.new(kind=REF_SINE, a=self.a, w=self.w, c=offset, t0=t0)

    def __call__(self, t: float) -> tuple[float, float, float]:
        return sine_ref(self.rc, t)


class SmoothStep(_Kernelled):
    """Eq. 38 generalised: start → target over ``duration`` s (SI)."""

    def __init__(self, start: float, target: float, duration: float, t0: float = 0.0):
        self.r0, self.dr, self.d, self.t0 = start, target - start, duration, t0
        self.rc = REFERENCE.new(kind=REF_SMOOTH_STEP, r0=start, dr=self.dr, d=duration, t0=t0)

    def __call__(self, t: float) -> tuple[float, float, float]:
        return smooth_step_ref(self.rc, t)


class Constant(_Kernelled):
    def __init__(self, value: float):
        self.v = value
        self.rc = REFERENCE.new(kind=REF_CONSTANT, v=value)

    def __call__(self, t: float) -> tuple[float, float, float]:
        return self.v, 0.0, 0.0


class Ramp(_Kernelled):
    """start + slope·(t − t0), held after ``duration`` (0 = endless)."""

    def __init__(self, start: float, slope: float, duration: float = 0.0, t0: float = 0.0):
        self.r0, self.k, self.d, self.t0 = start, slope, duration, t0
        self.rc = REFERENCE.new(kind=REF_RAMP, r0=start, k=slope, d=duration, t0=t0)

    def __call__(self, t: float) -> tuple[float, float, float]:
        return ramp_ref(self.rc, t)


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


class Waypoints(_Kernelled):
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
        self.knots = [self.t, self.r, v, a]
        self.rc = REFERENCE.new(kind=REF_WAYPOINTS, n=n)

    def __call__(self, t: float) -> tuple[float, float, float]:
        return waypoints_ref(self.knots, self.rc.n, t)


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


def load_waypoints(
    file: str, key: str = "reference.file", min_step_s: float = 0.001
) -> tuple[list[float], list[float]]:
    """Read (t, value) rows from CSV (``t,value`` with optional header) or YAML.

    YAML forms: ``[[t, v], ...]``, ``{points: [[t, v], ...]}`` or
    ``{t: [...], value: [...]}``. Times in [0, 600] s (the duration cap), each at
    least ``min_step_s`` (one sample period) after the previous one, values finite,
    at least two rows; otherwise :class:`ParamError` naming the row.
    """
    path = _resolve(file)
    if not path.is_file():
        raise ParamError(key, file, "an existing CSV or YAML waypoint file")
    rows: list[tuple[object, object]] = []
    if path.suffix.lower() in (".yaml", ".yml", ".json"):  # JSON is YAML (1.2)
        from pneu_msgs_py.params.yaml_file import load_yaml

        shapes = "a YAML list of [t, value], {points: [...]} or {t: [...], value: [...]}"
        data = load_yaml(path)
        if isinstance(data, dict):
            keys = sorted(map(str, data))
            if keys not in (["points"], ["t", "value"]):  # another key would be ignored
                raise ParamError(key, file, f"{shapes} (it has keys {', '.join(keys)})")
            if "points" in data:
                data = data["points"]
            elif not all(isinstance(data[k], list) for k in ("t", "value")):
                raise ParamError(key, file, f"{shapes}: t and value lists")
            elif len(data["t"]) != len(data["value"]):
                raise ParamError(key, file, "t and value lists of equal length")
            else:
                rows = list(zip(data["t"], data["value"]))
        if isinstance(data, list):
            for i, row in enumerate(data):
                if not isinstance(row, (list, tuple)) or len(row) != 2:
                    raise ParamError(f"{key}[{i}]", row, "a [t, value] pair")
                rows.append((row[0], row[1]))
        elif not rows:
            raise ParamError(key, file, shapes)
    else:
        from pneu_msgs_py.params.inputs import UnreadableInput, read_input

        try:
            raw = read_input(path)  # a regular file of bounded size, remembered as an input
            text = raw.decode("utf-8-sig")  # a BOM is not part of the first cell
        except UnreadableInput as err:
            raise ParamError(
                key, file, f"a readable CSV or YAML waypoint file ({err.problem})"
            ) from None
        except UnicodeDecodeError as err:
            raise ParamError(key, file, f"a UTF-8 CSV file (byte {err.start} is not)") from None
        header = True  # the first row that is not a comment may name the columns
        for i, row in enumerate(csv.reader(io.StringIO(text, newline=""))):
            cells = [c.strip() for c in row]
            while cells and not cells[-1]:  # a trailing separator (0,5,) adds no column
                cells.pop()
            if not cells or cells[0].startswith("#"):
                continue
            if header and not _is_number(cells[0]):
                header = False
                continue
            header = False
            if len(cells) != 2 or not all(cells):
                raise ParamError(f"{key}[row {i + 1}]", row, "two columns t, value")
            rows.append((cells[0], cells[1]))
    return _checked_rows(rows, key, file, min_step_s)


def _checked_rows(
    rows: list[tuple[object, object]], key: str, file: str, min_step_s: float
) -> tuple[list[float], list[float]]:
    """The waypoint rows as numbers: times increasing by a sample period, in the cap."""
    t: list[float] = []
    r: list[float] = []
    for i, (ti, ri) in enumerate(rows):
        tf_, rf_ = (_number(f"{key}[{i}].{n}", v) for n, v in (("t", ti), ("value", ri)))
        if t and tf_ < t[-1] + min_step_s:
            raise ParamError(
                f"{key}[{i}].t",
                tf_,
                f"strictly increasing time, at least one sample period after the previous row: "
                f">= {t[-1] + min_step_s:g} s",
            )
        if not 0.0 <= tf_ <= MAX_DURATION_S:
            raise ParamError(
                f"{key}[{i}].t", tf_, f"[0, {MAX_DURATION_S:g}] s (the duration cap of every run)"
            )
        t.append(tf_)
        r.append(rf_)
    if len(t) < 2:
        raise ParamError(key, file, "at least two waypoints")
    return t, r


def _number(key: str, value: object) -> float:
    """A finite number as typed (a CSV cell is read like a YAML value: ``010`` is 10,
    ``1:00`` and ``1_000`` are not numbers)."""
    from pneu_msgs_py.params.yaml_file import read_scalar

    v = read_scalar(value) if isinstance(value, str) else value
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ParamError(key, value, "a finite number")
    if not math.isfinite(v):
        raise ParamError(key, value, "a finite number (no NaN or inf)")
    return float(v)


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def make_reference(
    p: ReferenceParams, axis: str, sample_time_s: float = 0.001, rotary_control: str = "speed"
) -> Reference:
    """Build the reference of ``p`` (paper units: mm, rpm or degrees) as an SI callable for ``axis``."""
    u = 1.0 / axis_scale(axis, rotary_control)
    if p.kind == "sine":
        f_nyq = 0.5 / sample_time_s
        f_min = 1.0 / MAX_DURATION_S
        if not f_min <= p.frequency_hz < f_nyq:
            raise ParamError(
                "reference.frequency_hz",
                p.frequency_hz,
                f"[{f_min:.6g}, {f_nyq:g}) Hz (one period in the longest run, "
                f"{MAX_DURATION_S:g} s; Nyquist at T = {sample_time_s:g} s)",
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
        t, r = load_waypoints(p.file, min_step_s=sample_time_s)
        return Waypoints(t, [x * u for x in r], p.t0_s)
    raise ParamError(
        "reference.kind", p.kind, "one of sine, smooth_step, constant, ramp, waypoints"
    )
