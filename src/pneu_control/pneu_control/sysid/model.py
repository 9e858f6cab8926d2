"""What identification may change in the twin: the uncertain parameters, their bounds and scales.

Each :class:`FitParam` names a plant.yaml leaf (or a derived handle: a
valve's dead band, a shift of its flow curve's breakpoints), the axis whose
data inform it, a transform (``log`` for positive scale-like values: the fit
moves in relative steps; ``lin`` otherwise) and physical bounds. Geometry
from the paper's Table 1 (areas, dead volumes, mass, stroke, the motor's
R_m, r_m, L_m) and the datasheet constants stay fixed: they are facts with
tolerances, and letting them move would only trade against what is uncertain.

The fit variable is z = (g(p) − g(p_base)) / w with g the transform and w
its width (1 for ``log``: z = 1 is a factor e), so least squares works on
numbers of order one.

Not identifiable from the sensors we have, and therefore not fitted: the
motor's polytropic index separately from its chamber volumes (the motor's
volumes are fixed, so n only appears as n/V_m1 and n/V_m2) -- the motor uses
the index fitted on the cylinder, whose moving piston separates n from the
flow (p V^n under compression).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pneu_msgs_py.params.core import ParamError, flatten, with_updates

__all__ = [
    "AXIS_PARAMS",
    "FitParam",
    "FIT_PARAMS",
    "apply",
    "base_value",
    "is_handle",
    "shifted_table",
]

DEAD_BAND = "dead_band"  # handle suffix: shift of a valve's du_table breakpoints (V)


@dataclass(frozen=True)
class FitParam:
    """One parameter identification may change: its plant path, axis, bounds, unit and the scale of
    the fit's coordinate z."""

    name: str  # dotted plant.yaml path, or "<valve>.dead_band"
    axis: str  # linear | rotary: whose data inform it
    transform: str  # log | lin
    lo: float
    hi: float
    unit: str
    desc: str
    width: float = 1.0  # z = (g(p) - g(p0)) / width

    def to_z(self, value: float, base: float) -> float:
        """The fit coordinate of ``value`` about ``base`` (log or linear, over ``width``)."""
        if self.transform == "log":
            return math.log(value / base) / self.width
        return (value - base) / self.width

    def from_z(self, z: float, base: float) -> float:
        """The value at fit coordinate ``z`` about ``base`` (inverse of :meth:`to_z`)."""
        if self.transform == "log":
            return base * math.exp(z * self.width)
        return base + z * self.width

    def z_bounds(self, base: float) -> tuple[float, float]:
        """The bounds [lo, hi] as fit coordinates about ``base``."""
        return self.to_z(self.lo, base), self.to_z(self.hi, base)


