"""Start values from the excitation's sub-experiments: the mechanical group by equation error.

The output-error fit (:mod:`pneu_control.sysid.fit`) has compensating
valleys: a wrong inertia, Coulomb torque and inlet volume can be traded
against the flow curve, the supply and the leakages, and a start from the
catalogue values may roll into such a valley (issue 21: rotary J_m +49 %,
Q_n −46 %, p_s +56 %). The equations of motion, though, need no replay
and no valve: with the chamber pressures measured, each axis's force or
torque balance is linear in its mechanical parameters, so the turning and
sliding parts of the excitation (the rotary coast-downs and speed ramps,
the linear ramps and pulses) pin them by linear least squares (an
equation-error estimate, Ljung, *System Identification*, 2nd ed., sec. 7.3):

- motor, Eq. 7-9 with Eq. 8's torque:
  J_m ω̇ + M_c + M_v ω = K(θ) (p_m1 − p_m2) while the motor turns
  (ω > :data:`TURNING_RPM`), p_m2 quasi-steady through the exhaust throttle
  (:func:`pneu_sim.physics.replay.exhaust_pressures`); the throttle A_ex is
  the one number the torque is not linear in: a golden-section search over
  it for the smallest equation residual;
- cylinder, Eq. 1-2 with the mass of Table 1:
  A_f sign(v) + c_v v = A_c1 p_c1 − A_c2 p_c2 − A_r p_a − M ẍ while it slides
  faster than :data:`SLIDING_VS` times the base's Stribeck speed v_s (there the
  breakaway bump has died out; with it in the regression the bump and A_f
  trade, and the breakaway came out 17 % high on a nominal cylinder: the
  breakaway is left to the output-error fit, which sees the onsets).

Both sides are low-passed by the same Gaussian (σ :data:`FILTER_S`) before
the regression -- the equation stays exact for the filtered signals and the
derivatives fall on the filter's kernel, not on the sensors' noise; the
measured pressures are de-lagged by their sensor's time constant first.
The pressure sensors' offsets are unknown here (the fit finds them): a few
kPa shift the Coulomb terms by K̄ or A_c times that, a few per cent. These are
start values only: the output-error fit refines every one of them.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from pneu_sim.physics import kernel as k
from pneu_sim.physics import replay as rp

from pneu_control.sysid import model
from pneu_control.sysid.record import Record

__all__ = ["FILTER_S", "SLIDING_MM_S", "SLIDING_VS", "TURNING_RPM", "mechanical_start"]

FILTER_S = 0.015  # Gaussian σ of the equation-error filter (s): well below the motions' times
TURNING_RPM = 60.0  # the motor counts as turning above this (well clear of sticking)
SLIDING_MM_S = 5.0  # the piston counts as sliding above this
SLIDING_VS = 3.0  # ... and the force balance uses it above this many Stribeck speeds v_s
_MIN_SAMPLES = 2000  # fewer usable samples: no start from this group
_RPM = 60.0 / (2.0 * math.pi)


def _gauss(v: np.ndarray, sigma_samples: float) -> np.ndarray:
    half = int(math.ceil(3.0 * sigma_samples))
    w = np.exp(-0.5 * (np.arange(-half, half + 1) / sigma_samples) ** 2)
    return np.convolve(v, w / w.sum(), mode="same")


class _Filtered:
    """One record's samples with the same low-pass on every regressor; ``ok`` where the whole
    filter window is valid data."""

    def __init__(self, rec: Record, axis: str, names: tuple[str, ...]) -> None:
        self.T = rec.period_s
        self.s = FILTER_S / self.T
        ok = rec.valid[axis].copy()
        for n in names:
            ok &= np.isfinite(rec.y[n])
        self.raw_ok = ok
        self.ok = _gauss(ok.astype(float), self.s) > 1.0 - 1e-9
        self.y = {n: np.where(ok, rec.y[n], 0.0) for n in names}

    def f(self, v: np.ndarray) -> np.ndarray:
        return _gauss(np.where(self.raw_ok, v, 0.0), self.s)

    def delagged(self, name: str, tau: float) -> np.ndarray:
        """The pressure before its sensor's first-order lag: p + τ ṗ (ṗ on a short filter)."""
        p = self.y[name]
        return p + tau * np.gradient(_gauss(p, 2.0), self.T)


