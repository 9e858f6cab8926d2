"""The twin's inner loop: one 1 ms sample period of both axes and the sensor sample.

Everything here is numba ``@njit`` (``cache=True``, ``error_model="numpy"``) over
float64 arrays; the same functions run as plain Python through ``.py_func`` (the
reference the fast path is tested against). ``error_model="numpy"`` drops the
division-by-zero checks (no divisor here can be zero with validated parameters; a
zero would give inf/NaN instead of ZeroDivisionError): with the substep inlined
and K(θ) carried from one substep to the next, the period runs ≈ 1.4× faster with
bit-identical results. The substep's pieces keep that, measured: numba's reference-count
pruning removes the counts on ``st`` and ``prm`` from the substep loop as it stands, but
not once the motor chambers were a function of ``prm`` (inlined or not: an
``NRT_incref``/``NRT_decref`` calls in every substep in the LLVM IR, 13 % slower), so the pieces
read ``prm`` only where small (:func:`motor_speed`, :func:`sleeve_torque`) or take numbers
(:func:`swept_flow`, :func:`iso_flow`); check ``inspect_llvm`` of :func:`step_period` after
a change. Layouts of the state vector ``st`` and the parameter vector ``prm``
are the index constants below; :mod:`pneu_sim.physics.pack` fills ``prm`` from
:class:`~pneu_sim.physics.params.PlantParams`.

Integration (per substep h = T / n_sub, inputs held over T):

1. Valve spools: exact zero-order-hold discretisation of
   s'' = ω_n² (u − s) − 2 ζ ω_n s' (exact for any h), stroke clamped to 0..10 V,
   then a play operator of width ``hysteresis`` gives the effective opening y.
2. Piston (Eq. 1 with errata −A_r p_a, plus the external force F_ext − k_spring (x − x_0)):
   Karnopp stick/slip, semi-implicit Euler, viscous term implicit; sliding friction Eq. 2
   with S(ẋ) → sign(ẋ) plus a Stribeck breakaway bump, raised by the sleeve's friction
   μ_sleeve |T_rod| / r_sleeve (the torque the sleeve passes, from the last motor substep);
   a velocity that would cross zero within a step stops (stick).
   End stops ±L/2: exact inelastic clamp (x clamped, outward v → 0): never passes,
   never gains energy.
3. Chambers (Eq. 4–5, polytropic n): the volume term is integrated exactly,
   p ← p (V_old/V_new)^n (:func:`polytropic_factor`: pow to rounding, cheaper), so with no
   flow p V^n is conserved to rounding; the flow
   term is linearly implicit with the analytic ∂ṁ/∂p of the ISO 6358 flow, which
   keeps the stiff dead-volume dynamics stable at h = 0.1 ms.
4. Motor (Eq. 6–10): same stick/slip scheme on θ, ω, inertia J_m + J_load; friction Eq. 9
   raised by the cylinder seals' torque k_seal Σ(p_c − p_a)+ and the load (T_c, breakaway
   T_bk, c_load); inlet p_m1 (port A) fed by the valve's port 4 and drained by the swept
   displacement and leakage; p_m2 (port B) filled by them and drained through the silencer
   orifice (paper plumbing) or through the valve's port 2 (bidirectional: fed from supply
   when u < 5 V); both linearly implicit.
5. Sensors: first-order lags (exact per substep).

The scheme is first order in h; test_sim_integrator shows the convergence.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# ---------------------------------------------------------------- state layout
S_X = 0  # piston position, m
S_V = 1  # piston velocity, m/s
S_PC1 = 2  # chamber 1 pressure, Pa abs
S_PC2 = 3  # chamber 2 pressure, Pa abs
S_TH = 4  # motor angle, rad
S_OM = 5  # motor speed, rad/s
S_PM1 = 6  # motor inlet chamber, Pa abs
S_PM2 = 7  # motor exhaust chamber, Pa abs
S_SL = 8  # linear valve spool position (V equivalent)
S_SDL = 9  # its velocity, V/s
S_YL = 10  # its effective opening after hysteresis, V
S_SR = 11  # rotary valve spool position
S_SDR = 12
S_YR = 13
S_MC1 = 14  # gas mass chamber 1, kg
S_MC2 = 15  # gas mass chamber 2, kg
S_FP1 = 16  # pressure sensor lag states, Pa abs
S_FP2 = 17
S_FPM1 = 18
S_FX = 19  # laser lag state, m
S_T = 20  # time, s
S_CNT = 21  # encoder counts at the last tick (exact integer in float64)
S_UL = 22  # AO value held on the linear valve, V
S_UR = 23  # AO value held on the rotary valve, V
S_TROD = 24  # torque the sleeve passes to the rod side (seals + load), N*m, >= 0
N_STATE = 25

# ---------------------------------------------------------------- parameter layout
P_PA = 0
P_RT = 1  # R * T0
P_N = 2  # polytropic index
P_C1T = 3  # C_1 / sqrt(T0)
P_PSL = 4
P_PSR = 5
P_AC1 = 6
P_AC2 = 7
P_AR = 8
P_V1D = 9
P_V2D = 10
P_M = 11
P_AF = 12
P_FS = 13  # static (breakaway) friction, N
P_VS = 14
P_CV = 15
P_L = 16
P_RM = 17
P_DM = 18
P_LM = 19
P_RRM = 20  # rotor radius r_m
P_NV = 21  # vanes
P_J = 22
P_MC = 23
P_MS = 24  # static friction torque
P_MV = 25  # N*m*s/rad
P_VM1 = 26
P_VM2 = 27
P_KEX = 28  # silencer A_ex * C_1 / sqrt(T0)
P_KLK = 29
P_PFS = 30  # pressure sensor FS, Pa
P_PVFS = 31
P_PSIG = 32
P_POFF = 33  # 3 offsets, V: 33, 34, 35
P_PALPHA = 36  # per-substep lag factor 1 - exp(-h/tau)
P_XRANGE = 37
P_XVFS = 38
P_XSIG = 39  # V
P_XALPHA = 40
P_AIRP = 41  # AI range pressure, V
P_AILSBP = 42
P_AIRX = 43
P_AILSBX = 44
P_AINMAX = 45  # AI codes - 1
P_AOR = 46
P_AOLSB = 47
P_AONMAX = 48
P_CPR = 49  # counts per revolution (4 * ppr)
P_T = 50
P_NSUB = 51
P_H = 52
P_VALVE_L = 53  # valve block base (linear)
# valve block: offsets
VB_AMAX = 0
VB_ALEAK = 1
VB_B = 2
VB_BLAM = 3
VB_HW = 4  # half hysteresis width
VB_FLAP = 5  # normalised flow over which a closing path's leak fades out
VB_PHI11 = 6
VB_PHI12 = 7
VB_PHI21 = 8
VB_PHI22 = 9
VB_G1 = 10
VB_G2 = 11
# each port's signed normalised flow (pneu_sim.physics.valve_curve), TAB_N samples over 0-10 V
TAB_N = 1001
TAB_DU = 0.01
VB_TAB4 = 12
VB_TAB2 = VB_TAB4 + TAB_N
VB_SIZE = VB_TAB2 + TAB_N
P_VALVE_R = P_VALVE_L + VB_SIZE
# coupling and loads (appended: the indices above are those of the paper-only twin)
# rotary.plumbing: 0 = paper (motor port B -> silencer), 1 = bidirectional (B -> valve port 2)
P_PLUMB = P_VALVE_R + VB_SIZE
P_KSEAL = P_PLUMB + 1  # seal friction torque per Pa of chamber gauge pressure, N*m/Pa
P_SLV = P_PLUMB + 2  # mu_sleeve / r_sleeve, 1/m
P_TLC = P_PLUMB + 3  # load Coulomb torque, N*m
P_TLS = P_PLUMB + 4  # load static (breakaway) torque max(T_bk, T_c), N*m
P_CLD = P_PLUMB + 5  # load viscous, N*m*s/rad
P_JLD = P_PLUMB + 6  # load inertia, kg*m^2
P_KSP = P_PLUMB + 7  # spring on the rod, N/m
P_X0 = P_PLUMB + 8  # its relaxed position, m
P_FEXT = P_PLUMB + 9  # constant force on the rod, N
N_PRM = P_PLUMB + 10

# sensor output layout
O_PC1 = 0
O_PC2 = 1
O_PM1 = 2
O_X = 3
O_TH = 4
O_OM = 5
O_CNT = 6
N_OUT = 7

N_NOISE = 4  # p_c1, p_c2, p_m1, laser

TWO_PI = 2.0 * math.pi

_JIT = {"cache": True, "error_model": "numpy"}  # see the module docstring


@njit(**_JIT)
def iso_flow(p1, p2, K, b, b_lam):
    """Mass flow from node 1 to node 2 through an ISO 6358 orifice (Eq. 11–12).

    ṁ = K · p_u · C_d(r) · φ(r), r = p_d/p_u, K = A · C_1 / sqrt(T_u), with
    φ = 1 (r ≤ b, choked), φ = sqrt(1 − ((r − b)/(1 − b))²) (subsonic, corrected:
    errata Eq. 11), and a linear laminar patch φ ∝ (1 − r) for r ≥ b_lam so that
    ∂ṁ/∂p stays finite at r → 1. C_d(r) = 0.8153 + 0.0933 r − 0.1038 r² (Eq. 12).
    Signed: negative when p2 > p1. Returns (ṁ, ∂ṁ/∂p1, ∂ṁ/∂p2), kg/s and kg/(s·Pa).
    """
    if K <= 0.0:
        return 0.0, 0.0, 0.0
    if p1 >= p2:
        pu = p1
        pd = p2
    else:
        pu = p2
        pd = p1
    if pu <= 0.0:
        return 0.0, 0.0, 0.0
    r = pd / pu
    cd = 0.8153 + 0.0933 * r - 0.1038 * r * r  # Eq. 12
    dcd = 0.0933 - 0.2076 * r
    if r <= b:
        phi = 1.0
        dphi = 0.0
    elif r < b_lam:
        s = (r - b) / (1.0 - b)
        phi = math.sqrt(1.0 - s * s)
        dphi = -s / ((1.0 - b) * phi)
    else:
        s = (b_lam - b) / (1.0 - b)
        phil = math.sqrt(1.0 - s * s)
        phi = phil * (1.0 - r) / (1.0 - b_lam)
        dphi = -phil / (1.0 - b_lam)
    g = cd * phi
    dg = dcd * phi + cd * dphi
    m = K * pu * g
    dm_dpu = K * (g - r * dg)
    dm_dpd = K * dg
    if p1 >= p2:
        return m, dm_dpu, dm_dpd
    return -m, -dm_dpd, -dm_dpu


@njit(**_JIT)
def port_flow(prm, off, y):
    """A port's signed normalised flow at effective opening y (V): linear interpolation of
    its table at ``prm[off:off + TAB_N]`` (0-10 V; held flat beyond)."""
    q = y / TAB_DU
    if q <= 0.0:
        return prm[off]
    if q >= TAB_N - 1:
        return prm[off + TAB_N - 1]
    i = int(q)
    w = q - i
    return prm[off + i] * (1.0 - w) + prm[off + i + 1] * w


@njit(**_JIT)
def port_areas(f, a_max, a_leak, f_lap):
    """(supply → port, port → exhaust) areas of a port whose signed normalised flow is f.

    The opening path: a_leak + |f| a_max; the closing one leaks a_leak, fading out as
    |f| passes f_lap (both leak inside a dead band, where f = 0).
    """
    if f >= 0.0:
        fade = 1.0 - f / f_lap
        return a_leak + f * a_max, (a_leak * fade if fade > 0.0 else 0.0)
    fade = 1.0 + f / f_lap
    return (a_leak * fade if fade > 0.0 else 0.0), a_leak - f * a_max


@njit(**_JIT)
def valve_areas(prm, base, y):
    """Areas of the 5/3 paths for effective opening y (V).

    Returns (A_s4, A_4e, A_s2, A_2e): supply→port 4 (chamber 1 / motor port A),
    port 4→exhaust, supply→port 2 (chamber 2 / motor port B in bidirectional
    plumbing), port 2→exhaust, from each port's own curve (the catalogue's:
    u > 5 V opens supply→4 and 2→exhaust, u < 5 V the reverse) and the centre leak.
    """
    a_max = prm[base + VB_AMAX]
    a_leak = prm[base + VB_ALEAK]
    f_lap = prm[base + VB_FLAP]
    A_s4, A_4e = port_areas(port_flow(prm, base + VB_TAB4, y), a_max, a_leak, f_lap)
    A_s2, A_2e = port_areas(port_flow(prm, base + VB_TAB2, y), a_max, a_leak, f_lap)
    return A_s4, A_4e, A_s2, A_2e


@njit(**_JIT)
def spool_step(st, prm, base, i_s, i_sd, i_y, u):
    """Exact ZOH step of the 2nd-order spool, stroke clamp, then the play operator."""
    s = st[i_s]
    sd = st[i_sd]
    s_new = prm[base + VB_PHI11] * s + prm[base + VB_PHI12] * sd + prm[base + VB_G1] * u
    sd_new = prm[base + VB_PHI21] * s + prm[base + VB_PHI22] * sd + prm[base + VB_G2] * u
    if s_new > 10.0:
        s_new = 10.0
        if sd_new > 0.0:
            sd_new = 0.0
    elif s_new < 0.0:
        s_new = 0.0
        if sd_new < 0.0:
            sd_new = 0.0
    st[i_s] = s_new
    st[i_sd] = sd_new
    hw = prm[base + VB_HW]
    y = st[i_y]
    if s_new > y + hw:
        y = s_new - hw
    elif s_new < y - hw:
        y = s_new + hw
    st[i_y] = y
    return y


@njit(**_JIT)
def vane_factor(prm, theta):
    """K(θ) = ½ L_m (d² cos 2θ_v + 2 d R cos θ_v + R² − r²), M_m = K (p_m1 − p_m2) (Eq. 8).

    θ_v is the working vane's angle within its sector, θ_v ∈ [−π/z, π/z) for z vanes,
    so the torque ripple has period 2π/z. Units m³.
    """
    z = prm[P_NV]
    sector = TWO_PI / z
    tv = theta - sector * math.floor((theta + 0.5 * sector) / sector)
    c = math.cos(tv)
    d = prm[P_DM]
    R = prm[P_RM]
    r = prm[P_RRM]
    return 0.5 * prm[P_LM] * (d * d * (2.0 * c * c - 1.0) + 2.0 * d * R * c + R * R - r * r)


@njit(**_JIT)
def vane_factors(prm, theta):
    """:func:`vane_factor` at each angle of the array ``theta`` (one call from Python)."""
    out = np.empty(theta.shape[0])
    for i in range(theta.shape[0]):
        out[i] = vane_factor(prm, theta[i])
    return out


@njit(**_JIT)
def stick_slip(v, F, m, F_c, F_s, v_s, c_v, h):
    """One semi-implicit Euler step of m v̇ = F − F_f(v) with Karnopp sticking.

    Sliding: F_f = sign(v) (F_c + (F_s − F_c) exp(−(v/v_s)²)) + c_v v (Eq. 2 with
    S → sign, plus a Stribeck bump; Eq. 9 when F_s = F_c). Stuck (v = 0): stays while
    |F| ≤ F_s. A step whose velocity would change sign ends at v = 0 (stuck).
    """
    if v == 0.0:
        if abs(F) <= F_s:
            return 0.0
        sg = 1.0 if F > 0.0 else -1.0
        return h * (F - sg * F_s) / (m + h * c_v)
    sg = 1.0 if v > 0.0 else -1.0
    if v_s > 0.0:
        q = v / v_s
        g = F_c + (F_s - F_c) * math.exp(-q * q)
    else:
        g = F_c
    v_new = (m * v + h * (F - sg * g)) / (m + h * c_v)
    if v_new * sg < 0.0:
        return 0.0
    return v_new


POLY_SERIES = 3e-3  # |δ| below which polytropic_factor sums the series (see there)
_THIRD = 1.0 / 3.0


@njit(**_JIT)
def polytropic_factor(V_old, V_new, n):
    """(V_old/V_new)^n: a chamber's pressure factor over a volume step at fixed mass (Eq. 4,
    p V^n conserved).

    With δ = (V_old − V_new)/V_new the binomial series of (1 + δ)^n to δ⁵ (Horner); for
    |δ| < :data:`POLY_SERIES` the next term, n(n−1)…(n−5)/720 δ⁶, is below 1e-17 of the
    factor for 1 ≤ n ≤ 1.4, so this is pow to rounding at a fraction of its cost (a
    substep moves the piston by v·h, 0.1 mm at 1 m/s: δ ≈ 1e-3 mid-stroke). A larger
    step (near a dead volume at speed) takes pow itself.
    """
    d = (V_old - V_new) / V_new
    if abs(d) < POLY_SERIES:
        t = 1.0 + (n - 4.0) * 0.2 * d
        t = 1.0 + (n - 3.0) * 0.25 * d * t
        t = 1.0 + (n - 2.0) * _THIRD * d * t
        t = 1.0 + (n - 1.0) * 0.5 * d * t
        return 1.0 + n * d * t
    return (V_old / V_new) ** n


@njit(**_JIT)
def implicit_pressure(p, c, mdot, dmdot_dp, h):
    """Linearly implicit Euler of ṗ = c ṁ(p) (c = n R T0 / V); returns new p."""
    J = c * dmdot_dp
    if J > 0.0:
        J = 0.0
    return p + h * c * mdot / (1.0 - h * J)


@njit(**_JIT, inline="always")
def substep_linear(st, prm, u_l, h):
    """The cylinder axis over h seconds: valve #1 spool, piston, chambers, their sensor lags."""
    pa = prm[P_PA]
    RT = prm[P_RT]
    n = prm[P_N]
    C = prm[P_C1T]
    # --- 1. spool
    y_l = spool_step(st, prm, P_VALVE_L, S_SL, S_SDL, S_YL, u_l)
    bl = P_VALVE_L
    # --- 2. piston, Eq. 1 (errata: −A_r p_a)
    x = st[S_X]
    v = st[S_V]
    p1 = st[S_PC1]
    p2 = st[S_PC2]
    half = 0.5 * prm[P_L]
    F = prm[P_AC1] * p1 - prm[P_AC2] * p2 - prm[P_AR] * pa
    F_load = prm[P_FEXT] - prm[P_KSP] * (x - prm[P_X0])  # external force and spring
    if F_load != 0.0:
        F += F_load
    F_c = prm[P_AF]
    F_s = prm[P_FS]
    F_sl = prm[P_SLV] * st[S_TROD]  # sleeve on the I shaft: μ |T_rod| / r (estimated form)
    if F_sl > 0.0:
        F_c += F_sl
        F_s += F_sl
    if v == 0.0 and ((x >= half and F > 0.0) or (x <= -half and F < 0.0)):
        v_new = 0.0  # held by the end stop
    else:
        v_new = stick_slip(v, F, prm[P_M], F_c, F_s, prm[P_VS], prm[P_CV], h)
    x_new = x + h * v_new
    if x_new >= half:  # inelastic end stop
        x_new = half
        if v_new > 0.0:
            v_new = 0.0
    elif x_new <= -half:
        x_new = -half
        if v_new < 0.0:
            v_new = 0.0
    # --- 3. chambers, Eq. 5 volumes, polytropic volume term exactly
    V1o = prm[P_V1D] + prm[P_AC1] * (half + x)
    V2o = prm[P_V2D] + prm[P_AC2] * (half - x)
    V1 = prm[P_V1D] + prm[P_AC1] * (half + x_new)
    V2 = prm[P_V2D] + prm[P_AC2] * (half - x_new)
    if x_new != x:
        p1 = p1 * polytropic_factor(V1o, V1, n)
        p2 = p2 * polytropic_factor(V2o, V2, n)
    # flow term (Eq. 4 with n, Eq. 11 flows), linearly implicit
    A_s1, A_1e, A_s2, A_2e = valve_areas(prm, bl, y_l)
    b = prm[bl + VB_B]
    bla = prm[bl + VB_BLAM]
    ps = prm[P_PSL]
    mi, _d, dmi = iso_flow(ps, p1, A_s1 * C, b, bla)
    mo, dmo, _d = iso_flow(p1, pa, A_1e * C, b, bla)
    c1 = n * RT / V1
    p1n = implicit_pressure(p1, c1, mi - mo, dmi - dmo, h)
    mi, _d, dmi = iso_flow(ps, p2, A_s2 * C, b, bla)
    mo, dmo, _d = iso_flow(p2, pa, A_2e * C, b, bla)
    c2 = n * RT / V2
    p2n = implicit_pressure(p2, c2, mi - mo, dmi - dmo, h)
    st[S_MC1] += (p1n - p1) / c1
    st[S_MC2] += (p2n - p2) / c2
    st[S_X] = x_new
    st[S_V] = v_new
    st[S_PC1] = p1n
    st[S_PC2] = p2n
    # --- 5. sensor lags
    ap = prm[P_PALPHA]
    st[S_FP1] += ap * (p1n - st[S_FP1])
    st[S_FP2] += ap * (p2n - st[S_FP2])
    st[S_FX] += prm[P_XALPHA] * (x_new - st[S_FX])


