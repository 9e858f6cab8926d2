"""A :class:`~pneu_control.experiment.runner.RunSpec` -> the compiled loop's flat arrays.

Every constant is read from the Python object the runner builds (the algorithm,
the reference, the TD, the supervisor's thresholds, the sensor scaling), never
derived a second time, so both paths start from the same floats. The initial
controller state is the fresh algorithm's attributes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from pneu_msgs_py.contract.samples import AXES

from pneu_control.algorithms import make_algorithm
from pneu_control.controller.references import (
    Constant,
    Ramp,
    Sine,
    SmoothStep,
    Waypoints,
    axis_scale,
    make_reference,
)
from pneu_control.fastloop import layout as L
from pneu_control.observers.td import TrackingDifferentiator

__all__ = ["Packed", "pack_algorithm", "pack_reference", "pack_spec", "unsupported"]


@dataclass
class Packed:
    """The arrays :func:`pneu_control.fastloop.loop.closed_loop` takes (besides the plant's)."""

    active: np.ndarray  # int64[2]
    cp: np.ndarray  # float64[2, N_CP]
    ci: np.ndarray  # int64[2, N_CI]
    cs: np.ndarray  # float64[2, N_CS]
    wp: np.ndarray  # float64[2, 4, n]
    vt: np.ndarray  # float64[2, 2, n]
    sup_on: bool
    sp: np.ndarray  # float64[N_SP]
    si: np.ndarray  # int64[N_SI]


def unsupported(spec: Any) -> str | None:
    """Why the compiled loop cannot run ``spec`` (None: it can, with the same results)."""
    if spec.faults:
        return "injected faults (spec.faults) are not compiled"
    for axis in spec.axes:
        d = spec.controllers[axis].transport_delay_samples
        if d + 1 > L.MAX_HIST:
            return f"{axis}.transport_delay_samples = {d} > {L.MAX_HIST - 1}"
    return None


def pack_reference(ref: Any, cp: np.ndarray, ci: np.ndarray) -> list[list[float]]:
    """Fill the reference slots; returns the waypoint rows (t, r, v, a) or []."""
    if isinstance(ref, Sine):
        ci[L.CI_REF_KIND] = L.REF_SINE
        cp[L.CP_REF0 : L.CP_REF3 + 1] = (ref.a, ref.w, ref.c, ref.t0)
    elif isinstance(ref, SmoothStep):
        ci[L.CI_REF_KIND] = L.REF_SMOOTH_STEP
        cp[L.CP_REF0 : L.CP_REF3 + 1] = (ref.r0, ref.dr, ref.d, ref.t0)
    elif isinstance(ref, Constant):
        ci[L.CI_REF_KIND] = L.REF_CONSTANT
        cp[L.CP_REF0] = ref.v
    elif isinstance(ref, Ramp):
        ci[L.CI_REF_KIND] = L.REF_RAMP
        cp[L.CP_REF0 : L.CP_REF3 + 1] = (ref.r0, ref.k, ref.d, ref.t0)
    elif isinstance(ref, Waypoints):
        ci[L.CI_REF_KIND] = L.REF_WAYPOINTS
        ci[L.CI_NWP] = len(ref.t)
        return [ref.t, ref.r, ref.v, ref.a]
    else:  # a new reference kind must be mirrored in fastloop/reference.py first
        raise TypeError(f"reference {type(ref).__name__} has no compiled mirror")
    return []


def pack_algorithm(alg: Any, cp: np.ndarray, ci: np.ndarray) -> list[list[float]]:
    """Fill the algorithm's constants and options; returns the valve table rows or []."""
    name = alg.name
    ci[L.CI_ALG] = L.ALG_CODES[name]
    ci[L.CI_USES_TD] = alg.uses_td
    ci[L.CI_USES_THETA] = alg.uses_theta
    if name == "pid":
        for slot, attr in (
            (L.PID_T, "T"), (L.PID_KP, "kp"), (L.PID_KI, "ki"), (L.PID_KD, "kd"),
            (L.PID_AD, "a_d"), (L.PID_AY, "a_y"), (L.PID_KB, "kb"), (L.PID_LO, "lo"),
            (L.PID_HI, "hi"),
        ):  # fmt: skip
            cp[slot] = getattr(alg, attr)
        ci[L.CI_PID_ON_ERROR] = alg.on_error
        ci[L.CI_PID_AW] = {
            "conditional": L.AW_CONDITIONAL,
            "back_calculation": L.AW_BACK_CALCULATION,
            "none": L.AW_NONE,
        }[alg.aw]
        return []
    if name == "ladrc":
        for slot, attr in (
            (L.LA_T, "T"), (L.LA_T2H, "T2h"), (L.LA_KP, "kp"), (L.LA_KD, "kd"), (L.LA_B0, "b0"),
            (L.LA_FF, "ff"), (L.LA_L1, "l1"), (L.LA_L2, "l2"), (L.LA_L3, "l3"), (L.LA_LO, "lo"),
            (L.LA_HI, "hi"), (L.LA_TAU, "tau"), (L.LA_UN, "u_n"),
        ):  # fmt: skip
            cp[slot] = getattr(alg, attr)
        ci[L.CI_LA_DC] = alg.dc
        return []
    if name == "eso_smc":
        for slot, attr in (
            (L.SM_T, "T"), (L.SM_T2H, "T2h"), (L.SM_C1, "c1"), (L.SM_C2, "c2"), (L.SM_B0, "b0"),
            (L.SM_EPS, "eps"), (L.SM_DELTA, "delta"), (L.SM_K, "k"), (L.SM_L1, "l1"),
            (L.SM_L2, "l2"), (L.SM_L3, "l3"), (L.SM_FS, "fs"), (L.SM_MC, "M_c"), (L.SM_MV, "M_v"),
            (L.SM_FV, "fv"), (L.SM_FC, "fc"), (L.SM_INVWS, "inv_ws"), (L.SM_LO, "lo"),
            (L.SM_HI, "hi"), (L.SM_TAU, "tau"), (L.SM_UN, "u_n"),
        ):  # fmt: skip
            cp[slot] = getattr(alg, attr)
        cp[L.SM_TWO] = 2.0  # the exponent of cosh(x) ** 2, at run time (see algorithms.py)
        ci[L.CI_SM_AW] = alg.aw
        ci[L.CI_SM_DC] = alg.dc
        ci[L.CI_SM_FRIC] = alg.fric
        ci[L.CI_SM_ANGLE] = alg.angle
        return []
    # eso_smc_plus
    for slot, attr in (
        (L.PL_T, "T"), (L.PL_T2H, "T2h"), (L.PL_T3S, "T3s"), (L.PL_C1, "c1"), (L.PL_C2, "c2"),
        (L.PL_B0, "b0"), (L.PL_EPS, "eps"), (L.PL_DELTA, "delta"), (L.PL_K, "k"),
        (L.PL_AC1, "A_c1"), (L.PL_AC2, "A_c2"), (L.PL_F0, "F_0"), (L.PL_MK, "M_k"),
        (L.PL_INVMK, "inv_M_k"), (L.PL_AF, "A_f"), (L.PL_CVK, "c_v_k"), (L.PL_INVVS, "inv_vs"),
        (L.PL_KF, "k_F"), (L.PL_INVBF, "inv_bF"), (L.PL_NA1S, "nA1s"), (L.PL_NA2S, "nA2s"),
        (L.PL_V10, "V1_0"), (L.PL_V20, "V2_0"), (L.PL_BF, "b_F"), (L.PL_UN, "u_n"),
        (L.PL_LO, "lo"), (L.PL_HI, "hi"), (L.PL_VLO, "v_lo"), (L.PL_VHI, "v_hi"),
        (L.PL_TAU, "tau"),
    ):  # fmt: skip
        cp[slot] = getattr(alg, attr)
    if alg.angle:
        cp[L.PL_L4A : L.PL_L4D + 1] = alg.l4s
    else:
        cp[L.PL_L1 : L.PL_L3 + 1] = (alg.l1, alg.l2, alg.l3)
    ci[L.CI_PL_ANGLE] = alg.angle
    ci[L.CI_PL_ANGLE_INPUTS] = alg.angle_inputs
    ci[L.CI_PL_LIN_ID] = alg.lin_id
    ci[L.CI_PL_FORCE] = alg.force
    ci[L.CI_PL_FFW] = alg.ffw
    ci[L.CI_PL_DC] = alg.dc
    if alg.lin_id:
        return []
    v = alg.valve  # ValveCurve
    cp[L.PL_G], cp[L.PL_INVG], cp[L.PL_DUMAX], cp[L.PL_VMAX] = v.g, v.inv_g, v.du_max, v.v_max
    ci[L.CI_NVT] = len(v.du)
    return [v.du, v.fl]


_STATE = (  # cs slot <- algorithm attribute (the fresh object's value; absent: NaN)
    (L.CS_Z1, "z1"), (L.CS_Z2, "z2"), (L.CS_Z3, "z3"), (L.CS_Z4, "z4"), (L.CS_S, "s"),
    (L.CS_U_RAW, "u_raw"), (L.CS_INTEGRAL, "integral"), (L.CS_PID_D, "d"),
    (L.CS_PID_YF, "y_f"), (L.CS_PID_RDOT, "r_dot"), (L.CS_U_IN, "u_in"), (L.CS_F_K, "f_k"),
    (L.CS_PL_THR, "th_r"), (L.CS_PL_WRP, "w_r_prev"), (L.CS_PL_VIN, "v_in"),
    (L.CS_PL_FP, "F_p"), (L.CS_PL_AIN, "a_in"), (L.CS_PL_FDP, "F_d_prev"), (L.CS_PL_UFF, "u_ff"),
)  # fmt: skip


def _table(rows_per_axis: list[list[list[float]]], n_rows: int) -> np.ndarray:
    width = max([1] + [len(r[0]) for r in rows_per_axis if r])
    out = np.zeros((2, n_rows, width))
    for a, rows in enumerate(rows_per_axis):
        for i, row in enumerate(rows):
            out[a, i, : len(row)] = row
    return out


def _supervisor(sup: Any, scaling: Any, sp: np.ndarray, si: np.ndarray) -> None:
    th = sup.thresholds()
    p = sup.params
    sp[L.SP_X_HI], sp[L.SP_X_LO], sp[L.SP_X_ABS] = th["x_hi"], th["x_lo"], th["x_abs_max"]
    pm = th["p_max"]
    sp[L.SP_PMAX_C1], sp[L.SP_PMAX_C2], sp[L.SP_PMAX_M1] = pm["p_c1"], pm["p_c2"], pm["p_m1"]
    live = th["live_v"]
    if not (live["p_c1"] == live["p_c2"] == live["p_m1"]):
        raise ValueError("the compiled supervisor assumes one live range for the pressure sensors")
    sp[L.SP_PLO], sp[L.SP_PHI] = live["p_c1"]
    sp[L.SP_LLO], sp[L.SP_LHI] = live["x"]
    sp[L.SP_TOWARD] = th["u_toward_hi"]
    sp[L.SP_DECEL] = p.max_decel_m_s2
    sp[L.SP_HYST] = p.stroke_hyst_m
    sp[L.SP_MAX_RPM] = p.max_speed_rpm
    sp[L.SP_ACCEL] = p.max_accel_rad_s2
    sp[L.SP_STALL_PA] = p.stall_inlet_pa
    sp[L.SP_V_PER_PA], sp[L.SP_P_A] = scaling.v_per_pa, scaling.p_a
    sp[L.SP_V_PER_M], sp[L.SP_V_MID] = scaling.v_per_m, scaling.v_mid
    si[L.SI_T_NS], si[L.SI_WD_NS] = th["T_ns"], th["watchdog_ns"]
    si[L.SI_STUCK_NS], si[L.SI_STALL_NS] = th["stuck_ns"], th["stall_ns"]
    si[L.SI_NXW], si[L.SI_NCW] = th["velocity_window"], th["speed_window"]
    si[L.SI_CPR], si[L.SI_SLACK] = p.counts_per_rev, p.encoder_slack_counts


def pack_spec(spec: Any, sup: Any | None, scaling: Any | None) -> Packed:
    """The arrays for ``spec``; ``sup``/``scaling``: the run's supervisor and sensor scaling."""
    active = np.zeros(2, dtype=np.int64)
    cp = np.zeros((2, L.N_CP))
    ci = np.zeros((2, L.N_CI), dtype=np.int64)
    cs = np.zeros((2, L.N_CS))
    waypoints: list[list[list[float]]] = [[], []]
    valves: list[list[list[float]]] = [[], []]
    for a, axis in enumerate(AXES):
        if axis not in spec.axes:
            continue
        params = spec.controllers[axis]
        active[a] = 1
        T = params.sample_time_s
        td = TrackingDifferentiator(params.td.r, params.td.h, T)
        cp[a, L.CP_SCALE] = axis_scale(axis)
        cp[a, L.CP_T] = T
        cp[a, L.CP_NEUTRAL] = params.limits.u_neutral
        cp[a, L.CP_TD_R], cp[a, L.CP_TD_H], cp[a, L.CP_TD_T] = td.r, td.h, td.T
        ci[a, L.CI_LINEAR] = axis == "linear"
        ci[a, L.CI_ANGLE] = axis == "rotary" and params.rotary_model == "angle"
        ci[a, L.CI_TD_ON] = params.td.enabled
        ci[a, L.CI_DELAY] = params.transport_delay_samples
        waypoints[a] = pack_reference(make_reference(params.reference, axis, T), cp[a], ci[a])
        alg = make_algorithm(params, axis)
        valves[a] = pack_algorithm(alg, cp[a], ci[a])
        for slot, attr in _STATE:
            cs[a, slot] = getattr(alg, attr, math.nan)
        for i, u in enumerate(getattr(alg, "ff_pipe", ())):
            cs[a, L.CS_FF + i] = u
        cs[a, L.CS_U_LAST] = params.limits.u_neutral
        cs[a, L.CS_HIST : L.CS_HIST + params.transport_delay_samples + 1] = params.limits.u_neutral
    sp = np.zeros(L.N_SP)
    si = np.zeros(L.N_SI, dtype=np.int64)
    if sup is not None:
        _supervisor(sup, scaling, sp, si)
    else:
        si[L.SI_NXW] = si[L.SI_NCW] = 1  # unused windows, never empty arrays
    return Packed(
        active, cp, ci, cs, _table(waypoints, 4), _table(valves, 2), sup is not None, sp, si
    )
