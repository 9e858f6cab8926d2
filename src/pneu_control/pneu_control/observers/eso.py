"""Linear extended state observer (paper Eq. 13–18), discretised exactly.

Model (Eq. 13, extended state x3 = f, the total disturbance)::

    ẋ1 = x2,  ẋ2 = x3 + b0 u + f_k,  ẋ3 = ω(t)

(f_k: an optional known model part, e.g. friction, held over one sample.)
The continuous observer Eq. 18 with L = [3ω0, 3ω0², ω0³] (Eq. 17) places the
three error poles at −ω0. Forward-Euler discretisation of Eq. 18 (what a
Simulink discrete integrator does) has error poles at 1 − ω0 T and is stable
only for ω0 T < 2; it also only sees y(k) one sample later.

Here we use the *current* discrete observer on the exact ZOH model
(Franklin, Powell & Workman, Digital Control, §8.2)::

    predict  z⁻ = Φ z + Γ (b0 u + f_k),  Φ = [[1, T, T²/2], [0, 1, T], [0, 0, 1]],
                                          Γ = [T²/2, T, 0]
    correct  z  = z⁻ + L_d (y(k) − z⁻1)

with the error matrix (I − L_d C) Φ given the triple pole p = exp(−ω0 T),
the exact image of the continuous −ω0::

    l1 = 1 − p³,  l2 = 3 (1 − p)² (1 + p) / (2T),  l3 = (1 − p)³ / T²

(derived symbolically; for ω0 T → 0, L_d → T·[3ω0, 3ω0², ω0³], i.e. Eq. 17).
Stable for every ω0 > 0 since 0 < p < 1; we accept ω0 ≤ π/T
(:func:`pneu_control.controller.params.omega_0_max`). The estimation error of an
exact-ZOH plant with a constant disturbance decays as p^k with no offset.
"""

from __future__ import annotations

import math

from pneu_msgs_py.params.records import kernel

__all__ = [
    "eso_gains",
    "eso3_constants",
    "eso_error_matrix",
    "eso3_step",
    "eso3_observe",
    "predict3",
    "extrapolate",
    "LinearEso",
]


def eso_gains(omega_0: float, T: float) -> tuple[float, float, float]:
    """Current-observer gains L_d placing all three error poles at exp(−ω0 T)."""
    if not (omega_0 > 0.0 and T > 0.0):
        raise ValueError(f"ESO needs omega_0 > 0 and T > 0 (got {omega_0!r}, {T!r})")
    p = math.exp(-omega_0 * T)
    q = 1.0 - p
    return 1.0 - p * p * p, 3.0 * q * q * (1.0 + p) / (2.0 * T), q * q * q / (T * T)


def eso3_constants(omega_0: float, T: float) -> dict[str, float]:
    """The fields :func:`eso3_observe` reads from an algorithm's constants: T, T²/2, L_d."""
    l1, l2, l3 = eso_gains(omega_0, T)
    return {"T": T, "T2h": 0.5 * T * T, "l1": l1, "l2": l2, "l3": l3}


def eso_error_matrix(omega_0: float, T: float) -> list[list[float]]:
    """(I − L_d C) Φ: the estimation-error transition matrix (for analysis/tests)."""
    l1, l2, l3 = eso_gains(omega_0, T)
    phi = [[1.0, T, 0.5 * T * T], [0.0, 1.0, T], [0.0, 0.0, 1.0]]
    lc = [l1, l2, l3]
    return [[phi[i][j] - lc[i] * phi[0][j] for j in range(3)] for i in range(3)]


@kernel
def eso3_step(
    z1: float,
    z2: float,
    z3: float,
    acc: float,
    y: float,
    T: float,
    T2h: float,
    l1: float,
    l2: float,
    l3: float,
) -> tuple[float, float, float]:
    """One step of the current observer (Eq. 18, exact ZOH); the fast path every algorithm uses.

    ``acc`` = z3 + b0 u + f_k: the modelled acceleration over the last period
    (the caller adds the input and known parts it has); ``T2h`` = T²/2.
    Predict z⁻ = Φ z + Γ acc, correct with y(k): returns (z1, z2, z3).
    """
    z1p = z1 + T * z2 + T2h * acc
    z2p = z2 + T * acc
    ey = y - z1p
    return z1p + l1 * ey, z2p + l2 * ey, z3 + l3 * ey


@kernel
def eso3_observe(c, s, acc: float, y: float) -> tuple[float, float, float]:
    """:func:`eso3_step` on an algorithm's records: the constants ``c`` (T, T2h, l1..l3, as
    :func:`eso3_constants`) and the state ``s`` (z1..z3, updated); returns (z1, z2, z3).
    ``acc`` = z3 + b0 u + f_k as the caller models it (its rounding is the caller's)."""
    z1, z2, z3 = eso3_step(s.z1, s.z2, s.z3, acc, y, c.T, c.T2h, c.l1, c.l2, c.l3)
    s.z1 = z1
    s.z2 = z2
    s.z3 = z3
    return z1, z2, z3


@kernel
def predict3(z1, z2, z3, history, n_hist, u_n, b0, f_k, T, T2h):
    """(z1, z2) run over the transport delay with the commands already sent (Smith predictor).

    ``history[:n_hist]``: commands in V, oldest first (the one on the valve during the
    last period, then the d commands in the pipe); the model acceleration over each
    is z3 + b0 (u − u_n) + f_k.
    """
    for i in range(1, n_hist):
        du = history[i] - u_n
        acc = z3 + b0 * du + f_k
        z1 += T * z2 + T2h * acc
        z2 += T * acc
    return z1, z2


@kernel
def extrapolate(r: float, r_dot: float, r_ddot: float, tau: float) -> tuple[float, float]:
    """(r, ṙ) at t + τ from the reference and its derivatives at t (second order)."""
    return r + tau * r_dot + 0.5 * tau * tau * r_ddot, r_dot + tau * r_ddot


class LinearEso:
    """Third-order linear ESO in current-observer form (see module docstring).

    Units are the controller's (mm or rpm based): z1 ~ y, z2 ~ ẏ, z3 ~ f.
    ``update(y, u, f_k)``: ``u`` is the command deviation that was on the valve
    during the last sample period (V), ``f_k`` the known part over it.
    """

    __slots__ = ("T", "b0", "l1", "l2", "l3", "omega_0", "z1", "z2", "z3")

    def __init__(self, omega_0: float, b_0: float, T: float):
        self.l1, self.l2, self.l3 = eso_gains(omega_0, T)
        self.omega_0, self.b0, self.T = float(omega_0), float(b_0), float(T)
        self.z1 = self.z2 = self.z3 = 0.0

    def reset(self, z1: float, z2: float = 0.0, z3: float = 0.0) -> None:
        self.z1, self.z2, self.z3 = float(z1), float(z2), float(z3)

    def update(self, y: float, u: float, f_k: float = 0.0) -> None:
        T = self.T
        acc = self.z3 + self.b0 * u + f_k
        self.z1, self.z2, self.z3 = eso3_step(
            self.z1, self.z2, self.z3, acc, y, T, 0.5 * T * T, self.l1, self.l2, self.l3
        )
