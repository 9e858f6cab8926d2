"""Residual diagnostics of a replayed twin: is what is left noise, or a model that does not fit?

For one axis, the residuals r = y − ŷ of its signals (the twin replayed in
segments started from the measured state, :mod:`pneu_control.sysid.shooting`;
pressure offsets already taken off) are examined three ways:

whiteness
    the Ljung-Box portmanteau test (Ljung & Box 1978) on the residual at
    10 ms spacing, lags 10..100 ms, within segments only, and the ratio of
    the sensor noise σ (from the quiet segments) to the residual's RMS. A
    perfect twin leaves white sensor noise; an output-error residual at 1 kHz
    is coloured by any model error, so this says how far from noise, not
    whether the model is wrong.
bias by operating region
    where the plant was, per sample (:data:`REGIONS`): the valve voltage
    held, the measured speed, on the cylinder its position and pressure
    difference, the motor's inlet pressure, the signal's own rate of change;
    and the residual's level alone. Each region is cut in sextiles over this
    data; the residual is fitted by least squares on, per sextile, an
    indicator (an offset while there) and the time spent there since the
    segment's start (a growth while there: an integrating signal
    accumulates a flow or force error), plus the region's value and its
    integral since the start (a smooth trend, e.g. a viscous or lag term).
    The sum of squares that fit explains, T, less its mean under the null
    (E₀[T]), is the *share* of the residual's sum of squares the operating
    point explains, and in fit points
    E = 100·(‖r‖ − √(‖r‖² − (T − E₀[T]))) / ‖y − ȳ‖ -- what the fit %
    would gain without that bias (the validation's fit is
    100·(1 − ‖r‖/‖y − ȳ‖)). The null: every replayed segment's residual
    multiplied by a random sign (:data:`FLIPS` draws, seed 0): a residual
    that is zero-mean noise or a random start error, independent from one
    segment to the next, is unchanged in law; a bias tied to the operating
    point is not (Good, *Permutation Tests*, 2nd ed., on sign-flip tests).
per segment
    per segment of the excitation design (or 5 s windows without one) the
    residual's RMS and mean per signal, as ``fit % at this level``:
    100·(1 − RMS_segment / σ_y), the fit the whole bag would have if every
    segment looked like this one.

Structural-mismatch warning: some signal's bias by some operating region
is significant (sign-flip p below :data:`ALPHA` over the number of tests,
Bonferroni), explains at least :data:`MIN_SHARE` of the residual and costs
at least :data:`MIN_FIT_POINTS` fit points. A
perturbed twin of the model's own family, identified, leaves no such bias
(its residual is the start errors of the segments and noise); a plant of
another form does, in the region where the forms differ.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pneu_control.sysid.record import AXIS_SIGNALS, Record
from pneu_control.sysid.shooting import Segments

__all__ = [
    "ALPHA",
    "AxisDiagnostics",
    "FLIPS",
    "MIN_FIT_POINTS",
    "MIN_SHARE",
    "Piece",
    "diagnose",
    "ljung_box",
]

FLIPS = 4999  # sign-flip draws: p down to 1/5000
ALPHA = 0.01  # family-wise level of the operating-region tests
# A mismatch is called where the operating point explains at least MIN_SHARE of the
# residual's sum of squares (beyond chance), significantly, and that costs at least
# MIN_FIT_POINTS of the fit. Measured on one quick excitation (docs/calibration.md, the
# residual diagnostics): in-model twins, identified, leave at most 9 % explained and
# 0.09 fit points where significant; plants of another form (a valve curve, a Stribeck
# width, a pressure or a laser lag) and a wrong optimum 46-90 % and 0.29-25 fit points.
# Estimated between the two; a smaller effect is not worth a warning.
MIN_SHARE = 0.15
MIN_FIT_POINTS = 0.2
N_BINS = 6
LB_SPACING = 10  # samples between the Ljung-Box residuals (10 ms at 1 kHz)
LB_LAGS = 10
_V_HALF = 10  # samples either side for the measured speed (a centred difference)
_UNIT = {"x": ("mm", 1e3), "p_c1": ("kPa", 1e-3), "p_c2": ("kPa", 1e-3), "p_m1": ("kPa", 1e-3), "omega": ("rpm", 60.0 / (2 * math.pi))}  # fmt: skip
_RPM = 60.0 / (2 * math.pi)
_REGION_UNIT = {"valve": ("V", 1.0), "speed": ("mm/s", 1e3), "position": ("mm", 1e3), "pressure difference": ("kPa", 1e-3), "rotary speed": ("rpm", _RPM), "inlet pressure": ("kPa", 1e-3), "rate": ("/s", 1.0)}  # fmt: skip
_RATE_UNIT = {"x": ("mm/s", 1e3), "p_c1": ("kPa/s", 1e-3), "p_c2": ("kPa/s", 1e-3), "p_m1": ("kPa/s", 1e-3), "omega": ("rpm/s", _RPM)}  # fmt: skip
# where the plant was; "rate": the signal's own rate of change (a sensor lag or a missing
# dynamic shows as a residual that follows it)
# "level": the residual's mean alone (one bin: what the sensor offsets, bounded, leave)
REGIONS = {
    "linear": ("level", "valve", "speed", "position", "pressure difference", "rate"),
    "rotary": ("level", "valve", "rotary speed", "inlet pressure", "rate"),
}


@dataclass
class Piece:
    """One record's replay of one axis: the segments and the simulated sensor values at
    :attr:`Segments.index` (offsets added, as the sensors read them)."""

    rec: Record
    seg: Segments
    yhat: dict[str, np.ndarray]


@dataclass
class Region:
    """One bin of an operating region: its range (SI), samples, mean residual (SI), the mean's
    standard error from the segments' spread, and the residual's mean growth there (SI/s)."""

    lo: float
    hi: float
    n: int
    mean: float
    se: float
    growth: float


@dataclass
class RegionTest:
    """Bias of one signal by one operating region: the bins, the fit points it explains, p, and
    whether its growth (not its offset) explains most."""

    region: str
    bins: list[Region]
    fit_points: float
    p: float
    by_growth: bool = False
    share: float = 0.0  # of the residual's sum of squares, less the null's mean


@dataclass
class SignalDiagnostics:
    """Whiteness and operating-region bias of one signal's residual."""

    signal: str
    n: int
    rms: float  # SI
    spread: float  # ‖y − ȳ‖/√n, SI
    noise_sigma: float | None
    lb_q: float
    lb_p: float
    regions: list[RegionTest] = field(default_factory=list)

    @property
    def noise_share(self) -> float | None:
        """Sensor noise σ / residual RMS (1: the residual is the noise)."""
        if self.noise_sigma is None or self.rms <= 0.0:
            return None
        return self.noise_sigma / self.rms


