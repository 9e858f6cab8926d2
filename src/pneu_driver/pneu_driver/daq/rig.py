"""The rig's DAQ map and sensor scaling (``config/rig.yaml``) as one parameter group.

NI PCI-6221 (M Series): 16-bit AI (±10 V range, LSB ≈ 0.3 mV), two 16-bit AO,
two 32-bit counters with X4 quadrature decoding. Everything a volt means is
here; :mod:`pneu_driver.daq.scaling` applies it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pneu_msgs_py.contract.units import P_ATM_PA
from pneu_msgs_py.params.core import ParamError, from_dict, param, with_updates
from pneu_msgs_py.params.yaml_file import load_yaml, located

__all__ = [
    "ChannelMap",
    "AiParams",
    "PressureSensor",
    "LaserParams",
    "EncoderParams",
    "AoParams",
    "LoopParams",
    "RigParams",
    "AI_SENSORS",
    "DECODING_FACTOR",
    "load_rig_params",
]

# The four analog inputs, in the order RawSample.volts carries them.
AI_SENSORS = ("p_c1", "p_c2", "p_m1", "laser")
DECODING_FACTOR = {"X1": 1, "X2": 2, "X4": 4}
_TERMINALS = ("RSE", "NRSE", "DIFF", "PSEUDO_DIFF", "DEFAULT")
_TIMING = ("sample_clock", "on_demand")


@dataclass(frozen=True)
class ChannelMap:
    """Physical channel names on the device (without the ``Dev1/`` prefix)."""

    p_c1: str = param("ai0", desc="Huba 511, cylinder chamber 1 (cap side)", read_only=True)
    p_c2: str = param("ai1", desc="Huba 511, cylinder chamber 2 (rod side)", read_only=True)
    p_m1: str = param("ai2", desc="Huba 511, motor inlet chamber", read_only=True)
    laser: str = param("ai3", desc="Panasonic HG-C1200 analog output", read_only=True)
    encoder: str = param(
        "ctr0", desc="Omron E6B2-CWZ6C, A/B on the counter's default terminals", read_only=True
    )
    valve_linear: str = param("ao0", desc="MPYE valve #1 (cylinder)", read_only=True)
    valve_rotary: str = param("ao1", desc="MPYE valve #2 (motor inlet)", read_only=True)

    def _check(self) -> None:
        pattern = {
            "p_c1": r"ai\d+",
            "p_c2": r"ai\d+",
            "p_m1": r"ai\d+",
            "laser": r"ai\d+",
            "encoder": r"ctr\d+",
            "valve_linear": r"ao\d+",
            "valve_rotary": r"ao\d+",
        }
        seen: dict[str, str] = {}
        for name, pat in pattern.items():
            value = getattr(self, name)
            if not re.fullmatch(pat, value):
                raise ParamError(name, value, f"a channel name matching {pat!r}")
            if value in seen:
                raise ParamError(name, value, f"a channel not already used by {seen[value]}")
            seen[value] = name


@dataclass(frozen=True)
class AiParams:
    """Analog input range and terminal configuration, shared by the four sensors."""

    min_v: float = param(
        -10.0,
        unit="V",
        lo=-10.0,
        hi=10.0,
        desc="AI range low (PCI-6221: ±10, ±5, ±1, ±0.2 V)",
        read_only=True,
    )
    max_v: float = param(10.0, unit="V", lo=-10.0, hi=10.0, desc="AI range high", read_only=True)
    terminal_config: str = param(
        "RSE",
        choices=_TERMINALS,
        desc="AI terminal configuration (sensors powered from a supply whose 0 V is tied to AI GND: RSE; wiring unverified)",
        read_only=True,
    )

    def _check(self) -> None:
        if not self.min_v < self.max_v:
            raise ParamError("max_v", self.max_v, f"greater than min_v = {self.min_v:g} V")


@dataclass(frozen=True)
class PressureSensor:
    """Huba 511 (0–10 bar gauge ↔ 0–10 V): p_abs = p_atm + pa_per_v · (v − v_zero)."""

    pa_per_v: float = param(
        1.0e5,
        unit="Pa/V",
        lo=0.0,
        lo_open=True,
        desc="gain",
        source="Huba 511 datasheet: 0–10 bar ↔ 0–10 V",
    )
    v_zero: float = param(
        0.0, unit="V", lo=-1.0, hi=1.0, desc="output at 0 bar gauge (calibration offset)"
    )


@dataclass(frozen=True)
class LaserParams:
    """Panasonic HG-C1200 analog voltage: x = m_per_v · (v − v_mid) + offset_m.

    0–5 V spans the 200 ± 80 mm range (160 mm / 5 V = 0.032 m/V). ``v_mid`` is
    the range centre; ``offset_m`` is where mid-stroke sits relative to it.
    The sign of ``m_per_v`` says whether the voltage rises as the piston extends.
    """

    m_per_v: float = param(
        0.032,
        unit="m/V",
        lo=-1.0,
        hi=1.0,
        desc="gain (sign: + when the voltage rises with +x)",
        source="HG-C1200: 160 mm over 0–5 V",
    )
    v_mid: float = param(
        2.5, unit="V", lo=-10.0, hi=10.0, desc="output at the range centre (200 mm)"
    )
    offset_m: float = param(
        0.0,
        unit="m",
        lo=-0.08,
        hi=0.08,
        desc="x at v_mid (mounting offset; 0 = mid-stroke at range centre)",
    )

    def _check(self) -> None:
        if self.m_per_v == 0.0:
            raise ParamError("m_per_v", self.m_per_v, "a non-zero gain in [-1, 1] m/V")


@dataclass(frozen=True)
class EncoderParams:
    """Omron E6B2-CWZ6C quadrature encoder on a counter input."""

    ppr: int = param(
        1000,
        unit="pulses/rev",
        lo=1,
        hi=100000,
        desc="pulses per revolution of one channel (E6B2: 10…2000; 1000 likely)",
        read_only=True,
    )
    decoding: str = param(
        "X4", choices=tuple(DECODING_FACTOR), desc="quadrature decoding", read_only=True
    )
    counter_bits: int = param(
        32,
        lo=8,
        hi=64,
        desc="counter register width (PCI-6221: 32), for rollover unwrapping",
        read_only=True,
    )

    @property
    def counts_per_rev(self) -> int:
        return self.ppr * DECODING_FACTOR[self.decoding]


@dataclass(frozen=True)
class AoParams:
    """Valve command outputs (MPYE: 0–10 V, 5 V = closed centre)."""

    min_v: float = param(
        0.0, unit="V", lo=-10.0, hi=10.0, desc="lowest voltage ever written", read_only=True
    )
    max_v: float = param(
        10.0, unit="V", lo=-10.0, hi=10.0, desc="highest voltage ever written", read_only=True
    )
    safe_v: float = param(
        5.0,
        unit="V",
        lo=-10.0,
        hi=10.0,
        desc="safe value: valve closed centre",
        source="Festo MPYE operating instructions",
        read_only=True,
    )

    def _check(self) -> None:
        if not self.min_v < self.max_v:
            raise ParamError("max_v", self.max_v, f"greater than min_v = {self.min_v:g} V")
        if not self.min_v <= self.safe_v <= self.max_v:
            raise ParamError("safe_v", self.safe_v, f"[{self.min_v:g}, {self.max_v:g}] V")


@dataclass(frozen=True)
class LoopParams:
    """The 1 kHz loop: pacing source and tolerances."""

    rate_hz: float = param(
        1000.0,
        unit="Hz",
        lo=10.0,
        hi=5000.0,
        desc="sample clock rate",
        source="paper: 1 ms sampling period",
        read_only=True,
    )
    timing: str = param(
        "hardware",
        choices=("hardware", "software"),
        desc="hardware: the HW-timed single-point read paces the loop; software: perf_counter deadlines, on-demand I/O",
        read_only=True,
    )
    ao_timing: str = param(
        "sample_clock",
        choices=_TIMING,
        desc="hardware timing only: AO on the AI sample clock (written at tick k+1) or on demand",
        read_only=True,
    )
    ci_timing: str = param(
        "sample_clock",
        choices=_TIMING,
        desc="hardware timing only: encoder latched on the AI sample clock or read on demand",
        read_only=True,
    )
    read_timeout_s: float = param(
        0.1,
        unit="s",
        lo=0.002,
        hi=10.0,
        desc="a read that waits longer is an error (clock stopped)",
        read_only=True,
    )
    command_deadline_us: float = param(
        700.0,
        unit="us",
        lo=0.0,
        hi=5000.0,
        desc="after a sample, wait this long at most for the controllers' commands",
    )
    spin_us: float = param(
        200.0,
        unit="us",
        lo=0.0,
        hi=5000.0,
        desc="software timing: busy-wait this long before each deadline (sleep before)",
    )
    on_time_tol_us: float = param(
        200.0,
        unit="us",
        lo=0.0,
        lo_open=True,
        desc="a cycle starting later than this after its deadline is late",
    )
    max_consecutive_late: int = param(
        100, lo=1, hi=100000, desc="this many late cycles in a row stop the driver (valves safe)"
    )
    rt_priority: int = param(
        0,
        lo=0,
        hi=99,
        desc="SCHED_FIFO priority of the loop thread (0: normal scheduling; needs root, CAP_SYS_NICE or an rtprio limit)",
        read_only=True,
    )
    timerslack_ns: int = param(
        1,
        unit="ns",
        lo=0,
        hi=10_000_000,
        desc="Linux timer slack of the loop thread (0: leave the default 50 us)",
        read_only=True,
    )
    stats_window: int = param(
        60000, lo=100, hi=10_000_000, desc="cycles kept for jitter percentiles"
    )

    def _check(self) -> None:
        period_us = 1e6 / self.rate_hz
        if self.command_deadline_us >= period_us:
            raise ParamError(
                "command_deadline_us",
                self.command_deadline_us,
                f"[0, {period_us:g}) us (less than one period)",
            )
        if self.spin_us >= period_us:
            raise ParamError(
                "spin_us", self.spin_us, f"[0, {period_us:g}) us (less than one period)"
            )


@dataclass(frozen=True)
class RigParams:
    """Everything the driver needs to turn volts and counts into a SensorSample."""

    device: str = param(
        "Dev1",
        desc="NI-DAQmx device name (NI MAX / nidaqmx.system.System.local().devices)",
        read_only=True,
    )
    p_atm_pa: float = param(
        P_ATM_PA,
        unit="Pa",
        lo=5.0e4,
        hi=1.2e5,
        desc="ambient pressure added to gauge readings",
        source="ISO 2533 standard atmosphere",
    )
    channels: ChannelMap = param(ChannelMap)
    ai: AiParams = param(AiParams)
    p_c1: PressureSensor = param(PressureSensor)
    p_c2: PressureSensor = param(PressureSensor)
    p_m1: PressureSensor = param(PressureSensor)
    laser: LaserParams = param(LaserParams)
    encoder: EncoderParams = param(EncoderParams)
    ao: AoParams = param(AoParams)
    loop: LoopParams = param(LoopParams)

    def _check(self) -> None:
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_\-]*", self.device):
            raise ParamError("device", self.device, "a DAQmx device name such as Dev1")

    @property
    def period_s(self) -> float:
        return 1.0 / self.loop.rate_hz

    @property
    def period_ns(self) -> int:
        return round(1e9 / self.loop.rate_hz)


def load_rig_params(
    path: str | Path | None = None, overrides: dict[str, Any] | None = None
) -> RigParams:
    """Read ``rig.yaml`` (default: the project's ``config/rig.yaml``) strictly: every key
    present, none unknown, none twice (:mod:`pneu_msgs_py.params.yaml_file`).

    ``overrides`` are dotted names (``{"loop.timing": "software"}``) applied as one set.
    Raises :class:`ParamError` naming the bad key, its value and the allowed range.
    """
    if path is None:
        from pneu_msgs_py.params.paths import config_file

        path = config_file("rig.yaml")
    data = load_yaml(path)
    with located(path, data):
        rig = from_dict(RigParams, data if data is not None else {}, strict=True)
    if overrides:
        rig = with_updates(rig, overrides)
    return rig
