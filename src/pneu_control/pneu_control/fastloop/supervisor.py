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

from pneu_control.fastloop.layout import JIT

__all__ = ["RECORD", "SN_EVENT", "sup_check_sample", "sup_command", "sup_new", "sup_outputs"]

# the rules' three records in one (the rules read each by field name)
RECORD = RecordType(
    "CompiledSupervisor",
    (*rules.THRESHOLDS.defaults, *rules.STATE.defaults, *rules.FINDINGS.defaults),
)
# sn: int64 flags
SN_EVENT = 0  # set when the Python supervisor would emit an event or count (the caller clears it)
SN_SENSOR = 1  # the sensor keys present (rules.SENSOR_KEYS bits)
SN_WATCHDOG = 2  # the watchdog keys present (bit = axis)
SN_LATCH = 3  # the latched axes (bit = axis)
SN_LATE = 4  # the trip policy's late_command keys present (bit = axis)
SN_LATE_LIN = 5  # the late ticks counted so far, linear (a count is an event)
SN_LATE_ROT = 6  # ... rotary
N_SN = 7


def sup_new(sf: np.ndarray) -> tuple[np.ndarray, ...]:
    """The state the loop takes (plain numpy, allocated by the caller: the loop runs without
    NRT): ``sf``, a :data:`RECORD` array with the run's thresholds in it (:mod:`.pack`
    copies them by name from ``SafetySupervisor.threshold_record``), the flags ``sn`` and
    four unused arrays the loop's signature still passes."""
    unused = np.zeros(1)
    return sf, np.zeros(N_SN, dtype=np.int64), unused, unused, unused, unused


@njit(**JIT)
def _group(sn, slot, keys, axes):
    """``_update_group``: a changed key set (or count) is an event; ``axes`` (newly present
    keys') latch."""
    if keys != sn[slot]:
        sn[SN_EVENT] = 1
        sn[SN_LATCH] |= axes
        sn[slot] = keys


@njit(**JIT)
def sup_check_sample(sf, sn, xw_t, xw_x, cw_t, cw_c, now, p1, p2, pm, x, c, volts):
    """``check_sample(sample, raw_volts)`` (``volts`` = (p_c1, p_c2, p_m1, laser) V)."""
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
def sup_outputs(sf, sn, now):
    """``outputs(now_ns)``: (linear, rotary) V after the late-command policy, the watchdog,
    latches and the stroke and angle soft limits. A late tick counted is an event (the
    replay then counts it)."""
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
