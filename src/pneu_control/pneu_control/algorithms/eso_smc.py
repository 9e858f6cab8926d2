"""ESO-based sliding mode control (paper §4, Eq. 18, 23–31), derived afresh (errata).

Model (Eq. 25 with the total disturbance estimated by the ESO)::

    ÿ = f + f_k + b0 u,     z3 ≈ f        (f_k: known part, rotary friction only)

Error and surface (e = reference − measured, with the TD's v1, v2, v3 = ẍ_r)::

    e = v1 − z1,  ė = v2 − z2,  s = ė + 2 λ e + λ² ∫e dt            (Eq. 26 fixed)
    ṡ = ë + 2λ ė + λ² e = v3 − (f + f_k + b0 u) + 2λ ė + λ² e

Imposing the reaching law ṡ = −ε sat(s) (Eq. 28) gives the control law::

    u = (ε sat(s) + v3 + 2λ ė + λ² e − z3 − f_k) / b0               (Eq. 30/31 fixed)

z3 is the whole unknown disturbance: f(x) is not subtracted again (errata
Eq. 30). On s = 0: ë + 2λė + λ²e = −ṡ = 0 → E(p)/S(p) = p/(p + λ)², a double
pole at −λ; with ṡ = 0 the error decays as (1 + λt) e^{−λt}.

sat (Eq. 29): sign(s) for |s| > Δ, k s inside. Continuous only for k = 1/Δ;
the paper's k = 0.5, Δ = 0.1 is accepted (discontinuous) as printed. The
discrete boundary layer s(k+1) = s(k) − T ε k s(k−1) needs T ε k < 1
(checked by :class:`~pneu_control.controller.params.AxisControllerParams`).

∫e uses the rectangle rule. With ``integral_anti_windup`` (conditional
integration) the step is skipped while e pushes further into a saturation:
the valve command (u at a limit) or the reaching law (|s| > Δ with e of the
sign of s). Without the second condition a large λ²∫e keeps sat(s) = ±1 and,
because |ṡ| ≤ ε, leaves an offset e = ∓ε/λ² (0.019 mm with the paper's linear
gains) for |s|/ε seconds (tens of seconds after a blocked axis). The error
dynamics ë + 2λė + λ²e = −ε sat(s) do not contain ∫e, so freezing it never
changes the double pole.

Rotary friction compensation (Eq. 31 with Eq. 9, errata: M_f/J_m). Our rotary
model is the speed loop (y = ω in rpm, ẏ = ω̇, ÿ = f + b0 u): Eq. 7 puts
−M_f/J_m into ω̇, so its effect in ÿ is −(dM_f/dω) ω̇ / J_m. With
M_f = M_c tanh(ω/ω_s) + M_v ω (Eq. 9, sign smoothed over ω_s)::

    f_k = −(κ / J_m) (M_v + M_c sech²(z1/ω_s) / ω_s) z2    κ = 60/(2π) rpm per rad/s

(M_v in N·m/rpm, z2 in rpm/s, f_k in rpm/s²). The Coulomb level M_c itself
has no effect at a constant speed sign; only its reversal does, smoothed.
With ``rotary_model: angle`` (y = θ, ẏ = ω = z2) Eq. 31 holds as printed but
divided by J_m: f_k = −κ (M_c tanh(z2/ω_s) + M_v z2) / J_m in rpm/s.
f_k enters the ESO's z2 channel and the law, so it is never double counted.

Delay compensation (``delay_compensation``, not in the paper): with a
transport delay of d samples the command computed now acts from t + dT on.
The law then uses the ESO state predicted to t + dT with the exact model and
the d commands already sent, and the reference extrapolated to t + dT with
its derivatives (a Smith predictor on the ESO model). With the paper's
λ_R = 250 and d = 1, the uncompensated loop limit-cycles on an ideal double
integrator (tested); the compensated loop does not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pneu_msgs_py.contract.units import RPM_PER_RAD_S
from pneu_msgs_py.params.core import param

from pneu_control.algorithms.base import StepInput
from pneu_control.algorithms.smc import (
    NONNEGATIVE,
    POSITIVE,
    b_0_field,
    conditional_integral,
    delay_compensation_field,
    delta_field,
    epsilon_field,
    k_field,
    lambda_r_field,
    omega_0_field,
    sat,
)
from pneu_control.observers.eso import eso3_step, eso_gains, extrapolate, predict3

if TYPE_CHECKING:
    from pneu_control.controller.params import AxisControllerParams

__all__ = ["EsoSmc", "EsoSmcParams", "friction_gain_max"]


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

    lambda_r: float = lambda_r_field(250.0, "paper")
    omega_0: float = omega_0_field(25.0, "paper", "observer bandwidth ω0 (Eq. 17)")
    b_0: float = b_0_field(3000.0, "paper")
    epsilon: float = epsilon_field(1200.0, "paper")
    delta: float = delta_field(0.1, "paper")
    k: float = k_field(0.5, "paper (k·Δ = 0.05: discontinuous, see errata)")
    integral_anti_windup: bool = param(
        True,
        desc="freeze ∫e while e pushes further into a saturation (valve command, or |s| > Δ)",
    )
    delay_compensation: bool = delay_compensation_field()
    friction_compensation: bool = param(
        False,
        desc="rotary only: feed the friction torque of Eq. 9 into the ESO and the law (Eq. 31)",
    )
    M_c: float = param(
        0.1281,
        unit="N·m",
        desc="Coulomb friction torque (Eq. 9)",
        **NONNEGATIVE,
        source="paper Table 1",
    )
    M_v: float = param(
        8.66e-5,
        unit="N·m/rpm",
        desc="viscous friction coefficient (Eq. 9)",
        **NONNEGATIVE,
        source="paper Table 1",
    )
    J_m: float = param(
        3.5e-5,
        unit="kg·m²",
        desc="rotating inertia for M_f/J_m (paper silent)",
        **POSITIVE,
        source="plant-parameters.md (±50 %)",
    )
    coulomb_smoothing: float = param(
        100.0,
        unit="rpm",
        desc="ω_s of the smoothed sign tanh(ω/ω_s) in Eq. 9 (our choice; bounds the ESO friction gain)",
        **POSITIVE,
    )


def friction_gain_max(M_c: float, M_v: float, J_m: float, omega_s: float) -> float:
    """Largest damping gain c (1/s) of f_k = −c z2 (at zero speed)."""
    return RPM_PER_RAD_S / J_m * (M_v + M_c / omega_s)


class EsoSmc:
    name = "eso_smc"
    uses_td = True
    uses_theta = False
    uses_pressures = False

    def __init__(self, params: AxisControllerParams, axis: str):
        p = params.eso_smc
        T = params.sample_time_s
        self.T = T
        self.T2h = 0.5 * T * T
        lam = p.lambda_r
        self.c1 = 2.0 * lam  # coefficient of e in s (Eq. 26 fixed)
        self.c2 = lam * lam  # coefficient of ∫e
        self.b0 = p.b_0
        self.eps = p.epsilon
        self.delta = p.delta
        self.k = p.k
        self.aw = p.integral_anti_windup
        self.l1, self.l2, self.l3 = eso_gains(p.omega_0, T)
        self.fric = bool(p.friction_compensation) and axis == "rotary"
        self.angle = axis == "rotary" and params.rotary_model == "angle"
        self.fs = RPM_PER_RAD_S / p.J_m  # (rpm/s) per (N·m): M_f / J_m in the angle model
        self.M_c, self.M_v = p.M_c, p.M_v
        self.fv = RPM_PER_RAD_S * p.M_v / p.J_m  # 1/s
        self.fc = RPM_PER_RAD_S * p.M_c / (p.J_m * p.coulomb_smoothing)  # 1/s
        self.inv_ws = 1.0 / p.coulomb_smoothing
        lim = params.limits
        self.lo = lim.u_min - lim.u_neutral
        self.hi = lim.u_max - lim.u_neutral
        self.dc = p.delay_compensation and params.transport_delay_samples > 0
        self.tau = params.transport_delay_samples * T
        self.u_n = lim.u_neutral
        self.z1 = self.z2 = self.z3 = 0.0
        self.s = 0.0
        self.integral = 0.0
        self.u_raw = 0.0
        self.f_k = 0.0
        self.u_in = 0.0

    @property
    def hint(self) -> tuple[float, float, float]:
        return self.z1, self.z2, self.z3 + self.b0 * self.u_in + self.f_k

    def friction_term(self, z1: float, z2: float) -> float:
        """f_k (rpm/s²) of the rotary friction model; 0 when off."""
        if not self.fric:
            return 0.0
        if self.angle:  # Eq. 31 (errata): −M_f(ω)/J_m in the acceleration channel, ω = z2
            return -self.fs * (self.M_c * math.tanh(z2 * self.inv_ws) + self.M_v * z2)
        x = abs(z1) * self.inv_ws
        sech2 = 0.0 if x > 30.0 else 1.0 / (math.cosh(x) ** 2)
        return -(self.fv + self.fc * sech2) * z2

    def start(self, inp: StepInput, u_prev, hint):
        self.z1 = z1 = hint[0] if math.isfinite(hint[0]) else inp.y
        self.z2 = z2 = hint[1] if math.isfinite(hint[1]) else 0.0
        f_k = self.friction_term(z1, z2)
        self.f_k = f_k
        self.u_in = u_applied = inp.u_applied
        e = inp.r - z1
        ed = inp.r_dot - z2
        if u_prev is None:  # cold start: ∫e from 0 (Eq. 26), no disturbance estimate
            self.z3 = 0.0
            self.integral = 0.0
        else:  # switch: z3 = ÿ − b0 u_applied − f_k; start on the surface (s = 0)
            a = hint[2] if math.isfinite(hint[2]) else 0.0
            self.z3 = a - self.b0 * u_applied - f_k
            self.integral = -(ed + self.c1 * e) / self.c2
        s = ed + self.c1 * e + self.c2 * self.integral
        self.s = s
        nominal = (
            self.eps * sat(s, self.delta, self.k) + inp.r_ddot + self.c1 * ed + self.c2 * e - f_k
        )
        u = (nominal - self.z3) / self.b0
        self.u_raw = u
        return self.hi if u > self.hi else (self.lo if u < self.lo else u)

    def update(self, inp: StepInput):
        T = self.T
        self.u_in = u_applied = inp.u_applied
        z3 = self.z3
        # ESO, Eq. 18 discretised (pneu_control.observers.eso), f_k held
        z1, z2, z3 = eso3_step(
            self.z1, self.z2, z3, z3 + self.b0 * u_applied + self.f_k, inp.y, T, self.T2h,
            self.l1, self.l2, self.l3,
        )  # fmt: skip
        self.z1, self.z2, self.z3 = z1, z2, z3
        r, r_dot, r_ddot = inp.r, inp.r_dot, inp.r_ddot
        if self.dc:  # act on the state the command will meet: t + d T
            z1, z2 = predict3(z1, z2, z3, inp.history, self.u_n, self.b0, self.f_k, T, self.T2h)
            r, r_dot = extrapolate(r, r_dot, r_ddot, self.tau)
        # sliding surface, Eq. 26 (fixed: double pole at −λ)
        e = r - z1
        ed = r_dot - z2
        integral = self.integral + T * e
        c1, c2 = self.c1, self.c2
        s = ed + c1 * e + c2 * integral
        self.s = s
        if self.fric:
            f_k = self.friction_term(z1, z2)
            self.f_k = f_k
        else:
            f_k = 0.0
        # Eq. 30/31 (fixed): ṡ = −ε sat(s)  (Eq. 29)
        u = (self.eps * sat(s, self.delta, self.k) + r_ddot + c1 * ed + c2 * e - z3 - f_k) / self.b0
        self.u_raw = u
        if self.aw:  # conditional integration (see module docstring)
            self.integral = conditional_integral(
                self.integral, integral, e, u, s, self.lo, self.hi, self.delta
            )
        else:
            self.integral = integral
        hi, lo = self.hi, self.lo
        return hi if u > hi else (lo if u < lo else u)
