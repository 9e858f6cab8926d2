"""Names of the metadata records a pneu run's bag carries.

Written by :mod:`pneu_control.experiment.bag_log` (in-process runs) and the
logger node, read by :mod:`pneu_control.analysis.run_analysis`; kept here so the
reader does not import the writer's side.
"""

from __future__ import annotations

__all__ = [
    "END_METADATA",
    "EXCITE_METADATA",
    "FAULTS_METADATA",
    "INTERVALS_METADATA",
    "RUN_METADATA",
    "SAFETY_METADATA",
]

RUN_METADATA = "pneu.run"  # metadata record holding the run's full config
SAFETY_METADATA = "pneu.safety"  # supervisor on/off, its thresholds, allow_unsafe
FAULTS_METADATA = "pneu.faults"  # the injected faults (written at the start)
INTERVALS_METADATA = "pneu.fault_intervals"  # injected + safe intervals (written at the end)
EXCITE_METADATA = "pneu.excite"  # excitation design per axis (pneu_control.sysid)
END_METADATA = "pneu.end"  # how the run ended: completed / interrupted (signal, time) / failed
