"""The rig's DAQ map and sensor scaling (``config/rig.yaml``) as one parameter group.

NI PCI-6221 (M Series): 16-bit AI (±10 V range, LSB ≈ 0.3 mV), two 16-bit AO,
two 32-bit counters with X4 quadrature decoding. Everything a volt means is
here; :mod:`pneu_driver.daq.scaling` applies it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pneu_msgs_py.contract.units import P_ATM_PA
from pneu_msgs_py.params.core import ParamError, from_dict, param, with_updates
from pneu_msgs_py.params.yaml_file import load_yaml, located

__all__ = [
    "ChannelMap",
    "AiTerminals",
    "AiParams",
    "PressureSensor",
    "LaserParams",
    "EncoderParams",
    "AoParams",
    "HeartbeatParams",
    "LoopParams",
    "RigParams",
    "AI_SENSORS",
    "DECODING_FACTOR",
    "DIG_FILTERS",
    "ENCODER_PFI",
    "ROTARY_PLUMBINGS",
    "load_rig_params",
]

# The four analog inputs, in the order RawSample.volts carries them.
AI_SENSORS = ("p_c1", "p_c2", "p_m1", "laser")
DECODING_FACTOR = {"X1": 1, "X2": 2, "X4": 4}
# M Series AI terminal configurations (PSEUDO_DIFF is not an M Series mode)
_TERMINALS = ("DIFF", "NRSE", "RSE")
# PCI-6221: 16 single-ended or 8 differential inputs, aiN(+) paired with ai(N+8)(-), N = 0..7
# (NI-DAQmx Device Considerations, "M Series Physical Channels")
_DIFF_PAIRS = 8
# M Series PFI digital filter settings (M Series User Manual, PFI filters table): the name is
# the shortest pulse passed; the filter blocks pulses up to 100 ns / 6.4 us / 2.54 ms
DIG_FILTERS = {"off": 0.0, "125ns": 125e-9, "6.425us": 6.425e-6, "2.56ms": 2.56e-3}
# default encoder terminals per counter (M Series "Default Counter/Timer Pins"): A = SRC,
# Z = GATE, B = AUX as DO lines (PFI0-7 = port1/line0-7, PFI8-15 = port2/line0-7)
ENCODER_PFI = {
    "ctr0": {"port2/line0": "PFI8 (A)", "port2/line1": "PFI9 (Z)", "port2/line2": "PFI10 (B)"},
    "ctr1": {"port1/line3": "PFI3 (A)", "port1/line4": "PFI4 (Z)", "port2/line3": "PFI11 (B)"},
}
_TIMING = ("sample_clock", "on_demand")
# How valve #2 is piped to the motor: paper = port 4 -> motor port A, port B through a
# silencer; bidirectional = port 4 -> A, port 2 -> B (the twin's rotary.plumbing too)
ROTARY_PLUMBINGS = ("paper", "bidirectional")


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
class AiTerminals:
    """AI terminal configuration per sensor (DIFF: aiN against ai(N+8), the sensor's 0 V not AI GND).

    The pressure sensors and the laser share their 0 V with the valve supply:
    single-ended (RSE) reads every ground-loop millivolt as signal (10 mV =
    1 kPa or 0.32 mm), a differential input rejects it.
    """

    p_c1: str = param("DIFF", choices=_TERMINALS, desc="Huba 511 chamber 1", read_only=True)
    p_c2: str = param("DIFF", choices=_TERMINALS, desc="Huba 511 chamber 2", read_only=True)
    p_m1: str = param("DIFF", choices=_TERMINALS, desc="Huba 511 motor inlet", read_only=True)
    laser: str = param("DIFF", choices=_TERMINALS, desc="HG-C1200 analog output", read_only=True)


@dataclass(frozen=True)
class AiParams:
    """Analog input range (shared by the four sensors) and terminal configuration per sensor."""

    min_v: float = param(
        -10.0,
        unit="V",
        lo=-10.0,
        hi=10.0,
        desc="AI range low (PCI-6221: ±10, ±5, ±1, ±0.2 V)",
        read_only=True,
    )
    max_v: float = param(10.0, unit="V", lo=-10.0, hi=10.0, desc="AI range high", read_only=True)
    terminal: AiTerminals = param(AiTerminals)

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

    dig_filter: str = param(
        "125ns",
        choices=tuple(DIG_FILTERS),
        desc="digital filter on the A and B inputs: the shortest pulse passed (M Series: 125ns, "
        "6.425us, 2.56ms or off); see max_filtered_rpm",
        read_only=True,
    )

    @property
    def counts_per_rev(self) -> int:
        return self.ppr * DECODING_FACTOR[self.decoding]

    @property
    def max_filtered_rpm(self) -> float:
        """The highest speed whose quadrature edges the digital filter still passes [rpm].

        E6B2-C: phase A leads B by T/4 ± T/8 (Omron E6B2-C datasheet, timing chart), so
        the closest A and B edges are T/8 apart: 8 · width < 60 / (rpm · ppr).
        """
        width = DIG_FILTERS[self.dig_filter]
        return math.inf if width == 0.0 else 60.0 / (8.0 * width * self.ppr)


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
class HeartbeatParams:
    """A digital output toggled once per cycle by the loop, for an external missing-pulse relay.

    The relay (in series with the e-stop) holds the supply air on while it sees
    edges; a hung, killed or stopped loop, or a tripped supervisor, leaves the
    line still and the relay drops the supply (docs/rig.md, "Safety on the real rig").
    """

    enabled: bool = param(True, desc="toggle the line every cycle", read_only=True)
    line: str = param(
        "port0/line0",
        desc="DO line on the device (M Series: port0/line0-7 or a PFI line port1/2 not used by the encoder)",
        read_only=True,
    )
    stop_on_trip: bool = param(
        True,
        desc="stop toggling while the supervisor has a latched fault or the e-stop (the relay drops the supply)",
        read_only=True,
    )

    def _check(self) -> None:
        if not re.fullmatch(r"port\d+/line\d+", self.line):
            raise ParamError("line", self.line, "a DO line such as port0/line0")


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
    report_missed_samples: bool = param(
        True,
        desc="hardware timing: DAQmx Read reports missed sample clocks (DAQmx_RealTime_ReportMissedSamp); "
        "off, a late cycle reads a stale sample without an error",
        read_only=True,
    )
    switch_interval_us: float = param(
        200.0,
        unit="us",
        lo=0.0,
        hi=5000.0,
        desc="Python's GIL switch interval while the loop runs (sys.setswitchinterval; default 5000 us "
        "lets another thread hold the loop off for 5 ms); 0: leave it",
        read_only=True,
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
    rotary_plumbing: str = param(
        "paper",
        choices=ROTARY_PLUMBINGS,
        desc="valve #2 piping: paper = port 4 -> motor port A, port B exhausts through a"
        " silencer (one direction); bidirectional = also port 2 -> motor port B (u < 5 V"
        " brakes and reverses); ai p_m1 stays on port A",
        read_only=True,
    )
    channels: ChannelMap = param(ChannelMap)
    ai: AiParams = param(AiParams)
    p_c1: PressureSensor = param(PressureSensor)
    p_c2: PressureSensor = param(PressureSensor)
    p_m1: PressureSensor = param(PressureSensor)
    laser: LaserParams = param(LaserParams)
    encoder: EncoderParams = param(EncoderParams)
    ao: AoParams = param(AoParams)
    heartbeat: HeartbeatParams = param(HeartbeatParams)
    loop: LoopParams = param(LoopParams)

    def _check(self) -> None:
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_\-]*", self.device):
            raise ParamError("device", self.device, "a DAQmx device name such as Dev1")
        self._check_diff_pairs()
        pins = ENCODER_PFI.get(self.channels.encoder, {})
        if self.heartbeat.enabled and self.heartbeat.line in pins:
            raise ParamError(
                "heartbeat.line",
                self.heartbeat.line,
                f"a DO line not wired to {self.channels.encoder}'s encoder input "
                f"{pins[self.heartbeat.line]} (e.g. port0/line0)",
            )

    def _check_diff_pairs(self) -> None:
        """DIFF uses aiN and ai(N+8): N must be 0..7 and ai(N+8) free for it."""
        used = {getattr(self.channels, name): name for name in AI_SENSORS}
        for name in AI_SENSORS:
            if getattr(self.ai.terminal, name) != "DIFF":
                continue
            chan = getattr(self.channels, name)
            n = int(chan[2:])
            if n >= _DIFF_PAIRS:
                raise ParamError(
                    f"channels.{name}",
                    chan,
                    f"ai0..ai{_DIFF_PAIRS - 1} with ai.terminal.{name}: DIFF (aiN pairs with ai(N+8)), "
                    "or terminal NRSE/RSE",
                )
            neg = f"ai{n + _DIFF_PAIRS}"
            if neg in used:
                raise ParamError(
                    f"channels.{used[neg]}",
                    neg,
                    f"a channel other than {neg}: it is the (-) input of {name} ({chan}, DIFF)",
                )

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
