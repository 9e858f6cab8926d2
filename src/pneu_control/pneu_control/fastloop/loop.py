"""The whole closed loop as one compiled function: :func:`closed_loop` runs n cycles.

Per cycle k, the order of :class:`pneu_sim.cycle.rig_cycle.RigCycle` and the
runner: the supervisor checks s_k (with its raw volts) and gives the tick-k output;
each active axis (linear, then rotary) answers s_k; the answers go to the
supervisor (or, without one, are held); the plant steps k → k+1 under the tick-k
output with :func:`pneu_sim.physics.kernel.step_period` itself. After the last
cycle the supervisor still checks s_n, as the runner's last ``advance`` does.

``nogil``: threads can run loops side by side (each run owns its arrays).

Caching: numba's cache is keyed on this file only (a change in a file it calls is
not seen, numba docs "Cache limitations"), so :func:`refresh_cache` drops the cached
loop when any source it is built from changed (a digest kept beside the cache).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
from numba import njit
from numba.core.errors import NumbaExperimentalFeatureWarning
from pneu_msgs_py.params import records
from pneu_sim.physics import jit_cache
from pneu_sim.physics import kernel as plant_kernel
from pneu_sim.physics.kernel import step_period

from pneu_control.fastloop.axis import axis_update
from pneu_control.fastloop.layout import (
    JIT,
    N_REC_AXIS,
    NONFINITE_COMMAND,
    NONFINITE_SAMPLE,
    OK,
    REC_AXIS,
    REC_HELD,
    REC_SAMPLE,
)
from pneu_control.fastloop.supervisor import (
    SN_EVENT,
    sup_check_sample,
    sup_command,
    sup_outputs,
)
from pneu_driver import safety


# each algorithm's state record extends the base one and is passed where the base is taken
# (axis_update): by design, so numba's note on compiling it (one ~2 kB line) is not shown
def quiet_record_subtypes() -> None:
    """Hide numba's note on record subtypes (installed at import)."""
    warnings.filterwarnings(
        "ignore", r"(?s)Record\(.*has been considered a subtype", NumbaExperimentalFeatureWarning
    )


quiet_record_subtypes()

__all__ = ["closed_loop", "refresh_cache"]

_NEUTRAL_V = 5.0  # pneu_msgs_py.contract.samples.NEUTRAL_V: inactive axes, start


@njit(**JIT)
def _sample_finite(out):
    """Whether every field of the sample s_k in ``out`` (p_c1 … counts) is finite."""
    return (
        math.isfinite(out[0])
        and math.isfinite(out[1])
        and math.isfinite(out[2])
        and math.isfinite(out[3])
        and math.isfinite(out[4])
        and math.isfinite(out[5])
        and math.isfinite(out[6])
    )


@njit(**JIT)
def _supervise_sample(scale, sup_state, now, out):
    """``RigCycle._begin``: the supervisor checks s_k with its raw volts, then gives the tick-k
    output. Returns (linear V, rotary V, whether the Python supervisor has an event)."""
    sf, sn, xw_t, xw_x, cw_t, cw_c, volts = sup_state
    p1, p2, pm, x = out[0], out[1], out[2], out[3]
    sc = scale[0]
    vpp = sc.v_per_pa
    pa = sc.p_a
    volts[0] = (p1 - pa) * vpp  # pneu_sim.faults.injection.SensorScaling.volts
    volts[1] = (p2 - pa) * vpp
    volts[2] = (pm - pa) * vpp
    volts[3] = x * sc.v_per_m + sc.v_mid
    sn[SN_EVENT] = 0
    sup_check_sample(sf, sn, xw_t, xw_x, cw_t, cw_c, now, p1, p2, pm, x, np.int64(out[6]), volts)
    hold_l, hold_r = sup_outputs(sf, sn, now)
    return hold_l, hold_r, sn[SN_EVENT] != 0


@njit(**JIT)
def _record_sample(rec, k, out, hold_l, hold_r):
    """Row k's sample s_k and the output the DAQ holds during step k (``RigCycle.held_pair``)."""
    for i in range(7):
        rec[k, REC_SAMPLE + i] = out[i]
    rec[k, REC_HELD] = hold_l
    rec[k, REC_HELD + 1] = hold_r


