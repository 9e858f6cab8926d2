"""Parametric-bootstrap draws: the identified twin excited again, identified again.

The linearised interval of a fit (the segment sandwich of
:mod:`pneu_control.sysid.fit`) measures how far noise and start errors move
the optimum to first order. Measured over noise seeds on a plant of the
model's own family (docs/calibration.md, the intervals), the estimator
scatters 3-16 times more than that on the motor's flow scale, supply,
leakages and Coulomb torque (why is not established: the cost is not smooth
where the motor sticks and creeps at 5 V, and a start error runs through a
whole replay). What the estimator does on this experiment, the identified twin shows too
(Efron & Tibshirani, *An Introduction to the Bootstrap*, 1993, ch. 6: the
parametric bootstrap): each recorded design runs again on the identified
twin (its values and noise, a new seed: new noise and sensor offsets), the
same fit runs from the identified values, and the difference d between the
two fits is one draw of the estimator's error. With B draws the interval's
σ² is σ_fit² + mean(d²) and its quantile Student's t with B degrees of
freedom (B = :data:`REPLICATES`: t = 4.30 -- wide, but exact for normal
errors whatever their scale; each draw costs about a third of the fit).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from pneu_control.sysid.record import Record, load_record

__all__ = ["REPLICATES", "REPLICATE_SEED", "replicate_records"]

REPLICATE_SEED = 7919  # added to a design's seed (and 1, 2, .. per draw): noise and offsets
REPLICATES = 2  # draws: with t(2)'s quantile 4.30, exact for normal errors; each ~1/3 of a fit


def replicate_records(
    records: list[Record], axes: tuple[str, ...], plant, draw: int = 0
) -> list[Record]:
    """Each of ``records`` with a design for some of ``axes``: those designs run again together
    on ``plant`` (the supervisor on, as ``pneu excite``; the longer design sets the duration),
    in a temporary directory, read back as a record."""
    from pneu_driver.safety import load_safety_params

    from pneu_control.experiment.runner import RunSpec
    from pneu_control.sysid.excite import run_excitation

    out = []
    for rec in records:
        designs = {a: d for a, d in rec.designs.items() if a in axes}
        if not designs:
            continue
        spec = RunSpec(
            axes=tuple(a for a in ("linear", "rotary") if a in designs),
            controllers=designs,
            plant=plant,
            duration_s=max(d.duration_s for d in designs.values()),
            seed=min(d.seed for d in designs.values()) + REPLICATE_SEED + draw,
            name="identify/replicate",
            safety=load_safety_params(None),
        )
        with tempfile.TemporaryDirectory(prefix="pneu-replicate-") as d:
            run_excitation(spec, Path(d) / "run", progress=False, hide_plant=True)
            out.append(load_record(Path(d) / "run" / "run.mcap"))
    return out
