"""Linear axis: Eq. 1 (with −A_r p_a), Eq. 2 friction + breakaway, Eq. 4–5 chambers, end stops."""

import math

import numpy as np
import pytest
from pneu_msgs_py.params.core import with_updates
from pneu_sim.physics import kernel as k
from pneu_sim.physics.params import PlantParams
from pneu_sim.physics.plant import Plant

SEALED = {"valve_linear.leak_fraction": 0.0, "valve_rotary.leak_fraction": 0.0}


def sealed_plant(**extra):
    return Plant(with_updates(PlantParams(), {**SEALED, **extra}))


def volumes(p, x):
    lin = p.linear
    return (
        lin.V_1d + lin.A_c1 * (lin.L / 2 + x),
        lin.V_2d + lin.A_c2 * (lin.L / 2 - x),
    )


def energy(p, s):
    """Kinetic + polytropic gas potential p V/(n − 1) + ambient load A_r p_a x, J."""
    n = p.ambient.n_poly
    V1, V2 = volumes(p, s.x)
    return (
        0.5 * p.linear.M * s.v**2
        + (s.p_c1 * V1 + s.p_c2 * V2) / (n - 1)
        + p.linear.A_r * p.ambient.p_a * s.x
    )


def test_closed_valve_moved_piston_conserves_pVn_and_mass():
    plant = sealed_plant()
    p = plant.params
    n = p.ambient.n_poly
    plant.reset(x0=-0.02)
    plant.set_state(p_c1=3.0e5)  # ≈ 70 N imbalance: the piston swings on the gas springs
    s0 = plant.state
    V1, V2 = volumes(p, s0.x)
    inv1, inv2 = s0.p_c1 * V1**n, s0.p_c2 * V2**n
    e0 = energy(p, s0)
    xs, es = [], []
    for _ in range(800):
        plant.step(5.0, 5.0)
        s = plant.state
        V1, V2 = volumes(p, s.x)
        assert s.p_c1 * V1**n == pytest.approx(inv1, rel=1e-9)
        assert s.p_c2 * V2**n == pytest.approx(inv2, rel=1e-9)
        assert s.m_c1 == pytest.approx(s0.m_c1, rel=1e-12)
        assert s.m_c2 == pytest.approx(s0.m_c2, rel=1e-12)
        xs.append(s.x)
        es.append(energy(p, s))
    assert max(xs) - min(xs) > 0.01  # it really moved
    assert max(es) <= e0 * (1 + 1e-9)  # friction only removes energy
    assert es[-1] < e0


def test_static_equilibrium_no_drift():
    plant = sealed_plant()
    plant.reset(x0=0.03)
    s0 = plant.state
    for _ in range(2000):
        plant.step(5.0, 5.0)
    s = plant.state
    assert s.x == s0.x and s.v == 0.0
    assert s.p_c1 == pytest.approx(s0.p_c1, rel=1e-12)
    assert s.p_c2 == pytest.approx(s0.p_c2, rel=1e-12)


def test_rod_area_sees_atmosphere_errata_eq1():
    # both chambers at ambient: with the −A_r p_a term the net force is zero (no motion);
    # without it A_r p_a ≈ 11 N would exceed the 4.4 N breakaway and push the piston out
    plant = sealed_plant()
    p = plant.params
    assert p.linear.A_r * p.ambient.p_a > p.linear.A_f * p.linear.breakaway_ratio
    plant.reset()
    plant.set_state(p_c1=p.ambient.p_a, p_c2=p.ambient.p_a)
    for _ in range(500):
        plant.step(5.0, 5.0)
    assert plant.state.x == 0.0


@pytest.mark.parametrize(("u", "end"), [(10.0, 1.0), (0.0, -1.0), (7.0, 1.0)])
def test_full_opening_runs_to_end_stop_and_never_passes(u, end):
    plant = Plant(PlantParams())
    half = plant.params.linear.L / 2
    plant.reset()
    reached = None
    for i in range(1500):
        plant.step(u, 5.0)
        s = plant.state
        assert abs(s.x) <= half
        if reached is None and s.x == end * half:
            reached = i
    assert reached is not None and reached < 1000
    s = plant.state
    assert s.x == end * half and s.v == 0.0  # held by the stop, no bounce


def test_end_stop_impact_is_inelastic():
    plant = Plant(PlantParams())
    half = plant.params.linear.L / 2
    plant.reset(x0=0.07)
    vmax = 0.0
    for _ in range(300):
        plant.step(10.0, 5.0)
        s = plant.state
        vmax = max(vmax, s.v)
        if s.x == half:
            assert s.v == 0.0
    assert vmax > 0.02 and plant.state.x == half


def test_breakaway_holds_below_and_slides_above():
    plant = sealed_plant()
    p = plant.params
    lin = p.linear
    F_s = lin.A_f * lin.breakaway_ratio
    for frac, moves in ((0.9, False), (1.1, True)):
        plant.reset()
        s = plant.state
        p_c1 = (lin.A_c2 * s.p_c2 + lin.A_r * p.ambient.p_a + frac * F_s) / lin.A_c1
        plant.set_state(p_c1=p_c1)
        for _ in range(300):
            plant.step(5.0, 5.0)
        assert (plant.state.x != 0.0) == moves


def test_sliding_friction_is_eq2_plus_stribeck_bump():
    lin = PlantParams().linear
    F_s = lin.A_f * lin.breakaway_ratio
    h = 1e-4
    for F in (8.0, 20.0, 40.0):
        v = 0.0
        for _ in range(20000):
            v = k.stick_slip(v, F, lin.M, lin.A_f, F_s, lin.v_s, lin.c_v, h)
        # steady sliding: F = A_f sign(v) + c_v v (Eq. 2 for v >> 1/1000 s/m and >> v_s)
        assert v == pytest.approx((F - lin.A_f) / lin.c_v, rel=1e-6)
        eq2 = lin.A_f * 2 / math.pi * math.atan(1000 * v) + lin.c_v * v
        assert eq2 == pytest.approx(F, rel=0.01)
    # the friction a stuck piston can hold is F_s = breakaway_ratio * A_f, above Eq. 2's level
    assert k.stick_slip(0.0, 0.99 * F_s, lin.M, lin.A_f, F_s, lin.v_s, lin.c_v, h) == 0.0
    assert k.stick_slip(0.0, 1.01 * F_s, lin.M, lin.A_f, F_s, lin.v_s, lin.c_v, h) > 0.0


def test_pneumatic_spring_frequency():
    # small free oscillation, sealed, frictionless: ω² = n (p1 A1²/V1 + p2 A2²/V2) / M
    plant = sealed_plant(**{"linear.A_f": 0.0, "linear.c_v": 0.0, "linear.breakaway_ratio": 1.0})
    p = plant.params
    lin = p.linear
    plant.reset()
    s = plant.state
    V1, V2 = volumes(p, 0.0)
    k_pn = p.ambient.n_poly * (s.p_c1 * lin.A_c1**2 / V1 + s.p_c2 * lin.A_c2**2 / V2)
    f_expect = math.sqrt(k_pn / lin.M) / (2 * math.pi)
    plant.set_state(v=0.01)
    xs = np.array([plant.step(5.0, 5.0) and plant.state.x for _ in range(2000)])
    crossings = np.nonzero(np.diff(np.sign(xs)) > 0)[0]
    f_sim = (len(crossings) - 1) / ((crossings[-1] - crossings[0]) * plant.T)
    assert f_sim == pytest.approx(f_expect, rel=0.02)
