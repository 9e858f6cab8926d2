"""The twin as a stepped core: :class:`Plant` (both axes, valves, sensors, DAQ).

Model summary (equations as in Jia et al.; corrections per errata.md):

- Piston, Eq. 1 with the errata's −A_r·p_a term; friction Eq. 2 (A_f, c_v of
  Table 1) as the sliding level, plus a Stribeck breakaway bump to
  ``breakaway_ratio``·A_f and Karnopp sticking; inelastic end stops at ±L/2.
- Chambers, Eq. 4–5 with one polytropic index n (``ambient.n_poly`` = 1.2, see
  :mod:`pneu_sim.physics.params` for why) and the dead volumes of Table 1.
- Valves: ISO 6358 flow (Eq. 11 corrected, laminar patch), C_d of Eq. 12, the MPYE
  5/3 mapping (u > 5 V: supply → chamber 1 and chamber 2 → exhaust), opening curve
  from Festo's flow-vs-setpoint chart (dead band ≈ ±0.35 V comes out of it),
  centre leakage, 2nd-order spool, hysteresis (play).
- Motor, Eq. 6–10: vane torque with its ripple (period 2π/n_vanes), Eq. 9 friction
  (M_v per rpm converted), inlet chamber (port A) fed by valve 2 and drained by the swept
  displacement K(θ)·ω and leakage; port B vented through the silencer (``rotary.plumbing:
  paper``) or on the valve's second port (``bidirectional``: the same valve brakes and
  reverses the motor).
- Coupling through the torque transmission module (``coupling``): the cylinder seals'
  friction torque on the turning rod grows with the chamber pressures; the sleeve's
  friction on the linear axis grows with the torque it passes.
- External loads (``load``, all off by default; :meth:`Plant.set_load` between steps):
  load torque (Coulomb, breakaway, viscous), added rotary inertia, a spring and a
  constant force on the rod.
- Sensors: first-order lags, noise, fixed offsets within the pressure sensors'
  accuracy, 16-bit AI; X4 encoder counts and ω from Δcounts over T; 16-bit AO.

The numerics are in :mod:`pneu_sim.physics.kernel` (numba). One Python call per step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pneu_msgs_py.contract.samples import NEUTRAL_V, SensorSample
from pneu_msgs_py.params.core import ParamError, validate, with_updates

from pneu_sim.physics import kernel as k
from pneu_sim.physics.pack import pack_load, pack_params
from pneu_sim.physics.params import LOAD_FIELDS, PlantParams

__all__ = ["Plant", "TrueState", "neutral_leak_pressure"]


@dataclass(frozen=True, slots=True)
class TrueState:
    """The noise-free state (SI, pressures absolute)."""

    t: float  # s
    x: float  # m
    v: float  # m/s
    p_c1: float  # Pa
    p_c2: float  # Pa
    theta: float  # rad
    omega: float  # rad/s
    p_m1: float  # Pa
    p_m2: float  # Pa
    spool_linear: float  # spool position, V equivalent
    spool_rotary: float  # V equivalent
    opening_linear: float  # effective opening after hysteresis, V
    opening_rotary: float  # V
    m_c1: float  # gas mass chamber 1, kg
    m_c2: float  # gas mass chamber 2, kg
    u_linear: float  # AO value held, V
    u_rotary: float  # V
    T_rod: float  # torque the sleeve passes to the rod side (seals + load), N*m


def neutral_leak_pressure(prm: np.ndarray, base: int, p_s: float, p_a: float) -> float:
    """Port pressure where the centre leakage in equals the leakage out (u = 5 V), Pa.

    Without leakage the port is sealed: returns the mid pressure (p_s + p_a)/2.
    """
    C = prm[k.P_C1T]
    a_in, a_out, _, _ = k.valve_areas(prm, base, NEUTRAL_V)
    b, bl = prm[base + k.VB_B], prm[base + k.VB_BLAM]
    if a_in <= 0.0 or a_out <= 0.0:
        return 0.5 * (p_s + p_a)
    lo, hi = p_a, p_s
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        net = k.iso_flow(p_s, mid, a_in * C, b, bl)[0] - k.iso_flow(mid, p_a, a_out * C, b, bl)[0]
        if net > 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


_SETTABLE = {
    "x": k.S_X,
    "v": k.S_V,
    "p_c1": k.S_PC1,
    "p_c2": k.S_PC2,
    "theta": k.S_TH,
    "omega": k.S_OM,
    "p_m1": k.S_PM1,
    "p_m2": k.S_PM2,
}


class Plant:
    """Linear-rotary pneumatic actuator twin, stepped at the DAQ period T.

    Parameters
    ----------
    params : PlantParams
        The plant (see ``config/plant.yaml``).
    seed : int
        Fixes every random draw (sensor noise, sensor offsets): same params and seed
        give bit-identical samples.
    """

    def __init__(self, params: PlantParams, seed: int = 0):
        validate(params)
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ParamError("seed", seed, "an integer >= 0")
        self._seed_seq = np.random.SeedSequence(int(seed))
        off_ss, self._noise_ss = self._seed_seq.spawn(2)
        self._offsets_unit = np.random.Generator(np.random.PCG64(off_ss)).uniform(-1.0, 1.0, 3)
        self.params = params
        self.seed = int(seed)
        self.T = params.sim.T
        self._T_ns = round(self.T * 1e9)
        self._prm = pack_params(params, self._offsets_unit)
        self._st = np.zeros(k.N_STATE)
        self._out = np.zeros(k.N_OUT)
        self._k = 0
        self.reset()

    # ------------------------------------------------------------------ API
    def reset(self, x0: float = 0.0, omega0: float = 0.0) -> SensorSample:
        """Restart at rest at x0 (m) with the motor at omega0 (rad/s); returns sample k = 0.

        Linear: p_c2 at the valve's centre-leakage equilibrium, p_c1 so that Eq. 1 with
        the external force is balanced (no drift at t = 0; a force pushing out raises p_c2
        instead). Rotary: p_m2 = p_a (paper plumbing) or the rotary valve's centre-leakage
        pressure (bidirectional), p_m1 = p_m2 + M_f(ω0)/K̄ (the inlet pressure that holds
        ω0 against Eq. 9, the seals' torque and the load). Spools at 5 V. The noise stream
        restarts from the seed.
        """
        p = self.params
        lin, rot = p.linear, p.rotary
        x0 = float(x0)
        omega0 = float(omega0)
        if not (abs(x0) <= 0.5 * lin.L):
            raise ParamError("x0", x0, f"[{-0.5 * lin.L:g}, {0.5 * lin.L:g}] m")
        if not math.isfinite(omega0):
            raise ParamError("omega0", omega0, "a finite speed in rad/s")
        self._gen = np.random.Generator(np.random.PCG64(self._noise_ss))
        self._nb = p.sim.noise_block
        self._noise = np.empty((self._nb, k.N_NOISE))
        self._j = self._nb
        p_a = p.ambient.p_a
        RT = p.ambient.R * p.ambient.T_0
        st = np.zeros(k.N_STATE)
        half = 0.5 * lin.L
        p_ref = neutral_leak_pressure(self._prm, k.P_VALVE_L, p.supply.p_s_linear, p_a)
        ld = p.load
        F_load = ld.F_ext - ld.k_spring * (x0 - ld.x_0)
        p_c2 = p_ref
        p_c1 = (lin.A_c2 * p_c2 + lin.A_r * p_a) / lin.A_c1
        if F_load < 0.0:  # pulled in: chamber 1 holds it
            p_c1 = (lin.A_c2 * p_c2 + lin.A_r * p_a - F_load) / lin.A_c1
        elif F_load > 0.0:  # pushed out: chamber 2 holds it
            p_c2 = (lin.A_c1 * p_c1 - lin.A_r * p_a + F_load) / lin.A_c2
        st[k.S_X] = x0
        st[k.S_PC1] = p_c1
        st[k.S_PC2] = p_c2
        st[k.S_MC1] = p_c1 * (lin.V_1d + lin.A_c1 * (half + x0)) / RT
        st[k.S_MC2] = p_c2 * (lin.V_2d + lin.A_c2 * (half - x0)) / RT
        st[k.S_OM] = omega0
        T_seal = p.coupling.k_seal * (max(p_c1 - p_a, 0.0) + max(p_c2 - p_a, 0.0))
        T_coul = rot.M_c + T_seal + ld.T_c
        M_f = (math.copysign(T_coul, omega0) if omega0 != 0.0 else 0.0) + (
            rot.M_v_si + ld.c_load
        ) * omega0
        p_m2 = p_a
        if rot.plumbing == "bidirectional":
            p_m2 = neutral_leak_pressure(self._prm, k.P_VALVE_R, p.supply.p_s_rotary, p_a)
        st[k.S_PM1] = p_m2 + M_f / self.mean_vane_factor()
        st[k.S_PM2] = p_m2
        if omega0 != 0.0:
            st[k.S_TROD] = T_seal + ld.T_c + ld.c_load * abs(omega0)
        for i in (k.S_SL, k.S_YL, k.S_SR, k.S_YR, k.S_UL, k.S_UR):
            st[i] = NEUTRAL_V
        st[k.S_FP1] = st[k.S_PC1]
        st[k.S_FP2] = st[k.S_PC2]
        st[k.S_FPM1] = st[k.S_PM1]
        st[k.S_FX] = x0
        cpr = 4 * p.sensors.encoder.ppr
        cnt0 = math.floor(st[k.S_TH] * cpr / (2 * math.pi))
        st[k.S_CNT] = cnt0 - round(omega0 * cpr * self.T / (2 * math.pi))
        self._st[:] = st
        self._k = 0
        k.sample(self._st, self._prm, self._next_noise(), self._j - 1, self._out, self._st[k.S_CNT])
        return self._make_sample(0)

    def step(self, u_linear: float, u_rotary: float) -> SensorSample:
        """Write both AO voltages (clamped 0–10 V, 16-bit), hold them for T, sample tick k+1."""
        if not (math.isfinite(u_linear) and math.isfinite(u_rotary)):
            raise ValueError(
                f"valve command not finite: u_linear={u_linear!r}, u_rotary={u_rotary!r}"
            )
        j = self._j
        if j >= self._nb:
            self._gen.standard_normal(out=self._noise)
            j = 0
        self._j = j + 1
        k.step_period(self._st, self._prm, self._noise, j, u_linear, u_rotary, self._out)
        self._k += 1
        n = self._k
        o = self._out.tolist()
        return SensorSample(n, n * self._T_ns, o[0], o[1], o[2], o[3], o[4], o[5], int(o[6]))

    def run(self, u_linear: np.ndarray, u_rotary: np.ndarray) -> np.ndarray:
        """Open-loop run of len(u) steps in one numba call; rows = SensorSample fields
        p_c1, p_c2, p_m1, x, theta, omega, counts (same numbers as repeated :meth:`step`)."""
        u_l = np.ascontiguousarray(u_linear, dtype=np.float64)
        u_r = np.ascontiguousarray(u_rotary, dtype=np.float64)
        if u_l.shape != u_r.shape or u_l.ndim != 1:
            raise ValueError("u_linear and u_rotary must be 1-D arrays of equal length")
        if not (np.all(np.isfinite(u_l)) and np.all(np.isfinite(u_r))):
            raise ValueError("valve commands must be finite")
        n = u_l.shape[0]
        noise = self.noise_rows(n)
        out = np.empty((n, k.N_OUT))
        k.run_periods(self._st, self._prm, noise, u_l, u_r, out)
        self._k += n
        return out

    def noise_rows(self, n: int) -> np.ndarray:
        """The noise rows of the next ``n`` steps, (n, N_NOISE), drawn from the stream as
        ``n`` :meth:`step` calls would draw them (blocks refilled as they run out)."""
        noise = np.empty((n, k.N_NOISE))
        i = 0
        while i < n:
            if self._j >= self._nb:
                self._gen.standard_normal(out=self._noise)
                self._j = 0
            take = min(n - i, self._nb - self._j)
            noise[i : i + take] = self._noise[self._j : self._j + take]
            self._j += take
            i += take
        return noise

    def kernel_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(state, parameter vector, last sample) of :mod:`~pneu_sim.physics.kernel`, live.

        For compiled callers that step :func:`~pneu_sim.physics.kernel.step_period`
        themselves (``pneu_control.fastloop``) with :meth:`noise_rows`; the sample
        counter :attr:`k` is then not advanced.
        """
        return self._st, self._prm, self._out

    @property
    def k(self) -> int:
        """Index of the last sample returned."""
        return self._k

    @property
    def state(self) -> TrueState:
        s = self._st.tolist()
        return TrueState(
            t=self._k * self.T,
            x=s[k.S_X],
            v=s[k.S_V],
            p_c1=s[k.S_PC1],
            p_c2=s[k.S_PC2],
            theta=s[k.S_TH],
            omega=s[k.S_OM],
            p_m1=s[k.S_PM1],
            p_m2=s[k.S_PM2],
            spool_linear=s[k.S_SL],
            spool_rotary=s[k.S_SR],
            opening_linear=s[k.S_YL],
            opening_rotary=s[k.S_YR],
            m_c1=s[k.S_MC1],
            m_c2=s[k.S_MC2],
            u_linear=s[k.S_UL],
            u_rotary=s[k.S_UR],
            T_rod=s[k.S_TROD],
        )

    def set_state(self, **values: float) -> None:
        """Overwrite physical states (x, v, p_c1, p_c2, theta, omega, p_m1, p_m2; SI).

        For tests and scenario set-up. Chamber masses follow p V / (R T0); the sensor
        lags jump to the new values. Refused whole if any name or value is bad.
        """
        p = self.params
        half = 0.5 * p.linear.L
        for name, val in values.items():
            if name not in _SETTABLE:
                raise ParamError(name, val, "one of " + ", ".join(_SETTABLE))
            if not math.isfinite(val):
                raise ParamError(name, val, "a finite number")
            if name.startswith("p_") and val <= 0.0:
                raise ParamError(name, val, "(0, inf) Pa")
            if name == "x" and abs(val) > half:
                raise ParamError(name, val, f"[{-half:g}, {half:g}] m")
        st = self._st
        for name, val in values.items():
            st[_SETTABLE[name]] = float(val)
        lin = p.linear
        RT = p.ambient.R * p.ambient.T_0
        x = st[k.S_X]
        st[k.S_MC1] = st[k.S_PC1] * (lin.V_1d + lin.A_c1 * (half + x)) / RT
        st[k.S_MC2] = st[k.S_PC2] * (lin.V_2d + lin.A_c2 * (half - x)) / RT
        st[k.S_FP1] = st[k.S_PC1]
        st[k.S_FP2] = st[k.S_PC2]
        st[k.S_FPM1] = st[k.S_PM1]
        st[k.S_FX] = x

    def set_params(self, params: PlantParams) -> None:
        """Swap the plant mid-run (fault injection: supply drop, added mass); keeps state.

        ``sim.T`` and ``sim.noise_block`` cannot change while running.
        """
        validate(params)
        if params.sim.T != self.T:
            raise ParamError("sim.T", params.sim.T, f"{self.T:g} s (read-only while running)")
        if params.sim.noise_block != self._nb:
            raise ParamError(
                "sim.noise_block", params.sim.noise_block, f"{self._nb} (fixed while running)"
            )
        prm = pack_params(params, self._offsets_unit)
        self.params = params
        self._prm[:] = prm  # in place: kernel_arrays() callers keep a live vector

    def set_load(self, **values: float) -> None:
        """Change external loads (``load.*`` names: T_c, T_bk, c_load, J_load, k_spring,
        x_0, F_ext; SI) between steps, keeping the state.

        For tasks that switch loads between segments: the new values act from the next
        :meth:`step` (or compiled ``step_period``) on, so a run stays fully set by config,
        seed and the steps at which loads change. Written into the live parameter vector
        of :meth:`kernel_arrays`. Validated as one set; refused whole on a bad name or value.
        """
        for name, val in values.items():
            if name not in LOAD_FIELDS:
                raise ParamError(f"load.{name}", val, "one of " + ", ".join(LOAD_FIELDS))
        params = with_updates(self.params, {f"load.{n}": v for n, v in values.items()})
        self.params = params
        pack_load(self._prm, params.load)

    def mean_vane_factor(self) -> float:
        """K̄: mean of Eq. 8's geometric factor over a vane sector, m³ (torque / Δp)."""
        th = np.linspace(0.0, 2 * math.pi / self.params.rotary.n_vanes, 2001)
        vals = k.vane_factors(self._prm, th)
        return float(np.trapezoid(vals, th) / (th[-1] - th[0]))

    # ------------------------------------------------------------------ helpers
    def _next_noise(self) -> np.ndarray:
        if self._j >= self._nb:
            self._gen.standard_normal(out=self._noise)
            self._j = 0
        self._j += 1
        return self._noise

    def _make_sample(self, n: int) -> SensorSample:
        o = self._out.tolist()
        return SensorSample(n, n * self._T_ns, o[0], o[1], o[2], o[3], o[4], o[5], int(o[6]))
