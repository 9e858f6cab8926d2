"""One axis in the compiled loop: the same kernels :class:`AxisController.update` runs.

Nothing here is a control law: the reference (:func:`~pneu_control.controller.references.reference_at`),
the measurement, TD and angle-reference steps and the history
(:mod:`pneu_control.controller.axis`), and each algorithm's ``start``/``update``
(``KERNEL`` of its class in :mod:`pneu_control.algorithms`) are the Python cores' own
functions, compiled in. What the loop adds is the dispatch by algorithm code
(:data:`~.layout.COMPILED`) and the recorded row. A run is a cold start then plain
updates (no parameter change or algorithm switch in a run: no bumpless blending).
"""

from __future__ import annotations

import math

from numba import njit

from pneu_control.algorithms.coast import Coast
from pneu_control.algorithms.eso_smc import EsoSmc
from pneu_control.algorithms.eso_smc_plus import EsoSmcPlus
from pneu_control.algorithms.ladrc import Ladrc
from pneu_control.algorithms.pid import Pid
from pneu_control.algorithms.pva import Pva
from pneu_control.controller.axis import (
    cold_inputs,
    finish,
    measure,
    measured,
    state_values,
    step_inputs,
)
from pneu_control.controller.references import reference_at
from pneu_control.fastloop.layout import JIT

__all__ = ["axis_update"]

_NAN = math.nan
# the kernels of the algorithms in layout.COMPILED order (code = index)
_start0, _update0 = Pid.KERNEL.start, Pid.KERNEL.update
_start1, _update1 = Ladrc.KERNEL.start, Ladrc.KERNEL.update
_start2, _update2 = EsoSmc.KERNEL.start, EsoSmc.KERNEL.update
_start3, _update3 = EsoSmcPlus.KERNEL.start, EsoSmcPlus.KERNEL.update
_start4, _update4 = Coast.KERNEL.start, Coast.KERNEL.update
_start5, _update5 = Pva.KERNEL.start, Pva.KERNEL.update


@njit(**JIT)
def _start(code, a, algs, tab, inp):
    if code == 0:
        return _start0(algs[0][a], algs[1][a], tab, inp, _NAN, _NAN, _NAN, _NAN)
    if code == 1:
        return _start1(algs[2][a], algs[3][a], tab, inp, _NAN, _NAN, _NAN, _NAN)
    if code == 2:
        return _start2(algs[4][a], algs[5][a], tab, inp, _NAN, _NAN, _NAN, _NAN)
    if code == 3:
        return _start3(algs[6][a], algs[7][a], tab, inp, _NAN, _NAN, _NAN, _NAN)
    if code == 4:
        return _start4(algs[8][a], algs[9][a], tab, inp, _NAN, _NAN, _NAN, _NAN)
    return _start5(algs[10][a], algs[11][a], tab, inp, _NAN, _NAN, _NAN, _NAN)


@njit(**JIT)
def _update(code, a, algs, tab, inp):
    if code == 0:
        return _update0(algs[0][a], algs[1][a], tab, inp)
    if code == 1:
        return _update1(algs[2][a], algs[3][a], tab, inp)
    if code == 2:
        return _update2(algs[4][a], algs[5][a], tab, inp)
    if code == 3:
        return _update3(algs[6][a], algs[7][a], tab, inp)
    if code == 4:
        return _update4(algs[8][a], algs[9][a], tab, inp)
    return _update5(algs[10][a], algs[11][a], tab, inp)


@njit(**JIT)
def _estimates(code, a, algs):
    """(z1, z2, z3, s, u_raw) of the axis's algorithm state."""
    if code == 0:
        return _z(algs[1][a])
    if code == 1:
        return _z(algs[3][a])
    if code == 2:
        return _z(algs[5][a])
    if code == 3:
        return _z(algs[7][a])
    if code == 4:
        return _z(algs[9][a])
    return _z(algs[11][a])


@njit(**JIT)
def _z(s):
    return s.z1, s.z2, s.z3, s.s, s.u_raw


@njit(**JIT)
def _record(ac, ast, code, a, algs, rec, k, col, t, r, rd, y_si, u):
    z1, z2, z3, s, u_raw = _estimates(code, a, algs)
    vals = state_values(ac, ast, t, r, rd, y_si, z1, z2, z3, s, u_raw)
    for i in range(11):
        rec[k, col + i] = vals[i]
    rec[k, col + 11] = u


@njit(**JIT)
def axis_update(a, ac, ast, inp, rc, knots, code, algs, tab, uses_theta, t, x, omega, theta,
                p_c1, p_c2, rec, k, col):  # fmt: skip
    """One ``AxisController.update(sample)`` of axis ``a`` (t = stamp − first stamp, s); u (V).

    Records the state values and u into ``rec[k, col:col + 12]``.
    """
    y_si = measured(ac, x, omega, theta)
    r, rd, rdd = reference_at(rc, knots, t)
    ok, y, th = measure(ac, inp, y_si, theta, p_c1, p_c2, uses_theta)
    if not ok:  # NaN/inf: the last command again (n_nonfinite in Python)
        u = ast.u_last
        _record(ac, ast, code, a, algs, rec, k, col, t, r, rd, y_si, u)
        return u
    s = ac.scale
    rp = r * s
    rdp = rd * s
    rddp = rdd * s
    if ast.started == 0:
        cold_inputs(ac, ast, inp, y, th, rp, rdp, rddp)
        u_dev = _start(code, a, algs, tab, inp)
    else:
        step_inputs(ac, ast, inp, y, th, rp, rdp, rddp)
        u_dev = _update(code, a, algs, tab, inp)
    u = finish(ast, inp, u_dev + ac.neutral)
    _record(ac, ast, code, a, algs, rec, k, col, t, r, rd, y_si, u)
    return u
