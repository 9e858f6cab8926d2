"""The fixed CDR layouts the bag writer and readers use: they live in
:mod:`pneu_msgs_py.contract.cdr` (the wire codec shares them), re-exported here."""

from pneu_msgs_py.contract.cdr import (
    CDR_LE_HEADER,
    CdrDecodeError,
    FixedLayout,
    clock_layout,
    fluid_pressure_layout,
    joint_state_layout,
    layout_of,
    parse_fixed,
    split_stamp,
)

__all__ = [
    "CDR_LE_HEADER",
    "CdrDecodeError",
    "FixedLayout",
    "clock_layout",
    "fluid_pressure_layout",
    "joint_state_layout",
    "layout_of",
    "parse_fixed",
    "split_stamp",
]
