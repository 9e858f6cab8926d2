"""A :class:`~pneu_control.experiment.runner.RunSpec` -> the compiled loop's record arrays.

The loop starts from exactly the objects the runner builds: one
:class:`~pneu_control.controller.axis.AxisController` per active axis, whose kernel
records (axis constants and state, step input, reference, the algorithm's constants,
state and table) are copied field by field, by name, into structured arrays of the
same record types. Nothing is derived a second time, nothing is numbered by hand.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from pneu_msgs_py.contract.samples import AXES

from pneu_control.algorithms import ALGORITHM_CLASSES
from pneu_control.algorithms.base import STEP_INPUT, KernelAlgorithm
from pneu_control.controller.axis import AXIS_CONSTANTS, AXIS_STATE, AxisController
from pneu_control.controller.references import REFERENCE
from pneu_control.fastloop import layout as L

__all__ = ["Packed", "pack_spec", "unsupported"]


@dataclass
class Packed:
    """What :func:`pneu_control.fastloop.loop.closed_loop` takes besides the plant's arrays."""

    axes: tuple  # (active, ac, ast, inp, rc, knots, codes, tables, uses_theta), per axis
    algs: tuple  # (constants, state) record arrays of every compiled algorithm, per axis
    sup_on: bool
    sp: np.ndarray  # float64[N_SP]
    si: np.ndarray  # int64[N_SI]


def unsupported(spec: Any) -> str | None:
    """Why the compiled loop cannot run ``spec`` (None: it can, with the same results)."""
    if spec.faults:
        return "injected faults (spec.faults) are not compiled"
    for axis in spec.axes:
        name = spec.controllers[axis].algorithm
        cls = ALGORITHM_CLASSES[name]
        if name not in L.COMPILED or not issubclass(cls, KernelAlgorithm):
            return (
                f"{axis}.algorithm {name!r} is not in the compiled loop's table "
                f"(pneu_control/fastloop/layout.py COMPILED: {', '.join(L.COMPILED)})"
            )
    return None


def _padded(tables: list[Any]) -> np.ndarray:
    """float64[2, rows, width] from one 2-D table (list of rows) per axis, zero-padded."""
    rows = max(len(t) for t in tables)
    width = max(len(r) for t in tables for r in t)
    out = np.zeros((len(tables), rows, width))
    for a, t in enumerate(tables):
        for i, row in enumerate(t):
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
    r = sup.threshold_record  # the rest straight from the record the rules read
    sp[L.SP_STALL_BAND], sp[L.SP_STALL_OMEGA] = r.stall_band_v, r.stall_omega
    sp[L.SP_RAD_PER_COUNT], sp[L.SP_TH_HI], sp[L.SP_TH_LO] = r.rad_per_count, r.th_hi, r.th_lo
    sp[L.SP_AHYST], sp[L.SP_ADECEL] = r.angle_hyst, r.max_decel_rad_s2
    sp[L.SP_ROT_IDLE], sp[L.SP_ALAG] = r.rot_idle_v, r.angle_lag_s
    sp[L.SP_V_PER_PA], sp[L.SP_P_A] = scaling.v_per_pa, scaling.p_a
    sp[L.SP_V_PER_M], sp[L.SP_V_MID] = scaling.v_per_m, scaling.v_mid
    si[L.SI_T_NS], si[L.SI_WD_NS] = th["T_ns"], th["watchdog_ns"]
    si[L.SI_STUCK_NS], si[L.SI_STALL_NS] = th["stuck_ns"], th["stall_ns"]
    si[L.SI_NXW], si[L.SI_NCW] = th["velocity_window"], th["speed_window"]
    si[L.SI_CPR], si[L.SI_SLACK] = p.counts_per_rev, p.encoder_slack_counts
    si[L.SI_REVERSE] = r.stall_reverse
    si[L.SI_LATE_POLICY], si[L.SI_LATE_HOLD_NS] = th["late_policy"], th["late_hold_ns"]
    si[L.SI_LATE_RAMP_NS] = th["late_ramp_ns"]


def pack_spec(spec: Any, sup: Any | None, scaling: Any | None) -> Packed:
    """The arrays for ``spec``; ``sup``/``scaling``: the run's supervisor and sensor scaling."""
    n_ax = len(AXES)
    active = np.zeros(n_ax, dtype=np.int64)
    codes = np.zeros(n_ax, dtype=np.int64)
    uses_theta = np.zeros(n_ax, dtype=np.bool_)
    ac, ast = AXIS_CONSTANTS.array(n_ax), AXIS_STATE.array(n_ax)
    inp, rc = STEP_INPUT.array(n_ax), REFERENCE.array(n_ax)
    algs: list[np.ndarray] = []
    for name in L.COMPILED:
        cls = ALGORITHM_CLASSES[name]
        if issubclass(cls, KernelAlgorithm):
            algs += [cls.CONSTANTS.array(n_ax), cls.STATE.array(n_ax)]
    knots: list[Any] = [[[0.0]] * 4] * n_ax
    tables: list[Any] = [[[0.0]]] * n_ax
    for a, axis in enumerate(AXES):
        if axis not in spec.axes:
            continue
        ctl = AxisController(axis, spec.controllers[axis])  # the runner's own objects
        alg = ctl._alg
        active[a] = 1
        codes[a] = L.COMPILED.index(alg.name)
        uses_theta[a] = alg.uses_theta
        ctl._c.store(ac[a])
        ctl._st.store(ast[a])
        ctl._inp.store(inp[a])
        ctl._ref.rc.store(rc[a])
        knots[a] = ctl._ref.knots
        alg.c.store(algs[2 * codes[a]][a])
        alg.st.store(algs[2 * codes[a] + 1][a])
        tables[a] = alg.tab
    sp = np.zeros(L.N_SP)
    si = np.zeros(L.N_SI, dtype=np.int64)
    if sup is not None:
        _supervisor(sup, scaling, sp, si)
    else:
        si[L.SI_NXW] = si[L.SI_NCW] = 1  # unused windows, never empty arrays
    axes = (active, ac, ast, inp, rc, _padded(knots), codes, _padded(tables), uses_theta)
    return Packed(axes, tuple(algs), sup is not None, sp, si)
