"""One parametric-bootstrap draw: the identified twin excited again, identified again.

The linearised interval of a fit (:func:`pneu_control.sysid.fit._segment_sandwich`)
measures how far noise and start errors could move the optimum; it does not
see how far the optimum itself lies from the truth. An output-error fit
started from measured states has such a bias even on a plant of its own
family: every segment starts from a noisy, lagged, quantised state (errors in
the variables, through a non-linear replay), and the least squares stop at a
tolerance, not at the minimum. Both are properties of the method on this
experiment, so the identified twin shows them too (Efron & Tibshirani, *An
Introduction to the Bootstrap*, 1993, ch. 6 and 10: the parametric
bootstrap's estimate of bias): each recorded design runs again on the
identified twin (its noise, a new seed: new noise and sensor offsets), the
same fit runs from the identified values, and the difference d between the
two fits is one draw of the estimator's error (its bias plus its scatter).
The interval's σ becomes √(σ² + d²): one draw, but where the bias dominates,
as in the study, d is close to it every time.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from pneu_control.sysid.record import Record, load_record

__all__ = ["REPLICATE_SEED", "replicate_records"]

REPLICATE_SEED = 7919  # added to a design's seed: the replicate's noise and offsets


def replicate_records(records: list[Record], axes: tuple[str, ...], plant) -> list[Record]:
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
            seed=min(d.seed for d in designs.values()) + REPLICATE_SEED,
            name="identify/replicate",
            safety=load_safety_params(None),
        )
        with tempfile.TemporaryDirectory(prefix="pneu-replicate-") as d:
            run_excitation(spec, Path(d) / "run", progress=False, hide_plant=True)
            out.append(load_record(Path(d) / "run" / "run.mcap"))
    return out
