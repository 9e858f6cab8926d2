"""Plant parameters of the twin: one frozen dataclass per group, every value sourced.

``config/plant.yaml`` holds the same tree; each leaf is ``{value, unit, source}``
(:mod:`pneu_sim.physics.plant_file` loads and writes it).

Conventions: SI inside (m, Pa absolute, K, kg, s, rad). Two values keep the
paper's units so Table 1 can be typed verbatim: ``rotary.M_v`` (N·m/rpm) and the
valves' nominal flow ``Q_n`` is in m^3/s of ANR air (ISO 8778).

Thermodynamics (errata Eq. 4): the paper writes T = T0 yet keeps γ. We use one
polytropic index ``ambient.n_poly`` = 1.2 for both the flow and the volume terms,
ṗ = n R T0 / V · (ṁ_in − ṁ_out) − n p V̇ / V, with T0 in the flow terms (the
paper's T = T0). n = 1.2 is Richer & Hurmuzlu's (2000, JDSMC 122:416) α for the
compression term, between isothermal (1.0) and adiabatic (1.4) as measured for
small cylinders with heat exchange through the walls; one index keeps steady
states consistent (zero net mass flow ⇔ constant pressure).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from pneu_driver.daq.rig import ROTARY_PLUMBINGS
from pneu_msgs_py.contract.valve_chart import MPYE_DU_V, MPYE_FLOW
from pneu_msgs_py.params.core import ParamError, param

from pneu_sim.physics.valve_curve import check_curve

__all__ = [
    "AmbientParams",
    "SupplyParams",
    "LinearParams",
    "ValveParams",
    "RotaryParams",
    "CouplingParams",
    "LoadParams",
    "PressureSensorParams",
    "LaserParams",
    "EncoderParams",
    "DaqParams",
    "SensorParams",
    "SimParams",
    "PlantParams",
    "ParamError",
    "PlantConfigError",
    "MPYE_DU_V",
    "MPYE_FLOW",
    "PLUMBINGS",
    "LOAD_FIELDS",
    "K_SEAL_ESTIMATE",
]

P_ATM = 101325.0


# How valve #2 is piped to the motor (rotary.plumbing), as rig.yaml's rotary_plumbing.
PLUMBINGS = ROTARY_PLUMBINGS


class PlantConfigError(ParamError):
    """plant.yaml is malformed (not a {value, unit, source} leaf, unit mismatch, ...)."""


_PLANT_SHEET = "reference/plant-parameters.md"


@dataclass(frozen=True)
class AmbientParams:
    p_a: float = param(
        P_ATM,
        unit="Pa",
        lo=5e4,
        hi=1.2e5,
        desc="ambient (atmospheric) pressure, absolute",
        source="ISO 2533 standard atmosphere",
    )
    T_0: float = param(
        300.0,
        unit="K",
        lo=250.0,
        hi=350.0,
        desc="gas and ambient temperature (paper T = T0)",
        source="paper Table 1; range: laboratory air 17–37 °C (estimated; the paper gives 300 K only)",
        band=(290.0, 310.0),
    )
    R: float = param(
        287.0,
        unit="J/(kg*K)",
        lo=280.0,
        hi=295.0,
        desc="gas constant of air",
        source="paper Table 1",
    )
    gamma: float = param(
        1.4, unit="-", lo=1.0, hi=1.67, desc="ratio of specific heats", source="paper Table 1"
    )
    C_1: float = param(
        0.0404,
        unit="sqrt(K)*s/m",
        lo=0.03,
        hi=0.05,
        desc="ISO 6358 flow constant sqrt((γ/R)(2/(γ+1))^((γ+1)/(γ-1)))",
        source="paper Table 1 ('c_1'; errata: it is the flow constant)",
    )
    n_poly: float = param(
        1.2,
        unit="-",
        lo=1.0,
        hi=1.4,
        desc="polytropic index of the chamber process (flow and volume terms)",
        source="Richer & Hurmuzlu 2000 (α ≈ 1.2); paper's γ with T = T0 is inconsistent (errata Eq. 4); range: isothermal 1.0 to adiabatic 1.4",
        band=(1.0, 1.4),
    )

    def _check(self) -> None:
        c1 = (
            math.sqrt(
                (self.gamma / self.R)
                * (2.0 / (self.gamma + 1.0)) ** ((self.gamma + 1.0) / (self.gamma - 1.0))
            )
            if self.gamma > 1.0
            else float("nan")
        )
        if not (abs(self.C_1 - c1) <= 0.01 * c1):
            raise ParamError("C_1", self.C_1, f"within 1 % of {c1:.5g} (from gamma and R)")


@dataclass(frozen=True)
class SupplyParams:
    p_s_linear: float = param(
        0.2e6 + P_ATM,
        unit="Pa",
        lo=1.2e5,
        hi=1.1e6,
        desc="supply of the linear valve, absolute",
        source="paper: 0.2 MPa, read as gauge (a regulator setting is a gauge reading) + p_a; alternative: 0.2 MPa absolute (the paper does not say which)",
        alternatives=(("gauge", 0.2e6 + P_ATM), ("absolute", 0.2e6)),
    )
    p_s_rotary: float = param(
        0.4e6 + P_ATM,
        unit="Pa",
        lo=1.2e5,
        hi=1.1e6,
        desc="supply of the rotary valve, absolute",
        source="paper: 0.4 MPa, read as gauge (a regulator setting is a gauge reading) + p_a; alternative: 0.4 MPa absolute (the paper does not say which)",
        alternatives=(("gauge", 0.4e6 + P_ATM), ("absolute", 0.4e6)),
    )


@dataclass(frozen=True)
class LinearParams:
    A_c1: float = param(
        8.04e-4,
        unit="m^2",
        lo=0.0,
        lo_open=True,
        hi=1e-2,
        desc="piston area, cap side (chamber 1)",
        source="paper Table 1 (Ø32 bore); range ±0.6 %: ±0.1 mm on the bore (estimated machining tolerance)",
        band=(0.0007992, 0.0008088),
    )
    A_c2: float = param(
        6.912e-4,
        unit="m^2",
        lo=0.0,
        lo_open=True,
        hi=1e-2,
        desc="annulus area, rod side (chamber 2)",
        source="paper Table 1 (Ø32 bore, Ø12 rod); range ±0.6 %: ±0.1 mm on bore and rod (estimated machining tolerance)",
        band=(0.0006871, 0.0006953),
    )
    V_1d: float = param(
        1.1e-5,
        unit="m^3",
        lo=0.0,
        lo_open=True,
        hi=1e-3,
        desc="dead volume chamber 1 (incl. tubing)",
        source="paper Table 1; range ±30 %: the tubing to the valve is not given (estimated)",
        band=(7.7e-06, 1.43e-05),
    )
    V_2d: float = param(
        0.6e-5,
        unit="m^3",
        lo=0.0,
        lo_open=True,
        hi=1e-3,
        desc="dead volume chamber 2 (incl. tubing)",
        source="paper Table 1; range ±30 %: the tubing to the valve is not given (estimated)",
        band=(4.2e-06, 7.8e-06),
    )
    M: float = param(
        0.28,
        unit="kg",
        lo=0.0,
        lo_open=True,
        hi=100.0,
        desc="moving mass (piston, rods, load)",
        source="paper Table 1; range ±10 %: which parts of the sleeve and rotor move with the piston is not stated (estimated)",
        band=(0.252, 0.308),
    )
    L: float = param(
        0.15,
        unit="m",
        lo=0.0,
        lo_open=True,
        hi=2.0,
        desc="stroke; end stops at ±L/2",
        source="paper Table 1 (DSBC-32-150)",
    )
    A_f: float = param(
        2.95,
        unit="N",
        lo=0.0,
        hi=200.0,
        desc="sliding (Coulomb) friction level of Eq. 2",
        source="paper Eq. 2 fit; range ±25 %: seal friction moves with lubrication, pressure and temperature (estimated)",
        band=(2.213, 3.688),
    )
    c_v: float = param(
        88.81,
        unit="N*s/m",
        lo=0.0,
        hi=1e4,
        desc="viscous friction coefficient of Eq. 2",
        source="paper Eq. 2 fit; range ±25 %: seal friction moves with lubrication, pressure and temperature (estimated)",
        band=(66.61, 111.0),
    )
    breakaway_ratio: float = param(
        1.5,
        unit="-",
        lo=1.0,
        hi=3.0,
        desc="static (breakaway) friction / A_f",
        source="estimated: neither Festo nor the paper gives a breakaway figure for the DSBC-32 (Eq. 2 fits sliding only); 1.5 (4.4 N against 2.95 N sliding) is a guess between no breakaway (1.0) and twice the sliding level, chosen so stick-slip exists on the twin; pneu identify fits it from pulses started at rest; range [1.3, 2.0] estimated the same way (stick-slip present, up to twice the sliding level)",
        band=(1.3, 2.0),
    )
    v_s: float = param(
        0.01,
        unit="m/s",
        lo=0.0,
        lo_open=True,
        hi=1.0,
        desc="Stribeck velocity of the breakaway bump",
        source="estimated: order of 10 mm/s typical of lubricated pneumatic cylinder seals; range: 5-20 mm/s (estimated, ×/÷ 2)",
        band=(0.005, 0.02),
    )

    def _check(self) -> None:
        if not self.A_c2 < self.A_c1:
            raise ParamError(
                "A_c2", self.A_c2, f"(0, A_c1 = {self.A_c1:g}) m^2 (rod side is the annulus)"
            )

    @property
    def A_r(self) -> float:
        """Rod area A_c1 - A_c2 (errata Eq. 1: the rod sees p_a on it)."""
        return self.A_c1 - self.A_c2


@dataclass(frozen=True)
class ValveParams:
    Q_n: float = param(
        350.0 / 60000.0,
        unit="m^3/s",
        lo=0.0,
        lo_open=True,
        hi=0.1,
        desc="nominal flow (ANR) at p_n_up -> p_n_down, fully open",
        source="Festo MPYE-5-1/8-LF: 350 l/min (6 -> 5 bar gauge); range ±10 % (Festo nominal flow tolerance)",
        band=(0.00525, 0.006417),
    )
    p_n_up: float = param(
        6e5 + P_ATM,
        unit="Pa",
        lo=1e5,
        hi=2e6,
        desc="upstream pressure of the nominal-flow test, absolute",
        source="ISO 6358 nominal condition 6 bar gauge",
    )
    p_n_down: float = param(
        5e5 + P_ATM,
        unit="Pa",
        lo=1e5,
        hi=2e6,
        desc="downstream pressure of the nominal-flow test, absolute",
        source="ISO 6358 nominal condition 5 bar gauge",
    )
    T_n: float = param(
        293.15,
        unit="K",
        lo=250.0,
        hi=350.0,
        desc="temperature of the nominal-flow test",
        source="ISO 8778 (ANR, 20 °C)",
    )
    rho_n: float = param(
        1.185,
        unit="kg/m^3",
        lo=1.0,
        hi=1.4,
        desc="density of ANR air",
        source="ISO 8778 (100 kPa, 20 °C, 65 % RH)",
    )
    b: float = param(
        0.29,
        unit="-",
        lo=0.0,
        lo_open=True,
        hi=0.528,
        desc="critical pressure ratio",
        source="paper Table 1; range: Festo's 0.23 (MPYE-5-1/4 datasheet) to 0.35, ±0.06 about the paper's",
        band=(0.23, 0.35),
    )
    b_lam: float = param(
        0.999,
        unit="-",
        lo=0.9,
        hi=0.99999,
        desc="pressure ratio where the laminar (linear) patch starts",
        source="MathWorks Pneumatic Orifice (ISO 6358) default 0.999 (errata Eq. 11)",
    )
    du_table: tuple[float, ...] = param(
        MPYE_DU_V,
        unit="V",
        desc="|u - 5 V| breakpoints of the opening curve",
        source="Festo MPYE flow-vs-setpoint chart, digitised (" + _PLANT_SHEET + ")",
    )
    flow_table: tuple[float, ...] = param(
        MPYE_FLOW,
        unit="-",
        desc="normalised flow (= area fraction) at du_table",
        source="Festo MPYE flow-vs-setpoint chart, digitised (" + _PLANT_SHEET + ")",
    )
    u_curve: tuple[float, ...] = param(
        (),
        unit="V",
        desc="breakpoints (valve command) of the valve's own flow curve; empty: the catalogue's"
        " (du_table, flow_table) mirrored about 5 V",
        source="none: the catalogue curve (du_table, flow_table); pneu identify measures one",
    )
    flow_4: tuple[float, ...] = param(
        (),
        unit="-",
        desc="port 4's normalised flow at u_curve, signed (+ supply -> port 4, - port 4 ->"
        " exhaust; of the full-open flow Q_n), non-decreasing",
        source="none: the catalogue curve (du_table, flow_table); pneu identify measures one",
    )
    flow_2: tuple[float, ...] = param(
        (),
        unit="-",
        desc="port 2's normalised flow at u_curve, signed (+ supply -> port 2, - port 2 ->"
        " exhaust; of the full-open flow Q_n), non-increasing",
        source="none: the catalogue curve (du_table, flow_table); pneu identify measures one",
    )
    leak_fraction: float = param(
        0.01,
        unit="-",
        lo=0.0,
        hi=0.1,
        desc="centre leakage area per path / max area (on a closing path it fades out as the port's opening path passes flow_table's first step)",
        source="estimated: gives ≈ 9 l/min ANR at 6 bar with ports blocked, under the datasheet maximum of 20 l/min (LF); range: a tight new valve (≈ 2 l/min) to the datasheet maximum 20 l/min",
        band=(0.002, 0.022),
    )
    hysteresis: float = param(
        0.04,
        unit="V",
        lo=0.0,
        hi=1.0,
        desc="spool hysteresis (play) width",
        source="Festo MPYE catalogue: ≤ 0.4 % of max stroke (10 V span); range: 0 up to the catalogue's bound",
        band=(0.0, 0.04),
    )
    omega_n: float = param(
        2.0 * math.pi * 95.0,
        unit="rad/s",
        lo=1.0,
        hi=1e4,
        desc="spool natural frequency (2nd order)",
        source="Festo MPYE-5-1/8: -3 dB limit frequency ≈ 95 Hz ("
        + _PLANT_SHEET
        + "); range ±20 %: the limit frequency falls with amplitude and supply (estimated)",
        band=(477.5, 716.3),
    )
    zeta: float = param(
        0.7,
        unit="-",
        lo=0.05,
        hi=5.0,
        desc="spool damping ratio",
        source="estimated (" + _PLANT_SHEET + "); range 0.5-1.0 (estimated)",
        band=(0.5, 1.0),
    )

    def _check(self) -> None:
        if self.p_n_down >= self.p_n_up:
            raise ParamError("p_n_down", self.p_n_down, f"< p_n_up = {self.p_n_up:g} Pa")
        if self.b_lam <= self.b:
            raise ParamError("b_lam", self.b_lam, f"(b = {self.b:g}, 1)")
        du, fl = self.du_table, self.flow_table
        if len(du) < 2 or len(du) != len(fl):
            raise ParamError(
                "flow_table", list(fl), f"{len(du)} values, one per du_table entry (>= 2)"
            )
        if du[0] != 0.0 or any(b <= a for a, b in itertools.pairwise(du)) or du[-1] > 5.0:
            raise ParamError("du_table", list(du), "strictly increasing from 0 to at most 5 V")
        if fl[0] != 0.0 or fl[-1] != 1.0 or any(b < a for a, b in itertools.pairwise(fl)):
            raise ParamError("flow_table", list(fl), "non-decreasing from 0 to 1")
        bad = check_curve(self.u_curve, self.flow_4, self.flow_2)
        if bad is not None:
            raise ParamError(*bad)


@dataclass(frozen=True)
class RotaryParams:
    R_m: float = param(
        0.019,
        unit="m",
        lo=0.0,
        lo_open=True,
        hi=0.2,
        desc="stator bore radius (Eq. 6)",
        source="estimated ("
        + _PLANT_SHEET
        + "), checked against the 1AM's published free speed and power (test_sim_motor); range ±1 %: with L_m pinned on the datasheet torque, R_m and r_m shape the ripple (d_m ±15 %)",
        band=(0.01881, 0.01919),
    )
    r_m: float = param(
        0.0165,
        unit="m",
        lo=0.0,
        lo_open=True,
        hi=0.2,
        desc="rotor radius (Eq. 6)",
        source="estimated ("
        + _PLANT_SHEET
        + "); range ±1 %: with L_m pinned on the datasheet torque, R_m and r_m shape the ripple (d_m ±15 %)",
        band=(0.01634, 0.01666),
    )
    L_m: float = param(
        0.021,
        unit="m",
        lo=0.0,
        lo_open=True,
        hi=0.5,
        desc="vane length (Eq. 8)",
        source="estimated: sets the sector-mean Eq. 8 factor K = 1.87e-6 m^3 so that K * 100 psi = 1.29 N*m"
        " = 4 P_max / omega_free, the stall torque of a linear torque-speed line through Gast 1AM's"
        " 0.45 hp and 10 000 rpm at 100 psi (the sheet's 25 mm ignores the 2 d R cos term of Eq. 8); range ±20 %: a linear torque-speed line is an approximation (estimated)",
        band=(0.0168, 0.0252),
    )
    n_vanes: int = param(
        4,
        unit="-",
        lo=2,
        hi=16,
        desc="number of vanes (torque ripple period 2π/n)",
        source="Gast 1AM product data (4 vanes)",
    )
    J_m: float = param(
        3.5e-5,
        unit="kg*m^2",
        lo=0.0,
        lo_open=True,
        hi=1.0,
        desc="rotor + coupling + rod + piston inertia",
        source="estimated (" + _PLANT_SHEET + "); range ±50 %, as the sheet gives it",
        band=(1.75e-05, 5.25e-05),
    )
    M_c: float = param(
        0.1281,
        unit="N*m",
        lo=0.0,
        hi=10.0,
        desc="Coulomb friction torque (Eq. 9)",
        source="paper Eq. 9 fit; range ±25 %: vane friction moves with lubrication, pressure and temperature (estimated)",
        band=(0.09607, 0.1601),
    )
    M_v: float = param(
        8.66e-5,
        unit="N*m/rpm",
        lo=0.0,
        hi=0.1,
        desc="viscous friction torque per rpm (Eq. 9)",
        source="paper Eq. 9 fit (per r/min, = 8.27e-4 N·m·s/rad); range ±25 %: vane friction moves with lubrication, pressure and temperature (estimated)",
        band=(6.495e-05, 0.0001083),
    )
    static_ratio: float = param(
        1.0,
        unit="-",
        lo=1.0,
        hi=3.0,
        desc="static friction torque / M_c (Eq. 10: f(0) = 0 read as sticking up to M_c)",
        source="paper Eq. 10 (no breakaway measured); range up to 1.5: vane motors break away above their running friction (estimated)",
        band=(1.0, 1.5),
    )
    V_m1: float = param(
        1.4e-5,
        unit="m^3",
        lo=0.0,
        lo_open=True,
        hi=1e-3,
        desc="inlet chamber + tubing volume",
        source="estimated (" + _PLANT_SHEET + "); range ±50 % (estimated)",
        band=(7e-06, 2.1e-05),
    )
    V_m2: float = param(
        1.0e-5,
        unit="m^3",
        lo=0.0,
        lo_open=True,
        hi=1e-3,
        desc="exhaust chamber + port volume",
        source="estimated: exhaust-side cells and port of a 1AM-size motor; range ±50 % (estimated)",
        band=(5e-06, 1.5e-05),
    )
    A_ex: float = param(
        1.5e-5,
        unit="m^2",
        lo=0.0,
        lo_open=True,
        hi=1e-3,
        desc="silencer orifice area (ISO 6358 with Eq. 12 C_d, b as valve)",
        source="estimated: 1/8 NPT exhaust port (≈ 7 mm bore, 38 mm^2) throttled by a sintered silencer to ≈ 40 %; range ±50 % (estimated)",
        band=(7.5e-06, 2.25e-05),
    )
    k_leak: float = param(
        5e-10,
        unit="kg/(s*Pa)",
        lo=0.0,
        hi=1e-6,
        desc="vane/side leakage inlet -> exhaust, laminar",
        source="estimated: 5e-5 kg/s (≈ 2.5 l/min ANR) at 1 bar, ≈ 15 % of the 800 rpm consumption; range ×/÷ 2 (estimated)",
        band=(2.5e-10, 1e-09),
    )
    plumbing: str = param(
        "paper",
        unit="-",
        choices=PLUMBINGS,
        desc="valve #2 to motor piping: paper = port 4 -> motor port A only, port B exhausts"
        " through the silencer (drives one way, stops by friction); bidirectional = port 4 ->"
        " port A, port 2 -> port B (u > 5 V drives forward, u < 5 V brakes and reverses)",
        source="paper (Fig. 4 and text: one valve feeds the motor inlet, the exhaust chamber"
        " vents through a silencer); bidirectional: the MPYE is a 5/3 valve and the paper's"
        " 1AM-NRV is the reversible 1AM variant (Gast model code, not verified against a"
        " datasheet); a housing exhaust of the reversible 1AM, if it has one, is not modelled (no datasheet in reach)",
        read_only=True,
    )

    def _check(self) -> None:
        if not self.r_m < self.R_m:
            raise ParamError("r_m", self.r_m, f"(0, R_m = {self.R_m:g}) m")

    @property
    def d_m(self) -> float:
        """Eccentricity d_m = R_m - r_m (Eq. 6)."""
        return self.R_m - self.r_m

    @property
    def M_v_si(self) -> float:
        """M_v in N·m·s/rad."""
        return self.M_v * 60.0 / (2.0 * math.pi)


@dataclass(frozen=True)
class CouplingParams:
    """The torque transmission module couples the axes (paper, "Linear-rotary composite motion
    pneumatic actuator"): the motor turns the piston, piston rod and transmission rod inside the
    cylinder's seals, and the sleeve slides on the transmission rod's "I" shaft."""

    k_seal: float = param(
        0.0,
        unit="N*m/Pa",
        lo=0.0,
        hi=1e-5,
        desc="seal friction torque on the motor per Pa of chamber gauge pressure:"
        " T_seal = k_seal ((p_c1 - p_a)+ + (p_c2 - p_a)+), added to M_c",
        source="estimated (the paper is silent; its M_c is read as measured with the cylinder vented):"
        " a lip pressed by gauge p on a band b over its circumference gives a friction force"
        " mu pi d b p at radius d/2 when the rod turns, torque mu pi b d^2 p / 2; per chamber one"
        " piston lip (d = 32 mm) and one rod seal (12 mm: piston rod at the front cover,"
        " transmission rod at the rear cover, the latter's diameter estimated):"
        " k = mu pi b (D^2 + d^2) / 2 with mu = 0.1 (lubricated elastomer on steel), b = 0.5 mm,"
        " i.e. 0.5 N per bar axially on the piston lip, k = 9.2e-8 (K_SEAL_ESTIMATE); nominal 0 (off):"
        " with it on, the MPYE's centre leakage at 5 V leaves the motor at the edge of its creep"
        " (stick-slip), where a replay's speed hangs on sub-kPa pressure errors and the rotary"
        " identification of a known plant fails (held-out p_m1 fit 68-73 % with the true plant);"
        " range 0 to 3x the estimate (mu 0.05-0.2, b 0.3-1 mm)",
        band=(0.0, 2.8e-07),
    )
    mu_sleeve: float = param(
        0.15,
        unit="-",
        lo=0.0,
        hi=1.0,
        desc="friction coefficient of the sleeve on the transmission rod's I-shaped shaft",
        source="estimated: 430F stainless on 430F stainless (paper), greased: 0.1-0.2;"
        " range 0.05 (well lubricated) to 0.5 (dry stainless on stainless)",
        band=(0.05, 0.5),
    )
    r_sleeve: float = param(
        3e-3,
        unit="m",
        lo=0.0,
        lo_open=True,
        hi=0.05,
        desc="lever arm of the sleeve's flat contacts: F_sleeve = mu_sleeve |T_rod| / r_sleeve",
        source="estimated: the paper gives no dimensions of the I-shaped shaft; two flat faces"
        " about 3 mm from the axis carry the torque as a couple (normal force T/(2 r) on each);"
        " range 2-5 mm (estimated)",
        band=(0.002, 0.005),
    )


# k_seal as estimated in its source (CouplingParams.k_seal; nominal 0)
K_SEAL_ESTIMATE = 9.2e-8

# The load fields Plant.set_load can change between steps (task segments).
LOAD_FIELDS = ("T_c", "T_bk", "c_load", "J_load", "k_spring", "x_0", "F_ext")
_LOAD_SOURCE = "task setting: no external load in the paper's experiments (default 0 = off)"


@dataclass(frozen=True)
class LoadParams:
    """External loads set by a task (all off by default); ``Plant.set_load`` changes them
    between steps. The rotary ones act on the piston rod's output and pass the sleeve."""

    T_c: float = param(
        0.0,
        unit="N*m",
        lo=0.0,
        hi=10.0,
        desc="load Coulomb (sliding) friction torque on the rotary output",
        source=_LOAD_SOURCE,
    )
    T_bk: float = param(
        0.0,
        unit="N*m",
        lo=0.0,
        hi=10.0,
        desc="load breakaway torque: the load holds still while |torque| <= max(T_bk, T_c)",
        source=_LOAD_SOURCE,
    )
    c_load: float = param(
        0.0,
        unit="N*m*s/rad",
        lo=0.0,
        hi=1.0,
        desc="load viscous torque per rad/s",
        source=_LOAD_SOURCE,
    )
    J_load: float = param(
        0.0,
        unit="kg*m^2",
        lo=0.0,
        hi=1.0,
        desc="inertia added to the rotary output (on top of rotary.J_m)",
        source=_LOAD_SOURCE,
    )
    k_spring: float = param(
        0.0,
        unit="N/m",
        lo=0.0,
        hi=1e6,
        desc="spring on the rod: F = -k_spring (x - x_0)",
        source=_LOAD_SOURCE,
    )
    x_0: float = param(
        0.0,
        unit="m",
        lo=-1.0,
        hi=1.0,
        desc="position where the spring is relaxed (preload at x = 0: k_spring x_0)",
        source=_LOAD_SOURCE,
    )
    F_ext: float = param(
        0.0,
        unit="N",
        lo=-1e4,
        hi=1e4,
        desc="constant external force on the rod, + = extending",
        source=_LOAD_SOURCE,
    )


@dataclass(frozen=True)
class PressureSensorParams:
    fs: float = param(
        1.0e6,
        unit="Pa",
        lo=1e4,
        hi=1e8,
        desc="full scale (gauge) of the Huba 511",
        source="Huba 511.930002741: 0-10 bar relative",
    )
    v_fs: float = param(
        10.0,
        unit="V",
        lo=0.1,
        hi=10.0,
        desc="output at full scale",
        source="Huba 511: 0-10 V output",
    )
    accuracy_fs: float = param(
        0.005,
        unit="-",
        lo=0.0,
        hi=0.1,
        desc="static accuracy / FS; each sensor gets a fixed offset drawn uniformly in ±accuracy from the seed",
        source="Huba 511: ±0.5 % FS (" + _PLANT_SHEET + ", UNV)",
    )
    sigma_v: float = param(
        0.002,
        unit="V",
        lo=0.0,
        hi=1.0,
        desc="output noise (1 σ)",
        source="estimated: Huba gives no noise figure; 2 mV rms on 10 V is typical of amplified piezoresistive sensors; range 0.5-5 mV (estimated)",
        band=(0.0005, 0.005),
    )
    tau: float = param(
        2.3e-3,
        unit="s",
        lo=0.0,
        lo_open=True,
        hi=0.1,
        desc="first-order time constant",
        source="Huba 511: response < 5 ms read as 10-90 % rise, τ = 5 ms / 2.2; range: '< 5 ms' is a bound, down to 0.5 ms (estimated)",
        band=(0.0005, 0.0023),
    )


@dataclass(frozen=True)
class LaserParams:
    range_m: float = param(
        0.16,
        unit="m",
        lo=0.01,
        hi=1.0,
        desc="measuring span (200 ± 80 mm), centred on x = 0",
        source="Panasonic HG-C1200 datasheet",
    )
    v_fs: float = param(
        5.0,
        unit="V",
        lo=0.1,
        hi=10.0,
        desc="analog output at full span (0-5 V)",
        source="Panasonic HG-C1200 datasheet",
    )
    tau: float = param(
        0.68e-3,
        unit="s",
        lo=0.0,
        lo_open=True,
        hi=0.1,
        desc="first-order time constant at the chosen response setting (1.5 ms)",
        source="HG-C1200 response 1.5 ms read as 10-90 % rise, τ = 1.5 ms / 2.2; range: up to 1.5 ms read as the time constant",
        band=(0.00068, 0.0015),
    )
    sigma_m: float = param(
        86e-6,
        unit="m",
        lo=0.0,
        hi=0.01,
        desc="displacement noise (1 σ) at the 1.5 ms setting",
        source="estimated: repeatability 200 µm at the slowest (10 ms) setting read as ±3σ → 33 µm; × sqrt(10/1.5) for the 1.5 ms setting; range: ±2σ reading (130 µm) down to a unit 40 % better than the ±3σ reading (50 µm), estimated",
        band=(5e-05, 0.00013),
    )


@dataclass(frozen=True)
class EncoderParams:
    ppr: int = param(
        1000,
        unit="1/rev",
        lo=1,
        hi=100000,
        desc="pulses per revolution (one channel); X4 decoding gives 4·ppr counts",
        source="Omron E6B2-CWZ6C 1000 P/R variant (paper names the series only)",
    )


@dataclass(frozen=True)
class DaqParams:
    ai_bits: int = param(
        16, unit="bit", lo=8, hi=24, desc="AI resolution", source="NI PCI-6221: 16-bit AI"
    )
    ai_range_pressure: float = param(
        10.0,
        unit="V",
        lo=0.1,
        hi=10.0,
        desc="AI range ± of the pressure channels",
        source="NI PCI-6221 ranges ±10/5/1/0.2 V; ±10 V covers 0-10 V",
    )
    ai_range_laser: float = param(
        5.0,
        unit="V",
        lo=0.1,
        hi=10.0,
        desc="AI range ± of the laser channel",
        source="NI PCI-6221 ranges; ±5 V covers the laser's 0-5 V",
    )
    ao_bits: int = param(
        16, unit="bit", lo=8, hi=24, desc="AO resolution", source="NI PCI-6221: 16-bit AO"
    )
    ao_range: float = param(
        10.0,
        unit="V",
        lo=1.0,
        hi=10.0,
        desc="AO range ± (commands clamped to 0-10 V)",
        source="NI PCI-6221: ±10 V AO",
    )


@dataclass(frozen=True)
class SensorParams:
    pressure: PressureSensorParams = param(PressureSensorParams)
    laser: LaserParams = param(LaserParams)
    encoder: EncoderParams = param(EncoderParams)
    daq: DaqParams = param(DaqParams)


@dataclass(frozen=True)
class SimParams:
    T: float = param(
        1e-3,
        unit="s",
        lo=1e-5,
        hi=0.1,
        desc="sample period (DAQ clock)",
        source="paper: 1 ms sampling",
        read_only=True,
    )
    n_sub: int = param(
        10,
        unit="-",
        lo=1,
        hi=1000,
        desc="integration substeps per sample period",
        source="chosen: step-size convergence shown in test_sim_integrator",
    )
    noise_block: int = param(
        1000,
        unit="-",
        lo=1,
        hi=1000000,
        desc="samples of sensor noise drawn per refill of the seeded generator",
        source="chosen (speed); results do not depend on it",
    )


@dataclass(frozen=True)
class PlantParams:
    """The whole twin. Groups: ambient, supply, linear, valve_linear, valve_rotary, rotary,
    coupling, load, sensors, sim."""

    ambient: AmbientParams = param(AmbientParams)
    supply: SupplyParams = param(SupplyParams)
    linear: LinearParams = param(LinearParams)
    valve_linear: ValveParams = param(ValveParams)
    valve_rotary: ValveParams = param(ValveParams)
    rotary: RotaryParams = param(RotaryParams)
    coupling: CouplingParams = param(CouplingParams)
    load: LoadParams = param(LoadParams)
    sensors: SensorParams = param(SensorParams)
    sim: SimParams = param(SimParams)

    def _check(self) -> None:
        p_a = self.ambient.p_a
        for key in ("p_s_linear", "p_s_rotary"):
            v = getattr(self.supply, key)
            if v <= p_a:
                raise ParamError(f"supply.{key}", v, f"> ambient.p_a = {p_a:g} Pa")
