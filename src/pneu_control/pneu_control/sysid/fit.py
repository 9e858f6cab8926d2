"""Output-error fit of the twin to bags: least squares over the uncertain parameters, with statistics.

Per axis (the cylinder and the motor share only the polytropic index, fitted
on the cylinder first), the residual is the difference between each recorded
signal and the twin replayed on the recorded voltages
(:mod:`pneu_control.sysid.shooting`), signal by signal divided by the
signal's spread, so the cost is the sum over signals of (1 − fit)² with fit
as ``pneu validate`` reports it. ``scipy.optimize.least_squares`` (trust
region reflective, within the physical bounds of
:mod:`pneu_control.sysid.model`) minimises it; the Jacobian is by finite
differences of relative size ``diff_step``.

Besides the plant parameters each bag gets its pressure sensors' offsets
(nuisance parameters: the Huba 511's ±0.5 % FS), reported but not written
to the plant file.

Statistics at the optimum (linearised, Ljung's *System Identification*
§9.3): cov = s² (JᵀJ)⁻¹ with s² = Σr²/(m − p), inflated by the residuals'
integrated autocorrelation time (they are far from white: one 1 ms sample
is not one independent observation); 95 % intervals ±1.96σ; the
correlation matrix of the estimates, and every pair with |ρ| > 0.95 is
reported as not separately identifiable from these bags.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from pneu_control.sysid import model, shooting
from pneu_control.sysid.record import AXIS_SIGNALS, Record

__all__ = ["AxisFit", "FitOptions", "fit_axis"]

_OFFSET_WIDTH = 5e3  # Pa: z = 1 is one Huba accuracy band
_OFFSET_BOUND = 3e4  # Pa
_PRESSURE_OF = {"linear": ("p_c1", "p_c2"), "rotary": ("p_m1",)}
CORRELATED = 0.95


@dataclass(frozen=True)
class FitOptions:
    segment_s: dict[str, float] = field(default_factory=lambda: {"linear": 1.0, "rotary": 2.0})
    decimate: int = 4  # residual every 4th sample
    diff_step: float = 3e-3
    max_nfev: int = 40
    ftol: float = 1e-3  # stop when a step lowers the cost by less than 0.1 %
    xtol: float = 1e-4
    params: tuple[str, ...] | None = None  # names to fit (default: every parameter of the axis)


@dataclass
class AxisFit:
    axis: str
    names: list[str]
    units: list[str]
    base: list[float]
    value: list[float]
    sigma: list[float]  # 1 σ, in the parameter's unit
    corr: np.ndarray
    offsets: dict[str, dict[str, float]]  # record name -> signal -> Pa
    offsets_sigma: dict[str, dict[str, float]]
    cost_start: float
    cost: float
    nfev: int
    wall_s: float
    inflation: float
    n_residuals: int
    status: str
    plant: object = None  # the fitted PlantParams

    def ci95(self, i: int) -> float:
        return 1.96 * self.sigma[i]

    def rel_ci95(self, i: int) -> float:
        """95 % half-width relative to the value (log parameters; a dead band: in V)."""
        v = self.value[i]
        return self.ci95(i) / abs(v) if v else math.inf

    def correlated_pairs(self, limit: float = CORRELATED) -> list[tuple[str, str, float]]:
        out = []
        n = len(self.names)
        for i in range(n):
            for j in range(i + 1, n):
                r = float(self.corr[i, j])
                if abs(r) > limit:
                    out.append((self.names[i], self.names[j], r))
        return out


def _autocorr_time(r: np.ndarray, max_lag: int = 200) -> float:
    """Integrated autocorrelation time 1 + 2 Σ ρ(k) (truncated at the first ρ ≤ 0)."""
    r = r - r.mean()
    v = float(np.dot(r, r))
    if v <= 0.0 or len(r) < 4:
        return 1.0
    tau = 1.0
    for k in range(1, min(max_lag, len(r) // 4)):
        rho = float(np.dot(r[:-k], r[k:])) / v
        if rho <= 0.0:
            break
        tau += 2.0 * rho
    return tau


def fit_axis(
    axis: str,
    base,
    records: list[Record],
    options: FitOptions | None = None,
    log: Callable[[str], None] = print,
) -> AxisFit:
    """Fit ``axis``'s parameters of ``base`` (PlantParams) to ``records``."""
    from scipy.optimize import least_squares

    options = options or FitOptions()

    params = model.AXIS_PARAMS[axis]
    if options.params is not None:
        params = tuple(p for p in params if p.name in options.params)
    p0 = [model.base_value(base, p) for p in params]
    bounds = []
    for p, b in zip(params, p0):
        lo, hi = p.lo, p.hi
        if p.name.endswith("." + model.DEAD_BAND):
            table = getattr(base, p.name.split(".")[0]).du_table
            lo, hi = max(lo, -0.95 * table[1]), min(hi, 5.0 - table[-1])
        bounds.append((p.to_z(lo, b), p.to_z(hi, b)))
    segs = [shooting.segments_of(r, axis, options.segment_s[axis]) for r in records]
    used = [(r, s) for r, s in zip(records, segs) if len(s)]
    if not used:
        raise ValueError(f"{axis}: no usable data in the bags (axis not excited or all invalid)")
    signals = AXIS_SIGNALS[axis]
    pnames = _PRESSURE_OF[axis]
    # signal spreads over all records (fixed: the residual weights)
    scale = {}
    for name in signals:
        vals = np.concatenate([r.y[name][s.index] for r, s in used])
        scale[name] = float(np.std(vals)) or 1.0
    n_p = len(params)
    n_off = len(pnames) * len(used)
    dec = options.decimate
    meas = [{n: r.y[n][s.index][::dec] for n in signals} for r, s in used]

    def unpack(z: np.ndarray):
        vals = [p.from_z(float(zi), b) for p, zi, b in zip(params, z[:n_p], p0)]
        offs = []
        for j in range(len(used)):
            zo = z[n_p + j * len(pnames) : n_p + (j + 1) * len(pnames)]
            offs.append({name: float(v) * _OFFSET_WIDTH for name, v in zip(pnames, zo)})
        return vals, offs

    def residuals(z: np.ndarray) -> np.ndarray:
        vals, offs = unpack(z)
        plant = model.apply(base, params, vals)
        parts = []
        for (r, s), m, off in zip(used, meas, offs):
            sim = shooting.simulate(plant, r, s, off, axis)
            for name in signals:
                parts.append((m[name] - sim[name][::dec]) / scale[name])
        return np.concatenate(parts)

    z0 = np.zeros(n_p + n_off)
    lo = np.array([b[0] for b in bounds] + [-_OFFSET_BOUND / _OFFSET_WIDTH] * n_off)
    hi = np.array([b[1] for b in bounds] + [_OFFSET_BOUND / _OFFSET_WIDTH] * n_off)
    t0 = time.perf_counter()
    r0 = residuals(z0)
    cost0 = 0.5 * float(r0 @ r0)
    n_eval = [0]

    def tracked(z):
        n_eval[0] += 1
        r = residuals(z)
        c = 0.5 * float(r @ r)
        if n_eval[0] % (len(z) + 1) == 1:
            vals, _ = unpack(z)
            shown = ", ".join(f"{p.name.split('.')[-1]}={v:.4g}" for p, v in zip(params, vals))
            log(
                f"  {axis} eval {n_eval[0]:4d}  cost {c:.5g}  ({time.perf_counter() - t0:.0f} s)  {shown}"
            )
        return r

    res = least_squares(
        tracked,
        z0,
        bounds=(lo, hi),
        method="trf",
        x_scale=1.0,
        diff_step=options.diff_step,
        max_nfev=options.max_nfev,
        xtol=options.xtol,
        ftol=options.ftol,
    )
    wall = time.perf_counter() - t0
    J = res.jac
    r = res.fun
    m_res, p_all = J.shape
    s2 = float(r @ r) / max(m_res - p_all, 1)
    # residual autocorrelation (per record and signal, along time)
    taus = []
    k = 0
    for m in meas:
        for name in signals:
            n = m[name].size
            taus.append(_autocorr_time(r[k : k + n]))
            k += n
    infl = float(np.median(taus)) if taus else 1.0
    JtJ = J.T @ J
    cov_z = np.linalg.pinv(JtJ) * s2 * infl
    sd_z = np.sqrt(np.maximum(np.diag(cov_z), 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov_z / np.outer(sd_z, sd_z)
    corr = np.nan_to_num(corr)
    vals, offs = unpack(res.x)
    sigma = []
    for i, (p, v) in enumerate(zip(params, vals)):
        # σ of p from σ of z (first order): log: dp = p w dz; lin: dp = w dz
        sigma.append(abs(v) * p.width * sd_z[i] if p.transform == "log" else p.width * sd_z[i])
    offsets, offsets_sigma = {}, {}
    for j, ((rec, _s), off) in enumerate(zip(used, offs)):
        offsets[rec.name] = off
        offsets_sigma[rec.name] = {
            name: float(sd_z[n_p + j * len(pnames) + q] * _OFFSET_WIDTH)
            for q, name in enumerate(pnames)
        }
    plant = model.apply(base, params, vals)
    return AxisFit(
        axis=axis,
        names=[p.name for p in params],
        units=[p.unit for p in params],
        base=p0,
        value=vals,
        sigma=sigma,
        corr=corr[:n_p, :n_p],
        offsets=offsets,
        offsets_sigma=offsets_sigma,
        cost_start=cost0,
        cost=float(res.cost),
        nfev=int(res.nfev),
        wall_s=wall,
        inflation=infl,
        n_residuals=m_res,
        status=str(res.message),
        plant=plant,
    )