@njit(**_JIT, inline="always")
def motor_speed(prm, om, M_m, T_seal, h):
    """ω after h seconds under the vane torque M_m (Eq. 7, stick/slip on J_m + J_load).

    Friction Eq. 9–10 raised by the seal torque ``T_seal`` and the load (T_c, breakaway
    T_bk, c_load).
    """
    return stick_slip(
        om,
        M_m,
        prm[P_J] + prm[P_JLD],
        prm[P_MC] + T_seal + prm[P_TLC],
        prm[P_MS] + T_seal + prm[P_TLS],
        0.0,
        prm[P_MV] + prm[P_CLD],
        h,
    )


@njit(**_JIT, inline="always")
def sleeve_torque(prm, om, om_new, M_m, T_seal, h):
    """|T_rod|, the torque through the sleeve: what the rod side resists (seals, load, load
    inertia) while ω went from ``om`` to ``om_new`` over h; N·m, ≥ 0."""
    if om_new != 0.0:
        sg = 1.0 if om_new > 0.0 else -1.0
        T_lc = prm[P_TLC]
        c_ld = prm[P_CLD]
        J_ld = prm[P_JLD]
        return abs(sg * (T_seal + T_lc) + c_ld * om_new + J_ld * (om_new - om) / h)
    # stuck: statically indeterminate; at most what the motor applies
    return min(abs(M_m), T_seal + prm[P_TLS])


