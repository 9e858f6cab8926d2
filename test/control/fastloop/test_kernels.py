"""The kernels compiled against the same kernels run by CPython, on random inputs, bit for bit.

One source, two executions (DESIGN §12): the closed-loop tests
(test/control/experiment/test_compiled.py) cover the states a run visits; these reach
every branch directly: the TD's linear and nonlinear zones, each reference kind over
its whole time range, the rotary friction term (cosh ** 2: glibc pow, not x * x).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit
from pneu_control.algorithms import make_algorithm
from pneu_control.algorithms.eso_smc import friction_term
from pneu_control.controller.params import AxisControllerParams, ReferenceParams
from pneu_control.controller.references import REFERENCE, make_reference, reference_at
from pneu_control.observers.td import TrackingDifferentiator, td_step
from pneu_msgs_py.params.core import with_updates
from pneu_msgs_py.params.records import JIT

RNG = np.random.default_rng(20261201)


def _bits(values) -> list[int]:
    return np.asarray(values, dtype=np.float64).view(np.int64).tolist()


@njit(**JIT)
def _td_many(v, r, h, T, out):
    for i in range(v.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = td_step(v[i, 0], v[i, 1], v[i, 2], r, h, T)


@njit(**JIT)
def _ref_many(rc, knots, ts, out):
    for i in range(ts.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = reference_at(rc[0], knots, ts[i])


@njit(**JIT)
def _friction_many(c, z, out):
    for i in range(z.shape[0]):
        out[i] = friction_term(c[0], z[i, 0], z[i, 1])


def test_td_step_compiled_equals_python():
    v = RNG.normal(0.0, [5.0, 200.0, 5.0], size=(3000, 3))
    for r, h in ((50000.0, 0.001), (5000.0, 0.003)):
        td = TrackingDifferentiator(r, h, 0.001)
        want = []
        for v1, v2, x in v.tolist():
            td.reset(v1, v2)
            td.step(x)
            want.append((td.v1, td.v2, td.v3))
        got = np.empty((len(v), 3))
        _td_many(v, r, h, 0.001, got)
        assert _bits(got) == _bits(want)
    # both zones of fhan were visited (the test can fail in either)
    d = 50000.0 * 0.001
    y = v[:, 0] - v[:, 2] + 0.001 * v[:, 1]
    assert (np.abs(y) <= d * 0.001).any() and (np.abs(y) > d * 0.001).any()


@pytest.mark.parametrize(
    "ref",
    [
        {"kind": "sine", "amplitude": 20.0, "frequency_hz": 0.25, "offset": 1.0, "t0_s": 0.3},
        {"kind": "smooth_step", "offset": -3.0, "target": 120.0 / math.pi, "duration_s": 4.0},
        {"kind": "constant", "value": 800.0},
        {"kind": "ramp", "offset": 2.0, "slope": -7.5, "duration_s": 1.5, "t0_s": 0.1},
        {"kind": "ramp", "offset": 2.0, "slope": 3.0, "duration_s": 0.0},
        {"kind": "waypoints"},
    ],
)
@pytest.mark.parametrize("axis", ["linear", "rotary"])
def test_reference_compiled_equals_python(ref, axis, tmp_path):
    if ref["kind"] == "waypoints":
        f = tmp_path / "w.yaml"
        f.write_text("[[0.0, 0.0], [0.5, 4.0], [0.9, 1.0], [1.4, 9.0], [2.0, 9.0]]\n")
        ref = {"kind": "waypoints", "file": str(f)}
    py = make_reference(with_updates(ReferenceParams(), ref), axis)
    rc = REFERENCE.array(1)
    py.rc.store(rc[0])
    knots = np.array(py.knots, dtype=np.float64)
    ts = np.concatenate([np.arange(0.0, 6.0, 0.001), RNG.uniform(-1.0, 7.0, 2000)])
    got = np.empty((len(ts), 3))
    _ref_many(rc, knots, ts, got)
    assert _bits(got) == _bits([py(t) for t in ts.tolist()])


@pytest.mark.parametrize("model", ["speed", "angle"])
def test_rotary_friction_term_compiled_equals_python(model):
    params = with_updates(
        AxisControllerParams(),
        {"algorithm": "eso_smc", "eso_smc.friction_compensation": True, "rotary_model": model},
    )
    alg = make_algorithm(params, "rotary")
    c = alg.CONSTANTS.array(1)
    alg.c.store(c[0])
    z = np.concatenate(
        [RNG.uniform(-3500.0, 3500.0, (20000, 2)), RNG.normal(0.0, 300.0, (20000, 2))]
    )
    got = np.empty(len(z))
    _friction_many(c, z, got)
    assert _bits(got) == _bits([alg.friction_term(z1, z2) for z1, z2 in z.tolist()])


def test_cosh_squared_is_glibc_pow_not_a_product():
    """Why ``two`` is a field: x * x differs from CPython's x ** 2 for some x."""
    c = np.cosh(RNG.uniform(0.0, 30.0, 20000))
    assert any(v**2 != v * v for v in c.tolist())  # so the test above can fail
