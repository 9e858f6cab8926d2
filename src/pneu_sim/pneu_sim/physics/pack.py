"""PlantParams -> the flat float64 parameter vector of :mod:`pneu_sim.physics.kernel`.

Also the derived values the YAML does not hold: the valve's maximum area from its
nominal flow, the spool's exact ZOH matrices, each port's flow curve sampled on the kernel's grid.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from pneu_sim.physics import kernel as k
from pneu_sim.physics.params import PLUMBINGS, LoadParams, PlantParams, ValveParams
from pneu_sim.physics.valve_curve import leak_fade_flow, port_tables

__all__ = ["pack_params", "pack_load", "valve_max_area", "spool_zoh", "nominal_flow_per_area"]


def nominal_flow_per_area(v: ValveParams, C_1: float) -> float:
    """ṁ per m² of opening at the nominal-flow test condition (Eq. 11–12), kg/(s·m²)."""
    m, _, _ = k.iso_flow.py_func(v.p_n_up, v.p_n_down, C_1 / math.sqrt(v.T_n), v.b, v.b_lam)
    return m


def valve_max_area(v: ValveParams, C_1: float) -> float:
    """Full-open area A_max so that Eq. 11 gives the datasheet nominal flow, m².

    ṁ_n = Q_n ρ_ANR at p_n_up → p_n_down (6 → 5 bar gauge), T_n. For the MPYE-5-1/8-LF
    (350 l/min) this is ≈ 8.5 mm² (A·C_d ≈ 7 mm²).
    """
    return v.Q_n * v.rho_n / nominal_flow_per_area(v, C_1)


def _expm(a: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring with a Taylor series (small matrices)."""
    norm = float(np.max(np.sum(np.abs(a), axis=1)))
    s = max(0, math.ceil(math.log2(norm / 0.1))) if norm > 0.1 else 0
    b = a / 2.0**s
    out = np.eye(a.shape[0])
    term = np.eye(a.shape[0])
    for i in range(1, 20):
        term = term @ b / i
        out = out + term
    for _ in range(s):
        out = out @ out
    return out


@functools.lru_cache(maxsize=64)
def spool_zoh(omega_n: float, zeta: float, h: float) -> tuple[float, ...]:
    """Exact ZOH of s'' = ω_n² (u − s) − 2ζω_n s': (φ11, φ12, φ21, φ22, γ1, γ2)."""
    a = np.array([[0.0, 1.0], [-(omega_n**2), -2.0 * zeta * omega_n]])
    bvec = np.array([0.0, omega_n**2])
    phi = _expm(a * h)
    gam = np.linalg.solve(a, (phi - np.eye(2)) @ bvec)
    return (phi[0, 0], phi[0, 1], phi[1, 0], phi[1, 1], gam[0], gam[1])


def _valve_block(v: ValveParams, C_1: float, h: float) -> np.ndarray:
    blk = np.zeros(k.VB_SIZE)
    a_max = valve_max_area(v, C_1)
    blk[k.VB_AMAX] = a_max
    blk[k.VB_ALEAK] = v.leak_fraction * a_max
    blk[k.VB_B] = v.b
    blk[k.VB_BLAM] = v.b_lam
    blk[k.VB_HW] = 0.5 * v.hysteresis
    blk[k.VB_FLAP] = leak_fade_flow(v.flow_table)
    blk[k.VB_PHI11 : k.VB_G2 + 1] = spool_zoh(v.omega_n, v.zeta, h)
    blk[k.VB_TAB4 : k.VB_TAB2], blk[k.VB_TAB2 :] = port_tables(v)
    return blk