FIT_PARAMS: tuple[FitParam, ...] = (
    # linear axis (cylinder, valve #1)
    FitParam("valve_linear.Q_n", "linear", "log", 0.1 / 60e3 * 100, 2000 / 60e3, "m^3/s", "valve #1 flow-curve scale (nominal flow)"),
    FitParam("valve_linear.dead_band", "linear", "lin", -0.3, 0.25, "V", "valve #1 dead band: shift of the opening curve's breakpoints", width=0.1),
    FitParam("valve_linear.leak_fraction", "linear", "log", 1e-4, 0.1, "-", "valve #1 centre leakage area / max area"),
    FitParam("linear.A_f", "linear", "log", 0.05, 100.0, "N", "sliding friction (Eq. 2)"),
    FitParam("linear.c_v", "linear", "log", 1.0, 3000.0, "N*s/m", "viscous friction (Eq. 2)"),
    FitParam("linear.breakaway_ratio", "linear", "lin", 1.0, 3.0, "-", "breakaway / sliding friction", width=0.2),
    FitParam("ambient.n_poly", "linear", "lin", 1.0, 1.4, "-", "polytropic index", width=0.1),
    FitParam("supply.p_s_linear", "linear", "log", 1.3e5, 1.1e6, "Pa", "supply of valve #1, absolute"),
    # rotary axis (motor, valve #2)
    FitParam("valve_rotary.Q_n", "rotary", "log", 0.1 / 60e3 * 100, 2000 / 60e3, "m^3/s", "valve #2 flow-curve scale (nominal flow)"),
    FitParam("valve_rotary.dead_band", "rotary", "lin", -0.3, 0.25, "V", "valve #2 dead band: shift of the opening curve's breakpoints", width=0.1),
    FitParam("valve_rotary.leak_fraction", "rotary", "log", 1e-4, 0.1, "-", "valve #2 centre leakage area / max area"),
    FitParam("rotary.J_m", "rotary", "log", 1e-6, 1e-3, "kg*m^2", "motor + rod inertia"),
    FitParam("rotary.M_c", "rotary", "log", 1e-3, 2.0, "N*m", "Coulomb friction torque (Eq. 9)"),
    FitParam("rotary.M_v", "rotary", "log", 1e-7, 1e-2, "N*m/rpm", "viscous friction torque (Eq. 9)"),
    FitParam("rotary.V_m1", "rotary", "log", 1e-6, 5e-4, "m^3", "motor inlet chamber + tubing"),
    FitParam("rotary.V_m2", "rotary", "log", 1e-6, 5e-4, "m^3", "motor exhaust chamber"),
    FitParam("rotary.A_ex", "rotary", "log", 1e-7, 5e-4, "m^2", "exhaust throttle (silencer) area"),
    FitParam("rotary.k_leak", "rotary", "log", 1e-12, 1e-7, "kg/(s*Pa)", "vane leakage inlet -> exhaust"),
    FitParam("supply.p_s_rotary", "rotary", "log", 1.3e5, 1.1e6, "Pa", "supply of valve #2, absolute"),
)  # fmt: skip

AXIS_PARAMS = {
    axis: tuple(p for p in FIT_PARAMS if p.axis == axis) for axis in ("linear", "rotary")
}


def shifted_table(du_table: tuple[float, ...], shift_v: float) -> tuple[float, ...]:
    """The opening curve's breakpoints moved by ``shift_v`` (all but the 0 V one): a wider
    (> 0) or narrower (< 0) dead band with the curve's shape kept."""
    out = (0.0, *(d + shift_v for d in du_table[1:]))
    if out[1] <= 0.0 or out[-1] > 5.0:
        raise ParamError(
            "dead_band", shift_v, f"({-du_table[1]:g}, {5.0 - du_table[-1]:g}] V for this table"
        )
    return out


def is_handle(name: str) -> bool:
    """Is ``name`` a handle of a valve's own curve (``<valve>.flow_<port>@<what>``,
    :mod:`pneu_control.sysid.curve`)?"""
    return "@" in name


def base_value(base, p: FitParam) -> float:
    """The value of ``p`` in the base plant (0 for a dead-band shift; a curve knot's on the
    base's curve, :mod:`pneu_control.sysid.curve`)."""
    if p.name.endswith("." + DEAD_BAND):
        return 0.0
    if is_handle(p.name):
        from pneu_control.sysid import curve

        return curve.base_value(base, p.name)
    return float(flatten(base)[p.name])


def apply(base, params: tuple[FitParam, ...], values: list[float]):
    """``base`` PlantParams with ``params`` set to ``values`` (validated)."""
    updates: dict[str, object] = {}
    knots = {p.name: v for p, v in zip(params, values) if is_handle(p.name)}
    if knots:  # a valve's own curve (pneu_control.sysid.curve)
        from pneu_control.sysid import curve

        updates.update(curve.updates(base, knots))
    for p, v in zip(params, values):
        if is_handle(p.name):
            continue
        if p.name.endswith("." + DEAD_BAND):
            valve = p.name.split(".")[0]
            table = getattr(base, valve).du_table
            updates[f"{valve}.du_table"] = shifted_table(table, v)
        else:
            updates[p.name] = v
    return with_updates(base, updates)
