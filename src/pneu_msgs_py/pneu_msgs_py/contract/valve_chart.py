"""The Festo MPYE-5 flow-vs-setpoint chart: one reference table for the twin and the controllers.

The twin's valve model (:mod:`pneu_sim.physics.params`, ``valves``) and ESO-SMC+'s
valve linearisation (:mod:`pneu_control.algorithms.eso_smc_plus_params`) read the
same digitised chart, so neither package imports the other for it.
"""

from __future__ import annotations

__all__ = ["MPYE_DU_V", "MPYE_FLOW"]

# Festo MPYE-5 normalised flow vs |u - 5 V| (digitised from Festo's flow-vs-setpoint
# chart, reference/plant-parameters.md).
MPYE_DU_V = (
    0.0, 0.36, 0.71, 0.94, 1.20, 1.43, 1.66, 1.86, 2.12, 2.47, 2.81, 3.16, 3.47, 3.81,
    4.20, 4.62, 4.75,
)  # fmt: skip
MPYE_FLOW = (
    0.0, 0.01, 0.03, 0.06, 0.11, 0.18, 0.26, 0.31, 0.40, 0.48, 0.59, 0.67, 0.74, 0.82,
    0.90, 0.98, 1.00,
)  # fmt: skip