def _rotary(base, records: list[Record], log: Callable[[str], None]) -> dict[str, float]:
    prm0 = rp.replay_params(base)
    tau = base.sensors.pressure.tau
    data = []
    for rec in records:
        fl = _Filtered(rec, "rotary", ("omega", "theta", "p_m1"))
        om = fl.y["omega"]
        turning = fl.ok & (fl.f((om * _RPM > 0.5 * TURNING_RPM).astype(float)) > 1.0 - 1e-9)
        w_f = fl.f(om)
        m = turning & (w_f * _RPM > TURNING_RPM)
        if m.sum() == 0:
            continue
        K = k.vane_factors(prm0, fl.y["theta"])
        p1 = fl.delagged("p_m1", tau)
        data.append((fl, m, K, p1, _gauss(om, 2.0), w_f, np.gradient(w_f, fl.T)))
    if sum(int(d[1].sum()) for d in data) < _MIN_SAMPLES:
        return {}
    X = np.concatenate([np.column_stack([dw[m], np.ones(m.sum()), w[m] * _RPM]) for _f, m, _K, _p, _ws, w, dw in data])  # fmt: skip
    p_ex = next(p for p in model.AXIS_PARAMS["rotary"] if p.name == "rotary.A_ex")

    def solve(log_a: float) -> tuple[float, np.ndarray]:
        from pneu_msgs_py.params.core import with_updates

        prm = rp.replay_params(with_updates(base, {"rotary.A_ex": math.exp(log_a)}))
        kbar = rp.mean_vane_factor(prm)
        y = []
        for fl, m, K, p1, ws, _w, _dw in data:
            p2 = rp.exhaust_pressures(prm, p1, np.maximum(ws, 0.0), kbar)
            y.append(fl.f(K * (p1 - p2))[m])
        y = np.concatenate(y)
        beta = np.linalg.lstsq(X, y, rcond=None)[0]
        r = y - X @ beta
        return float(r @ r), beta

    a, b = (
        math.log(max(p_ex.lo, base.rotary.A_ex / 8)),
        math.log(min(p_ex.hi, base.rotary.A_ex * 8)),
    )
    g = (math.sqrt(5.0) - 1.0) / 2.0
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = solve(c)[0], solve(d)[0]
    for _ in range(14):  # golden section: the bracket shrinks to 0.2 % of its log width
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = solve(c)[0]
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = solve(d)[0]
    log_a = 0.5 * (a + b)
    _, (J, M_c, M_v) = solve(log_a)
    out = {"rotary.J_m": J, "rotary.M_c": M_c, "rotary.M_v": M_v, "rotary.A_ex": math.exp(log_a)}
    log(
        "  rotary: equation-error start (torque balance over "
        f"{X.shape[0]} turning samples): "
        + ", ".join(f"{n.split('.')[-1]}={v:.4g}" for n, v in out.items())
    )
    return out


def _linear(base, records: list[Record], log: Callable[[str], None]) -> dict[str, float]:
    lin, pa = base.linear, base.ambient.p_a
    tau = base.sensors.pressure.tau
    A_r = lin.A_c1 - lin.A_c2
    X, y = [], []
    for rec in records:
        fl = _Filtered(rec, "linear", ("x", "p_c1", "p_c2"))
        x_f = fl.f(fl.y["x"])
        v_f = np.gradient(x_f, fl.T)
        a_f = np.gradient(v_f, fl.T)
        v = np.gradient(_gauss(fl.y["x"], 5.0), fl.T)  # the speed the friction law reads
        sliding = fl.f((np.abs(v) * 1e3 > 0.5 * SLIDING_MM_S).astype(float)) > 1.0 - 1e-9
        half = 0.5 * lin.L - 2e-3  # away from the end stops (their force is not in Eq. 1)
        fast = np.abs(v_f) > SLIDING_VS * lin.v_s  # past the Stribeck bump: e^-9 of it left
        m = fl.ok & sliding & fast & (np.abs(x_f) < half)
        if not m.any():
            continue
        F = lin.A_c1 * fl.delagged("p_c1", tau) - lin.A_c2 * fl.delagged("p_c2", tau) - A_r * pa
        X.append(np.column_stack([fl.f(np.sign(v))[m], v_f[m]]))
        y.append((fl.f(F) - lin.M * a_f)[m])
    if sum(len(v) for v in y) < _MIN_SAMPLES:
        return {}
    X, y = np.concatenate(X), np.concatenate(y)
    A_f, c_v = np.linalg.lstsq(X, y, rcond=None)[0]
    out = {"linear.A_f": A_f, "linear.c_v": c_v}
    log(
        f"  linear: equation-error start (force balance over {len(y)} sliding samples): "
        + ", ".join(f"{n.split('.')[-1]}={v:.4g}" for n, v in out.items())
    )
    return out


def mechanical_start(
    axis: str, base, records: list[Record], names, log: Callable[[str], None] = print
) -> dict[str, float]:
    """Start values of ``axis``'s mechanical parameters among ``names`` from ``records`` by
    equation error (see the module docstring); each one inside its physical bounds, and none
    where the data have too few turning or sliding samples or an estimate is not physical."""
    found = (_rotary if axis == "rotary" else _linear)(base, records, log)
    out = {}
    for p in model.AXIS_PARAMS[axis]:
        v = found.get(p.name)
        if p.name in names and v is not None and math.isfinite(v) and p.lo < v < p.hi:
            out[p.name] = float(v)
    return out
