"""Controller parameter groups (one frozen dataclass each) and the YAML loader.

Gains are typed in the paper's units (DESIGN §5): the linear controller works
in mm (position), the rotary controller in rpm (speed). Each field's unit
string gives both readings, ``linear | rotary``. Topics, samples and the twin
stay SI; :class:`pneu_control.controller.axis.AxisController` converts at its boundary.

``config/controllers.yaml`` is a ROS 2 params file::

    linear_controller:
      ros__parameters:
        algorithm: eso_smc
        pid: {kp: 0.38, ...}
        ...

:func:`load_controller_params` reads ``<axis>_controller.ros__parameters``,
applies dotted overrides (``{"eso_smc.epsilon": 900}``) and validates the
whole set once (nothing half-applied).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pneu_msgs_py.params.core import ParamError, flatten, from_dict, param, with_updates

__all__ = [
    "ALGORITHMS",
    "REFERENCE_KINDS",
    "PidParams",
    "LadrcParams",
    "EsoSmcParams",
    "EsoSmcPlusParams",
    "TdParams",
    "LimitsParams",
    "ReferenceParams",
    "AxisControllerParams",
    "load_controller_params",
    "omega_0_max",
    "ParamError",
]

ALGORITHMS = ("pid", "ladrc", "eso_smc", "eso_smc_plus")
REFERENCE_KINDS = ("sine", "smooth_step", "constant", "ramp", "waypoints")

_POS = {"lo": 0.0, "lo_open": True}  # strictly positive
_NONNEG = {"lo": 0.0}


@dataclass(frozen=True)
class PidParams:
    """Parallel PID, u = u_n + Kp e + Ki ∫e dt + Kd ė_f (e = reference − measured).

    Paper (Results): linear Kp 0.38, Ki 4.6, Kd 0.0128; rotary Kp 0.25,
    Ki 0.22, Kd 0.004. The derivative is filtered (first order, time constant
    ``tf``); the paper is silent on filtering (our choice, see DESIGN §8).
    """

    kp: float = param(0.38, unit="V/mm | V/rpm", desc="proportional gain", **_POS, source="paper")
    ki: float = param(
        4.6, unit="V/(mm·s) | V/(rpm·s)", desc="integral gain", **_NONNEG, source="paper"
    )
    kd: float = param(
        0.0128, unit="V·s/mm | V·s/rpm", desc="derivative gain", **_NONNEG, source="paper"
    )
    tf: float = param(
        0.002, unit="s", desc="derivative low-pass time constant (exact ZOH discretisation)", **_POS
    )
    derivative_on: str = param(
        "error", choices=("error", "measurement"), desc="differentiate the error or −measurement"
    )
    anti_windup: str = param(
        "conditional",
        choices=("conditional", "back_calculation", "none"),
        desc="integrator anti-windup strategy",
    )
    tt: float = param(0.05, unit="s", desc="back-calculation tracking time constant", **_POS)
    y_filter_tf: float = param(
        0.0,
        unit="s",
        desc="first-order low-pass on the raw measurement before P and D (0 = off)",
        lo=0.0,
        hi=1.0,
    )


@dataclass(frozen=True)
class LadrcParams:
    """Linear ADRC (Gao 2003): linear ESO (Eq. 18, gains Eq. 17) and PD on the estimates.

    u0 = λ1² (v1 − z1) + 2 λ1 (v2 − z2),  u = (u0 − z3) / b0.
    λ1 is the controller bandwidth ω_c (critically damped PD). Paper: linear
    λ1 390, ω0 31.5, b0 5900; rotary λ1 10, ω0 15, b0 500.
    """

    lambda_1: float = param(
        390.0, unit="1/s", desc="controller bandwidth ω_c", **_POS, source="paper"
    )
    omega_0: float = param(
        31.5, unit="rad/s", desc="observer bandwidth ω0 (Eq. 17)", **_POS, source="paper"
    )
    b_0: float = param(
        5900.0, unit="mm/s²/V | rpm/s²/V", desc="input gain estimate b0", **_POS, source="paper"
    )
    accel_feedforward: bool = param(
        False, desc="add the TD's reference acceleration v3 to u0 (not in the paper)"
    )
    delay_compensation: bool = param(
        False,
        desc="predict the ESO state over the transport delay with the commands already sent "
        "and act on the prediction (not in the paper)",
    )


@dataclass(frozen=True)
class EsoSmcParams:
    """ESO-based sliding mode control (Eq. 18, 26, 28–31, corrected per errata).

    s = ė + 2 λ_R e + λ_R² ∫e dt, e = v1 − z1, ė = v2 − z2 (double pole at −λ_R);
    u = (ε sat(s) + v3 + 2 λ_R ė + λ_R² e − z3 − f_k) / b0,
    sat(s) = clamp(k s, −1, 1) for |s| ≤ Δ and sign(s) outside (Eq. 29). Only
    k = 1/Δ is continuous; the paper prints k = 0.5 with Δ = 0.1 (discontinuous
    jump from kΔ to 1 at |s| = Δ). We accept k ≤ 1/Δ and require the discrete
    boundary-layer gain ε k T < 1 (see :class:`AxisControllerParams`).
    """

    lambda_r: float = param(
        250.0, unit="1/s", desc="sliding surface pole λ_R (double)", **_POS, source="paper"
    )
    omega_0: float = param(
        25.0, unit="rad/s", desc="observer bandwidth ω0 (Eq. 17)", **_POS, source="paper"
    )
    b_0: float = param(
        3000.0, unit="mm/s²/V | rpm/s²/V", desc="input gain estimate b0", **_POS, source="paper"
    )
    epsilon: float = param(
        1200.0, unit="mm/s² | rpm/s²", desc="reaching-law gain ε (Eq. 28)", **_POS, source="paper"
    )
    delta: float = param(
        0.1,
        unit="mm/s | rpm/s",
        desc="boundary layer half-width Δ (Eq. 29)",
        **_POS,
        source="paper",
    )
    k: float = param(
        0.5,
        unit="s/mm | s/rpm",
        desc="slope of sat inside the layer (Eq. 29); continuous only for k = 1/Δ",
        **_POS,
        source="paper (k·Δ = 0.05: discontinuous, see errata)",
    )
    integral_anti_windup: bool = param(
        True,
        desc="freeze ∫e while e pushes further into a saturation (valve command, or |s| > Δ)",
    )
    delay_compensation: bool = param(
        False,
        desc="predict the ESO state over the transport delay with the commands already sent "
        "and act on the prediction (not in the paper)",
    )
    friction_compensation: bool = param(
        False,
        desc="rotary only: feed the friction torque of Eq. 9 into the ESO and the law (Eq. 31)",
    )
    M_c: float = param(
        0.1281,
        unit="N·m",
        desc="Coulomb friction torque (Eq. 9)",
        **_NONNEG,
        source="paper Table 1",
    )
    M_v: float = param(
        8.66e-5,
        unit="N·m/rpm",
        desc="viscous friction coefficient (Eq. 9)",
        **_NONNEG,
        source="paper Table 1",
    )
    J_m: float = param(
        3.5e-5,
        unit="kg·m²",
        desc="rotating inertia for M_f/J_m (paper silent)",
        **_POS,
        source="plant-parameters.md (±50 %)",
    )
    coulomb_smoothing: float = param(
        100.0,
        unit="rpm",
        desc="ω_s of the smoothed sign tanh(ω/ω_s) in Eq. 9 (our choice; bounds the ESO friction gain)",
        **_POS,
    )


# Festo MPYE flow-vs-setpoint chart (normalised flow at |u − 5 V|), digitised: the
# controller's own copy of the datasheet curve (the twin was built from the same chart)
MPYE_CHART_DU_V = (
    0.0, 0.36, 0.71, 0.94, 1.20, 1.43, 1.66, 1.86, 2.12, 2.47, 2.81, 3.16, 3.47, 3.81,
    4.20, 4.62, 4.75,
)  # fmt: skip
MPYE_CHART_FLOW = (
    0.0, 0.01, 0.03, 0.06, 0.11, 0.18, 0.26, 0.31, 0.40, 0.48, 0.59, 0.67, 0.74, 0.82,
    0.90, 0.98, 1.00,
)  # fmt: skip


@dataclass(frozen=True)
class EsoSmcPlusParams:
    """ESO-SMC+ (ours, beyond the paper): see :mod:`pneu_control.algorithms.eso_smc_plus`.

    The ESO-SMC law and surface (double pole at −λ_R, reaching law ε sat(s))
    with (1) on the rotary axis a 4-state ESO on the encoder *angle*
    (θ‴ = f + b0 u), so that the surface's ∫e_ω is the measured angle error;
    (2) the valve's static flow curve inverted (Festo chart), so that b0 holds
    over the whole opening range; (3) analytic reference derivatives where the
    reference is known exactly.
    """

    lambda_r: float = param(
        20.0, unit="1/s", desc="sliding surface pole λ_R (double)", **_POS, source="pneu tune"
    )
    omega_0: float = param(
        30.0, unit="rad/s", desc="observer bandwidth ω0 (all poles)", **_POS, source="pneu tune"
    )
    b_0: float = param(
        2400.0,
        unit="mm/s²/V | rpm/s²/V",
        desc="input gain estimate b0 (of the linearised command)",
        **_POS,
        source="pneu tune (step response)",
    )
    epsilon: float = param(
        960.0, unit="mm/s² | rpm/s²", desc="reaching-law gain ε (Eq. 28)", **_POS
    )
    delta: float = param(
        1.92, unit="mm/s | rpm/s", desc="boundary layer half-width Δ (Eq. 29)", **_POS
    )
    k: float = param(
        0.52, unit="s/mm | s/rpm", desc="slope of sat inside the layer (k = 1/Δ continuous)", **_POS
    )
    reference_derivatives: str = param(
        "analytic",
        choices=("analytic", "td"),
        desc="reference and derivatives: analytic (exact, no TD lag) or the TD (soft start)",
    )
    rotary_observer: str = param(
        "angle",
        choices=("angle", "speed"),
        desc="rotary: 4-state ESO on the encoder angle (θ‴ = f + b0 u) or the paper's "
        "3-state ESO on the quantised speed; ignored on the linear axis",
    )
    valve_linearisation: bool = param(
        False, desc="invert the valve's static flow curve (valve_du_table/valve_flow_table)"
    )
    valve_du_table: tuple[float, ...] = param(
        MPYE_CHART_DU_V,
        unit="V",
        desc="|u − 5 V| breakpoints of the valve flow curve",
        source="Festo MPYE flow-vs-setpoint chart, digitised",
    )
    valve_flow_table: tuple[float, ...] = param(
        MPYE_CHART_FLOW,
        unit="-",
        desc="normalised flow at valve_du_table",
        source="Festo MPYE flow-vs-setpoint chart, digitised",
    )
    valve_unit_v: float = param(
        1.0,
        unit="V",
        desc="opening where the linearised command equals the raw one (b0 is identified there)",
        lo=0.0,
        lo_open=True,
        hi=4.0,
        source="pneu tune identifies b0 with ±1 V steps",
    )
    delay_compensation: bool = param(
        False,
        desc="predict the ESO state over the transport delay with the commands already sent",
    )
    linear_model: str = param(
        "position",
        choices=("position", "force"),
        desc="linear: ESO-SMC on the laser position (ẍ = f + b0 u), or the cascade on the "
        "measured chamber pressures: the surface asks for a piston force (with the Eq. 2 "
        "friction), an inner loop makes the pressure force F_p (Eq. 1) follow it",
    )
    friction_feedforward: bool = param(
        False,
        desc="linear_model position: feed the Eq. 2 friction of the reference speed forward "
        "through the pressure rate, u_ff = (d/dt) F_f(ṙ) / b_F",
    )
    b_F: float = param(
        500.0,
        unit="N/s/V",
        desc="linear_model force: rate of the pressure force per volt of valve command",
        **_POS,
        source="pneu tune (slope of F_p after ±1 V steps)",
    )
    force_bandwidth: float = param(
        150.0,
        unit="rad/s",
        desc="linear_model force: bandwidth k_F of the inner pressure-force loop",
        **_POS,
        source="rule: k_F = 1/(3 τ_p), τ_p = 2.3 ms pressure-sensor lag (Huba 511)",
    )
    n_poly: float = param(
        1.2,
        unit="-",
        desc="polytropic index of the chamber process",
        lo=1.0,
        hi=1.4,
        source="as the twin (plant.yaml ambient.n_poly)",
    )
    V_1d: float = param(
        1.1e-5, unit="m^3", desc="dead volume chamber 1", **_POS, source="paper Table 1"
    )
    V_2d: float = param(
        0.6e-5, unit="m^3", desc="dead volume chamber 2", **_POS, source="paper Table 1"
    )
    L: float = param(0.15, unit="m", desc="stroke", **_POS, source="paper Table 1")
    A_c1: float = param(
        8.04e-4, unit="m^2", desc="cap-side piston area (Eq. 1)", **_POS, source="paper Table 1"
    )
    A_c2: float = param(
        6.912e-4, unit="m^2", desc="rod-side annulus area (Eq. 1)", **_POS, source="paper Table 1"
    )
    M: float = param(0.28, unit="kg", desc="moving mass (Eq. 1)", **_POS, source="paper Table 1")
    p_a: float = param(
        101325.0,
        unit="Pa",
        desc="ambient pressure on the rod (errata Eq. 1)",
        **_POS,
        source="ISO 2533",
    )
    A_f: float = param(
        2.95, unit="N", desc="Coulomb friction level (Eq. 2)", **_NONNEG, source="paper Eq. 2 fit"
    )
    c_v: float = param(
        88.81, unit="N*s/m", desc="viscous friction (Eq. 2)", **_NONNEG, source="paper Eq. 2 fit"
    )
    v_s: float = param(
        10.0,
        unit="mm/s",
        desc="sign smoothing of the Coulomb term, A_f tanh(ẋ/v_s)",
        **_POS,
        source="order of the seal Stribeck velocity (plant-parameters.md)",
    )

    def _check(self) -> None:
        if not self.A_c2 < self.A_c1:
            raise ParamError("A_c2", self.A_c2, f"(0, A_c1 = {self.A_c1:g}) m^2")
        du, fl = self.valve_du_table, self.valve_flow_table
        if len(du) < 2 or len(du) != len(fl):
            raise ParamError(
                "valve_flow_table", list(fl), f"{len(du)} values, one per valve_du_table entry"
            )
        if du[0] != 0.0 or any(b <= a for a, b in itertools.pairwise(du)) or du[-1] > 5.0:
            raise ParamError(
                "valve_du_table", list(du), "strictly increasing from 0 to at most 5 V"
            )
        if fl[0] != 0.0 or fl[-1] != 1.0 or any(b <= a for a, b in itertools.pairwise(fl)):
            raise ParamError("valve_flow_table", list(fl), "strictly increasing from 0 to 1")
        if self.valve_unit_v >= du[-1]:
            raise ParamError(
                "valve_unit_v", self.valve_unit_v, f"(0, {du[-1]:g}) V (inside the table)"
            )


@dataclass(frozen=True)
class TdParams:
    """Tracking differentiator (Eq. 23–24, fhan of Han 2009) on the reference.

    ``r`` bounds the reference acceleration d²v1/dt² (mm/s² linear, rpm/s²
    rotary); ``h`` is fhan's filter factor h0 (≥ the sample time).
    Used by LADRC and ESO-SMC; PID uses the reference directly.
    """

    enabled: bool = param(True, desc="use the TD; off = analytic reference derivatives")
    r: float = param(50000.0, unit="mm/s² | rpm/s²", desc="speed factor r", **_POS, source="paper")
    h: float = param(
        0.001, unit="s", desc="filter factor h (≥ sample time)", **_POS, source="paper"
    )


@dataclass(frozen=True)
class LimitsParams:
    """Valve command limits: MPYE 0–10 V, 5 V closed centre."""

    u_min: float = param(0.0, unit="V", desc="lowest valve command", lo=0.0, hi=10.0)
    u_max: float = param(10.0, unit="V", desc="highest valve command", lo=0.0, hi=10.0)
    u_neutral: float = param(5.0, unit="V", desc="closed-centre command (u = 0)", lo=0.0, hi=10.0)

    def _check(self) -> None:
        if not self.u_min < self.u_neutral < self.u_max:
            raise ParamError(
                "u_neutral",
                self.u_neutral,
                f"strictly between u_min = {self.u_min:g} V and u_max = {self.u_max:g} V",
            )


@dataclass(frozen=True)
class ReferenceParams:
    """Reference signal, in paper units (mm linear position, rpm rotary speed).

    kinds:
      - ``sine``: offset + amplitude·sin(2π f (t − t0))
      - ``smooth_step``: Eq. 38 generalised, offset → target in duration_s
      - ``constant``: value
      - ``ramp``: offset + slope·(t − t0), held after duration_s (0 = never)
      - ``waypoints``: quintic Hermite through (t, value) rows of ``file``
    Before ``t0_s`` every kind holds its value at t0.
    """

    kind: str = param("sine", choices=REFERENCE_KINDS, desc="reference type")
    amplitude: float = param(20.0, unit="mm | rpm", desc="sine amplitude", source="paper")
    frequency_hz: float = param(0.25, unit="Hz", desc="sine frequency", lo=0.0, source="paper")
    offset: float = param(0.0, unit="mm | rpm", desc="sine offset; start of smooth_step and ramp")
    target: float = param(
        120.0 / math.pi, unit="mm | rpm", desc="smooth_step end value", source="paper Eq. 38"
    )
    duration_s: float = param(
        4.0,
        unit="s",
        desc="smooth_step duration; ramp duration (0 = endless)",
        lo=0.0,
        source="paper Eq. 38",
    )
    value: float = param(800.0, unit="mm | rpm", desc="constant value", source="paper (800 rpm)")
    slope: float = param(0.0, unit="mm/s | rpm/s", desc="ramp slope")
    file: str = param("", desc="waypoint file (CSV t,value or YAML), paper units")
    t0_s: float = param(0.0, unit="s", desc="start time; the reference holds before it", lo=0.0)

    def _check(self) -> None:
        if self.kind == "sine" and self.frequency_hz <= 0.0:
            raise ParamError("frequency_hz", self.frequency_hz, "(0, Nyquist) Hz for a sine")
        if self.kind == "smooth_step" and self.duration_s <= 0.0:
            raise ParamError("duration_s", self.duration_s, "(0, inf) s for a smooth_step")
        if self.kind == "waypoints" and not self.file:
            raise ParamError("file", self.file, "a CSV or YAML waypoint file for kind waypoints")


def omega_0_max(sample_time_s: float) -> float:
    """Largest accepted observer bandwidth: the Nyquist frequency π/T (rad/s).

    The ZOH current observer is stable for every ω0 > 0 (poles exp(−ω0 T));
    above π/T a continuous bandwidth has no meaning on the sampled signal.
    """
    return math.pi / sample_time_s


@dataclass(frozen=True)
class AxisControllerParams:
    """Everything one axis controller needs, validated as one set."""

    algorithm: str = param("eso_smc", choices=ALGORITHMS, desc="active control algorithm")
    pid: PidParams = param(PidParams)
    ladrc: LadrcParams = param(LadrcParams)
    eso_smc: EsoSmcParams = param(EsoSmcParams)
    eso_smc_plus: EsoSmcPlusParams = param(EsoSmcPlusParams)
    td: TdParams = param(TdParams)
    limits: LimitsParams = param(LimitsParams)
    reference: ReferenceParams = param(ReferenceParams)
    sample_time_s: float = param(
        0.001,
        unit="s",
        desc="controller period T",
        lo=0.0,
        lo_open=True,
        hi=0.1,
        read_only=True,
        source="paper (1 ms)",
    )
    transport_delay_samples: int = param(
        1,
        desc="samples between a sample and the start of the command computed from it (DESIGN §3); "
        "the ESO predicts with the command actually on the valve",
        lo=0,
        hi=5,
        read_only=True,
    )
    rotary_model: str = param(
        "speed",
        choices=("speed", "angle"),
        desc="rotary LADRC/ESO-SMC plant model: speed (ω̈ = f + b0 u, b0 rpm/s²/V) or angle "
        "(θ̈ = f + b0 u on θ_r = ∫ω_r, b0 rpm/s/V); ignored on the linear axis",
        read_only=True,
    )
    bumpless_time_s: float = param(
        0.1,
        unit="s",
        desc="time constant of the decaying offset that blends a switched algorithm's first "
        "command into the last one (no jump; per-sample change ≤ offset·T/τ)",
        lo=0.0,
        lo_open=True,
        hi=10.0,
    )

    def _check(self) -> None:
        T = self.sample_time_s
        smc = self.eso_smc
        if smc.friction_compensation:
            from pneu_msgs_py.contract.units import RPM_PER_RAD_S

            c_max = RPM_PER_RAD_S / smc.J_m * (smc.M_v + smc.M_c / smc.coulomb_smoothing)
            if c_max * T >= 1.0:
                ws_min = smc.M_c / (1.0 / (T * RPM_PER_RAD_S / smc.J_m) - smc.M_v)
                raise ParamError(
                    "eso_smc.coulomb_smoothing",
                    smc.coulomb_smoothing,
                    f"({ws_min:.6g}, inf) rpm so that the friction damping gain "
                    f"c = κ(M_v + M_c/ω_s)/J_m stays below 1/T (now {c_max:.4g} 1/s)",
                )
        w_max = omega_0_max(T)
        for group in ("ladrc", "eso_smc", "eso_smc_plus"):
            w0 = getattr(self, group).omega_0
            if w0 > w_max:
                raise ParamError(
                    f"{group}.omega_0", w0, f"(0, {w_max:.6g}] rad/s (π/T at T = {T:g} s)"
                )
        f_nyq = 0.5 / T
        if self.reference.frequency_hz >= f_nyq:
            raise ParamError(
                "reference.frequency_hz",
                self.reference.frequency_hz,
                f"[0, {f_nyq:g}) Hz (below Nyquist 1/(2T) at T = {T:g} s)",
            )
        if self.td.h < T * (1.0 - 1e-9):
            raise ParamError("td.h", self.td.h, f"[{T:g}, inf) s (at least the sample time)")
        if smc.k * smc.delta > 1.0 + 1e-12:
            raise ParamError(
                "eso_smc.k",
                smc.k,
                f"(0, 1/Δ = {1.0 / smc.delta:g}] (sat must not exceed 1 in the layer)",
            )
        gain = smc.epsilon * smc.k * T
        if gain >= 1.0:
            raise ParamError(
                "eso_smc.k",
                smc.k,
                f"(0, {1.0 / (smc.epsilon * T):.6g}) so that ε·k·T < 1 (discrete boundary layer "
                f"stable with a one-sample delay; ε = {smc.epsilon:g}, T = {T:g} s)",
            )
        plus = self.eso_smc_plus
        if plus.k * plus.delta > 1.0 + 1e-12:
            raise ParamError(
                "eso_smc_plus.k",
                plus.k,
                f"(0, 1/Δ = {1.0 / plus.delta:g}] (sat must not exceed 1 in the layer)",
            )
        if plus.epsilon * plus.k * T >= 1.0:
            raise ParamError(
                "eso_smc_plus.k",
                plus.k,
                f"(0, {1.0 / (plus.epsilon * T):.6g}) so that ε·k·T < 1 (ε = {plus.epsilon:g}, "
                f"T = {T:g} s)",
            )


def _find_controllers_yaml() -> Path:
    try:
        from pneu_msgs_py.params.paths import config_file

        p = config_file("controllers.yaml")
        if p.is_file():
            return p
    except FileNotFoundError:
        pass
    here = Path(__file__).resolve()
    for parent in here.parents:
        cand = parent / "config" / "controllers.yaml"
        if cand.is_file():
            return cand
    raise FileNotFoundError("config/controllers.yaml not found: set PNEU_CONFIG_DIR")


def _section(data: Any, axis: str, path: Path) -> Mapping[str, Any]:
    key = f"{axis}_controller"
    if not isinstance(data, Mapping) or key not in data:
        raise ParamError(key, None, f"a top-level '{key}:' section in {path}")
    node = data[key]
    if not isinstance(node, Mapping) or "ros__parameters" not in node:
        raise ParamError(f"{key}.ros__parameters", None, f"a 'ros__parameters:' mapping in {path}")
    params = node["ros__parameters"]
    if not isinstance(params, Mapping):
        raise ParamError(f"{key}.ros__parameters", params, "a mapping")
    return params


def params_from_mapping(data: Mapping[str, Any]) -> AxisControllerParams:
    """Build from a nested (YAML-shaped) mapping; missing keys take defaults."""
    return from_dict(AxisControllerParams, data, strict=False)


def load_controller_params(
    axis: str,
    path: str | Path | None = None,
    overrides: Mapping[str, object] | None = None,
) -> AxisControllerParams:
    """Read ``<axis>_controller.ros__parameters`` of ``path`` (default config/controllers.yaml).

    ``overrides`` are dotted names (``"eso_smc.epsilon": 900``) applied on top
    and validated with the file's values as one set; the reference (and its
    waypoint file) is checked by building it.
    """
    import yaml

    if axis not in ("linear", "rotary"):
        raise ParamError("axis", axis, "one of linear, rotary")
    p = Path(path) if path is not None else _find_controllers_yaml()
    with open(p, encoding="utf-8") as fh:
        data = yaml.safe_load(fh)
    params = params_from_mapping(_section(data, axis, p))
    if overrides:
        params = with_updates(params, dict(overrides))
    from pneu_control.controller.references import make_reference

    make_reference(params.reference, axis, sample_time_s=params.sample_time_s)
    return params


def flat_params(params: AxisControllerParams) -> dict[str, Any]:
    """Dotted-name view (what ``ros2 param list`` shows)."""
    return flatten(params)
