"""Run an excitation experiment in-process: the twin, the supervisor, the exciter, a bag.

The control cycle is :class:`pneu_sim.cycle.rig_cycle.RigCycle`'s, through the
in-process runner (:func:`pneu_control.experiment.runner.run`) with each
axis's :class:`~pneu_control.sysid.design.ExcitationDesign` in place of its
controller parameters; the supervisor is on (``config/safety.yaml``) as on the
rig. The bag's metadata carries every design and the seed (``pneu.excite``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pneu_control.experiment import session
from pneu_control.experiment.runner import RunResult, RunSpec
from pneu_control.sysid.design import design_for

__all__ = ["excitation_spec", "run_excitation"]


def excitation_spec(
    axes: tuple[str, ...],
    plant: Any,
    *,
    seed: int = 0,
    level: str = "full",
    safety_file: str | Path | None = None,
) -> RunSpec:
    """The run of ``axes``'s designs (run together: the longer one sets the duration)."""
    from pneu_driver.safety import load_safety_params

    designs = {axis: design_for(axis, seed, level) for axis in axes}
    return RunSpec(
        axes=tuple(axes),
        controllers=designs,
        plant=plant,
        duration_s=max(d.duration_s for d in designs.values()),
        seed=seed,
        name="excite/" + "+".join(axes),
        safety=load_safety_params(safety_file),
    )


def run_excitation(
    spec: RunSpec, out_dir: str | Path | Any, *, progress: bool = True, hide_plant: bool = False
) -> RunResult:
    """Run ``spec`` and write ``run.mcap`` (+ metrics.json, timeseries.npz) into ``out_dir``
    (a path, or its claim :func:`pneu_control.experiment.session.run_dir`; the lifecycle of
    :func:`~pneu_control.experiment.session.execute`: claimed, ``.partial`` names, a signal
    finishes the files marked interrupted).

    ``hide_plant``: the bag's recorded config names no plant parameters (a
    blind identification study; the identifier reads no metadata but the
    designs anyway, and this makes sure nothing else could leak).
    """
    hidden = {"plant": "hidden (blind identification study)"} if hide_plant else None
    return session.execute(spec, out_dir, bag=True, progress=progress, echo_overrides=hidden)