@dataclass
class SegmentStats:
    """One design segment (or window): label, kind, times, samples and per signal the RMS and
    mean residual (SI) and the fit % at that level."""

    label: str
    kind: str
    t0_s: float
    t1_s: float
    n: int
    rms: dict[str, float]
    mean: dict[str, float]
    fit_level: dict[str, float]


@dataclass
class AxisDiagnostics:
    """The diagnostics of one axis, and the structural-mismatch warning (empty: none)."""

    axis: str
    signals: dict[str, SignalDiagnostics]
    segments: list[SegmentStats]
    tests: int
    evidence: list[tuple[str, str, float, float]]  # (signal, region, fit points, p)
    warning: str = ""

    def worst_segments(self, k: int = 3) -> list[SegmentStats]:
        """The ``k`` segments with the lowest fit at their level (worst signal)."""
        ranked = [s for s in self.segments if s.fit_level]
        return sorted(ranked, key=lambda s: min(s.fit_level.values()))[:k]

    def lines(self, warning: bool = True) -> list[str]:
        """Markdown: one table of the signals (whiteness, largest operating-region bias), the
        worst segments, then (``warning``) the warning if any."""
        out = [
            f"{self.axis}: residuals | RMS | noise σ / RMS | Ljung-Box p (white?) | "
            "most explained by an operating region (share, fit points, p) |",
            "|---|---|---|---|---|",
        ]
        for s in self.signals.values():
            unit, k = _UNIT[s.signal]
            ns = "—" if s.noise_share is None else f"{s.noise_share:.2f}"
            top = max(s.regions, key=lambda r: r.share, default=None)
            big = (
                "—"
                if top is None
                else f"{top.region}: {100 * top.share:.0f} %, {top.fit_points:.2f}, p {_p(top.p)}"
            )
            white = "yes" if s.lb_p >= ALPHA else "no"
            out.append(
                f"| {s.signal} | {s.rms * k:.3g} {unit} | {ns} | {_p(s.lb_p)} ({white}) | {big} |"
            )
        worst = self.worst_segments()
        if worst:
            out.append(
                f"{self.axis}: worst segments (fit % at their residual level): "
                + "; ".join(
                    f"{s.label} ({s.t0_s:.1f}-{s.t1_s:.1f} s): "
                    + ", ".join(f"{n} {v:.0f}" for n, v in s.fit_level.items())
                    for s in worst
                )
            )
        if warning and self.warning:
            out.append(self.warning)
        return out

    def to_dict(self) -> dict[str, Any]:
        """The diagnostics as plain data (SI units)."""
        return {
            "axis": self.axis,
            "warning": self.warning,
            "structural_mismatch": bool(self.warning),
            "tests": self.tests,
            "evidence": [
                {"signal": s, "region": r, "fit_points": e, "p": p} for s, r, e, p in self.evidence
            ],
            "signals": {
                name: {
                    "n": s.n,
                    "rms": s.rms,
                    "spread": s.spread,
                    "noise_sigma": s.noise_sigma,
                    "noise_share": s.noise_share,
                    "ljung_box_q": s.lb_q,
                    "ljung_box_p": s.lb_p,
                    "ljung_box_lags_s": [LB_SPACING * k for k in range(1, LB_LAGS + 1)],
                    "regions": [
                        {
                            "region": t.region,
                            "fit_points": t.fit_points,
                            "p": t.p,
                            "bins": [vars(b) for b in t.bins],
                        }
                        for t in s.regions
                    ],
                }
                for name, s in self.signals.items()
            },
            "segments": [vars(s) for s in self.segments],
        }


