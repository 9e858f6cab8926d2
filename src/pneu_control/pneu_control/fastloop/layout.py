"""The compiled loop's record layout: which algorithms it dispatches, one recorded row, the
sensor scaling, status.

The controllers' and references' constants and states are kernel records with named
fields (:mod:`pneu_msgs_py.params.records`), declared where each step is written; this
module only says what the loop itself adds.
"""

from __future__ import annotations

from pneu_msgs_py.params.records import JIT, RecordType

__all__ = ["COMPILED", "JIT", "N_REC", "N_REC_AXIS", "REC_AXIS", "REC_HELD", "REC_SAMPLE", "SCALE"]

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

# ---------------------------------------------------------------- sensor scaling
# the raw volts the supervisor's sample rules read (pneu_sim.faults.injection.SensorScaling)
SCALE = RecordType(
    "SensorScale", [("v_per_pa", "f"), ("p_a", "f"), ("v_per_m", "f"), ("v_mid", "f")]
)

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
