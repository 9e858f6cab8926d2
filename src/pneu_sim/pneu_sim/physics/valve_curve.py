"""A proportional valve's flow-vs-voltage characteristic, per port: the catalogue's, or its own.

The MPYE is a 5/3 valve: port 4 and port 2 each connect to the supply or to
the exhaust, the other way round for u above and below the null. A port's
curve f(u) is its *signed* normalised flow (the open area over the full-open
area A_max that the nominal flow Q_n gives): + supply → port, − port →
exhaust. Port 4's curve is non-decreasing in u, port 2's non-increasing.

- The catalogue curve (``ValveParams.du_table``/``flow_table``, Festo's chart)
  is symmetric: f_4(u) = table(u − 5 V) above 5 V, −table(5 V − u) below, and
  f_2(u) = −f_4(u).
- A valve's own curve (``ValveParams.u_curve``, ``flow_4``, ``flow_2``; what
  ``pneu identify`` measures) may have a dead band of its own, a null offset,
  a different gain on either side or either port, and any monotone shape.

The twin's kernel samples each port's curve on a 10 mV grid over 0-10 V
(:func:`port_tables`, packed by :mod:`pneu_sim.physics.pack`; read by
:func:`pneu_sim.physics.kernel.valve_areas`): one representation for the
nominal twin, perturbed twins and identified ones.

|f| is bounded by :data:`FLOW_BOUND` = 1.25 of the catalogue's full-open flow:
Festo's ±10 % nominal-flow tolerance, plus 15 % for the ISO 6358 discharge law
(Eq. 12) being a fit (estimated); anything beyond is another valve size (the
MPYE-5-1/8-HF is 2×).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "FLOW_BOUND",
    "GRID_DV",
    "GRID_N",
    "catalogue_curve",
    "check_curve",
    "grid",
    "leak_fade_flow",
    "port_curves",
    "port_tables",
]

FLOW_BOUND = 1.25  # |f| / full-open catalogue flow (see the module docstring)
GRID_DV = 0.01  # V: the kernel's sampling of the curves
GRID_N = 1001  # 0 .. 10 V
U_NULL = 5.0  # V: the catalogue's null


def grid() -> np.ndarray:
    """The kernel's voltage grid, 0 .. 10 V every :data:`GRID_DV` (V)."""
    return np.arange(GRID_N) * GRID_DV


def catalogue_curve(du_table, flow_table) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, f_4, f_2) of the symmetric catalogue chart mirrored about 5 V (u increasing)."""
    du = np.asarray(du_table, dtype=float)
    fl = np.asarray(flow_table, dtype=float)
    u = np.concatenate((U_NULL - du[:0:-1], U_NULL + du))
    f4 = np.concatenate((-fl[:0:-1], fl))
    return u, f4, -f4


def port_curves(v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, f_4, f_2) of ``v`` (:class:`~pneu_sim.physics.params.ValveParams`): its own
    curve when it has one, else the catalogue's."""
    if len(v.u_curve):
        return (
            np.asarray(v.u_curve, dtype=float),
            np.asarray(v.flow_4, dtype=float),
            np.asarray(v.flow_2, dtype=float),
        )
    return catalogue_curve(v.du_table, v.flow_table)


def leak_fade_flow(flow_table) -> float:
    """The normalised flow over which the closing path's centre leakage fades out: the
    catalogue's first step (1 % at 0.36 V: the leak of the land that closes is gone once the
    opening land passes it; with the catalogue curve, a fade over its first 0.36 V)."""
    return float(next(f for f in flow_table if f > 0.0))


def port_tables(v) -> tuple[np.ndarray, np.ndarray]:
    """Each port's curve sampled on :func:`grid` (held flat beyond the breakpoints)."""
    u, f4, f2 = port_curves(v)
    g = grid()
    return np.interp(g, u, f4), np.interp(g, u, f2)


def check_curve(u_curve, flow_4, flow_2) -> tuple[str, object, str] | None:
    """None if (u_curve, flow_4, flow_2) is a valid own curve (or all empty), else the
    refusal (field, value, allowed)."""
    n = len(u_curve)
    if n == 0 and not len(flow_4) and not len(flow_2):
        return None
    # numpy's comparisons are Python's on floats (NaN compares False either way); a fit
    # checks a curve per Jacobian column
    if n < 2 or np.any(np.diff(np.asarray(u_curve, dtype=float)) <= 0.0):
        return (
            "u_curve",
            list(u_curve),
            "empty (the catalogue curve) or >= 2 voltages strictly increasing",
        )
    if u_curve[0] < 0.0 or u_curve[-1] > 10.0:
        return ("u_curve", list(u_curve), "voltages in [0, 10] V")
    for name, f, sign in (("flow_4", flow_4, 1.0), ("flow_2", flow_2, -1.0)):
        if len(f) != n:
            return (name, list(f), f"{n} values, one per u_curve entry")
        fa = np.asarray(f, dtype=float)
        if np.any(np.abs(fa) > FLOW_BOUND):
            return (name, list(f), f"values in [-{FLOW_BOUND:g}, {FLOW_BOUND:g}]")
        if np.any(sign * np.diff(fa) < 0.0):
            word = "non-decreasing" if sign > 0 else "non-increasing"
            return (name, list(f), f"{word} in u (port {name[-1]})")
    return None
