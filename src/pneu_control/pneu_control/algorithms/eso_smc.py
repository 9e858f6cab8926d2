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
from pneu_msgs_py.params.records import RecordType, kernel

from pneu_control.algorithms.base import AlgorithmKernel, KernelAlgorithm, deviation_band
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
    reaching_command,
    sliding_surface,
    surface_step,
)
from pneu_control.observers.eso import eso3_constants, eso3_observe, extrapolate, predict3

if TYPE_CHECKING:
    from pneu_control.controller.params import AxisControllerParams

__all__ = [
    "ESO_SMC_CONSTANTS",
    "ESO_SMC_STATE",
    "EsoSmc",
    "EsoSmcParams",
    "eso_smc_start",
    "eso_smc_update",
    "friction_gain_max",
]


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


ESO_SMC_CONSTANTS = RecordType(
    "EsoSmcConstants",
    [
        ("T", "f"), ("T2h", "f"), ("c1", "f"), ("c2", "f"), ("b0", "f"), ("eps", "f"),
        ("delta", "f"), ("k", "f"), ("l1", "f"), ("l2", "f"), ("l3", "f"), ("fs", "f"),
        ("M_c", "f"), ("M_v", "f"), ("fv", "f"), ("fc", "f"), ("inv_ws", "f"), ("lo", "f"),
        ("hi", "f"), ("tau", "f"), ("u_n", "f"),
        ("two", "f", 2.0),  # the exponent of cosh(x) ** 2, a field: see friction_term
        ("aw", "i"), ("dc", "i"), ("fric", "i"), ("angle", "i"),
    ],
)  # fmt: skip
ESO_SMC_STATE = RecordType(
    "EsoSmcState",
    [("z1", "f", 0.0), ("z2", "f", 0.0), ("z3", "f", 0.0), ("s", "f", 0.0),
     ("u_raw", "f", 0.0), ("integral", "f", 0.0), ("f_k", "f", 0.0), ("u_in", "f", 0.0)],
)  # fmt: skip


@kernel
def friction_term(c, z1, z2):
    """f_k (rpm/s²) of the rotary friction model; 0 when off."""
    if not c.fric:
        return 0.0
    if c.angle:  # Eq. 31 (errata): −M_f(ω)/J_m in the acceleration channel, ω = z2
        return -c.fs * (c.M_c * math.tanh(z2 * c.inv_ws) + c.M_v * z2)
    x = abs(z1) * c.inv_ws
    # cosh(x) ** 2 is pow(cosh, 2.0); the exponent is a field so that LLVM cannot fold a
    # constant 2.0 into c * c (which differs from pow in the last bit; records.py)
    sech2 = 0.0 if x > 30.0 else 1.0 / (math.cosh(x) ** c.two)
    return -(c.fv + c.fc * sech2) * z2


@kernel
def eso_smc_hint(c, s):
    return s.z1, s.z2, s.z3 + c.b0 * s.u_in + s.f_k


@kernel
def eso_smc_start(c, s, table, inp, u_prev, h0, h1, h2):
    z1 = h0 if math.isfinite(h0) else inp.y
    z2 = h1 if math.isfinite(h1) else 0.0
    s.z1 = z1
    s.z2 = z2
    f_k = friction_term(c, z1, z2)
    s.f_k = f_k
    u_applied = inp.u_applied
    s.u_in = u_applied
    e = inp.r - z1
    ed = inp.r_dot - z2
    if u_prev != u_prev:  # cold start: ∫e from 0 (Eq. 26), no disturbance estimate
        s.z3 = 0.0
        s.integral = 0.0
    else:  # switch: z3 = ÿ − b0 u_applied − f_k; start on the surface (s = 0)
        a = h2 if math.isfinite(h2) else 0.0
        s.z3 = a - c.b0 * u_applied - f_k
        s.integral = -(ed + c.c1 * e) / c.c2
    sv = sliding_surface(e, ed, s.integral, c.c1, c.c2)
    s.s = sv
    nominal = reaching_command(sv, e, ed, inp.r_ddot, c.c1, c.c2, c.eps, c.delta, c.k) - f_k
    u = (nominal - s.z3) / c.b0
    s.u_raw = u
    return c.hi if u > c.hi else (c.lo if u < c.lo else u)