def pack_params(p: PlantParams, offsets_unit: np.ndarray | None = None) -> np.ndarray:
    """The kernel's parameter vector. ``offsets_unit``: 3 draws in [−1, 1] scaling the
    pressure sensors' accuracy band into fixed offsets (zeros if None)."""
    prm = np.zeros(k.N_PRM)
    amb, lin, rot, sen = p.ambient, p.linear, p.rotary, p.sensors
    h = p.sim.T / p.sim.n_sub
    prm[k.P_PA] = amb.p_a
    prm[k.P_RT] = amb.R * amb.T_0
    prm[k.P_N] = amb.n_poly
    prm[k.P_C1T] = amb.C_1 / math.sqrt(amb.T_0)
    prm[k.P_PSL] = p.supply.p_s_linear
    prm[k.P_PSR] = p.supply.p_s_rotary
    prm[k.P_AC1] = lin.A_c1
    prm[k.P_AC2] = lin.A_c2
    prm[k.P_AR] = lin.A_r
    prm[k.P_V1D] = lin.V_1d
    prm[k.P_V2D] = lin.V_2d
    prm[k.P_M] = lin.M
    prm[k.P_AF] = lin.A_f
    prm[k.P_FS] = lin.A_f * lin.breakaway_ratio
    prm[k.P_VS] = lin.v_s
    prm[k.P_CV] = lin.c_v
    prm[k.P_L] = lin.L
    prm[k.P_RM] = rot.R_m
    prm[k.P_DM] = rot.d_m
    prm[k.P_LM] = rot.L_m
    prm[k.P_RRM] = rot.r_m
    prm[k.P_NV] = rot.n_vanes
    prm[k.P_J] = rot.J_m
    prm[k.P_MC] = rot.M_c
    prm[k.P_MS] = rot.M_c * rot.static_ratio
    prm[k.P_MV] = rot.M_v_si
    prm[k.P_VM1] = rot.V_m1
    prm[k.P_VM2] = rot.V_m2
    prm[k.P_KEX] = rot.A_ex * amb.C_1 / math.sqrt(amb.T_0)
    prm[k.P_KLK] = rot.k_leak
    ps = sen.pressure
    prm[k.P_PFS] = ps.fs
    prm[k.P_PVFS] = ps.v_fs
    prm[k.P_PSIG] = ps.sigma_v
    off = np.zeros(3) if offsets_unit is None else np.asarray(offsets_unit, dtype=float)
    prm[k.P_POFF : k.P_POFF + 3] = off * ps.accuracy_fs * ps.v_fs
    prm[k.P_PALPHA] = -math.expm1(-h / ps.tau)
    ls = sen.laser
    prm[k.P_XRANGE] = ls.range_m
    prm[k.P_XVFS] = ls.v_fs
    prm[k.P_XSIG] = ls.sigma_m / ls.range_m * ls.v_fs
    prm[k.P_XALPHA] = -math.expm1(-h / ls.tau)
    daq = sen.daq
    prm[k.P_AIRP] = daq.ai_range_pressure
    prm[k.P_AILSBP] = 2.0 * daq.ai_range_pressure / 2**daq.ai_bits
    prm[k.P_AIRX] = daq.ai_range_laser
    prm[k.P_AILSBX] = 2.0 * daq.ai_range_laser / 2**daq.ai_bits
    prm[k.P_AINMAX] = 2**daq.ai_bits - 1
    prm[k.P_AOR] = daq.ao_range
    prm[k.P_AOLSB] = 2.0 * daq.ao_range / 2**daq.ao_bits
    prm[k.P_AONMAX] = 2**daq.ao_bits - 1
    prm[k.P_CPR] = 4 * sen.encoder.ppr
    prm[k.P_T] = p.sim.T
    prm[k.P_NSUB] = p.sim.n_sub
    prm[k.P_H] = h
    prm[k.P_VALVE_L : k.P_VALVE_L + k.VB_SIZE] = _valve_block(p.valve_linear, amb.C_1, h)
    prm[k.P_VALVE_R : k.P_VALVE_R + k.VB_SIZE] = _valve_block(p.valve_rotary, amb.C_1, h)
    prm[k.P_PLUMB] = PLUMBINGS.index(rot.plumbing)
    cp = p.coupling
    prm[k.P_KSEAL] = cp.k_seal
    prm[k.P_SLV] = cp.mu_sleeve / cp.r_sleeve
    pack_load(prm, p.load)
    return prm


def pack_load(prm: np.ndarray, ld: LoadParams) -> None:
    """Write the external loads into ``prm`` in place (Plant.set_load between steps)."""
    prm[k.P_TLC] = ld.T_c
    prm[k.P_TLS] = max(ld.T_bk, ld.T_c)
    prm[k.P_CLD] = ld.c_load
    prm[k.P_JLD] = ld.J_load
    prm[k.P_KSP] = ld.k_spring
    prm[k.P_X0] = ld.x_0
    prm[k.P_FEXT] = ld.F_ext
