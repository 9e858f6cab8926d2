"""Extended state observer of any order on an integrator chain, exact ZOH, current form.

Model (n states; the last one is the extended state, the total disturbance f)::

    ẋ_i = x_{i+1} (i < n−1),   ẋ_{n−1} = x_n + b0 u,   ẋ_n = 0 (+ unknown drift)

n = 3 is the paper's ESO (Eq. 13, :mod:`pneu_control.observers.eso`); n = 4 is the
*angle* observer of :mod:`pneu_control.algorithms.eso_smc_plus`: the rotary
speed obeys ω̈ = f + b0 u (valve → inlet pressure → torque), so the encoder
angle obeys θ''' = f + b0 u and the states are (θ, ω, ω̇, f).

Discretisation (Franklin, Powell & Workman, Digital Control, §8.2)::

    predict  z⁻ = Φ z + Γ b0 u,   Φ_ij = T^(j−i)/(j−i)!  (j ≥ i),   Γ_i = T^(n−1−i)/(n−1−i)!
    correct  z  = z⁻ + L (y(k) − z⁻_1)

(Γ has 0 in the extended state; indices from 1.) L places every eigenvalue of
the error matrix (I − L C) Φ at p = exp(−ω0 T), the exact image of the
continuous pole −ω0 (Ackermann's formula for the current estimator)::

    L = α(Φ) O⁻¹ e_n,   α(z) = (z − p)^n,   O = [C Φ; C Φ²; …; C Φⁿ],   C = e_1ᵀ

For n = 3 this gives :func:`pneu_control.observers.eso.eso_gains` (tested). Stable for
every ω0 > 0; the error of an exact-ZOH plant with constant f decays as p^k
with no offset.
"""

from __future__ import annotations

import math

import numpy as np
from pneu_msgs_py.params.records import kernel

__all__ = ["chain_gains", "chain_matrices", "eso4_step", "predict4", "ChainEso"]


def chain_matrices(n: int, T: float) -> tuple[np.ndarray, np.ndarray]:
    """(Φ, Γ) of the n-state chain over one sample T (Γ for a unit input in state n−1)."""
    phi = np.zeros((n, n))
    for i in range(n):
        for j in range(i, n):
            phi[i, j] = T ** (j - i) / math.factorial(j - i)
    gam = np.zeros(n)
    for i in range(n - 1):
        gam[i] = T ** (n - 1 - i) / math.factorial(n - 1 - i)
    return phi, gam


def chain_gains(n: int, omega_0: float, T: float) -> tuple[float, ...]:
    """Current-observer gains placing all n error poles at exp(−ω0 T) (Ackermann)."""
    if n < 2:
        raise ValueError(f"n: {n!r} refused; allowed: an integer >= 2")
    if not (omega_0 > 0.0 and T > 0.0):
        raise ValueError(f"chain ESO needs omega_0 > 0 and T > 0 (got {omega_0!r}, {T!r})")
    phi, _ = chain_matrices(n, T)
    p = math.exp(-omega_0 * T)
    c = np.zeros(n)
    c[0] = 1.0
    rows, m = [], np.eye(n)
    for _ in range(n):
        m = m @ phi
        rows.append(c @ m)
    obs = np.array(rows)
    # α(Φ) = (Φ − p I)^n
    a = np.linalg.matrix_power(phi - p * np.eye(n), n)
    e_n = np.zeros(n)
    e_n[-1] = 1.0
    gains = a @ np.linalg.solve(obs, e_n)
    return tuple(float(g) for g in gains)


@kernel
def eso4_step(z1, z2, z3, z4, jerk, y, T, T2h, T3s, l1, l2, l3, l4):
    """One step of the 4-state current observer (fast path of :class:`ChainEso`, n = 4).

    ``jerk`` = z4 + b0 u (the modelled third derivative over the last
    period); ``T2h`` = T²/2, ``T3s`` = T³/6; ``l1..l4`` the gains of
    :func:`chain_gains` (n = 4). Returns (z1, z2, z3, z4).
    """
    z1p = z1 + T * z2 + T2h * z3 + T3s * jerk
    z2p = z2 + T * z3 + T2h * jerk
    z3p = z3 + T * jerk
    ey = y - z1p
    return z1p + l1 * ey, z2p + l2 * ey, z3p + l3 * ey, z4 + l4 * ey


@kernel
def predict4(z1, z2, z3, z4, history, n_hist, u_n, b0, T, T2h, T3s):
    """(z1, z2, z3) of the 4-state chain run over the transport delay (as :func:`predict3`).

    ``history[:n_hist]``: commands in V, oldest first; the model jerk over each of
    ``history[1:n_hist]`` is z4 + b0 (u − u_n).
    """
    for i in range(1, n_hist):
        du = history[i] - u_n
        jerk = z4 + b0 * du
        z1 += T * z2 + T2h * z3 + T3s * jerk
        z2 += T * z3 + T2h * jerk
        z3 += T * jerk
    return z1, z2, z3


class ChainEso:
    """Slow, obvious n-state ESO (reference for tests and the fast kernels).

    ``update(y, u)``: ``u`` is the command deviation that was on the valve during
    the last sample period (V); states ``z`` in the controller's units.
    """

    def __init__(self, n: int, omega_0: float, b_0: float, T: float):
        self.n, self.b0, self.T = int(n), float(b_0), float(T)
        self.phi, self.gam = chain_matrices(self.n, self.T)
        self.L = np.array(chain_gains(self.n, omega_0, self.T))
        self.z = np.zeros(self.n)

    def reset(self, *z: float) -> None:
        self.z = np.zeros(self.n)
        self.z[: len(z)] = z

    def update(self, y: float, u: float) -> None:
        zp = self.phi @ self.z + self.gam * (self.b0 * u)
        self.z = zp + self.L * (y - zp[0])