@kernel
def eso_smc_update(c, s, table, inp):
    T = c.T
    u_applied = inp.u_applied
    s.u_in = u_applied
    # ESO, Eq. 18 discretised (pneu_control.observers.eso), f_k held
    z1, z2, z3 = eso3_observe(c, s, s.z3 + c.b0 * u_applied + s.f_k, inp.y)
    r = inp.r
    r_dot = inp.r_dot
    r_ddot = inp.r_ddot
    if c.dc:  # act on the state the command will meet: t + d T
        z1, z2 = predict3(z1, z2, z3, inp.history, inp.n_hist, c.u_n, c.b0, s.f_k, T, c.T2h)
        r, r_dot = extrapolate(r, r_dot, r_ddot, c.tau)
    # sliding surface, Eq. 26 (fixed: double pole at −λ)
    e, ed, integral, sv = surface_step(c, s, r, r_dot, z1, z2)
    if c.fric:
        f_k = friction_term(c, z1, z2)
        s.f_k = f_k
    else:
        f_k = 0.0
    # Eq. 30/31 (fixed): ṡ = −ε sat(s)  (Eq. 29)
    u = (reaching_command(sv, e, ed, r_ddot, c.c1, c.c2, c.eps, c.delta, c.k) - z3 - f_k) / c.b0
    s.u_raw = u
    if c.aw:  # conditional integration (see module docstring)
        s.integral = conditional_integral(s.integral, integral, e, u, sv, c.lo, c.hi, c.delta)
    else:
        s.integral = integral
    hi = c.hi
    lo = c.lo
    return hi if u > hi else (lo if u < lo else u)


class EsoSmc(KernelAlgorithm):
    name = "eso_smc"
    uses_td = True
    CONSTANTS = ESO_SMC_CONSTANTS
    STATE = ESO_SMC_STATE
    KERNEL = AlgorithmKernel(eso_smc_start, eso_smc_update, eso_smc_hint)

    def constants(self, params: AxisControllerParams, axis: str):
        p = params.eso_smc
        T = params.sample_time_s
        lam = p.lambda_r
        lim = params.limits
        return ESO_SMC_CONSTANTS.new(
            **eso3_constants(p.omega_0, T),
            c1=2.0 * lam,  # coefficient of e in s (Eq. 26 fixed)
            c2=lam * lam,  # coefficient of ∫e
            b0=p.b_0,
            eps=p.epsilon,
            delta=p.delta,
            k=p.k,
            fs=RPM_PER_RAD_S / p.J_m,  # (rpm/s) per (N·m): M_f / J_m in the angle model
            M_c=p.M_c,
            M_v=p.M_v,
            fv=RPM_PER_RAD_S * p.M_v / p.J_m,  # 1/s
            fc=RPM_PER_RAD_S * p.M_c / (p.J_m * p.coulomb_smoothing),  # 1/s
            inv_ws=1.0 / p.coulomb_smoothing,
            **deviation_band(params),
            tau=params.transport_delay_samples * T,
            u_n=lim.u_neutral,
            aw=int(p.integral_anti_windup),
            dc=int(p.delay_compensation and params.transport_delay_samples > 0),
            fric=int(bool(p.friction_compensation) and axis == "rotary"),
            angle=int(axis == "rotary" and params.rotary_model == "angle"),
        )

    def friction_term(self, z1: float, z2: float) -> float:
        """f_k (rpm/s²) of the rotary friction model at (z1, z2); 0 when off."""
        return friction_term(self.c, z1, z2)
