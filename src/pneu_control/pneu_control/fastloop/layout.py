"""Index constants of the compiled loop's flat arrays (one place; numba reads them as constants).

Per axis (row 0 linear, row 1 rotary):

- ``cp`` float64[2, N_CP]: controller constants (gains, derived coefficients), read
  from the Python objects the runner would build (:mod:`.pack`);
- ``ci`` int64[2, N_CI]: options (algorithm, flags, lengths);
- ``cs`` float64[2, N_CS]: controller state, initialised from the fresh Python objects;
- ``wp`` float64[2, 4, n]: waypoint knots (t, r, v, a), ``vt`` float64[2, 2, n]:
  ESO-SMC+'s valve table (du, flow).

Supervisor: ``sp`` float64[N_SP] thresholds, ``si`` int64[N_SI] integer thresholds.
"""

from __future__ import annotations

# how every compiled mirror is built: no fastmath (no FMA contraction, no reassociation), no
# division checks, and no NRT (numba's reference counting: with it every call that passes
# an array does an atomic incref/decref pair, measured at ~17 % of the loop; without it
# nothing may allocate an array inside, the caller allocates). Not cached: only the loop
# (pneu_control.fastloop.loop) is, as one unit.
JIT = {"error_model": "numpy", "_nrt": False}

# ---------------------------------------------------------------- algorithms, references
ALG_PID, ALG_LADRC, ALG_ESO_SMC, ALG_ESO_SMC_PLUS = 0, 1, 2, 3
ALG_CODES = {
    "pid": ALG_PID,
    "ladrc": ALG_LADRC,
    "eso_smc": ALG_ESO_SMC,
    "eso_smc_plus": ALG_ESO_SMC_PLUS,
}
REF_SINE, REF_SMOOTH_STEP, REF_CONSTANT, REF_RAMP, REF_WAYPOINTS = 0, 1, 2, 3, 4
AW_CONDITIONAL, AW_BACK_CALCULATION, AW_NONE = 0, 1, 2
MAX_HIST = 6  # transport_delay_samples <= 5 (AxisControllerParams): d + 1 commands

# ---------------------------------------------------------------- cp: controller constants
N_CP = 95
(
    CP_SCALE, CP_T, CP_NEUTRAL, CP_TD_R, CP_TD_H, CP_TD_T, CP_REF0, CP_REF1, CP_REF2, CP_REF3,
    PID_T, PID_KP, PID_KI, PID_KD, PID_AD, PID_AY, PID_KB, PID_LO, PID_HI,
    LA_T, LA_T2H, LA_KP, LA_KD, LA_B0, LA_FF, LA_L1, LA_L2, LA_L3, LA_LO, LA_HI, LA_TAU, LA_UN,
    SM_T, SM_T2H, SM_C1, SM_C2, SM_B0, SM_EPS, SM_DELTA, SM_K, SM_L1, SM_L2, SM_L3, SM_FS, SM_MC,
    SM_MV, SM_FV, SM_FC, SM_INVWS, SM_LO, SM_HI, SM_TAU, SM_UN, SM_TWO,
    PL_T, PL_T2H, PL_T3S, PL_C1, PL_C2, PL_B0, PL_EPS, PL_DELTA, PL_K, PL_L1, PL_L2, PL_L3,
    PL_L4A, PL_L4B, PL_L4C, PL_L4D, PL_AC1, PL_AC2, PL_F0, PL_MK, PL_INVMK, PL_AF, PL_CVK,
    PL_INVVS, PL_KF, PL_INVBF, PL_NA1S, PL_NA2S, PL_V10, PL_V20, PL_BF, PL_UN, PL_LO, PL_HI,
    PL_VLO, PL_VHI, PL_TAU, PL_G, PL_INVG, PL_DUMAX, PL_VMAX,
) = range(N_CP)  # fmt: skip

# ---------------------------------------------------------------- ci: options
N_CI = 23
(
    CI_ALG, CI_LINEAR, CI_ANGLE, CI_TD_ON, CI_DELAY, CI_REF_KIND, CI_NWP, CI_USES_TD,
    CI_USES_THETA, CI_PID_ON_ERROR, CI_PID_AW, CI_LA_DC, CI_SM_AW, CI_SM_DC, CI_SM_FRIC,
    CI_SM_ANGLE, CI_PL_ANGLE, CI_PL_ANGLE_INPUTS, CI_PL_LIN_ID, CI_PL_FORCE, CI_PL_FFW, CI_PL_DC,
    CI_NVT,
) = range(N_CI)  # fmt: skip

# ---------------------------------------------------------------- cs: controller state
CS_STARTED = 0  # 0/1
CS_U_LAST = 1  # V, the last command
CS_TH_R = 2  # AxisController angle mode: θ_r (rpm·s)
CS_V1_PREV = 3
CS_TD_V1, CS_TD_V2, CS_TD_V3 = 4, 5, 6
CS_HIST = 7  # MAX_HIST commands, V, oldest first (AxisController._u_hist)
_base = CS_HIST + MAX_HIST
(
    CS_Z1, CS_Z2, CS_Z3, CS_Z4, CS_S, CS_U_RAW, CS_INTEGRAL, CS_PID_D, CS_PID_YF, CS_PID_RDOT,
    CS_U_IN, CS_F_K, CS_PL_THR, CS_PL_WRP, CS_PL_VIN, CS_PL_FP, CS_PL_AIN, CS_PL_FDP, CS_PL_UFF,
) = range(_base, _base + 19)  # fmt: skip
CS_FF = _base + 19  # ESO-SMC+ friction feed-forward pipe, MAX_HIST values, oldest first
N_CS = CS_FF + MAX_HIST

# one recorded row per cycle: the sample (p_c1, p_c2, p_m1, x, theta, omega, counts), the
# held output (linear, rotary), then per axis STATE_FIELDS (11) and the command u
REC_SAMPLE = 0
REC_HELD = 7
REC_AXIS = 9  # + 12 * axis
N_REC_AXIS = 12
N_REC = REC_AXIS + 2 * N_REC_AXIS

# ---------------------------------------------------------------- supervisor thresholds
N_SP = 20
(
    SP_X_HI, SP_X_LO, SP_X_ABS, SP_PMAX_C1, SP_PMAX_C2, SP_PMAX_M1, SP_PLO, SP_PHI, SP_LLO, SP_LHI,
    SP_TOWARD, SP_DECEL, SP_HYST, SP_MAX_RPM, SP_ACCEL, SP_STALL_PA, SP_V_PER_PA, SP_P_A,
    SP_V_PER_M, SP_V_MID,
) = range(N_SP)  # fmt: skip
SI_T_NS, SI_WD_NS, SI_STUCK_NS, SI_STALL_NS, SI_NXW, SI_NCW, SI_CPR, SI_SLACK = range(8)
N_SI = 8

# ---------------------------------------------------------------- kernel status
OK = 0
NONFINITE_SAMPLE = (
    1  # the plant produced a NaN/inf sample (Python: the supervisor's non_finite rule)
)
NONFINITE_COMMAND = 2  # a controller answered NaN (Python: refused, output_sanity, watchdog)
STATUS_TEXT = {
    NONFINITE_SAMPLE: "a sample was not finite (non_finite rule and NaN controller paths are not compiled)",
    NONFINITE_COMMAND: "a controller answered NaN (refusal and watchdog after a NaN are not compiled)",
}