@njit(**JIT)
def _axis_answer(a, view, algs, t, out, rec, k, sup_on, sup_state, now):
    """Axis a's answer u_k to s_k (``AxisController.update``, recorded in its columns of row k),
    then, with the supervisor on, its ``command`` check (not for a NaN u: the caller stops).

    ``view`` = (ac, ast, inp, rc, knots, code, table, uses_theta) of the axis.
    Returns (u, whether the Python supervisor has an event).
    """
    ac, ast, inp, rc, kn, code, tab, th = view
    u = axis_update(
        a, ac, ast, inp, rc, kn, code, algs, tab, th, t, out[3], out[5], out[4], out[0], out[1],
        rec, k, REC_AXIS + a * N_REC_AXIS,
    )  # fmt: skip
    if u != u or not sup_on:
        return u, False
    sf, sn = sup_state[0], sup_state[1]
    sn[SN_EVENT] = 0
    sup_command(sf, sn, a, u, now)
    return u, sn[SN_EVENT] != 0


@njit(cache=True, nogil=True, **JIT)
def closed_loop(n, T_ns, st, prm, noise, out, axes, algs, sup_on, scale, sup_state, rec):
    """Run n cycles from the plant state ``st`` whose sample s_0 is in ``out``.

    ``noise[k]``: the plant's noise row for step k (as :meth:`Plant.step` draws it).
    ``axes`` = (active, ac, ast, inp, rc, knots, codes, tables, uses_theta): per axis a (0
    linear, 1 rotary) whether it has a controller, its axis constants and state, step
    input, reference and knots, algorithm code and table (:mod:`.pack`); ``algs`` the
    constants and state records of every compiled algorithm, per axis. ``sup_state``: the
    supervisor's fresh state with the run's thresholds (:func:`.supervisor.sup_new`) and 4
    floats of scratch for the raw volts, ``scale`` the sensor scaling (:data:`.layout.SCALE`). ``rec`` float64[n, N_REC]: one row per cycle (layout: ``REC_*`` in
    :mod:`.layout`; the axis columns are written only for active axes).
    Returns (status, k, last_event): status :data:`~.layout.OK` or why the loop stopped
    at cycle k; ``last_event`` the last cycle (n = the final check) at which the Python
    supervisor emits an event or counts something (−1: none).
    """
    hold_l = _NEUTRAL_V
    hold_r = _NEUTRAL_V
    last_event = -1
    active, ac, ast, inp, rc, knots, codes, tables, uses_theta = axes
    # one view per axis, made once
    view0 = (ac[0], ast[0], inp[0], rc[0], knots[0], codes[0], tables[0], uses_theta[0])
    view1 = (ac[1], ast[1], inp[1], rc[1], knots[1], codes[1], tables[1], uses_theta[1])
    act0 = active[0]
    act1 = active[1]
    for k in range(n + 1):
        now = k * T_ns
        if not _sample_finite(out):
            return NONFINITE_SAMPLE, k, last_event
        if sup_on:  # RigCycle._begin: check s_k, then the tick-k output
            hold_l, hold_r, event = _supervise_sample(scale, sup_state, now, out)
            if event:
                last_event = k
        if k == n:
            break
        _record_sample(rec, k, out, hold_l, hold_r)
        t = now * 1e-9  # (stamp - first stamp) * 1e-9, first stamp 0
        ans_l = hold_l
        ans_r = hold_r
        if act0:
            ans_l, event = _axis_answer(0, view0, algs, t, out, rec, k, sup_on, sup_state, now)
            if ans_l != ans_l:
                return NONFINITE_COMMAND, k, last_event
            if event:
                last_event = k
        if act1:
            ans_r, event = _axis_answer(1, view1, algs, t, out, rec, k, sup_on, sup_state, now)
            if ans_r != ans_r:
                return NONFINITE_COMMAND, k, last_event
            if event:
                last_event = k
        step_period(st, prm, noise, k, hold_l, hold_r, out)  # k -> k+1 under the tick-k output
        if not sup_on:  # RigCycle.advance: the DAQ now holds the (finite) answers u_k
            hold_l = ans_l
            hold_r = ans_r
    return OK, n, last_event


def _sources() -> list[Path]:
    """Every file the loop is compiled from: fastloop/, the kernels' modules, the plant."""
    here = Path(__file__).resolve().parent
    pkg = here.parent
    kernels = [
        *sorted((pkg / "algorithms").glob("*.py")),
        *sorted((pkg / "observers").glob("*.py")),
        pkg / "controller" / "axis.py",
        pkg / "controller" / "references.py",
        Path(records.__file__).resolve(),
        *sorted(Path(safety.__file__).resolve().parent.glob("*.py")),
    ]
    return [*sorted(here.glob("*.py")), *kernels, Path(plant_kernel.__file__).resolve()]


def refresh_cache() -> None:
    """Drop the cached :func:`closed_loop` if a source it is compiled from changed."""
    jit_cache.refresh_cache(closed_loop, _sources(), "loop.closed_loop")


refresh_cache()
