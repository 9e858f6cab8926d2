"""DAQ channel scaling: volts and counts ↔ SI, and the last clamp before an AO write.

Pure functions of :class:`~pneu_driver.daq.rig.RigParams`; no nidaqmx, no state
except :class:`Scaler`'s previous count (for the speed over one period).

- Pressure (Huba 511): p = p_atm + pa_per_v · (v − v_zero)       [Pa abs]
- Position (HG-C1200): x = m_per_v · (v − v_mid) + offset_m      [m, 0 = mid-stroke]
- Encoder (X4):        θ = 2π · counts / (ppr · 4)               [rad]
                       ω = 2π · Δcounts / (ppr · 4 · Δt)         [rad/s]
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pneu_msgs_py.contract.samples import SensorSample

from pneu_driver.daq.rig import AoParams, LaserParams, PressureSensor, RigParams

__all__ = [
    "RawSample",
    "pressure_pa",
    "pressure_volts",
    "position_m",
    "laser_volts",
    "angle_rad",
    "unwrap_counts",
    "ao_volts",
    "Scaler",
]

_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True, slots=True)
class RawSample:
    """What a DAQ backend reads at one tick.

    ``volts`` = (p_c1, p_c2, p_m1, laser) in :data:`~pneu_driver.daq.rig.AI_SENSORS` order;
    ``counts`` = cumulative encoder count (already unwrapped, Python int).
    """

    volts: tuple[float, float, float, float]
    counts: int


def pressure_pa(v: float, sensor: PressureSensor, p_atm_pa: float) -> float:
    """Huba 511 gauge output [V] → absolute pressure [Pa]."""
    return p_atm_pa + sensor.pa_per_v * (v - sensor.v_zero)


def pressure_volts(p_pa: float, sensor: PressureSensor, p_atm_pa: float) -> float:
    """Inverse of :func:`pressure_pa` (for simulated backends)."""
    return sensor.v_zero + (p_pa - p_atm_pa) / sensor.pa_per_v


def position_m(v: float, laser: LaserParams) -> float:
    """HG-C1200 analog output [V] → piston displacement [m], 0 = mid-stroke, + = extending."""
    return laser.m_per_v * (v - laser.v_mid) + laser.offset_m


def laser_volts(x_m: float, laser: LaserParams) -> float:
    """Inverse of :func:`position_m`."""
    return laser.v_mid + (x_m - laser.offset_m) / laser.m_per_v


def angle_rad(counts: int, counts_per_rev: int) -> float:
    """Cumulative encoder count → motor angle [rad]."""
    return _TWO_PI * counts / counts_per_rev


def unwrap_counts(prev_cumulative: int, raw: int, bits: int = 32) -> int:
    """Extend a ``bits``-wide counter reading to an unbounded cumulative count.

    The step since ``prev_cumulative`` is taken modulo 2**bits into
    [-2**(bits-1), 2**(bits-1)), so the register may roll over (or read
    signed or unsigned) as long as it moves less than half its range per
    read (32 bits at 10 000 rpm, 4000 counts/rev: 54 minutes).
    """
    modulus = 1 << bits
    half = modulus >> 1
    step = (int(raw) - prev_cumulative) % modulus
    if step >= half:
        step -= modulus
    return prev_cumulative + step


def ao_volts(u: float, ao: AoParams) -> float:
    """The voltage actually written for a command ``u``: clamped to the AO range, NaN → safe.

    The supervisor never passes a bad value; this is the last line of defence.
    """
    if not math.isfinite(u):
        return ao.safe_v
    return min(max(u, ao.min_v), ao.max_v)


class Scaler:
    """Raw DAQ readings → :class:`SensorSample`, keeping the previous count for ω.

    ``omega`` is the count difference over the time since the previous sample,
    so it is quantised to 2π / (counts_per_rev · T) (15 rpm at 4000 counts/rev, 1 ms).
    """

    __slots__ = ("_cpr", "_period_ns", "_prev_counts", "_prev_k", "rig")

    def __init__(self, rig: RigParams):
        self.rig = rig
        self._cpr = rig.encoder.counts_per_rev
        self._period_ns = rig.period_ns
        self._prev_counts: int | None = None
        self._prev_k = 0

    def reset(self) -> None:
        self._prev_counts = None

    def sample(self, k: int, stamp_ns: int, raw: RawSample) -> SensorSample:
        """Scale ``raw`` read at tick ``k`` (stamped ``stamp_ns``) into SI."""
        rig = self.rig
        v1, v2, vm, vx = raw.volts
        counts = int(raw.counts)
        if self._prev_counts is None or k <= self._prev_k:
            omega = 0.0
        else:
            dt_s = (k - self._prev_k) * self._period_ns * 1e-9
            omega = _TWO_PI * (counts - self._prev_counts) / (self._cpr * dt_s)
        self._prev_counts = counts
        self._prev_k = k
        return SensorSample(
            k=k,
            stamp_ns=stamp_ns,
            p_c1=pressure_pa(v1, rig.p_c1, rig.p_atm_pa),
            p_c2=pressure_pa(v2, rig.p_c2, rig.p_atm_pa),
            p_m1=pressure_pa(vm, rig.p_m1, rig.p_atm_pa),
            x=position_m(vx, rig.laser),
            theta=angle_rad(counts, self._cpr),
            omega=omega,
            counts=counts,
        )

    def raw(self, s: SensorSample) -> RawSample:
        """The inverse: what the DAQ would have read for ``s`` (simulated backends)."""
        rig = self.rig
        return RawSample(
            volts=(
                pressure_volts(s.p_c1, rig.p_c1, rig.p_atm_pa),
                pressure_volts(s.p_c2, rig.p_c2, rig.p_atm_pa),
                pressure_volts(s.p_m1, rig.p_m1, rig.p_atm_pa),
                laser_volts(s.x, rig.laser),
            ),
            counts=int(s.counts),
        )