def _p(p: float) -> str:
    return f"< {1.0 / (FLIPS + 1):.0e}" if p <= 1.0 / (FLIPS + 1) else f"{p:.2g}"


def ljung_box(parts: list[np.ndarray], lags: int = LB_LAGS) -> tuple[float, float]:
    """Ljung-Box Q over ``lags`` of the pooled autocorrelation of ``parts`` (products within a
    part only, the pooled mean taken off) and its χ²(lags) p-value."""
    from scipy.stats import chi2

    parts = [p for p in parts if len(p) > lags + 1]
    if not parts:
        return 0.0, 1.0
    mean = float(np.mean(np.concatenate(parts)))  # one mean: a part's own would bias ρ low
    parts = [p - mean for p in parts]
    n = sum(len(p) for p in parts)
    var = sum(float(p @ p) for p in parts)
    if n <= lags + 1 or var <= 0.0:
        return 0.0, 1.0
    q = 0.0
    for k in range(1, lags + 1):
        rho = sum(float(p[:-k] @ p[k:]) for p in parts) / var
        q += rho * rho / (n - k)
    q *= n * (n + 2)
    return q, float(chi2.sf(q, lags))


def _quantum_sigma(y: np.ndarray) -> float | None:
    """σ of a quantised signal's rounding (q/√12, q its smallest step), e.g. the encoder speed
    (one count per period); None without two distinct values."""
    v = np.unique(y)
    d = np.diff(v)
    d = d[d > 1e-9 * max(float(np.max(np.abs(v))), 1.0)] if len(v) > 1 else d
    return float(np.min(d)) / math.sqrt(12.0) if len(d) else None


def _rate(y: np.ndarray, T: float) -> np.ndarray:
    """Centred-difference rate over ±_V_HALF samples (NaN at the ends): it leaves out the centre
    sample, so its noise is not the residual's."""
    v = np.full(len(y), math.nan)
    h = _V_HALF
    if len(y) > 2 * h:
        v[h:-h] = (y[2 * h :] - y[: -2 * h]) / (2 * h * T)
    return v


def _smooth(y: np.ndarray, half: int = 5) -> np.ndarray:
    """Centred moving mean over ±``half`` samples (NaN where any is missing)."""
    k = np.ones(2 * half + 1) / (2 * half + 1)
    return np.convolve(y, k, mode="same")


def _regions(axis: str, rec: Record) -> dict[str, np.ndarray]:
    """Per sample the operating point (see :data:`REGIONS`): the voltage held over the period
    before it, the measured speed (a centred difference of x; the encoder's, smoothed), the
    position, the measured pressures (smoothed)."""
    T = rec.period_s
    y = rec.y
    u = np.concatenate(([rec.u[axis][0]], rec.u[axis][:-1]))
    if axis == "linear":
        return {
            "valve": u,
            "speed": _rate(y["x"], T),
            "position": y["x"],
            "pressure difference": _smooth(y["p_c1"] - y["p_c2"]),
        }
    return {"valve": u, "rotary speed": _smooth(y["omega"]), "inlet pressure": _smooth(y["p_m1"])}


