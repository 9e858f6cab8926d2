"""The valve's opening from a port's measured mass flow: the twin's flow law (Eq. 11-12) inverted.

Given a chamber's pressure p and the mass flow into it ṁ (from the pressure
and volume measured at a known volume, ṁ = (V ṗ / n + p V̇) / (R T0), Eq. 4),
the port's signed normalised flow f is the one for which the valve's two paths
(:func:`pneu_sim.physics.kernel.port_areas`: supply → port and port → exhaust,
with the centre leak) pass ṁ: a bisection, since ṁ grows with f. Also the
sensitivity ∂ṁ/∂f there: where it is small (the chamber near the supply or the
exhaust pressure) ṁ says little about f.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numba import njit

from pneu_sim.physics import jit_cache
from pneu_sim.physics import kernel as k
from pneu_sim.physics.valve_curve import FLOW_BOUND

__all__ = ["port_flow_from_mass_flow"]


@njit(cache=True)
def _port_mass_flow(prm, base, f, p, p_s):
    a_max = prm[base + k.VB_AMAX]
    a_leak = prm[base + k.VB_ALEAK]
    A_s, A_e = k.port_areas(f, a_max, a_leak, prm[base + k.VB_FLAP])
    C = prm[k.P_C1T]
    b = prm[base + k.VB_B]
    bl = prm[base + k.VB_BLAM]
    return k.iso_flow(p_s, p, A_s * C, b, bl)[0] - k.iso_flow(p, prm[k.P_PA], A_e * C, b, bl)[0]


@njit(cache=True)
def _invert(prm, base, p, mdot, p_s, f_out, sens_out):
    for i in range(p.shape[0]):
        lo = -FLOW_BOUND
        hi = FLOW_BOUND
        for _ in range(48):
            mid = 0.5 * (lo + hi)
            if _port_mass_flow(prm, base, mid, p[i], p_s) < mdot[i]:
                lo = mid
            else:
                hi = mid
        f = 0.5 * (lo + hi)
        f_out[i] = f
        d = 5e-3
        sens_out[i] = (
            _port_mass_flow(prm, base, f + d, p[i], p_s)
            - _port_mass_flow(prm, base, f - d, p[i], p_s)
        ) / (2.0 * d)


def port_flow_from_mass_flow(
    prm: np.ndarray, axis: str, p: np.ndarray, mdot: np.ndarray, p_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """(f, ∂ṁ/∂f) per sample: the signed normalised flow of a port of ``axis``'s valve that
    passes ``mdot`` (kg/s, into the chamber at ``p``, Pa abs) from the supply ``p_s``."""
    base = k.P_VALVE_L if axis == "linear" else k.P_VALVE_R
    pp = np.ascontiguousarray(p, dtype=np.float64)
    mm = np.ascontiguousarray(mdot, dtype=np.float64)
    f = np.empty(pp.shape[0])
    s = np.empty(pp.shape[0])
    _invert(prm, base, pp, mm, float(p_s), f, s)
    return f, s


for _name, _fn in (("_port_mass_flow", _port_mass_flow), ("_invert", _invert)):
    jit_cache.refresh_cache(_fn, (Path(__file__), Path(k.__file__)), f"flow_inverse.{_name}")
