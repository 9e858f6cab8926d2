"""What the supervisor reports: levels, transitions (``SafetyEvent``) and per-axis states."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pneu_msgs_py.contract.samples import NEUTRAL_V

__all__ = [
    "OK",
    "WARN",
    "ERROR",
    "LEVEL_BYTE",
    "SAFE_V",
    "SENSOR_AXIS",
    "SafetyEvent",
    "AxisStatus",
]

OK, WARN, ERROR = "OK", "WARN", "ERROR"
LEVEL_BYTE = {OK: 0, WARN: 1, ERROR: 2}  # diagnostic_msgs/DiagnosticStatus.level
SAFE_V = NEUTRAL_V  # MPYE closed centre

# Which axis depends on which sensor (a fault there makes that valve safe).
SENSOR_AXIS = {
    "p_c1": "linear",
    "p_c2": "linear",
    "x": "linear",
    "p_m1": "rotary",
    "encoder": "rotary",
}


@dataclass(frozen=True, slots=True)
class SafetyEvent:
    """One transition, as ``/diagnostics`` and the bag record it.

    ``axis`` is ``linear``, ``rotary`` or ``all``; ``rule`` the rule name
    (``watchdog``, ``live_range``, ``estop``…); ``level`` OK/WARN/ERROR;
    ``values`` key-value pairs (diagnostic_msgs/KeyValue) as strings.
    """

    stamp_ns: int
    axis: str
    rule: str
    level: str
    message: str
    values: tuple[tuple[str, str], ...] = ()

    def as_dict(self) -> dict[str, Any]:
        return {
            "stamp_ns": self.stamp_ns,
            "axis": self.axis,
            "rule": self.rule,
            "level": self.level,
            "message": self.message,
            "values": dict(self.values),
        }


@dataclass(frozen=True, slots=True)
class AxisStatus:
    """``state``: OK, LIMITED (soft limit holding back a direction) or SAFE (valve at 5 V).

    ``causes``: why it is SAFE now (``estop``, latched fault keys such as
    ``live_range:p_c1``, ``no_command``, ``no_sample``); ``present``: fault
    conditions that are present right now (latched or not).
    """

    axis: str
    state: str
    causes: tuple[str, ...]
    present: tuple[str, ...]
