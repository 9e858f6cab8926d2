"""Compiled mirrors against their Python originals on random inputs, bit for bit.

The closed-loop tests (test/control/experiment/test_compiled.py) cover the
states a run visits; these reach every branch directly: the TD's linear and
nonlinear zones, each reference kind over its whole time range, the rotary
friction term (cosh ** 2: glibc pow, not x * x), the valve curve beyond full
opening.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pneu_control.algorithms import make_algorithm
from pneu_control.algorithms.valve_curve import ValveCurve
from pneu_control.controller.params import AxisControllerParams, ReferenceParams
from pneu_control.controller.references import make_reference
from pneu_control.fastloop import layout as L
from pneu_control.fastloop.algorithms import _friction_term
from pneu_control.fastloop.pack import pack_algorithm, pack_reference
from pneu_control.fastloop.plus import _to_linear, _to_valve
from pneu_control.fastloop.reference import reference, td_step
from pneu_control.observers.td import TrackingDifferentiator
from pneu_msgs_py.params.core import with_updates

RNG = np.random.default_rng(20261201)


def _bits(a: float) -> int:
    return int(np.float64(a).view(np.int64))


def test_td_step_equals_the_python_td():
    for r, h in ((50000.0, 0.001), (5000.0, 0.003)):
        td = TrackingDifferentiator(r, h, 0.001)
        for v1, v2, x in RNG.normal(0.0, [5.0, 200.0, 5.0], size=(3000, 3)):
            td.reset(v1, v2)
            td.step(x)
            got = td_step(float(v1), float(v2), float(x), td.r, td.h, td.T)
            assert tuple(map(_bits, got)) == tuple(map(_bits, (td.v1, td.v2, td.v3)))


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
def test_reference_equals_the_python_reference(ref, axis, tmp_path):
    if ref["kind"] == "waypoints":
        f = tmp_path / "w.yaml"
        f.write_text("[[0.0, 0.0], [0.5, 4.0], [0.9, 1.0], [1.4, 9.0], [2.0, 9.0]]\n")
        ref = {"kind": "waypoints", "file": str(f)}
    p = with_updates(ReferenceParams(), ref)
    py = make_reference(p, axis)
    cp = np.zeros(L.N_CP)
    ci = np.zeros(L.N_CI, dtype=np.int64)
    rows = pack_reference(py, cp, ci)
    wp = np.zeros((4, max(1, len(rows[0]) if rows else 1)))
    for i, row in enumerate(rows):
        wp[i] = row
    for t in np.concatenate([np.arange(0.0, 6.0, 0.001), RNG.uniform(-1.0, 7.0, 2000)]):
        got = reference(cp, ci, wp, float(t))
        assert tuple(map(_bits, got)) == tuple(map(_bits, py(float(t)))), t


@pytest.mark.parametrize("model", ["speed", "angle"])
def test_rotary_friction_term_equals_python(model):
    params = with_updates(
        AxisControllerParams(),
        {"algorithm": "eso_smc", "eso_smc.friction_compensation": True, "rotary_model": model},
    )
    alg = make_algorithm(params, "rotary")
    cp = np.zeros(L.N_CP)
    ci = np.zeros(L.N_CI, dtype=np.int64)
    pack_algorithm(alg, cp, ci)
    z = np.concatenate(
        [RNG.uniform(-3500.0, 3500.0, (20000, 2)), RNG.normal(0.0, 300.0, (20000, 2))]
    )
    for z1, z2 in z.tolist():
        assert _bits(_friction_term(cp, ci, z1, z2)) == _bits(alg.friction_term(z1, z2))


def test_cosh_squared_is_glibc_pow_not_a_product():
    """Why SM_TWO is read at run time: x * x differs from CPython's x ** 2 for some x."""
    c = np.cosh(RNG.uniform(0.0, 30.0, 20000))
    assert any(v**2 != v * v for v in c.tolist())  # so the test below can fail


def test_valve_curve_equals_python():
    params = with_updates(
        AxisControllerParams(),
        {"algorithm": "eso_smc_plus", "eso_smc_plus.valve_linearisation": True},
    )
    alg = make_algorithm(params, "linear")
    cp = np.zeros(L.N_CP)
    ci = np.zeros(L.N_CI, dtype=np.int64)
    du, fl = pack_algorithm(alg, cp, ci)
    vt = np.array([du, fl])
    curve: ValveCurve = alg.valve
    for x in np.concatenate(
        [RNG.uniform(-7.0, 7.0, 20000), [0.0, -0.0, curve.v_max, -curve.v_max, 4.75, 5.0]]
    ).tolist():
        assert _bits(_to_linear(cp, ci, vt, x)) == _bits(curve.to_linear(x)), x
        try:
            want = curve.to_valve(x)
        except IndexError:  # Python's table lookup past the end (q rounded to 1.0)
            assert math.isnan(_to_valve(cp, ci, vt, x))
            continue
        assert _bits(_to_valve(cp, ci, vt, x)) == _bits(want), x