@njit(**_JIT)
def swept_flow(K, om, pm1, pm2, RT):
    """Gas the motor's swept displacement carries from p_m1 to p_m2: ṁ_sw = K ω p_up / (R T0).

    At the upstream density: p_up = p_m1 for ω ≥ 0, p_m2 for ω < 0 (``K`` = K(θ), Eq. 8).
    Returns (ṁ_sw, ∂ṁ_sw/∂p_m1, ∂ṁ_sw/∂p_m2), kg/s and kg/(s·Pa).
    """
    if om >= 0.0:
        return K * om * pm1 / RT, K * om / RT, 0.0
    return K * om * pm2 / RT, 0.0, K * om / RT


@njit(**_JIT, inline="always")
def substep_rotary(st, prm, u_r, h, K):
    """The motor axis over h seconds: valve #2 spool, motor, its chambers, the inlet sensor lag.

    Reads p_c1, p_c2 (seal torque) as the linear substep left them; writes S_TROD, which
    the next linear substep reads (sleeve friction).

    ``K`` = K(θ) at the current angle (Eq. 8, :func:`vane_factor`); returns K at the new angle.
    """
    pa = prm[P_PA]
    RT = prm[P_RT]
    n = prm[P_N]
    C = prm[P_C1T]
    # --- 1. spool
    y_r = spool_step(st, prm, P_VALVE_R, S_SR, S_SDR, S_YR, u_r)
    # --- 4. motor, Eq. 7–10
    th = st[S_TH]
    om = st[S_OM]
    pm1 = st[S_PM1]
    pm2 = st[S_PM2]
    M_m = K * (pm1 - pm2)  # Eq. 8
    # seal friction torque of the turning piston and rods (estimated form, see CouplingParams)
    g1 = st[S_PC1] - pa
    g2 = st[S_PC2] - pa
    T_seal = prm[P_KSEAL] * ((g1 if g1 > 0.0 else 0.0) + (g2 if g2 > 0.0 else 0.0))
    om_new = motor_speed(prm, om, M_m, T_seal, h)
    st[S_TROD] = sleeve_torque(prm, om, om_new, M_m, T_seal, h)
    th_new = th + h * om_new
    K = vane_factor(prm, th_new)
    br = P_VALVE_R
    A_s4, A_4e, A_s2, A_2e = valve_areas(prm, br, y_r)
    b = prm[br + VB_B]
    bla = prm[br + VB_BLAM]
    mi, _d, dmi = iso_flow(prm[P_PSR], pm1, A_s4 * C, b, bla)
    mo, dmo, _d = iso_flow(pm1, pa, A_4e * C, b, bla)
    msw, dmsw1, dmsw2 = swept_flow(K, om_new, pm1, pm2, RT)
    klk = prm[P_KLK]
    mlk = klk * (pm1 - pm2)
    cm1 = n * RT / prm[P_VM1]
    pm1n = implicit_pressure(pm1, cm1, mi - mo - msw - mlk, dmi - dmo - dmsw1 - klk, h)
    msw = swept_flow(K, om_new, pm1n, pm2, RT)[0]
    mlk = klk * (pm1n - pm2)
    cm2 = n * RT / prm[P_VM2]
    if prm[P_PLUMB] == 0.0:  # paper: port B vents through the silencer
        mex, dmex, _d = iso_flow(pm2, pa, prm[P_KEX], prm[br + VB_B], prm[br + VB_BLAM])
        pm2n = implicit_pressure(pm2, cm2, msw + mlk - mex, dmsw2 - klk - dmex, h)
    else:  # bidirectional: port B on the valve's port 2 (supply when u < 5 V, else exhaust)
        mi2, _d, dmi2 = iso_flow(prm[P_PSR], pm2, A_s2 * C, b, bla)
        mo2, dmo2, _d = iso_flow(pm2, pa, A_2e * C, b, bla)
        pm2n = implicit_pressure(pm2, cm2, msw + mlk + mi2 - mo2, dmsw2 - klk + dmi2 - dmo2, h)
    st[S_TH] = th_new
    st[S_OM] = om_new
    st[S_PM1] = pm1n
    st[S_PM2] = pm2n
    # --- 5. sensor lag
    st[S_FPM1] += prm[P_PALPHA] * (pm1n - st[S_FPM1])
    return K


