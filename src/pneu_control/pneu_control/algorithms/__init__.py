"""Control algorithms behind one interface (:mod:`.base`): PID, LADRC, ESO-SMC, ESO-SMC+ (ours)."""

from __future__ import annotations

from ..ctrl_params import AxisControllerParams
from .base import Algorithm
from .eso_smc import EsoSmc
from .eso_smc_plus import EsoSmcPlus
from .ladrc import Ladrc
from .pid import Pid

__all__ = [
    "Algorithm",
    "Pid",
    "Ladrc",
    "EsoSmc",
    "EsoSmcPlus",
    "make_algorithm",
    "ALGORITHM_CLASSES",
]

ALGORITHM_CLASSES = {"pid": Pid, "ladrc": Ladrc, "eso_smc": EsoSmc, "eso_smc_plus": EsoSmcPlus}


def make_algorithm(params: AxisControllerParams, axis: str) -> Algorithm:
    """The algorithm named by ``params.algorithm``, built from its validated group."""
    return ALGORITHM_CLASSES[params.algorithm](params, axis)
