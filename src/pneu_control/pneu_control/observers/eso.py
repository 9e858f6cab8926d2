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

__all__ = ["eso_gains", "eso_error_matrix", "LinearEso"]


def eso_gains(omega_0: float, T: float) -> tuple[float, float, float]:
    """Current-observer gains L_d placing all three error poles at exp(−ω0 T)."""
    if not (omega_0 > 0.0 and T > 0.0):
        raise ValueError(f"ESO needs omega_0 > 0 and T > 0 (got {omega_0!r}, {T!r})")
    p = math.exp(-omega_0 * T)
    q = 1.0 - p
    return 1.0 - p * p * p, 3.0 * q * q * (1.0 + p) / (2.0 * T), q * q * q / (T * T)


def eso_error_matrix(omega_0: float, T: float) -> list[list[float]]:
    """(I − L_d C) Φ: the estimation-error transition matrix (for analysis/tests)."""
    l1, l2, l3 = eso_gains(omega_0, T)
    phi = [[1.0, T, 0.5 * T * T], [0.0, 1.0, T], [0.0, 0.0, 1.0]]
    lc = [l1, l2, l3]
    return [[phi[i][j] - lc[i] * phi[0][j] for j in range(3)] for i in range(3)]


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
        z2 = self.z2
        z1p = self.z1 + T * z2 + 0.5 * T * T * acc  # predict, exact ZOH
        z2p = z2 + T * acc
        e = y - z1p  # correct with y(k)
        self.z1 = z1p + self.l1 * e
        self.z2 = z2p + self.l2 * e
        self.z3 = self.z3 + self.l3 * e
