"""Static valve-flow linearisation of the MPYE (ESO-SMC+, item 2 of its docstring).

The MPYE's flow is a progressive function F(|u − 5 V|) of the setpoint
(Festo chart; the ±0.35 V "dead band" is its flat start). A *linearised*
command v maps to the valve deviation u = sign(v) F⁻¹(g |v|), g = F(u_1)/u_1
(u_1 = ``valve_unit_v``, where b0 is identified); beyond full opening the map
continues with unit slope, so it is a bijection.

The map is two kernels (:func:`to_linear`, :func:`to_valve`) on a record with the
fields of :data:`VALVE_FIELDS` and the chart as a table with the rows (du, flow)
(:func:`valve_table`); ESO-SMC+ passes its own constants record, which has those
fields. A NaN maps to NaN (a plain lookup would read past the table).
"""

from __future__ import annotations

from typing import Any

from pneu_msgs_py.params.records import RecordType, kernel

__all__ = [
    "VALVE_CURVE",
    "VALVE_FIELDS",
    "ValveCurve",
    "to_linear",
    "to_valve",
    "valve_constants",
    "valve_table",
]

# g = F(u_1)/u_1, its inverse, the table's last |u − 5 V| (full opening), |v| there,
# the number of breakpoints
VALVE_FIELDS = [("g", "f"), ("inv_g", "f"), ("du_max", "f"), ("v_max", "f"), ("n_vt", "i")]
VALVE_CURVE = RecordType("ValveCurveConstants", VALVE_FIELDS)


@kernel
def bisect_right(a, n, x):
    """:func:`bisect.bisect_right` on ``a[:n]`` (the same loop as CPython's)."""
    lo = 0
    hi = n
    while lo < hi:
        mid = (lo + hi) // 2
        if x < a[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@kernel
def interpolate(xs, ys, n, x):
    """ys at x on the breakpoints xs[:n] (linear; the last segment beyond its end)."""
    i = bisect_right(xs, n, x) - 1
    if i > n - 2:  # x at or past the last breakpoint (or NaN)
        i = n - 2
    return ys[i] + (ys[i + 1] - ys[i]) * (x - xs[i]) / (xs[i + 1] - xs[i])


@kernel
def flow(c, table, a):
    """F(a): normalised flow at the opening a = |u − 5 V| ≥ 0 (1 from full opening on)."""
    n = c.n_vt
    du = table[0]
    if a >= du[n - 1]:
        return 1.0
    return interpolate(du, table[1], n, a)


@kernel
def to_linear(c, table, u):
    """Valve deviation u (V) → linearised command v."""
    a = u if u >= 0.0 else -u
    if a >= c.du_max:
        v = c.v_max + (a - c.du_max)
    else:
        v = flow(c, table, a) * c.inv_g
    return v if u >= 0.0 else -v


@kernel
def to_valve(c, table, v):
    """Linearised command v → valve deviation u (V): the inverse of :func:`to_linear`."""
    a = v if v >= 0.0 else -v
    if a >= c.v_max:
        u = c.du_max + (a - c.v_max)
    else:
        u = interpolate(table[1], table[0], c.n_vt, a * c.g)
    return u if v >= 0.0 else -u


def valve_table(du_table: Any, flow_table: Any) -> list[list[float]]:
    """The chart as the kernels read it: rows (du, flow), floats."""
    return [[float(v) for v in du_table], [float(v) for v in flow_table]]


def valve_constants(du_table: Any, flow_table: Any, unit_v: float) -> dict[str, Any]:
    """The :data:`VALVE_FIELDS` values of the chart with b0's unit point ``unit_v`` (V)."""
    table = valve_table(du_table, flow_table)
    n = len(table[0])
    g = flow(VALVE_CURVE.new(n_vt=n), table, unit_v) / unit_v
    inv_g = 1.0 / g
    return {"g": g, "inv_g": inv_g, "du_max": table[0][-1], "v_max": inv_g, "n_vt": n}


class ValveCurve:
    """The map v ↔ u of one chart (see the module docstring), for tests and analysis.

    ``to_valve(v)``: linearised command → valve deviation u (V).
    ``to_linear(u)``: valve deviation → linearised command (its inverse).
    """

    def __init__(self, du_table: Any, flow_table: Any, unit_v: float):
        self.c = VALVE_CURVE.new(**valve_constants(du_table, flow_table, unit_v))
        self.table = valve_table(du_table, flow_table)
        self.du, self.fl = self.table
        self.g, self.inv_g, self.du_max, self.v_max = (
            self.c.g,
            self.c.inv_g,
            self.c.du_max,
            self.c.v_max,
        )

    def to_linear(self, u: float) -> float:
        return to_linear(self.c, self.table, u)

    def to_valve(self, v: float) -> float:
        return to_valve(self.c, self.table, v)
