"""Parameters of ESO-SMC+ (:mod:`pneu_control.algorithms.eso_smc_plus`): gains, options, model."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

from pneu_msgs_py.contract.valve_chart import MPYE_DU_V, MPYE_FLOW
from pneu_msgs_py.params.core import ParamError, param

from pneu_control.algorithms.smc import (
    NONNEGATIVE,
    POSITIVE,
    b_0_field,
    delay_compensation_field,
    delta_field,
    epsilon_field,
    k_field,
    lambda_r_field,
    omega_0_field,
)

__all__ = ["EsoSmcPlusParams"]


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

    lambda_r: float = lambda_r_field(20.0, "design rule (module docstring)")
    omega_0: float = omega_0_field(
        30.0, "design rule (module docstring)", "observer bandwidth ω0 (all poles)"
    )
    b_0: float = b_0_field(
        2400.0,
        "1.5 × pneu tune's step-response b0",
        "input gain estimate b0 (of the linearised command)",
    )
    epsilon: float = epsilon_field(960.0)
    delta: float = delta_field(1.92)
    k: float = k_field(0.52)
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
        MPYE_DU_V,
        unit="V",
        desc="|u − 5 V| breakpoints of the valve flow curve",
        source="Festo MPYE flow-vs-setpoint chart, digitised (pneu_msgs_py.contract.valve_chart)",
    )
    valve_flow_table: tuple[float, ...] = param(
        MPYE_FLOW,
        unit="-",
        desc="normalised flow at valve_du_table",
        source="Festo MPYE flow-vs-setpoint chart, digitised (pneu_msgs_py.contract.valve_chart)",
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
    delay_compensation: bool = delay_compensation_field()
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
        **POSITIVE,
        source="pneu tune (slope of F_p after ±1 V steps)",
    )
    force_bandwidth: float = param(
        150.0,
        unit="rad/s",
        desc="linear_model force: bandwidth k_F of the inner pressure-force loop",
        **POSITIVE,
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
        1.1e-5, unit="m^3", desc="dead volume chamber 1", **POSITIVE, source="paper Table 1"
    )
    V_2d: float = param(
        0.6e-5, unit="m^3", desc="dead volume chamber 2", **POSITIVE, source="paper Table 1"
    )
    L: float = param(0.15, unit="m", desc="stroke", **POSITIVE, source="paper Table 1")
    A_c1: float = param(
        8.04e-4, unit="m^2", desc="cap-side piston area (Eq. 1)", **POSITIVE, source="paper Table 1"
    )
    A_c2: float = param(
        6.912e-4,
        unit="m^2",
        desc="rod-side annulus area (Eq. 1)",
        **POSITIVE,
        source="paper Table 1",
    )
    M: float = param(
        0.28, unit="kg", desc="moving mass (Eq. 1)", **POSITIVE, source="paper Table 1"
    )
    p_a: float = param(
        101325.0,
        unit="Pa",
        desc="ambient pressure on the rod (errata Eq. 1)",
        **POSITIVE,
        source="ISO 2533",
    )
    A_f: float = param(
        2.95,
        unit="N",
        desc="Coulomb friction level (Eq. 2)",
        **NONNEGATIVE,
        source="paper Eq. 2 fit",
    )
    c_v: float = param(
        88.81,
        unit="N*s/m",
        desc="viscous friction (Eq. 2)",
        **NONNEGATIVE,
        source="paper Eq. 2 fit",
    )
    v_s: float = param(
        10.0,
        unit="mm/s",
        desc="sign smoothing of the Coulomb term, A_f tanh(ẋ/v_s)",
        **POSITIVE,
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
