"""Plant variants for robustness checks: moving mass/inertia and supply pressure scaled.

Used by the tuning score (``pneu tune``) and the closed-loop robustness tests
(issue 3: "each controller is stable on the twin across ±30 % plant mass and
supply-pressure changes"). Supply scaling acts on the gauge pressure (the
regulator setting); mass scaling acts on the piston assembly M and the
rotating inertia J_m alike.
"""

from __future__ import annotations

import dataclasses
from typing import Any

__all__ = ["ROBUSTNESS_VARIANTS", "scaled_plant"]

# (mass factor, supply factor): the corners the tuning score and the tests use
ROBUSTNESS_VARIANTS: tuple[tuple[float, float], ...] = ((1.3, 0.7), (0.7, 1.3))


def scaled_plant(plant: Any, *, mass: float = 1.0, supply: float = 1.0) -> Any:
    """A copy of ``plant`` (PlantParams) with M, J_m ×``mass`` and gauge supplies ×``supply``."""
    p_a = plant.ambient.p_a
    lin = dataclasses.replace(plant.linear, M=plant.linear.M * mass)
    rot = dataclasses.replace(plant.rotary, J_m=plant.rotary.J_m * mass)
    sup = dataclasses.replace(
        plant.supply,
        p_s_linear=p_a + (plant.supply.p_s_linear - p_a) * supply,
        p_s_rotary=p_a + (plant.supply.p_s_rotary - p_a) * supply,
    )
    return dataclasses.replace(plant, linear=lin, rotary=rot, supply=sup)
