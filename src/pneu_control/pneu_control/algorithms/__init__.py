"""Control algorithms behind one interface (:mod:`.base`): PID, LADRC, ESO-SMC, ESO-SMC+, coast and pva (ours).

Each module holds one algorithm and its parameter group; :mod:`.smc` what the
sliding-mode laws share, :mod:`.valve_curve` the MPYE flow linearisation.
To add an algorithm: a module with ``XParams`` (a frozen dataclass of
:func:`pneu_msgs_py.params.core.param` fields) and a class implementing
:class:`.base.Algorithm`, the documented way a :class:`.base.KernelAlgorithm` (its
steps kernels on records, DESIGN §12); register both below and in
:class:`pneu_control.controller.params.AxisControllerParams` (a field named
after it, and its name in ``ALGORITHMS``). It then runs in every Python path; the
compiled loop runs it once its name is in :data:`pneu_control.fastloop.layout.COMPILED`
with a branch in ``fastloop/axis.py``'s dispatch, and until then a run of it falls back
to the Python runner, saying so in one line.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pneu_control.algorithms.base import Algorithm, StepInput
from pneu_control.algorithms.coast import Coast, CoastParams
from pneu_control.algorithms.eso_smc import EsoSmc, EsoSmcParams
from pneu_control.algorithms.eso_smc_plus import EsoSmcPlus, EsoSmcPlusParams
from pneu_control.algorithms.ladrc import Ladrc, LadrcParams
from pneu_control.algorithms.pid import Pid, PidParams
from pneu_control.algorithms.pva import Pva, PvaParams

if TYPE_CHECKING:
    from pneu_control.controller.params import AxisControllerParams

__all__ = [
    "Algorithm",
    "StepInput",
    "PidParams",
    "LadrcParams",
    "EsoSmcParams",
    "EsoSmcPlusParams",
    "CoastParams",
    "PvaParams",
    "Pid",
    "Ladrc",
    "EsoSmc",
    "EsoSmcPlus",
    "Coast",
    "Pva",
    "make_algorithm",
    "ALGORITHM_CLASSES",
]

ALGORITHM_CLASSES = {
    "pid": Pid,
    "ladrc": Ladrc,
    "eso_smc": EsoSmc,
    "eso_smc_plus": EsoSmcPlus,
    "coast": Coast,
    "pva": Pva,
}


def make_algorithm(params: AxisControllerParams, axis: str) -> Algorithm:
    """The algorithm named by ``params.algorithm``, built from its validated group."""
    return ALGORITHM_CLASSES[params.algorithm](params, axis)
