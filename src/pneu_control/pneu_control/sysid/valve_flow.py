"""The cylinder valve's curve measured directly: each chamber's mass flow at known volume, inverted.

The cylinder's chambers are flow meters: with the piston's position measured,
each chamber's volume is known (Table 1's areas and dead volumes), and its
mass balance (Eq. 4) gives the flow through its port,
ṁ = (V ṗ / n + p V̇) / (R T0), from the measured pressure and position
(derivatives by a local line over :data:`WINDOW` samples). The twin's flow
law inverted at the measured pressure (:mod:`pneu_sim.physics.flow_inverse`)
turns each sample into the port's signed normalised flow at the valve's
opening then (the spool model over the recorded voltages). Per 50 mV of
opening, the median over the samples where the flow is sensitive to the
opening (the chamber away from the supply and exhaust pressures) -- and a
monotone (pool-adjacent-violators) fit across them -- is a direct estimate
of the curve: the start of the output-error
curve stage, from every segment where the valve moved air at known volume
(the pulses from rest and their blocked decays above all).

Only the cylinder: the motor's inlet flow also feeds its swept volume and
vane leakage, which are among what is fitted.
"""

from __future__ import annotations

import numpy as np
from pneu_sim.physics import kernel as pk
from pneu_sim.physics import replay as rp
from pneu_sim.physics.flow_inverse import port_flow_from_mass_flow

from pneu_control.sysid.record import Record

__all__ = ["WINDOW", "estimate_curve", "isotonic"]

WINDOW = 15  # samples of the local line giving ṗ and ẋ (15 ms)
_SENSITIVE = 0.15  # of the full-open choked ∂ṁ/∂f: below it a sample says little of f
_SIGN = {"4": 1.0, "2": -1.0}


def _line_fit(y: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """(centred mean, slope per s) of ``y`` over :data:`WINDOW` samples (NaN near gaps)."""
    h = WINDOW // 2
    j = np.arange(-h, h + 1, dtype=float)
    mean = np.convolve(y, np.full(WINDOW, 1.0 / WINDOW), mode="same")
    slope = np.convolve(y, (j / (j @ j))[::-1], mode="same") / T
    bad = np.convolve(~np.isfinite(y), np.ones(WINDOW), mode="same") > 0
    mean[bad] = np.nan
    slope[bad] = np.nan
    return mean, slope


def _samples(plant, rec: Record, offsets: dict[str, float]):
    """Per sample: opening y (V), and per port (g = σ f, ∂ṁ/∂f) from the chamber balances."""
    lin, amb = plant.linear, plant.ambient
    prm = rp.replay_params(plant)
    y = rp.spool_trajectory(prm, "linear", rec.u["linear"])[:, 2]
    T = rec.period_s
    x, xd = _line_fit(rec.y["x"], T)
    RT, n, half = amb.R * amb.T_0, amb.n_poly, 0.5 * lin.L
    out = {}
    for port, name, area, vd, sgn in (
        ("4", "p_c1", lin.A_c1, lin.V_1d, 1.0),
        ("2", "p_c2", lin.A_c2, lin.V_2d, -1.0),
    ):
        p, pd = _line_fit(rec.y[name] - offsets.get(name, 0.0), T)
        V = vd + area * (half + sgn * x)
        mdot = (V * pd / n + p * sgn * area * xd) / RT
        ok = np.isfinite(mdot) & np.isfinite(p) & rec.valid["linear"]
        f = np.full(rec.n, np.nan)
        s = np.zeros(rec.n)
        f[ok], s[ok] = port_flow_from_mass_flow(
            prm, "linear", p[ok], mdot[ok], plant.supply.p_s_linear
        )
        out[port] = (_SIGN[port] * f, s)
    full = prm[pk.P_VALVE_L + pk.VB_AMAX] * prm[pk.P_C1T] * plant.supply.p_s_linear * 0.8
    return y, out, _SENSITIVE * full


def isotonic(g: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted least-squares non-decreasing fit (pool adjacent violators)."""
    blocks: list[list[float]] = []  # [value, weight, count]
    for gi, wi in zip(g.tolist(), w.tolist()):
        blocks.append([gi, wi, 1])
        while len(blocks) > 1 and blocks[-2][0] > blocks[-1][0]:
            v2, w2, c2 = blocks.pop()
            v1, w1, c1 = blocks.pop()
            blocks.append([(v1 * w1 + v2 * w2) / (w1 + w2), w1 + w2, c1 + c2])
    return np.concatenate([np.full(c, v) for v, _w, c in blocks])


GRID_V = 0.05  # V: the estimate's bins
MIN_BIN = 30  # sensitive samples for a bin's median


def estimate_curve(
    plant, records: list[Record], offsets: dict[str, dict[str, float]]
) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per port: (u every :data:`GRID_V` over 0-10 V, g there, samples behind each) -- the
    monotone fit over the bins with at least :data:`MIN_BIN` sensitive samples (NaN at the
    others). ``offsets``: record path -> pressure signal -> sensor offset (Pa)."""
    u_grid = np.round(np.arange(0.0, 10.0 + 1e-9, GRID_V), 2)
    edges = np.concatenate(([-np.inf], 0.5 * (u_grid[1:] + u_grid[:-1]), [np.inf]))
    acc: dict[str, list[list[np.ndarray]]] = {p: [[] for _ in u_grid] for p in ("4", "2")}
    for rec in records:
        y, ports, s_min = _samples(plant, rec, offsets.get(rec.path, {}))
        bins = np.digitize(y, edges) - 1
        for port, (g, s) in ports.items():
            use = np.isfinite(g) & (s >= s_min)
            for j in np.unique(bins[use]):
                acc[port][j].append(g[use & (bins == j)])
    out = {}
    for port, lists in acc.items():
        vals = [np.concatenate(v) if v else np.zeros(0) for v in lists]
        cnt = np.array([len(v) for v in vals])
        med = np.array([float(np.median(v)) if len(v) else np.nan for v in vals])
        ok = cnt >= MIN_BIN
        g = np.full(len(u_grid), np.nan)
        if ok.any():
            g[ok] = isotonic(med[ok], cnt[ok].astype(float))
        out[port] = (u_grid, g, cnt)
    return out
