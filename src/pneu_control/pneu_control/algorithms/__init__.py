"""Control algorithms behind one interface (:mod:`.base`): PID, LADRC, ESO-SMC, ESO-SMC+ (ours)."""

from __future__ import annotations

from pneu_control.algorithms.base import Algorithm
from pneu_control.algorithms.eso_smc import EsoSmc
from pneu_control.algorithms.eso_smc_plus import EsoSmcPlus
from pneu_control.algorithms.ladrc import Ladrc
from pneu_control.algorithms.pid import Pid
from pneu_control.controller.params import AxisControllerParams

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
