"""The compiled loop's record layout: which algorithms it dispatches, one recorded row, status.

The controllers' and references' constants and states are kernel records with named
fields (:mod:`pneu_msgs_py.params.records`), declared where each step is written; this
module only says what the loop itself adds.
"""

from __future__ import annotations

from pneu_msgs_py.params.records import JIT

__all__ = ["COMPILED", "JIT", "N_REC", "N_REC_AXIS", "REC_AXIS", "REC_HELD", "REC_SAMPLE"]

# the algorithms the loop dispatches, by name: code = index (fastloop/axis.py). An algorithm
# registered in pneu_control.algorithms but not here runs in the Python runner (one line says so).
COMPILED = ("pid", "ladrc", "eso_smc", "eso_smc_plus", "coast", "pva")

# one recorded row per cycle: the sample (p_c1, p_c2, p_m1, x, theta, omega, counts), the
# held output (linear, rotary), then per axis STATE_FIELDS (11) and the command u
REC_SAMPLE = 0
REC_HELD = 7
REC_AXIS = 9  # + 12 * axis
N_REC_AXIS = 12
N_REC = REC_AXIS + 2 * N_REC_AXIS

# ---------------------------------------------------------------- supervisor thresholds
N_SP = 29
(
    SP_X_HI, SP_X_LO, SP_X_ABS, SP_PMAX_C1, SP_PMAX_C2, SP_PMAX_M1, SP_PLO, SP_PHI, SP_LLO, SP_LHI,
    SP_TOWARD, SP_DECEL, SP_HYST, SP_MAX_RPM, SP_ACCEL, SP_STALL_PA, SP_V_PER_PA, SP_P_A,
    SP_V_PER_M, SP_V_MID, SP_STALL_BAND, SP_STALL_OMEGA, SP_RAD_PER_COUNT, SP_TH_HI, SP_TH_LO,
    SP_AHYST, SP_ADECEL, SP_ROT_IDLE, SP_ALAG,
) = range(N_SP)  # fmt: skip
(
    SI_T_NS, SI_WD_NS, SI_STUCK_NS, SI_STALL_NS, SI_NXW, SI_NCW, SI_CPR, SI_SLACK, SI_REVERSE,
    SI_LATE_POLICY, SI_LATE_HOLD_NS, SI_LATE_RAMP_NS,
) = range(12)  # fmt: skip
N_SI = 12

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
