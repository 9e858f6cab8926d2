"""A :class:`~pneu_control.experiment.runner.RunSpec` -> the compiled loop's record arrays.

The loop starts from exactly the objects the runner builds: one
:class:`~pneu_control.controller.axis.AxisController` per active axis, whose kernel
records (axis constants and state, step input, reference, the algorithm's constants,
state and table) are copied field by field, by name, into structured arrays of the
same record types. Nothing is derived a second time, nothing is numbered by hand.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from pneu_driver.safety.rules import THRESHOLDS, fresh_array
from pneu_msgs_py.contract.samples import AXES

from pneu_control.algorithms import ALGORITHM_CLASSES
from pneu_control.algorithms.base import STEP_INPUT, KernelAlgorithm
from pneu_control.controller.axis import AXIS_CONSTANTS, AXIS_STATE, AxisController
from pneu_control.controller.references import REFERENCE
from pneu_control.fastloop import layout as L
from pneu_control.fastloop.supervisor import RECORD as SUP_RECORD

__all__ = ["Packed", "pack_spec", "unsupported"]


@dataclass
class Packed:
    """What :func:`pneu_control.fastloop.loop.closed_loop` takes besides the plant's arrays."""

    axes: tuple  # (active, ac, ast, inp, rc, knots, codes, tables, uses_theta), per axis
    algs: tuple  # (constants, state) record arrays of every compiled algorithm, per axis
    sup_on: bool
    sf: np.ndarray  # the supervisor's record (fastloop.supervisor.RECORD), thresholds in it
    scale: np.ndarray  # the sensor scaling (layout.SCALE)


def unsupported(spec: Any) -> str | None:
    """Why the compiled loop cannot run ``spec`` (None: it can, with the same results)."""
    if spec.faults:
        return "injected faults (spec.faults) are not compiled"
    for axis in spec.axes:
        name = spec.controllers[axis].algorithm
        cls = ALGORITHM_CLASSES[name]
        if name not in L.COMPILED or not issubclass(cls, KernelAlgorithm):
            return (
                f"{axis}.algorithm {name!r} is not in the compiled loop's table "
                f"(pneu_control/fastloop/layout.py COMPILED: {', '.join(L.COMPILED)})"
            )
    return None


def _padded(tables: list[Any]) -> np.ndarray:
    """float64[2, rows, width] from one 2-D table (list of rows) per axis, zero-padded."""
    rows = max(len(t) for t in tables)
    width = max(len(r) for t in tables for r in t)
    out = np.zeros((len(tables), rows, width))
    for a, t in enumerate(tables):
        for i, row in enumerate(t):
            out[a, i, : len(row)] = row
    return out


def _supervisor(sup: Any, scaling: Any) -> tuple[np.ndarray, np.ndarray]:
    """The supervisor's record with the run's thresholds (copied by name from the record the
    Python supervisor's rules read) and the sensor scaling of the raw volts."""
    sf = fresh_array(SUP_RECORD)
    scale = L.SCALE.array(1)
    if sup is None:
        sf[0]["n_xw"] = sf[0]["n_cw"] = 1  # unused windows, never empty arrays
        return sf, scale
    live = sup.thresholds()["live_v"]
    if not (live["p_c1"] == live["p_c2"] == live["p_m1"]):
        raise ValueError("the compiled supervisor assumes one live range for the pressure sensors")
    th = sup.threshold_record
    for name, *_ in THRESHOLDS.defaults:
        sf[0][name] = getattr(th, name)
    for name, *_ in L.SCALE.defaults:
        scale[0][name] = getattr(scaling, name)
    return sf, scale


def pack_spec(spec: Any, sup: Any | None, scaling: Any | None) -> Packed:
    """The arrays for ``spec``; ``sup``/``scaling``: the run's supervisor and sensor scaling."""
    n_ax = len(AXES)
    active = np.zeros(n_ax, dtype=np.int64)
    codes = np.zeros(n_ax, dtype=np.int64)
    uses_theta = np.zeros(n_ax, dtype=np.bool_)
    ac, ast = AXIS_CONSTANTS.array(n_ax), AXIS_STATE.array(n_ax)
    inp, rc = STEP_INPUT.array(n_ax), REFERENCE.array(n_ax)
    algs: list[np.ndarray] = []
    for name in L.COMPILED:
        cls = ALGORITHM_CLASSES[name]
        if issubclass(cls, KernelAlgorithm):
            algs += [cls.CONSTANTS.array(n_ax), cls.STATE.array(n_ax)]
    knots: list[Any] = [[[0.0]] * 4] * n_ax
    tables: list[Any] = [[[0.0]]] * n_ax
    for a, axis in enumerate(AXES):
        if axis not in spec.axes:
            continue
        ctl = AxisController(axis, spec.controllers[axis])  # the runner's own objects
        alg = ctl._alg
        active[a] = 1
        codes[a] = L.COMPILED.index(alg.name)
        uses_theta[a] = alg.uses_theta
        ctl._c.store(ac[a])
        ctl._st.store(ast[a])
        ctl._inp.store(inp[a])
        ctl._ref.rc.store(rc[a])
        knots[a] = ctl._ref.knots
        alg.c.store(algs[2 * codes[a]][a])
        alg.st.store(algs[2 * codes[a] + 1][a])
        tables[a] = alg.tab
    sf, scale = _supervisor(sup, scaling)
    axes = (active, ac, ast, inp, rc, _padded(knots), codes, _padded(tables), uses_theta)
    return Packed(axes, tuple(algs), sup is not None, sf, scale)
