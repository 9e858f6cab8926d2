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

import hashlib
import math
import warnings
from pathlib import Path

import numpy as np
from numba import njit
from numba.core.errors import NumbaExperimentalFeatureWarning
from pneu_msgs_py.params import records
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
    SP_P_A,
    SP_V_MID,
    SP_V_PER_M,
    SP_V_PER_PA,
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


@njit(cache=True, nogil=True, **JIT)
def closed_loop(n, T_ns, st, prm, noise, out, axes, algs, sup_on, sp, si, sup_state, rec):
    """Run n cycles from the plant state ``st`` whose sample s_0 is in ``out``.

    ``noise[k]``: the plant's noise row for step k (as :meth:`Plant.step` draws it).
    ``axes`` = (active, ac, ast, inp, rc, knots, codes, tables, uses_theta): per axis a (0
    linear, 1 rotary) whether it has a controller, its axis constants and state, step
    input, reference and knots, algorithm code and table (:mod:`.pack`); ``algs`` the
    constants and state records of every compiled algorithm, per axis. ``sup_state``: the
    supervisor's fresh state (:func:`.supervisor.sup_new`) and 4 floats of scratch for
    the raw volts. ``rec`` float64[n, N_REC]: one row per cycle (layout: ``REC_*`` in
    :mod:`.layout`; the axis columns are written only for active axes).
    Returns (status, k, last_event): status :data:`~.layout.OK` or why the loop stopped
    at cycle k; ``last_event`` the last cycle (n = the final check) at which the Python
    supervisor emits an event or counts something (−1: none).
    """
    sf, sn, xw_t, xw_x, cw_t, cw_c, volts = sup_state
    hold_l = _NEUTRAL_V
    hold_r = _NEUTRAL_V
    last_event = -1
    vpp = sp[SP_V_PER_PA]
    pa = sp[SP_P_A]
    vpm = sp[SP_V_PER_M]
    vmid = sp[SP_V_MID]
    active, ac, ast, inp, rc, knots, codes, tables, uses_theta = axes
    # one view per axis, made once
    ac0, ast0, inp0, rc0, kn0, tab0 = ac[0], ast[0], inp[0], rc[0], knots[0], tables[0]
    ac1, ast1, inp1, rc1, kn1, tab1 = ac[1], ast[1], inp[1], rc[1], knots[1], tables[1]
    code0, code1 = codes[0], codes[1]
    th0, th1 = uses_theta[0], uses_theta[1]
    act0 = active[0]
    act1 = active[1]
    for k in range(n + 1):
        now = k * T_ns
        p1 = out[0]
        p2 = out[1]
        pm = out[2]
        x = out[3]
        th = out[4]
        om = out[5]
        cnt = out[6]
        if not (
            math.isfinite(p1)
            and math.isfinite(p2)
            and math.isfinite(pm)
            and math.isfinite(x)
            and math.isfinite(th)
            and math.isfinite(om)
            and math.isfinite(cnt)
        ):
            return NONFINITE_SAMPLE, k, last_event
        if sup_on:  # RigCycle._begin: check s_k, then the tick-k output
            volts[0] = (p1 - pa) * vpp  # pneu_sim.faults.injection.SensorScaling.volts
            volts[1] = (p2 - pa) * vpp
            volts[2] = (pm - pa) * vpp
            volts[3] = x * vpm + vmid
            sn[SN_EVENT] = 0
            sup_check_sample(
                sp, si, sf, sn, xw_t, xw_x, cw_t, cw_c, now, p1, p2, pm, x, np.int64(cnt), volts
            )
            hold_l, hold_r = sup_outputs(sp, si, sf, sn, now)
            if sn[SN_EVENT]:
                last_event = k
        if k == n:
            break
        for i in range(7):
            rec[k, REC_SAMPLE + i] = out[i]
        rec[k, REC_HELD] = hold_l  # what the DAQ holds during step k (RigCycle.held_pair)
        rec[k, REC_HELD + 1] = hold_r
        t = now * 1e-9  # (stamp - first stamp) * 1e-9, first stamp 0
        ans_l = hold_l
        ans_r = hold_r
        if act0:
            u = axis_update(
                0, ac0, ast0, inp0, rc0, kn0, code0, algs, tab0, th0, t, x, om, th, p1, p2,
                rec, k, REC_AXIS,
            )  # fmt: skip
            if u != u:
                return NONFINITE_COMMAND, k, last_event
            if sup_on:
                sn[SN_EVENT] = 0
                sup_command(sf, sn, 0, u, now)
                if sn[SN_EVENT]:
                    last_event = k
            ans_l = u
        if act1:
            u = axis_update(
                1, ac1, ast1, inp1, rc1, kn1, code1, algs, tab1, th1, t, x, om, th, p1, p2,
                rec, k, REC_AXIS + N_REC_AXIS,
            )  # fmt: skip
            if u != u:
                return NONFINITE_COMMAND, k, last_event
            if sup_on:
                sn[SN_EVENT] = 0
                sup_command(sf, sn, 1, u, now)
                if sn[SN_EVENT]:
                    last_event = k
            ans_r = u
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
    digest = hashlib.sha256()
    for f in _sources():
        digest.update(f.read_bytes())
    cache = getattr(closed_loop, "_cache", None)  # numba's Dispatcher cache (no public API)
    path = getattr(cache, "cache_path", None)
    if path is None:
        return
    stamp = Path(path) / "loop.closed_loop.sources"
    want = digest.hexdigest()
    try:
        if stamp.read_text() == want:
            return
    except OSError:
        pass
    cache.flush()
    try:
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.write_text(want)
    except OSError:
        pass  # read-only cache: numba recompiles in memory


refresh_cache()
