"""The safety supervisor shared by the runner, the sim node and the driver, and its parameters.

- :mod:`.params` -- ``SafetyParams`` (``config/safety.yaml``) and its loader;
- :mod:`.events` -- levels, ``SafetyEvent`` transitions and ``AxisStatus``;
- :mod:`.rules` -- the decision rules, written once as kernels on records (Python and compiled);
- :mod:`.supervisor` -- ``SafetySupervisor``, the per-axis state machine around them.
"""

from pneu_driver.safety.events import (
    ERROR,
    LEVEL_BYTE,
    OK,
    SAFE_V,
    SENSOR_AXIS,
    WARN,
    AxisStatus,
    SafetyEvent,
)
from pneu_driver.safety.params import SafetyParams, check_plumbing, load_safety_params
from pneu_driver.safety.supervisor import SafetySupervisor

__all__ = [
    "ERROR",
    "LEVEL_BYTE",
    "OK",
    "SAFE_V",
    "SENSOR_AXIS",
    "WARN",
    "AxisStatus",
    "SafetyEvent",
    "SafetyParams",
    "SafetySupervisor",
    "check_plumbing",
    "load_safety_params",
]