@njit(**_JIT, inline="always")
def substep(st, prm, u_l, u_r, h, K):
    """Advance both axes and the sensor lags by h seconds (inputs u_l, u_r held).

    The axes couple through the torque transmission module only: the motor reads the chamber
    pressures this substep's linear step left (seal torque), the piston the sleeve torque
    the previous motor substep left (S_TROD). ``K`` =
    K(θ) at the current angle (Eq. 8, :func:`vane_factor`); returns K at the new angle.
    """
    substep_linear(st, prm, u_l, h)
    K = substep_rotary(st, prm, u_r, h, K)
    st[S_T] += h
    return K


@njit(**_JIT)
def quantise(v, rng, lsb, nmax):
    """DAQ converter: code = round((v + rng)/lsb) clamped to [0, nmax]; returns volts."""
    q = math.floor((v + rng) / lsb + 0.5)
    if q < 0.0:
        q = 0.0
    elif q > nmax:
        q = nmax
    return q * lsb - rng


@njit(**_JIT)
def ao_value(prm, u):
    """Valve command as the AO writes it: clamp to 0..10 V, then 16-bit quantisation."""
    if u < 0.0:  # non-finite commands are refused by Plant.step before this
        u = 0.0
    if u > 10.0:
        u = 10.0
    return quantise(u, prm[P_AOR], prm[P_AOLSB], prm[P_AONMAX])


