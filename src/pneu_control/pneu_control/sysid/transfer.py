"""Tuning that transfers, measured: gains tuned on the identified twin, run on the true one.

For a perturbed ("true") plant and the plant identified from its bags:
``pneu tune``'s method (:mod:`pneu_control.experiment.tuning`: b0 from the
twin's step response, the fixed grid, the tuning experiments) runs once on
each; both gain sets then run the paper's experiments on the *true* plant.
The gap per controller and experiment is (m_identified − m_true)/m_true for
e_max and RMSE; the gains transfer when neither is above
:data:`TRANSFER_TOLERANCE` (doing better than the true-twin gains is no gap).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from pneu_control.controller.params import load_controller_params
from pneu_control.experiment import session, tuning
from pneu_control.experiment.catalog import PAPER_EXPERIMENTS, Experiment
from pneu_control.experiment.runner import run as run_spec

__all__ = ["TRANSFER_TOLERANCE", "TransferRow", "transfer", "tuned_gains"]

TRANSFER_TOLERANCE = 0.20


@dataclass(frozen=True)
class TransferRow:
    """One algorithm and experiment on the true twin: with the gains tuned on the identified twin
    and with those tuned on the true one."""

    axis: str
    algorithm: str
    experiment: str
    unit: str
    e_max_identified: float
    e_max_true: float
    rmse_identified: float
    rmse_true: float

    @staticmethod
    def _gap(a: float, b: float) -> float:
        return (a - b) / b if b > 0 and math.isfinite(a) else math.inf

    @property
    def gap_e_max(self) -> float:
        """Relative e_max gap of the identified-twin gains to the true-twin gains (inf if
        undefined)."""
        return self._gap(self.e_max_identified, self.e_max_true)

    @property
    def gap_rmse(self) -> float:
        """Relative RMSE gap of the identified-twin gains to the true-twin gains (inf if
        undefined)."""
        return self._gap(self.rmse_identified, self.rmse_true)

    @property
    def within(self) -> bool:
        """Are both gaps within :data:`TRANSFER_TOLERANCE`?"""
        return max(self.gap_e_max, self.gap_rmse) <= TRANSFER_TOLERANCE

    def to_dict(self) -> dict[str, Any]:
        """The row as plain data, with the gaps."""
        d = dict(self.__dict__)
        d.update(gap_e_max=self.gap_e_max, gap_rmse=self.gap_rmse, within=self.within)
        return d

    def markdown(self) -> str:
        """The row as a line of the Markdown table under :data:`HEADER`."""
        return (
            f"| {self.axis} | {self.algorithm} | {self.experiment} | {self.e_max_identified:.3f} / "
            f"{self.e_max_true:.3f} {self.unit} | {100 * self.gap_e_max:+.1f} % | "
            f"{self.rmse_identified:.3f} / {self.rmse_true:.3f} {self.unit} | "
            f"{100 * self.gap_rmse:+.1f} % | {'yes' if self.within else '**no**'} |"
        )


HEADER = (
    "| axis | controller | experiment | e_max identified / true gains | gap | "
    "RMSE identified / true gains | gap | within 20 % |\n|---|---|---|---|---|---|---|---|"
)


def tuned_gains(
    plant,
    axis: str,
    algorithms: tuple[str, ...],
    *,
    stride: int = 1,
    corners: bool = True,
    log: Callable[[str], None] = print,
) -> dict[str, dict[str, float]]:
    """``pneu tune``'s gains on ``plant`` (``stride``/``corners``: a coarser, faster search)."""
    paper = load_controller_params(axis)
    b0 = tuning.identify_b0(axis, plant)
    score = tuning.make_score(axis, plant, corners=corners)
    out = {}
    for alg in algorithms:
        best, cost, n = tuning.tune_axis(axis, alg, b0, score, paper, stride=stride)
        log(f"  {axis} {alg}: b0 {b0:.4g}, tuning RMSE {cost:.4g} after {n} runs")
        out[alg] = best
    return out


def _metrics(plant, exp: Experiment, algorithm: str, gains: dict[str, float], seed: int):
    spec = session.build_spec(
        axes=(exp.axis,),
        reference=dict(exp.reference),
        duration_s=exp.duration_s,
        plant=plant,
        seed=seed,
    )
    params = load_controller_params(
        exp.axis, None, {**exp.reference, "algorithm": algorithm, **gains}
    )
    spec = replace(spec, controllers={exp.axis: params}, windows={exp.axis: exp.window})
    return run_spec(spec).metrics[exp.axis]


def transfer(
    true_plant,
    identified_plant,
    axes: tuple[str, ...],
    algorithms: tuple[str, ...] = ("pid", "ladrc", "eso_smc"),
    *,
    stride: int = 1,
    corners: bool = True,
    experiments: tuple[str, ...] | None = None,
    log: Callable[[str], None] = print,
) -> list[TransferRow]:
    """Tune on both plants, run both gain sets on ``true_plant``; one row per controller and
    experiment of the paper (``experiments``: ids to keep)."""
    rows = []
    for axis in axes:
        log(f"{axis}: tuning on the identified twin")
        g_id = tuned_gains(
            identified_plant, axis, algorithms, stride=stride, corners=corners, log=log
        )
        log(f"{axis}: tuning on the true twin")
        g_true = tuned_gains(true_plant, axis, algorithms, stride=stride, corners=corners, log=log)
        for exp in PAPER_EXPERIMENTS:
            if exp.axis != axis or (experiments and exp.id not in experiments):
                continue
            for alg in algorithms:
                if alg not in exp.controllers:
                    continue
                m_id = _metrics(true_plant, exp, alg, g_id[alg], 0)
                m_tr = _metrics(true_plant, exp, alg, g_true[alg], 0)
                rows.append(
                    TransferRow(
                        axis, alg, exp.id, m_id.unit, m_id.e_max, m_tr.e_max, m_id.rmse, m_tr.rmse
                    )
                )
                log(rows[-1].markdown())
    return rows
