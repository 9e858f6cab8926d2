"""Static valve-flow linearisation of the MPYE (ESO-SMC+, item 2 of its docstring).

The MPYE's flow is a progressive function F(|u − 5 V|) of the setpoint
(Festo chart; the ±0.35 V "dead band" is its flat start). A *linearised*
command v maps to the valve deviation u = sign(v) F⁻¹(g |v|), g = F(u_1)/u_1
(u_1 = ``valve_unit_v``, where b0 is identified); beyond full opening the map
continues with unit slope, so it is a bijection.
"""

from __future__ import annotations

import bisect

__all__ = ["IDENTITY", "ValveCurve"]


class ValveCurve:
    """Static valve-flow linearisation v ↔ u (see the module docstring).

    ``to_valve(v)``: linearised command → valve deviation u (V).
    ``to_linear(u)``: valve deviation → linearised command (its inverse).
    """

    __slots__ = ("du", "du_max", "fl", "g", "inv_g", "v_max")

    def __init__(self, du_table, flow_table, unit_v: float):
        self.du = [float(v) for v in du_table]
        self.fl = [float(v) for v in flow_table]
        self.g = self._flow(unit_v) / unit_v
        self.inv_g = 1.0 / self.g
        self.du_max = self.du[-1]
        self.v_max = self.inv_g  # |v| at full opening

    def _flow(self, a: float) -> float:
        du, fl = self.du, self.fl
        if a >= du[-1]:
            return 1.0
        i = bisect.bisect_right(du, a) - 1
        return fl[i] + (fl[i + 1] - fl[i]) * (a - du[i]) / (du[i + 1] - du[i])

    def to_linear(self, u: float) -> float:
        a = u if u >= 0.0 else -u
        if a >= self.du_max:
            v = self.v_max + (a - self.du_max)
        else:
            v = self._flow(a) * self.inv_g
        return v if u >= 0.0 else -v

    def to_valve(self, v: float) -> float:
        a = v if v >= 0.0 else -v
        if a >= self.v_max:
            u = self.du_max + (a - self.v_max)
        else:
            q = a * self.g
            du, fl = self.du, self.fl
            i = bisect.bisect_right(fl, q) - 1
            u = du[i] + (du[i + 1] - du[i]) * (q - fl[i]) / (fl[i + 1] - fl[i])
        return u if v >= 0.0 else -u


class _Identity:
    @staticmethod
    def to_linear(u: float) -> float:
        return u

    @staticmethod
    def to_valve(v: float) -> float:
        return v


IDENTITY = _Identity()