@njit(**_JIT)
def sample(st, prm, noise, j, out, count_prev):
    """Sensor sample at the current tick (sample-and-hold of the lagged signals).

    Pressures: gauge volts + offset + noise, clipped to the sensor's 0..v_fs, AI
    quantised, converted back with the nominal scaling (what the driver does).
    Laser: 0..v_fs over ±range/2, noise, AI quantised. Encoder: X4 counts of the
    true angle; ω = Δcounts · 2π / (4 ppr T).
    """
    pa = prm[P_PA]
    pfs = prm[P_PFS]
    pvfs = prm[P_PVFS]
    for i in range(3):
        vv = (st[S_FP1 + i] - pa) / pfs * pvfs + prm[P_POFF + i] + prm[P_PSIG] * noise[j, i]
        if vv < 0.0:
            vv = 0.0
        elif vv > pvfs:
            vv = pvfs
        vv = quantise(vv, prm[P_AIRP], prm[P_AILSBP], prm[P_AINMAX])
        out[O_PC1 + i] = vv / pvfs * pfs + pa
    rng = prm[P_XRANGE]
    xvfs = prm[P_XVFS]
    vv = (st[S_FX] / rng + 0.5) * xvfs + prm[P_XSIG] * noise[j, 3]
    if vv < 0.0:
        vv = 0.0
    elif vv > xvfs:
        vv = xvfs
    vv = quantise(vv, prm[P_AIRX], prm[P_AILSBX], prm[P_AINMAX])
    out[O_X] = (vv / xvfs - 0.5) * rng
    cpr = prm[P_CPR]
    cnt = math.floor(st[S_TH] * cpr / TWO_PI)
    out[O_TH] = cnt * TWO_PI / cpr
    out[O_OM] = (cnt - count_prev) * TWO_PI / (cpr * prm[P_T])
    out[O_CNT] = cnt
    st[S_CNT] = cnt


@njit("void(f8[::1], f8[::1], f8[:, ::1], i8, f8, f8, f8[::1])", **_JIT)
def step_period(st, prm, noise, j, u_l, u_r, out):
    """Hold the AO values for one period T (n_sub substeps), then sample the sensors."""
    ul = ao_value(prm, u_l)
    ur = ao_value(prm, u_r)
    st[S_UL] = ul
    st[S_UR] = ur
    nsub = int(prm[P_NSUB])
    h = prm[P_H]
    K = vane_factor(prm, st[S_TH])
    for _ in range(nsub):
        K = substep(st, prm, ul, ur, h, K)
    sample(st, prm, noise, j, out, st[S_CNT])


@njit(**_JIT)
def run_periods(st, prm, noise, u_l, u_r, out_all):
    """Many periods in one call: u_l[k], u_r[k], noise[k] -> out_all[k, :] (open loop)."""
    out = np.empty(N_OUT)
    for k in range(u_l.shape[0]):
        step_period(st, prm, noise, k, u_l[k], u_r[k], out)
        for i in range(N_OUT):
            out_all[k, i] = out[i]
