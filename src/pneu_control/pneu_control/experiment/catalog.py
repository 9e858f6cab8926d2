"""The paper's experiments (DESIGN §8) as data: reference, duration, window, figures.

Reference values are in the paper's units (mm, rpm) because they are typed
as controller parameters (``reference.*``); the runner converts to SI.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from pneu_control.analysis.metrics import WindowSpec

__all__ = ["PAPER_CONTROLLERS", "PAPER_EXPERIMENTS", "Experiment", "experiment_by_id"]

PAPER_CONTROLLERS = ("pid", "ladrc", "eso_smc")  # the controllers the paper compares


@dataclass(frozen=True)
class Experiment:
    """One of the paper's experiments: reference, duration, window, the paper's figures."""

    id: str
    axis: str  # "linear" | "rotary"
    title: str
    reference: dict[str, object]  # dotted reference.* overrides (paper units)
    duration_s: float
    window: WindowSpec
    controllers: tuple[str, ...]  # the controllers the paper reports for it
    unit: str
    # paper figures per controller: (e_max, rmse); None where the paper gives none
    paper: dict[str, tuple[float | None, float | None]] = field(default_factory=dict)
    band: tuple[float, float] | None = None  # paper's stated steady band (unit), if any


_EQ38_TARGET_MM = 120.0 / math.pi  # Eq. 38 at t = 4 s: 30·4/π = 38.197 mm

PAPER_EXPERIMENTS: tuple[Experiment, ...] = (
    Experiment(
        id="sine_20mm_0p25hz",
        axis="linear",
        title="Sine 20 mm, 0.25 Hz (paper Fig. 11)",
        reference={
            "reference.kind": "sine",
            "reference.amplitude": 20.0,
            "reference.frequency_hz": 0.25,
            "reference.offset": 0.0,
        },
        duration_s=20.0,
        window=WindowSpec(kind="sine", frequency_hz=0.25),
        controllers=PAPER_CONTROLLERS,
        unit="mm",
        paper={"pid": (1.4, 0.441), "ladrc": (0.8, 0.398), "eso_smc": (0.44, 0.176)},
    ),
    Experiment(
        id="speed_800rpm",
        axis="rotary",
        title="Constant speed 800 rpm (paper Fig. 12)",
        reference={"reference.kind": "constant", "reference.value": 800.0},
        duration_s=10.0,
        window=WindowSpec(kind="speed", average_s=60.0 / 800.0),  # one revolution
        controllers=PAPER_CONTROLLERS,
        unit="rpm",
        paper={"pid": (15.0, None), "ladrc": (2.5, None), "eso_smc": (2.0, None)},
    ),
    Experiment(
        id="speed_700rpm",
        axis="rotary",
        title="Constant speed 700 rpm, 800 rpm gains (paper Fig. 13)",
        reference={"reference.kind": "constant", "reference.value": 700.0},
        duration_s=10.0,
        window=WindowSpec(kind="speed", average_s=60.0 / 700.0),  # one revolution
        controllers=("eso_smc",),
        unit="rpm",
        # the paper states the band 696–702 rpm: the largest deviation is 4 rpm
        paper={"eso_smc": (4.0, None)},
        band=(696.0, 702.0),
    ),
    Experiment(
        id="smooth_step_eq38",
        axis="linear",
        title="Smooth step, Eq. 38: 0 → 120/π mm in 4 s, then hold (paper Fig. 14)",
        reference={
            "reference.kind": "smooth_step",
            "reference.target": _EQ38_TARGET_MM,
            "reference.duration_s": 4.0,
            "reference.offset": 0.0,
        },
        duration_s=10.0,
        window=WindowSpec(kind="positioning", t_start_s=5.0),
        controllers=("eso_smc",),
        unit="mm",
        paper={"eso_smc": (0.04, None)},
    ),
)


def experiment_by_id(exp_id: str, field: str = "--only") -> Experiment:
    """The experiment called ``exp_id``; a :class:`ParamError` on ``field`` naming the known
    ones."""
    for exp in PAPER_EXPERIMENTS:
        if exp.id == exp_id:
            return exp
    from pneu_msgs_py.params.core import ParamError

    known = ", ".join(e.id for e in PAPER_EXPERIMENTS)
    raise ParamError(field, exp_id, f"one of {known}")