def _bins(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bin index per sample from sextiles of ``values`` (ties merged), and the edges."""
    ok = np.isfinite(values)
    edges = np.unique(np.quantile(values[ok], np.linspace(0.0, 1.0, N_BINS + 1)))
    if len(edges) < 2:
        edges = np.array([values[ok].min(), values[ok].max()])
    idx = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, len(edges) - 2)
    idx[~ok] = -1
    return idx, edges


def _columns(
    b: np.ndarray, n_bins: int, values: np.ndarray, starts: np.ndarray, T: float
) -> np.ndarray:
    """The regressors of a region with bins ``b`` (-1: left out) of ``values``: per bin an
    indicator (the residual's offset while there) and the time spent there since the segment's
    start (its growth while there: an integrating signal accumulates a flow or force error),
    then the value itself, scaled, and its integral since the start (a smooth trend, e.g. a
    viscous or lag term, that bins catch only in steps); segment ``i`` starts at row
    ``starts[i]``. ``n_bins`` 0: the level (a constant, the time since the start)."""
    n = len(b)
    row = np.arange(n)
    first = starts[np.searchsorted(starts, row, side="right") - 1]
    if n_bins == 0:
        return np.column_stack([np.ones(n), T * (row - first + 1)])
    m = b >= 0
    ind = np.zeros((n, n_bins + 1))
    ind[row[m], b[m]] = 1.0
    v = np.where(m, values, 0.0)
    scale = float(np.std(v[m])) if m.any() else 0.0
    ind[:, n_bins] = (v - float(np.median(v[m]))) / scale * m if scale > 0 else 0.0
    cs = np.cumsum(ind, axis=0)
    before = np.where((first > 0)[:, None], cs[np.maximum(first - 1, 0)], 0.0)
    grow = T * (cs - before)
    return np.hstack([ind[:, :n_bins], grow[:, :n_bins], ind[:, n_bins:], grow[:, n_bins:]])


def _ls_test(
    r: np.ndarray, X: np.ndarray, starts: np.ndarray, signs: np.ndarray
) -> tuple[float, float, float]:
    """T = ‖P r‖², the residual's sum of squares the least-squares fit on ``X`` explains, its
    sign-flip null's mean (one sign per segment, a row of ``signs`` per draw) and p."""
    G = np.add.reduceat(X * r[:, None], starts, axis=0)  # X_jᵀ r_j per segment j
    A = np.linalg.pinv(X.T @ X)
    g = G.sum(axis=0)
    t_obs = float(g @ A @ g)
    gs = signs[:, : len(starts)] @ G
    t_null = np.einsum("fk,kl,fl->f", gs, A, gs)
    p = (1.0 + float(np.sum(t_null >= t_obs))) / (1.0 + len(t_null))
    return t_obs, float(np.mean(t_null)), p


def _ls(r: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, float]:
    """Least squares of ``r`` on ``X``: the coefficients and the sum of squares explained."""
    g = X.T @ r
    beta = np.linalg.pinv(X.T @ X) @ g
    return beta, float(g @ beta)


def _region_bins(
    edges: np.ndarray, b: np.ndarray, r: np.ndarray, seg_id: np.ndarray, X: np.ndarray, k: int
) -> tuple[list[Region], bool]:
    """Per bin: its range, samples, mean residual (the offsets-only fit on the indicators) with
    its standard error (from the spread of the segments' means in it), and its growth (the
    growth-only fit on the times spent there, SI/s); and whether the growth explains more."""
    kk = max(k, 1)
    mean, t_off = _ls(r, X[:, :kk])
    growth, t_grow = _ls(r, X[:, kk : 2 * kk])
    out = []
    for j in range(max(len(edges) - 1, 1)):
        m = b == j
        if not m.any():
            continue
        ids, inv = np.unique(seg_id[m], return_inverse=True)
        seg_means = np.bincount(inv, weights=r[m]) / np.bincount(inv)
        se = float(np.std(seg_means) / math.sqrt(len(ids))) if len(ids) > 1 else math.nan
        lo, hi = (float(edges[j]), float(edges[j + 1])) if k else (-math.inf, math.inf)
        out.append(Region(lo, hi, int(m.sum()), float(mean[j]), se, float(growth[j])))
    return out, t_grow > t_off


def _segment_windows(rec: Record, axis: str) -> list[tuple[str, str, float, float]]:
    """(label, kind, t0, t1) of each design segment, or of 5 s windows without a design."""
    d = rec.designs.get(axis)
    if d is not None:
        out = []
        for s in d.segments:
            kind = s.kind if s.kind != "closed" else f"closed {s.ref.get('kind', '')}".strip()
            out.append((s.label, kind, s.t0_s, s.t1_s))
        return out
    t_end = rec.n * rec.period_s
    starts = np.arange(0.0, t_end, 5.0)
    return [
        (f"{a:.0f}-{min(a + 5.0, t_end):.0f} s", "window", a, min(a + 5.0, t_end)) for a in starts
    ]


def _pooled(axis: str, pieces: list[Piece]):
    """The pieces' samples pooled: per signal the residual and the measurement, the segment of
    each sample, the operating point per region (per signal for its rate), the residual at
    LB_SPACING within each segment (Ljung-Box)."""
    names = AXIS_SIGNALS[axis]
    res, meas, lb = ({n: [] for n in names} for _ in range(3))
    seg_ids, ops = [], {k: [] for k in REGIONS[axis] if k not in ("rate", "level")}
    rates = {n: [] for n in names}
    offset = 0
    for pc in pieces:
        idx = pc.seg.index
        seg_ids.append(np.repeat(np.arange(len(pc.seg)), pc.seg.lengths) + offset)
        offset += len(pc.seg)
        here = _regions(axis, pc.rec)
        for k in ops:
            ops[k].append(here[k][idx])
        bounds = np.concatenate(([0], np.cumsum(pc.seg.lengths)))
        for n in names:
            r = pc.rec.y[n][idx] - pc.yhat[n]
            res[n].append(r)
            meas[n].append(pc.rec.y[n][idx])
            rates[n].append(_rate(pc.rec.y[n], pc.rec.period_s)[idx])
            lb[n].extend(r[a:b:LB_SPACING] for a, b in itertools.pairwise(bounds))
    cat = {n: (np.concatenate(res[n]), np.concatenate(meas[n])) for n in names}
    ops_cat = {k: np.concatenate(v) for k, v in ops.items()}
    rate_cat = {n: np.concatenate(v) for n, v in rates.items()}
    return cat, np.concatenate(seg_ids), offset, ops_cat, rate_cat, lb


def diagnose(
    axis: str, pieces: list[Piece], noise: dict[str, float] | None = None
) -> AxisDiagnostics:
    """The diagnostics of ``axis`` over ``pieces`` (see the module docstring); ``noise``: sensor
    σ per signal (SI) where known."""
    noise = noise or {}
    names = AXIS_SIGNALS[axis]
    cat, seg_id, n_seg, ops, rates, lb = _pooled(axis, pieces)
    n_seg = max(n_seg, 1)
    starts = np.flatnonzero(np.concatenate(([True], seg_id[1:] != seg_id[:-1])))
    T = pieces[0].rec.period_s if pieces else 1e-3
    signs = np.random.default_rng(0).choice([-1.0, 1.0], size=(FLIPS, n_seg))
    binned = {k: _bins(v) for k, v in ops.items()}
    signals: dict[str, SignalDiagnostics] = {}
    tests = len(names) * len(REGIONS[axis])
    evidence = []
    for n in names:
        r, y = cat[n]
        ok = np.isfinite(r) & np.isfinite(y)
        r = np.where(ok, r, 0.0)
        norm = float(np.linalg.norm(y[ok] - y[ok].mean())) if ok.any() else 0.0
        q, p_lb = ljung_box([p[np.isfinite(p)] for p in lb[n]])
        r2 = float(r @ r)
        rms = float(np.sqrt(np.mean(r[ok] ** 2))) if ok.any() else 0.0
        spread = norm / math.sqrt(max(int(ok.sum()), 1))
        sigma = noise.get(n, _quantum_sigma(y[ok]) if n == "omega" else None)
        sd = SignalDiagnostics(n, int(ok.sum()), rms, spread, sigma, q, p_lb)
        for region in REGIONS[axis]:
            if region == "level":
                b, edges = np.zeros(len(r), dtype=np.int64), np.array([-math.inf, math.inf])
                vals = np.zeros(len(r))
            else:
                vals = rates[n] if region == "rate" else ops[region]
                b, edges = binned[region] if region != "rate" else _bins(vals)
            b = np.where(ok & np.isfinite(vals), b, -1)
            k = 0 if region == "level" else len(edges) - 1
            X = _columns(b, k, vals, starts, T) * ok[:, None]
            t_obs, t0, p = _ls_test(r, X, starts, signs)
            gain = max(t_obs - t0, 0.0)
            e = 100.0 * (math.sqrt(r2) - math.sqrt(max(r2 - gain, 0.0))) / norm if norm else 0.0
            bins, by_growth = _region_bins(edges, b, r, seg_id, X, k)
            test = RegionTest(region, bins, e, p, by_growth, gain / r2 if r2 else 0.0)
            sd.regions.append(test)
            if p < ALPHA / tests and test.share >= MIN_SHARE and e >= MIN_FIT_POINTS:
                evidence.append((n, region, e, p))
        signals[n] = sd
    seg_rows = [row for pc in pieces for row in _per_segment(axis, pc, signals)]
    evidence.sort(key=lambda ev: -ev[2])
    diag = AxisDiagnostics(axis, signals, seg_rows, tests, evidence)
    if evidence:
        diag.warning = _warning(axis, evidence, signals)
    return diag


def _per_segment(axis: str, pc: Piece, signals: dict[str, SignalDiagnostics]) -> list[SegmentStats]:
    t = pc.rec.t[pc.seg.index]
    rows = []
    for label, kind, t0, t1 in _segment_windows(pc.rec, axis):
        m = (t >= t0) & (t < t1)
        if m.sum() < 10:
            continue
        rms, mean, level = {}, {}, {}
        for n, sd in signals.items():
            r = pc.rec.y[n][pc.seg.index][m] - pc.yhat[n][m]
            r = r[np.isfinite(r)]
            if not len(r):
                continue
            rms[n] = float(np.sqrt(np.mean(r**2)))
            mean[n] = float(np.mean(r))
            level[n] = 100.0 * (1.0 - rms[n] / sd.spread) if sd.spread > 0 else math.nan
        rows.append(SegmentStats(label, kind, float(t0), float(t1), int(m.sum()), rms, mean, level))
    return rows


def _describe(sd: SignalDiagnostics, region: str) -> str:
    """Where the bias of ``sd`` by ``region`` is: overall, or its lowest and highest bins (as
    an offset, or as a growth from each restart where that explains most)."""
    test = next(t for t in sd.regions if t.region == region)
    su, sk = _UNIT[sd.signal]
    if region == "level":
        b = test.bins[0]
        if test.by_growth:
            return f"{sd.signal} drifting {b.growth * sk:+.3g} {su}/s from each restart"
        return f"{sd.signal} off by {b.mean * sk:+.3g} {su} throughout"
    ru, rk = _RATE_UNIT[sd.signal] if region == "rate" else _REGION_UNIT[region]
    name = f"{sd.signal} rate" if region == "rate" else region
    what = (lambda x: x.growth) if test.by_growth else (lambda x: x.mean)
    ends = sorted(test.bins, key=what)
    ends = [ends[0], ends[-1]] if len(ends) > 1 else ends
    verb, per = ("drifting", "/s") if test.by_growth else ("off by", "")
    return f"{sd.signal} {verb} " + ", ".join(
        f"{what(x) * sk:+.3g} {su}{per} at {name} {x.lo * rk:.3g}..{x.hi * rk:.3g} {ru}"
        for x in ends
    )


def _warning(axis: str, evidence, signals) -> str:
    s, region, e, p = evidence[0]
    test = next(t for t in signals[s].regions if t.region == region)
    more = f"; {len(evidence) - 1} more signal/region pair(s)" if len(evidence) > 1 else ""
    by = "overall" if region == "level" else f"by {region}"
    return (
        f"warning: structural mismatch on the {axis} axis: the residuals follow the operating "
        f"point, not noise ({_describe(signals[s], region)}: {100 * test.share:.0f} % of the "
        f"residual {by}, {e:.1f} fit points, p {_p(p)}{more}) -- the twin does not explain "
        "this plant (an effect its model lacks, or a wrong optimum): identified values may "
        "stand in for it (docs/calibration.md)"
    )
