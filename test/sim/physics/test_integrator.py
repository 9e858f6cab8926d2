"""Numerics: determinism, fast path == reference, step-size convergence."""

import math

import numpy as np
import pytest
from pneu_msgs_py.params.core import with_updates
from pneu_sim.physics import kernel as k
from pneu_sim.physics.params import PlantParams
from pneu_sim.physics.plant import Plant


def inputs(n, T=1e-3):
    t = np.arange(n) * T
    return 5.0 + 1.5 * np.sin(2 * math.pi * 1.0 * t), 6.0 + 1.0 * np.sin(2 * math.pi * 2.0 * t)


def samples_bytes(plant, n=1500):
    u_l, u_r = inputs(n)
    plant.reset()
    rows = [plant.step(a, b) for a, b in zip(u_l.tolist(), u_r.tolist())]
    arr = np.array(
        [[s.k, s.stamp_ns, s.p_c1, s.p_c2, s.p_m1, s.x, s.theta, s.omega, s.counts] for s in rows]
    )
    return arr.tobytes(), arr


def test_same_seed_byte_identical_other_seed_differs():
    a, _ = samples_bytes(Plant(PlantParams(), seed=5))
    b, _ = samples_bytes(Plant(PlantParams(), seed=5))
    c, _ = samples_bytes(Plant(PlantParams(), seed=6))
    assert a == b
    assert a != c


def test_reset_restarts_the_noise_stream():
    plant = Plant(PlantParams(), seed=2)
    a, _ = samples_bytes(plant, 300)
    b, _ = samples_bytes(plant, 300)
    assert a == b


def test_noise_block_size_does_not_change_results():
    a, _ = samples_bytes(Plant(PlantParams(), seed=4))
    b, _ = samples_bytes(Plant(with_updates(PlantParams(), {"sim.noise_block": 7}), seed=4))
    assert a == b


def test_run_equals_repeated_step():
    n = 1200
    u_l, u_r = inputs(n)
    p1 = Plant(PlantParams(), seed=9)
    p1.reset()
    rows = [p1.step(a, b) for a, b in zip(u_l.tolist(), u_r.tolist())]
    p2 = Plant(PlantParams(), seed=9)
    p2.reset()
    out = p2.run(u_l, u_r)
    ref = np.array([[s.p_c1, s.p_c2, s.p_m1, s.x, s.theta, s.omega, s.counts] for s in rows])
    assert out.tobytes() == ref.tobytes()
    assert p1.state == p2.state


def test_numba_kernel_equals_python_reference():
    plant = Plant(PlantParams(), seed=1)
    plant.reset()
    st_fast = plant._st.copy()
    st_ref = plant._st.copy()
    prm = plant._prm
    rng = np.random.default_rng(0)
    noise = rng.standard_normal((400, k.N_NOISE))
    out_fast = np.zeros(k.N_OUT)
    out_ref = np.zeros(k.N_OUT)
    u_l, u_r = inputs(400)
    for j in range(400):
        k.step_period(st_fast, prm, noise, j, u_l[j], u_r[j], out_fast)
        k.step_period.py_func(st_ref, prm, noise, j, u_l[j], u_r[j], out_ref)
        assert np.allclose(out_fast, out_ref, rtol=1e-12, atol=0)
    assert np.allclose(st_fast, st_ref, rtol=1e-12, atol=1e-15)
    assert abs(st_fast[k.S_X]) > 1e-3 and st_fast[k.S_OM] > 1.0  # both axes moved


def test_inner_functions_equal_python_reference():
    prm = Plant(PlantParams())._prm
    rng = np.random.default_rng(3)
    for _ in range(200):
        p1, p2 = rng.uniform(0.9e5, 7e5, 2)
        assert np.allclose(
            k.iso_flow(p1, p2, 1e-7, 0.29, 0.999),
            k.iso_flow.py_func(p1, p2, 1e-7, 0.29, 0.999),
            rtol=1e-13,
            atol=0,
        )
        y = rng.uniform(0, 10)
        assert k.valve_areas(prm, k.P_VALVE_L, y) == pytest.approx(
            k.valve_areas.py_func(prm, k.P_VALVE_L, y), rel=1e-13
        )
        th = rng.uniform(-50, 50)
        assert k.vane_factor(prm, th) == pytest.approx(k.vane_factor.py_func(prm, th), rel=1e-13)


def _trajectory(n_sub, n=1000):
    p = with_updates(PlantParams(), {"sim.n_sub": n_sub})
    plant = Plant(p)
    plant.reset()
    u_l, u_r = inputs(n)
    xs, ws, ps = [], [], []
    for a, b in zip(u_l.tolist(), u_r.tolist()):
        plant.step(a, b)
        s = plant.state
        xs.append(s.x)
        ws.append(s.omega)
        ps.append(s.p_c1)
    return np.array(xs), np.array(ws), np.array(ps)


def test_step_size_convergence_first_order():
    ref = _trajectory(320)
    errs = []
    for n_sub in (5, 10, 20, 40):
        tr = _trajectory(n_sub)
        errs.append([np.max(np.abs(a - b)) for a, b in zip(tr, ref)])
    errs = np.array(errs)  # rows: n_sub; cols: x, ω, p_c1
    ratios = errs[:-1] / errs[1:]
    assert np.all(ratios > 1.6) and np.all(ratios < 2.6)  # halving h halves the error
    x_err, w_err, p_err = errs[1]  # the default n_sub = 10
    assert x_err < 0.05e-3  # m: far below the laser noise
    assert w_err < 5.0 / 9.549  # rad/s: below one encoder count per window (15 rpm)
    assert p_err < 100.0  # Pa: below the sensor noise


def test_stable_at_the_stiff_end_of_stroke():
    # full opening holds the piston on the stop with a 6 cm^3 dead volume: the
    # chamber time constant (~0.1 ms) is at the substep; the implicit flow term is stable
    p = with_updates(PlantParams(), {"sim.n_sub": 2})
    plant = Plant(p)
    plant.reset()
    for _ in range(600):
        plant.step(0.0, 10.0)
    s = plant.state
    assert s.x == -p.linear.L / 2
    assert s.p_c2 == pytest.approx(p.supply.p_s_linear, rel=1e-6)
    assert s.p_c1 == pytest.approx(p.ambient.p_a, rel=1e-6)
    assert math.isfinite(s.p_m1) and s.omega > 0


@pytest.mark.parametrize("n", [1.0, 1.05, 1.2, 1.35, 1.4])
def test_the_polytropic_factor_is_pow_to_rounding(n):
    """(V_old/V_new)^n by its series (the cylinder's volume step, every substep) is pow's to
    one unit in the last place wherever it sums the series, compiled and as Python, and is
    pow itself beyond."""
    rng = np.random.default_rng(7)
    V_new = 10 ** rng.uniform(-5.5, -3.5, 4000)  # dead volume .. full chamber, m^3
    d = rng.uniform(-k.POLY_SERIES, k.POLY_SERIES, 4000)
    d[:4] = (0.0, 1e-12, 0.999 * k.POLY_SERIES, -0.999 * k.POLY_SERIES)
    for V, dd in zip(V_new, d):
        V_old = V * (1.0 + dd)
        want = (V_old / V) ** n
        for f in (k.polytropic_factor, k.polytropic_factor.py_func):
            assert abs(f(V_old, V, n) - want) <= np.spacing(want)
    for dd in (1.01 * k.POLY_SERIES, 0.05, -0.05):
        V_old = 1e-5 * (1.0 + dd)
        assert k.polytropic_factor(V_old, 1e-5, n) == (V_old / 1e-5) ** n
