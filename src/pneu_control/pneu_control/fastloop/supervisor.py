"""The supervisor in the compiled loop: :mod:`pneu_driver.safety.rules` compiled in, no copy.

Every decision (sample rules, command check, late-command policy, watchdog, soft
limits, output) is a rule of :mod:`pneu_driver.safety.rules`, the same source
:class:`~pneu_driver.safety.supervisor.SafetySupervisor` runs in Python, here on
one numba record holding the rules' thresholds, state and findings. What is
left here is what only the compiled loop needs:

- the latches as bits (a fault latches its axis for the rest of the run: the
  runner never acknowledges) and the last key mask of each group, as the Python
  groups are dicts of keys;
- the event flag ``sn[SN_EVENT]``: a changed key mask, a zone change, any
  command outcome the rules report or a late tick counted, so that the caller
  knows the last cycle at which the Python supervisor emits an event or counts
  something. The events
  themselves are not re-implemented: :mod:`pneu_control.experiment.compiled`
  replays the Python supervisor over the recorded samples and commands up to that cycle.

Non-finite sample fields are not checked here (the loop stops on one first and
the caller falls back). State: ``sf`` a one-record structured array
(:data:`RECORD`), ``sn`` int64 flags, indices below.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from pneu_driver.safety import rules
from pneu_msgs_py.params.records import RecordType

from pneu_control.fastloop.layout import (
    JIT,
    SI_CPR,
    SI_LATE_HOLD_NS,
    SI_LATE_POLICY,
    SI_LATE_RAMP_NS,
    SI_NCW,
    SI_NXW,
    SI_REVERSE,
    SI_SLACK,
    SI_STALL_NS,
    SI_STUCK_NS,
    SI_T_NS,
    SI_WD_NS,
    SP_ACCEL,
    SP_ADECEL,
    SP_AHYST,
    SP_ALAG,
    SP_DECEL,
    SP_HYST,
    SP_LHI,
    SP_LLO,
    SP_MAX_RPM,
    SP_PHI,
    SP_PLO,
    SP_PMAX_C1,
    SP_PMAX_C2,
    SP_PMAX_M1,
    SP_RAD_PER_COUNT,
    SP_ROT_IDLE,
    SP_STALL_BAND,
    SP_STALL_OMEGA,
    SP_STALL_PA,
    SP_TH_HI,
    SP_TH_LO,
    SP_TOWARD,
    SP_X_ABS,
    SP_X_HI,
    SP_X_LO,
)

__all__ = ["RECORD", "SN_EVENT", "sup_check_sample", "sup_command", "sup_new", "sup_outputs"]

# the rules' three records in one (the rules read each by field name)
RECORD = RecordType(
    "CompiledSupervisor",
    (*rules.THRESHOLDS.defaults, *rules.STATE.defaults, *rules.FINDINGS.defaults),
)
# sn: int64 flags
SN_EVENT = 0  # set when the Python supervisor would emit an event or count (the caller clears it)
SN_LOADED = 1  # the thresholds are in the record
SN_SENSOR = 2  # the sensor keys present (rules.SENSOR_KEYS bits)
SN_WATCHDOG = 3  # the watchdog keys present (bit = axis)
SN_LATCH = 4  # the latched axes (bit = axis)
SN_LATE = 5  # the trip policy's late_command keys present (bit = axis)
SN_LATE_LIN = 6  # the late ticks counted so far, linear (a count is an event)
SN_LATE_ROT = 7  # ... rotary
N_SN = 8


def sup_new(si: np.ndarray) -> tuple[np.ndarray, ...]:
    """Fresh state (plain numpy, allocated by the caller: the loop runs without NRT):
    (sf, sn, and four unused arrays the loop's signature still passes)."""
    unused = np.zeros(1)
    return rules.fresh_array(RECORD), np.zeros(N_SN, dtype=np.int64), unused, unused, unused, unused


@njit(**JIT)
def _load(sp, si, sf, sn):
    """The thresholds packed by :mod:`.pack` (from ``SafetySupervisor.thresholds()``) into the record."""
    if sn[SN_LOADED]:
        return
    sn[SN_LOADED] = 1
    r = sf[0]
    r.T_ns = si[SI_T_NS]
    r.watchdog_ns = si[SI_WD_NS]
    r.late_policy = si[SI_LATE_POLICY]
    r.late_hold_ns = si[SI_LATE_HOLD_NS]
    r.late_ramp_ns = si[SI_LATE_RAMP_NS]
    r.stuck_ns = si[SI_STUCK_NS]
    r.stall_ns = si[SI_STALL_NS]
    r.n_xw = si[SI_NXW]
    r.n_cw = si[SI_NCW]
    r.counts_per_rev = si[SI_CPR]
    r.encoder_slack_counts = si[SI_SLACK]
    r.x_hi = sp[SP_X_HI]
    r.x_lo = sp[SP_X_LO]
    r.x_abs_max = sp[SP_X_ABS]
    r.p_max_c1 = sp[SP_PMAX_C1]
    r.p_max_c2 = sp[SP_PMAX_C2]
    r.p_max_m1 = sp[SP_PMAX_M1]
    r.p_live_lo = sp[SP_PLO]
    r.p_live_hi = sp[SP_PHI]
    r.x_live_lo = sp[SP_LLO]
    r.x_live_hi = sp[SP_LHI]
    r.u_toward_hi = sp[SP_TOWARD]
    r.max_decel_m_s2 = sp[SP_DECEL]
    r.stroke_hyst_m = sp[SP_HYST]
    r.max_speed_rpm = sp[SP_MAX_RPM]
    r.max_accel_rad_s2 = sp[SP_ACCEL]
    r.stall_inlet_pa = sp[SP_STALL_PA]
    r.stall_band_v = sp[SP_STALL_BAND]
    r.stall_omega = sp[SP_STALL_OMEGA]
    r.stall_reverse = si[SI_REVERSE]
    r.rad_per_count = sp[SP_RAD_PER_COUNT]
    r.th_hi = sp[SP_TH_HI]
    r.th_lo = sp[SP_TH_LO]
    r.angle_hyst = sp[SP_AHYST]
    r.max_decel_rad_s2 = sp[SP_ADECEL]
    r.rot_idle_v = sp[SP_ROT_IDLE]
    r.angle_lag_s = sp[SP_ALAG]


@njit(**JIT)
def _group(sn, slot, keys, axes):
    """``_update_group``: a changed key set (or count) is an event; ``axes`` (newly present
    keys') latch."""
    if keys != sn[slot]:
        sn[SN_EVENT] = 1
        sn[SN_LATCH] |= axes
        sn[slot] = keys


@njit(**JIT)
def sup_check_sample(sp, si, sf, sn, xw_t, xw_x, cw_t, cw_c, now, p1, p2, pm, x, c, volts):
    """``check_sample(sample, raw_volts)`` (``volts`` = (p_c1, p_c2, p_m1, laser) V)."""
    _load(sp, si, sf, sn)
    r = sf[0]
    keys = rules.sample_faults(r, r, r, now, p1, p2, pm, x, c, volts, 1)
    _group(sn, SN_SENSOR, keys, rules.sensor_key_axes(keys & ~sn[SN_SENSOR]))


@njit(**JIT)
def sup_command(sf, sn, axis, u, stamp):
    """``command(axis, u, stamp_ns)``: a refusal latches the axis; every outcome but "taken"
    is an event or a count."""
    done = rules.command(sf[0], sf[0], axis, u, stamp)
    if done:
        sn[SN_EVENT] = 1
    if done & rules.CMD_REFUSED:
        sn[SN_LATCH] |= 1 << axis


@njit(**JIT)
def sup_outputs(sp, si, sf, sn, now):
    """``outputs(now_ns)``: (linear, rotary) V after the late-command policy, the watchdog,
    latches and the stroke and angle soft limits. A late tick counted is an event (the
    replay then counts it)."""
    _load(sp, si, sf, sn)
    r = sf[0]
    gone = rules.watchdog_faults(r, r, now)
    _group(sn, SN_WATCHDOG, gone, gone & ~sn[SN_WATCHDOG])
    late = rules.late_faults(r, r, now)
    _group(sn, SN_LATE, late, late & ~sn[SN_LATE])
    if rules.update_zone(r, r, r):
        sn[SN_EVENT] = 1
    latch = sn[SN_LATCH]
    u_l = rules.output_v(r, r, 0, latch & 1, now)
    u_r = rules.output_v(r, r, 1, latch & 2, now)
    _group(sn, SN_LATE_LIN, r.late_ticks[0], 0)
    _group(sn, SN_LATE_ROT, r.late_ticks[1], 0)
    return u_l, u_r
