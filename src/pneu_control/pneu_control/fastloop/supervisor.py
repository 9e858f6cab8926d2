"""Compiled mirror of the decisions of :class:`pneu_driver.safety.supervisor.SafetySupervisor`.

What is mirrored is what decides the valve voltages in a run without injected
faults: every sample rule (live range, over-pressure, position range, frozen
values, encoder jump, overspeed, no rotation), the command check (a value
outside 0–10 V refused and latched), the watchdog, the latches (a fault
latches its axis for the rest of the run: the runner never acknowledges) and
the stroke soft limits with their hysteresis. Which fault keys are present is
a bit mask per group, as the Python groups are dicts of keys; a change of a
mask, a zone, a first command or a counter is flagged, so that the caller
knows the last cycle where the Python supervisor emits an event or counts
something. The events themselves (messages, values, order) are not
re-implemented: :mod:`pneu_control.experiment.compiled` replays the Python
supervisor over the recorded samples and commands up to that cycle.

Non-finite samples are not mirrored (the loop stops and the caller falls back).
State lives in two arrays: ``sf`` (float) and ``sn`` (int), indices below.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from pneu_control.fastloop.layout import (
    JIT,
    SI_CPR,
    SI_NCW,
    SI_NXW,
    SI_SLACK,
    SI_STALL_NS,
    SI_STUCK_NS,
    SI_T_NS,
    SI_WD_NS,
    SP_ACCEL,
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
    SP_STALL_PA,
    SP_TOWARD,
    SP_X_ABS,
    SP_X_HI,
    SP_X_LO,
)

__all__ = ["sup_check_sample", "sup_command", "sup_new", "sup_outputs"]

SAFE_V = 5.0  # pneu_driver.safety.events.SAFE_V (MPYE closed centre)
_TWO_PI = 2.0 * math.pi

# sensor-group fault keys, one bit each (rule:sensor as in the Python supervisor)
B_NF = 0  # non_finite:<p_c1|p_c2|p_m1|x> (raw volts), bits 0..3
B_LIVE = 4  # live_range:<...>, bits 4..7
B_OVER = 8  # over_pressure:<p_c1|p_c2|p_m1>, bits 8..10
B_POS = 11  # position_range:x
B_STUCK = 12  # stuck:<...>, bits 12..15
B_JUMP = 16  # encoder_jump:encoder
B_OVERSPEED = 17  # overspeed
B_NO_ROT = 18  # no_rotation:encoder
B_STROKE = 19  # stroke_limit:x (the piston at or beyond a soft limit)
ROT_BITS = (1 << 2) | (1 << 6) | (1 << 10) | (1 << 14) | (1 << 16) | (1 << 17) | (1 << 18)
LIN_BITS = ((1 << 20) - 1) & ~ROT_BITS

# sf: float state
SF_X, SF_V, SF_RATE, SF_CMD_U, SF_FV = 0, 1, 2, 3, 5  # SF_CMD_U: 2 axes, SF_FV: 4 channels
N_SF = 9
# sn: int state
(
    SN_HAVE_SAMPLE, SN_ENC_HAVE, SN_ENC_C, SN_ENC_T, SN_HAS_RATE, SN_STALL_HAVE, SN_STALL_C,
    SN_STALL_SINCE, SN_XW_HEAD, SN_XW_N, SN_CW_HEAD, SN_CW_N, SN_SENSOR, SN_WD, SN_ZONE_HI,
    SN_ZONE_LO, SN_EVENT,
) = range(17)  # fmt: skip
SN_SAN = 17  # 2 axes: output_sanity present
SN_LATCH = 19  # 2 axes: something latched
SN_CMD_HAVE = 21  # 2 axes
SN_CMD_T = 23  # 2 axes: stamp of the last accepted command
SN_FT = 25  # 4 channels: since when the value is frozen
N_SN = 29


def sup_new(si: np.ndarray) -> tuple[np.ndarray, ...]:
    """Fresh state (plain numpy, allocated by the caller: the loop runs without NRT):
    (sf, sn, x window stamps, x window values, count window stamps, counts)."""
    sf = np.zeros(N_SF)
    sf[SF_FV : SF_FV + 4] = math.nan  # never equal: every channel starts fresh
    sf[SF_X] = math.nan
    nxw = int(si[SI_NXW])
    ncw = int(si[SI_NCW])
    return (
        sf,
        np.zeros(N_SN, dtype=np.int64),
        np.zeros(nxw, dtype=np.int64),
        np.zeros(nxw),
        np.zeros(ncw, dtype=np.int64),
        np.zeros(ncw, dtype=np.int64),
    )


@njit(**JIT)
def _group(sn, slot, new):
    """``_update_group``: a changed key set is an event; newly present keys latch their axis."""
    prev = sn[slot]
    if new != prev:
        sn[SN_EVENT] = 1
        added = new & ~prev
        if slot == SN_SENSOR:
            if added & LIN_BITS:
                sn[SN_LATCH] = 1
            if added & ROT_BITS:
                sn[SN_LATCH + 1] = 1
        else:  # watchdog: bit = axis
            if added & 1:
                sn[SN_LATCH] = 1
            if added & 2:
                sn[SN_LATCH + 1] = 1
        sn[slot] = new


@njit(**JIT)
def _push(sn, head, count, size):
    """Append to a ring of ``size`` (a ``deque(maxlen=size)``): (slot to write, oldest slot)."""
    j = sn[head]
    nxt = j + 1
    if nxt == size:
        nxt = 0
    sn[head] = nxt
    if sn[count] < size:
        sn[count] += 1
    return j, (nxt if sn[count] == size else 0)


@njit(**JIT)
def sup_check_sample(sp, si, sf, sn, xw_t, xw_x, cw_t, cw_c, now, p1, p2, pm, x, c, volts):
    """``check_sample(sample, raw_volts)`` (``volts`` = (p_c1, p_c2, p_m1, laser) V)."""
    mask = 0
    plo = sp[SP_PLO]
    phi = sp[SP_PHI]
    llo = sp[SP_LLO]
    lhi = sp[SP_LHI]
    v0 = volts[0]
    v1 = volts[1]
    v2 = volts[2]
    v3 = volts[3]
    if not (plo <= v0 <= phi and plo <= v1 <= phi and plo <= v2 <= phi and llo <= v3 <= lhi):
        for i in range(4):
            v = volts[i]
            lo = llo if i == 3 else plo
            hi = lhi if i == 3 else phi
            if not math.isfinite(v):
                mask |= 1 << (B_NF + i)
            elif v < lo or v > hi:
                mask |= 1 << (B_LIVE + i)
    if p1 > sp[SP_PMAX_C1]:
        mask |= 1 << B_OVER
    if p2 > sp[SP_PMAX_C2]:
        mask |= 1 << (B_OVER + 1)
    if pm > sp[SP_PMAX_M1]:
        mask |= 1 << (B_OVER + 2)
    if abs(x) > sp[SP_X_ABS]:
        mask |= 1 << B_POS
    elif x >= sp[SP_X_HI] or x <= sp[SP_X_LO]:
        mask |= 1 << B_STROKE
    stuck_ns = si[SI_STUCK_NS]
    for i in range(4):  # frozen analog values (the raw volts)
        v = volts[i]
        if v != sf[SF_FV + i]:
            sf[SF_FV + i] = v
            sn[SN_FT + i] = now
        elif now - sn[SN_FT + i] > stuck_ns:
            mask |= 1 << (B_STUCK + i)
    if math.isfinite(x):  # piston velocity over the window
        j, o = _push(sn, SN_XW_HEAD, SN_XW_N, xw_t.shape[0])
        xw_t[j] = now
        xw_x[j] = x
        t0 = xw_t[o]
        x0 = xw_x[o]
        sf[SF_V] = (x - x0) / ((now - t0) * 1e-9) if now > t0 else 0.0
        sf[SF_X] = x
    else:
        sf[SF_X] = math.nan
    # encoder: jump against the previous speed, then overspeed over the window
    cpr = si[SI_CPR]
    has_rate = 0
    rate = 0.0
    if sn[SN_ENC_HAVE] and now > sn[SN_ENC_T]:
        c0 = sn[SN_ENC_C]
        t0 = sn[SN_ENC_T]
        m = (now - t0) / si[SI_T_NS]
        dc = c - c0
        if sn[SN_HAS_RATE]:
            dt_s = (now - t0) * 1e-9
            allowed = sp[SP_ACCEL] * dt_s * dt_s * cpr / _TWO_PI + si[SI_SLACK]
            deviation = abs(dc - sf[SF_RATE] * m)
            if deviation > allowed:
                mask |= 1 << B_JUMP
        rate = dc / m
        has_rate = 1
    sn[SN_ENC_HAVE] = 1
    sn[SN_ENC_C] = c
    sn[SN_ENC_T] = now
    sn[SN_HAS_RATE] = has_rate
    sf[SF_RATE] = rate
    j, o = _push(sn, SN_CW_HEAD, SN_CW_N, cw_t.shape[0])
    cw_t[j] = now
    cw_c[j] = c
    t0 = cw_t[o]
    if now > t0:
        rpm = (c - cw_c[o]) * 60.0e9 / (cpr * (now - t0))
        if abs(rpm) > sp[SP_MAX_RPM]:
            mask |= 1 << B_OVERSPEED
    # dead encoder / blocked rotor
    if not pm > sp[SP_STALL_PA] or not sn[SN_STALL_HAVE] or c != sn[SN_STALL_C]:
        sn[SN_STALL_HAVE] = 1
        sn[SN_STALL_C] = c
        sn[SN_STALL_SINCE] = now
    elif now - sn[SN_STALL_SINCE] > si[SI_STALL_NS]:
        mask |= 1 << B_NO_ROT
    sn[SN_HAVE_SAMPLE] = 1
    _group(sn, SN_SENSOR, mask)


@njit(**JIT)
def sup_command(sf, sn, axis, u, stamp):
    """``command(axis, u, stamp_ns)``: refused outside [0, 10] V (NaN included)."""
    if not (0.0 <= u <= 10.0):
        sn[SN_EVENT] = 1  # refused_commands counts even when the fault is already present
        if not sn[SN_SAN + axis]:
            sn[SN_SAN + axis] = 1
            sn[SN_LATCH + axis] = 1
        return
    if sn[SN_SAN + axis]:  # the refusal is gone
        sn[SN_SAN + axis] = 0
        sn[SN_EVENT] = 1
    if sn[SN_CMD_HAVE + axis] and stamp < sn[SN_CMD_T + axis]:
        sn[SN_EVENT] = 1  # stale_commands
        return
    if not sn[SN_CMD_HAVE + axis]:
        sn[SN_EVENT] = 1  # "<axis> commands arriving"
    sf[SF_CMD_U + axis] = u
    sn[SN_CMD_T + axis] = stamp
    sn[SN_CMD_HAVE + axis] = 1


@njit(**JIT)
def _update_zone(sp, sf, sn):
    """Stroke soft limits with the braking distance v²/(2a), hysteresis on leaving."""
    x = sf[SF_X]
    v = sf[SF_V]
    if not math.isfinite(x):
        return
    d_brake = v * v / (2.0 * sp[SP_DECEL])
    reach_hi = x + (d_brake if v > 0.0 else 0.0)
    reach_lo = x - (d_brake if v < 0.0 else 0.0)
    x_hi = sp[SP_X_HI]
    x_lo = sp[SP_X_LO]
    zhi = sn[SN_ZONE_HI]
    zlo = sn[SN_ZONE_LO]
    if not (zhi or zlo) and x_lo < reach_lo and reach_hi < x_hi:
        return
    hyst = sp[SP_HYST]
    if not zhi and reach_hi >= x_hi:
        sn[SN_ZONE_HI] = 1
        sn[SN_EVENT] = 1
    elif zhi and reach_hi < x_hi - hyst:
        sn[SN_ZONE_HI] = 0
        sn[SN_EVENT] = 1
    if not zlo and reach_lo <= x_lo:
        sn[SN_ZONE_LO] = 1
        sn[SN_EVENT] = 1
    elif zlo and reach_lo > x_lo + hyst:
        sn[SN_ZONE_LO] = 0
        sn[SN_EVENT] = 1


@njit(**JIT)
def sup_outputs(sp, si, sf, sn, now):
    """``outputs(now_ns)``: (linear, rotary) V after the watchdog, latches and soft limits."""
    wd = 0
    wd_ns = si[SI_WD_NS]
    for a in range(2):
        if sn[SN_CMD_HAVE + a] and now - sn[SN_CMD_T + a] > wd_ns:
            wd |= 1 << a
    _group(sn, SN_WD, wd)
    _update_zone(sp, sf, sn)
    have = sn[SN_HAVE_SAMPLE]
    out_l = SAFE_V
    if not (sn[SN_LATCH] or not sn[SN_CMD_HAVE] or not have):
        u = sf[SF_CMD_U]
        push = (u - SAFE_V) * sp[SP_TOWARD]  # > 0: drives toward +x
        if (sn[SN_ZONE_HI] and push > 0.0) or (sn[SN_ZONE_LO] and push < 0.0):
            u = SAFE_V
        out_l = u
    out_r = SAFE_V
    if not (sn[SN_LATCH + 1] or not sn[SN_CMD_HAVE + 1] or not have):
        out_r = sf[SF_CMD_U + 1]
    return out_l, out_r
