"""``pneu bench --only identify``: the wall and CPU time of ``identify`` on one quick both-axes
excitation, as a user runs it (issue 21's figure).

The plant is the identification study's "valve #1 curve of another shape" (a form the twin
cannot take: the curve stage has the most to do) or, ``in_model``, the study's motor with
J_m, M_c and V_m1 changed together; excited once (seed 11, quick level, both axes), then
identified from ``config/plant.yaml`` with the default options (bootstrap draws included).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

__all__ = ["identify_figures"]

PLANTS = {
    "structural": "valve #1 curve of another shape",
    "in_model": "motor J_m x1.5, M_c x0.6, V_m1 x1.6",
}


def identify_figures(which: tuple[str, ...] = ("structural", "in_model")) -> dict[str, Any]:
    """``identify_s_<which>`` (wall) and ``identify_cpu_s_<which>`` (this process's CPU time,
    numba's threads included) per plant of :data:`PLANTS`."""
    from pneu_sim.physics.plant_file import load_plant

    from pneu_control.sysid.excite import excitation_spec, run_excitation
    from pneu_control.sysid.identify import identify
    from pneu_control.sysid.record import load_record
    from pneu_control.sysid.study import perturbed_plant

    base = load_plant()
    out: dict[str, Any] = {}
    for key in which:
        truth = perturbed_plant(base, PLANTS[key])
        with tempfile.TemporaryDirectory(prefix="pneu-bench-identify-") as tmp:
            spec = excitation_spec(("linear", "rotary"), truth, seed=11, level="quick")
            run_excitation(spec, Path(tmp) / "bag", progress=False, hide_plant=True)
            rec = load_record(Path(tmp) / "bag" / "run.mcap")
            w0, c0 = time.perf_counter(), time.process_time()
            identify([rec], base, log=lambda _m: None)
            out[f"identify_s_{key}"] = time.perf_counter() - w0
            out[f"identify_cpu_s_{key}"] = time.process_time() - c0
    return out
