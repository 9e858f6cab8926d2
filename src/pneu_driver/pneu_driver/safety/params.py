"""Thresholds of every safety rule (``config/safety.yaml``), validated once."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pneu_msgs_py.params.core import ParamError, from_dict, param, with_updates
from pneu_msgs_py.params.yaml_file import load_yaml, located

from pneu_driver.safety.rules import LATE_POLICIES

__all__ = ["SafetyParams", "check_plumbing", "load_safety_params"]


@dataclass(frozen=True)
class SafetyParams:
    """Thresholds of every rule (``config/safety.yaml``); defaults are the safe ones.

    Values that would silently disable a protection (negative margins, a
    watchdog longer than 1 s, a speed limit above the rated speed) are refused
    unless ``allow_unsafe`` is true; :meth:`unsafe_overrides` lists them so a
    run can record them in its bag metadata.
    """

    allow_unsafe: bool = param(
        False, desc="accept parameters that weaken a protection (reported in the bag metadata)"
    )
    # command watchdog
    watchdog_ms: float = param(
        50.0,
        unit="ms",
        lo=0.0,
        lo_open=True,
        hi=60000.0,
        desc="no fresh command for this long: the controller is gone → that valve safe (latched)",
        source="a controller silent for 50 periods is gone, not late: latched (the heartbeat "
        "stops, an operator acknowledges); its valve is closed (5 V) already from "
        "late_hold_ms on, so this bounds the time to the latch, not the motion; 2.5x "
        "late_hold_ms: a burst of 21-49 late ticks closes the valve for its rest and the axis "
        "resumes without an operator",
    )
    # late commands: the tick's output when the axis' command does not answer the newest sample
    late_policy: str = param(
        "hold",
        choices=LATE_POLICIES,
        desc="an axis' command late for a tick (older than one period when the output takes "
        "effect): hold = the last command; ramp = from the last command linearly to 5 V over "
        "late_ramp_ms; trip = the axis safe at the first late tick (latched, late_command). "
        "hold and ramp act for late_hold_ms, then 5 V (not latched) until the command is fresh "
        "again or watchdog_ms latches it",
        source="hold: at 1 kHz a late controller's next commands are close to its last one: "
        "ESO-SMC on the twin, a burst of 20 late ticks with the controllers computing, off "
        "the undisturbed run by 0.55 mm / 15 rpm held, 0.44 mm / 180 rpm ramped, the axis "
        "lost with trip (DESIGN §14); the stroke and angle soft limits act on the held output "
        "on every sample",
    )
    late_hold_ms: float = param(
        20.0,
        unit="ms",
        lo=0.0,
        hi=1000.0,
        desc="late commands are held (or ramped) this long, then 5 V until fresh again",
        allowed="[0, 1000] ms, less than watchdog_ms",
        source="bursts of a few to ~20 late 1 ms ticks in the separate-process deployment on a "
        "loaded 2-core machine (issue 19) ride through; held 20 ms the piston moves 25 mm at "
        "the twin's top speed (1.25 m/s, valve fully open), 10 mm at the 0.5 m/s the braking "
        "rule is sized for, while the stroke soft limits (hold at the braking way, trip at the "
        "limit) act on every sample; the motor at max_speed_rpm turns 180°, within "
        "angle_lag_ms = 20 ms of the angle rule's braking way",
    )
    late_ramp_ms: float = param(
        20.0,
        unit="ms",
        lo=0.0,
        hi=1000.0,
        desc="late_policy ramp: from the last command to 5 V over this long (0: 5 V at the first "
        "late tick, not latched)",
        allowed="[0, 1000] ms, at most late_hold_ms",
        source="= late_hold_ms: the ramp reaches 5 V as the hold ends, no step",
    )
    publisher_trip: bool = param(
        False,
        desc="more than one publisher on an axis' valve command topic (the count the ROS graph "
        "shows the driver or sim node, once a second) trips that axis safe (latched); off: "
        "reported in /diagnostics only",
    )
    # stroke soft limits (linear axis)
    stroke_m: float = param(
        0.150,
        unit="m",
        lo=0.0,
        lo_open=True,
        hi=2.0,
        desc="cylinder stroke; x = 0 at mid-stroke",
        source="Festo DSBC-32-150",
    )
    stroke_margin_m: float = param(
        0.010, unit="m", lo=-0.5, hi=0.5, desc="soft limit this far inside each end stop"
    )
    stroke_hyst_m: float = param(
        0.001,
        unit="m",
        lo=0.0,
        hi=0.05,
        desc="leave the soft-limit zone only this far back inside it",
    )
    max_decel_m_s2: float = param(
        20.0,
        unit="m/s^2",
        lo=0.0,
        lo_open=True,
        hi=1.0e4,
        desc="braking deceleration assumed for the braking distance v²/(2a)",
    )
    velocity_window_ms: float = param(
        10.0,
        unit="ms",
        lo=0.0,
        lo_open=True,
        hi=1000.0,
        desc="piston velocity from the position difference over this window",
    )
    extend_above_neutral: bool = param(
        True, desc="valve #1 above 5 V drives the piston toward +x (extending)"
    )
    position_margin_m: float = param(
        0.005,
        unit="m",
        lo=-0.5,
        hi=0.5,
        desc="x beyond an end stop by more than this is implausible",
    )
    # rotary axis
    max_speed_rpm: float = param(
        1500.0,
        unit="rpm",
        lo=0.0,
        lo_open=True,
        hi=1.0e5,
        desc="motor speed above this → rotary valve safe (latched)",
    )
    rated_speed_rpm: float = param(
        6000.0,
        unit="rpm",
        lo=0.0,
        lo_open=True,
        hi=1.0e5,
        desc="rating: min(Gast 1AM free speed ≈ 10 000 rpm, encoder 100 kHz / 1000 P/R = 6000 rpm)",
        source="Gast 1AM catalogue (UNV); Omron E6B2-CWZ6C datasheet",
    )
    speed_window_ms: float = param(
        10.0,
        unit="ms",
        lo=0.0,
        lo_open=True,
        hi=1000.0,
        desc="speed for the overspeed rule from counts over this window",
    )
    counts_per_rev: int = param(
        4000,
        unit="counts/rev",
        lo=1,
        hi=10_000_000,
        desc="encoder counts per revolution (rig.yaml encoder.ppr × decoding)",
    )
    max_accel_rad_s2: float = param(
        5.0e4,
        unit="rad/s^2",
        lo=0.0,
        hi=1.0e7,
        desc="a count step deviating from the previous speed by more than this acceleration allows is a jump",
    )
    encoder_slack_counts: int = param(
        2, unit="counts", lo=0, hi=1000, desc="quantisation allowance added to the jump bound"
    )
    # pressures (absolute)
    supply_linear_pa: float = param(
        301325.0,
        unit="Pa",
        lo=1.0e5,
        hi=2.0e6,
        desc="valve #1 supply, absolute (paper 0.2 MPa read as gauge)",
    )
    supply_rotary_pa: float = param(
        501325.0,
        unit="Pa",
        lo=1.0e5,
        hi=2.0e6,
        desc="valve #2 supply, absolute (paper 0.4 MPa read as gauge)",
    )
    pressure_margin_pa: float = param(
        5.0e4,
        unit="Pa",
        lo=-1.0e6,
        hi=1.0e6,
        desc="a pressure above supply + margin is implausible",
    )
    # angle soft limits (rotary axis): off by default (a free spindle may turn forever)
    angle_limits: bool = param(
        False,
        desc="rotary soft limits on: a tool on a hose or a cable cannot turn forever",
    )
    angle_min_deg: float = param(
        -3600.0,
        unit="°",
        lo=-1.0e6,
        hi=1.0e6,
        desc="lowest angle the tool on the motor tolerates (θ = 0 where the encoder count "
        "started); the soft limit is angle_margin_deg inside it",
        allowed="[-1e+06, 1e+06] °, less than angle_max_deg",
    )
    angle_max_deg: float = param(
        3600.0,
        unit="°",
        lo=-1.0e6,
        hi=1.0e6,
        desc="highest angle the tool on the motor tolerates; the soft limit is "
        "angle_margin_deg inside it",
        allowed="[-1e+06, 1e+06] °, more than angle_min_deg",
    )
    angle_margin_deg: float = param(
        30.0,
        unit="°",
        lo=-3600.0,
        hi=3600.0,
        desc="angle soft limit this far inside each end of [angle_min_deg, angle_max_deg]",
    )
    angle_hyst_deg: float = param(
        1.0,
        unit="°",
        lo=0.0,
        hi=90.0,
        desc="leave the angle soft-limit zone only this far back inside it",
    )
    angle_lag_ms: float = param(
        20.0,
        unit="ms",
        lo=0.0,
        hi=1000.0,
        desc="the motor turns on at its speed this long once held (transport delay, spool, the "
        "chambers' trapped or venting air): the braking angle's ω·t_lag",
    )
    max_decel_rad_s2: float = param(
        5000.0,
        unit="rad/s^2",
        lo=0.0,
        lo_open=True,
        hi=1.0e6,
        desc="motor deceleration once held, for the braking angle's ω²/(2a)",
    )
    # stalled rotation: driven, yet not turning (dead encoder or blocked rotor)
    rotary_plumbing: str = param(
        "paper",
        choices=("paper", "bidirectional"),
        desc="which valve #2 directions drive the motor: paper = above 5 V only (port B "
        "vents); bidirectional = both (port 2 -> port B); must be the rig's rotary_plumbing "
        "and the twin's rotary.plumbing",
    )
    stall_band_v: float = param(
        0.3,
        unit="V",
        lo=0.0,
        hi=4.5,
        desc="paper plumbing: valve #2 above 5 V + this drives the motor (port B vents: the "
        "inlet's pressure is the drive); inside it: holding, not driving",
    )
    stall_band_bidir_v: float = param(
        1.0,
        unit="V",
        lo=0.0,
        hi=4.5,
        desc="bidirectional plumbing: valve #2 beyond 5 V ± this drives the motor either way "
        "(port B's pressure is not measured: an angle held against friction may keep the "
        "valve off centre with both chambers pressurised)",
    )
    stall_inlet_pa: float = param(
        2.51325e5,
        unit="Pa",
        lo=1.0e5,
        hi=2.0e6,
        desc="forward drive counts only with the inlet p_m1 (absolute) above this: 1.5 bar "
        "gauge, over 2x the Coulomb level M_c/K = 0.128 N*m / 1.87e-6 m^3 = 68 kPa "
        "(paper Table 1, twin); reverse drive: port B's pressure is not measured",
    )
    stall_speed_rpm: float = param(
        5.0,
        unit="rpm",
        lo=0.0,
        lo_open=True,
        hi=1000.0,
        desc="|motor speed| over speed_window_ms below this is not turning",
    )
    stall_ms: float = param(
        100.0,
        unit="ms",
        lo=0.0,
        lo_open=True,
        hi=1000.0,
        desc="driven (valve beyond the band, and forward p_m1 above stall_inlet_pa) yet below "
        "stall_speed_rpm for longer than this: dead encoder or blocked rotor -> rotary safe",
    )
    # frozen values and live voltage ranges
    stuck_ms: float = param(
        250.0,
        unit="ms",
        lo=0.0,
        lo_open=True,
        hi=60000.0,
        desc="an analog value bit-identical for longer than this is frozen",
    )
    pressure_live_v: tuple[float, float] = param(
        (-0.3, 10.3), unit="V", desc="Huba 511 output outside this is a broken wire / dead sensor"
    )
    laser_live_v: tuple[float, float] = param(
        (-0.3, 5.3), unit="V", desc="HG-C1200 output outside this is a lost beam / broken wire"
    )

    def _check(self) -> None:
        for name in ("pressure_live_v", "laser_live_v"):
            rng = getattr(self, name)
            if len(rng) != 2 or not rng[0] < rng[1]:
                raise ParamError(name, list(rng), "[lo, hi] volts with lo < hi")
        if self.stroke_margin_m >= self.stroke_m / 2:
            raise ParamError(
                "stroke_margin_m",
                self.stroke_margin_m,
                f"less than half the stroke ({self.stroke_m / 2:g} m)",
            )
        if not self.angle_min_deg < self.angle_max_deg:
            raise ParamError(
                "angle_max_deg",
                self.angle_max_deg,
                f"more than angle_min_deg ({self.angle_min_deg:g} °), at most 1e+06 °",
            )
        half = (self.angle_max_deg - self.angle_min_deg) / 2.0
        if self.angle_margin_deg >= half:
            raise ParamError(
                "angle_margin_deg",
                self.angle_margin_deg,
                f"less than half the angle range ({half:g} °)",
            )
        if not self.late_hold_ms < self.watchdog_ms:
            raise ParamError(
                "late_hold_ms",
                self.late_hold_ms,
                f"[0, {self.watchdog_ms:g}) ms, less than watchdog_ms (a controller that is "
                "gone must trip)",
            )
        if self.late_ramp_ms > self.late_hold_ms:
            raise ParamError(
                "late_ramp_ms",
                self.late_ramp_ms,
                f"[0, {self.late_hold_ms:g}] ms, at most late_hold_ms (the ramp ends within the hold)",
            )
        if self.allow_unsafe:
            return
        if self.angle_margin_deg < 0.0:
            raise ParamError(
                "angle_margin_deg", self.angle_margin_deg, "≥ 0 ° (or set allow_unsafe: true)"
            )
        if self.stroke_margin_m < 0.0:
            raise ParamError(
                "stroke_margin_m", self.stroke_margin_m, "≥ 0 m (or set allow_unsafe: true)"
            )
        if self.position_margin_m < 0.0:
            raise ParamError(
                "position_margin_m", self.position_margin_m, "≥ 0 m (or set allow_unsafe: true)"
            )
        if self.pressure_margin_pa < 0.0:
            raise ParamError(
                "pressure_margin_pa", self.pressure_margin_pa, "≥ 0 Pa (or set allow_unsafe: true)"
            )
        if self.watchdog_ms > 1000.0:
            raise ParamError(
                "watchdog_ms", self.watchdog_ms, "(0, 1000] ms (or set allow_unsafe: true)"
            )
        if self.max_speed_rpm > self.rated_speed_rpm:
            raise ParamError(
                "max_speed_rpm",
                self.max_speed_rpm,
                f"(0, {self.rated_speed_rpm:g}] rpm = rated_speed_rpm (or set allow_unsafe: true)",
            )

    def unsafe_overrides(self) -> tuple[str, ...]:
        """Which protections these values weaken (empty when all are within the safe bounds)."""
        out = []
        if self.stroke_margin_m < 0.0:
            out.append(
                f"stroke_margin_m={self.stroke_margin_m:g} m < 0: soft limit beyond the end stops"
            )
        if self.position_margin_m < 0.0:
            out.append(f"position_margin_m={self.position_margin_m:g} m < 0")
        if self.angle_margin_deg < 0.0:
            out.append(
                f"angle_margin_deg={self.angle_margin_deg:g} ° < 0: angle soft limit beyond the range"
            )
        if self.pressure_margin_pa < 0.0:
            out.append(f"pressure_margin_pa={self.pressure_margin_pa:g} Pa < 0")
        if self.watchdog_ms > 1000.0:
            out.append(f"watchdog_ms={self.watchdog_ms:g} ms > 1000 ms")
        if self.max_speed_rpm > self.rated_speed_rpm:
            out.append(
                f"max_speed_rpm={self.max_speed_rpm:g} > rated_speed_rpm={self.rated_speed_rpm:g}"
            )
        return tuple(out)


def check_plumbing(params: SafetyParams, plumbing: str, source: str) -> None:
    """Refuse a supervisor whose ``rotary_plumbing`` is not the hardware's ``plumbing`` (named
    by ``source``): the stall rule reads from it which valve directions drive the motor."""
    if params.rotary_plumbing != plumbing:
        raise ParamError(
            "rotary_plumbing",
            params.rotary_plumbing,
            f"{plumbing!r}, {source} (config/safety.yaml: the stall rule must know which "
            "valve directions drive the motor)",
        )


def load_safety_params(
    path: str | Path | None = None, overrides: dict[str, Any] | None = None
) -> SafetyParams:
    """Read ``safety.yaml`` (default: the project's ``config/safety.yaml``) strictly: every key
    present, none unknown, none twice (:mod:`pneu_msgs_py.params.yaml_file`)."""
    if path is None:
        from pneu_msgs_py.params.paths import config_file

        path = config_file("safety.yaml")
    data = load_yaml(path)
    with located(path, data):
        params = from_dict(SafetyParams, data if data is not None else {}, strict=True)
    if overrides:
        params = with_updates(params, overrides)
    return params
