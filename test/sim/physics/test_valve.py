"""Valve model: ISO 6358 flow (errata form), Eq. 12, opening curve, 5/3 mapping, spool."""

import math

import numpy as np
import pytest
from pneu_msgs_py.params.core import with_updates
from pneu_sim.physics import kernel as k
from pneu_sim.physics.pack import pack_params, spool_zoh, valve_max_area
from pneu_sim.physics.params import PlantParams
from pneu_sim.physics.plant import Plant

B = 0.29
B_LAM = 0.999
C1T = 0.0404 / math.sqrt(300.0)
A = 8e-6


def iso6358_reference(p_u, p_d, area, b=B, T=300.0, C_1=0.0404):
    """ISO 6358 as written in the standard (MathWorks block form), with Eq. 12's C_d."""
    r = p_d / p_u
    cd = 0.8153 + 0.0933 * r - 0.1038 * r**2
    m_choked = area * cd * C_1 * p_u / math.sqrt(T)
    if r <= b:
        return m_choked
    return m_choked * math.sqrt(1.0 - ((r - b) / (1.0 - b)) ** 2)


@pytest.mark.parametrize("p_d", [1.0e5, 1.2e5, 1.5e5])  # p_d / p_u <= b: choked
def test_choked_matches_standard(p_d):
    m, _, _ = k.iso_flow(6e5, p_d, A * C1T, B, B_LAM)
    assert m == pytest.approx(iso6358_reference(6e5, p_d, A), rel=1e-12)
    # choked flow does not depend on the downstream pressure except through C_d(r)
    assert m == pytest.approx(
        A * C1T * 6e5 * (0.8153 + 0.0933 * p_d / 6e5 - 0.1038 * (p_d / 6e5) ** 2)
    )


@pytest.mark.parametrize("p_d", [2.0e5, 3.0e5, 4.5e5, 5.9e5])  # subsonic
def test_subsonic_matches_standard_not_misprint(p_d):
    p_u = 6e5
    m, _, _ = k.iso_flow(p_u, p_d, A * C1T, B, B_LAM)
    assert m == pytest.approx(iso6358_reference(p_u, p_d, A), rel=1e-12)
    r = p_d / p_u
    misprint = math.sqrt(max(0.0, 1 - ((p_d - B) / (p_u - B)) ** 2))  # paper's Eq. 11 factor
    correct = math.sqrt(1 - ((r - B) / (1 - B)) ** 2)
    assert abs(correct - misprint) > 0.01
    assert m / iso6358_reference(p_u, p_u * B, A) * (0.8153 + 0.0933 * B - 0.1038 * B**2) / (
        0.8153 + 0.0933 * r - 0.1038 * r**2
    ) == pytest.approx(correct, rel=1e-12)


def test_continuous_at_critical_ratio_and_laminar_patch():
    p_u = 5e5
    for r0 in (B, B_LAM):
        eps = 1e-11
        lo = k.iso_flow(p_u, p_u * (r0 - eps), A * C1T, B, B_LAM)[0]
        hi = k.iso_flow(p_u, p_u * (r0 + eps), A * C1T, B, B_LAM)[0]
        assert hi == pytest.approx(lo, rel=1e-6, abs=1e-12)
    # the laminar patch keeps the slope finite at r -> 1 (the pure formula's is infinite)
    _, _, d = k.iso_flow(p_u, p_u * (1 - 1e-7), A * C1T, B, B_LAM)
    assert math.isfinite(d) and d < 0


def test_zero_at_equal_pressure_and_sign_follows_difference():
    for p in (1e5, 3e5, 7e5):
        assert k.iso_flow(p, p, A * C1T, B, B_LAM)[0] == 0.0
    rng = np.random.default_rng(1)
    for _ in range(50):
        p1, p2 = rng.uniform(0.8e5, 8e5, 2)
        m12 = k.iso_flow(p1, p2, A * C1T, B, B_LAM)[0]
        m21 = k.iso_flow(p2, p1, A * C1T, B, B_LAM)[0]
        assert m12 == -m21
        assert math.copysign(1.0, m12) == math.copysign(1.0, p1 - p2)


def test_partials_match_finite_differences():
    rng = np.random.default_rng(2)
    for _ in range(100):
        p1, p2 = rng.uniform(1e5, 7e5, 2)
        if abs(p1 / p2 - 1) < 2e-3 or abs(min(p1, p2) / max(p1, p2) - B) < 1e-3:
            continue
        _m, d1, d2 = k.iso_flow(p1, p2, A * C1T, B, B_LAM)
        hstep = 1.0
        fd1 = (
            k.iso_flow(p1 + hstep, p2, A * C1T, B, B_LAM)[0]
            - k.iso_flow(p1 - hstep, p2, A * C1T, B, B_LAM)[0]
        ) / 2
        fd2 = (
            k.iso_flow(p1, p2 + hstep, A * C1T, B, B_LAM)[0]
            - k.iso_flow(p1, p2 - hstep, A * C1T, B, B_LAM)[0]
        ) / 2
        assert d1 == pytest.approx(fd1, rel=1e-5, abs=1e-14)
        assert d2 == pytest.approx(fd2, rel=1e-5, abs=1e-14)


def test_max_area_reproduces_nominal_flow():
    p = PlantParams()
    v = p.valve_linear
    a_max = valve_max_area(v, p.ambient.C_1)
    assert 7e-6 < a_max < 10e-6  # ≈ 8.5 mm² (A·C_d ≈ 7 mm²) for 350 l/min
    m = iso6358_reference(v.p_n_up, v.p_n_down, a_max, b=v.b, T=v.T_n)
    assert m / v.rho_n * 60000.0 == pytest.approx(350.0, rel=1e-9)  # l/min ANR


def _prm(**updates):
    return pack_params(with_updates(PlantParams(), updates) if updates else PlantParams())


def test_opening_curve_dead_band_saturation_and_mapping():
    prm = _prm()
    base = k.P_VALVE_L
    a_max = prm[base + k.VB_AMAX]
    a_leak = prm[base + k.VB_ALEAK]
    # centre: every path only leaks
    assert k.valve_areas(prm, base, 5.0) == (a_leak, a_leak, a_leak, a_leak)
    # dead band: within ±0.3 V the opening path passes < 1 % of full flow
    for y in (4.7, 5.2, 5.3):
        assert max(k.valve_areas(prm, base, y)) < a_leak + 0.01 * a_max
    # saturation: beyond |u - 5| = 4.75 V full area
    for y in (0.0, 0.25, 9.75, 10.0):
        assert max(k.valve_areas(prm, base, y)) == pytest.approx(a_leak + a_max)
    # table point: |u - 5| = 2.12 V -> 40 %
    assert k.valve_areas(prm, base, 7.12)[0] == pytest.approx(a_leak + 0.40 * a_max)
    # 5/3: u > 5 V supply -> port 4 (chamber 1) and port 2 (chamber 2) -> exhaust
    s4, e4, s2, e2 = k.valve_areas(prm, base, 8.0)
    assert s4 == e2 > a_leak and e4 == s2 == 0.0
    s4, e4, s2, e2 = k.valve_areas(prm, base, 2.0)
    assert s2 == e4 > a_leak and s4 == e2 == 0.0
    # monotone in |u - 5|
    ys = np.linspace(5.0, 10.0, 501)
    opening = [k.valve_areas(prm, base, y)[0] for y in ys]
    assert np.all(np.diff(opening) >= 0)


def _own_curve(db_lo=0.5, db_hi=0.3, gain_lo=0.6, gain_hi=1.0, port2_scale=0.8):
    """A valve of its own: dead band [5 - db_lo, 5 + db_hi] V (a null offset), linear
    above it with another gain on either side, port 2 with less flow than port 4."""
    u = (
        0.0,
        5.0 - db_lo - 1.0 / gain_lo,
        5.0 - db_lo,
        5.0 + db_hi,
        5.0 + db_hi + 1.0 / gain_hi,
        10.0,
    )
    f4 = (-1.0, -1.0, 0.0, 0.0, 1.0, 1.0)
    return {
        "valve_linear.u_curve": u,
        "valve_linear.flow_4": f4,
        "valve_linear.flow_2": tuple(-port2_scale * f for f in f4),
    }


def test_own_curve_mirroring_the_catalogue_is_the_catalogue_twin():
    """One representation: the catalogue written as an own curve gives the same bytes."""
    from pneu_sim.physics.valve_curve import catalogue_curve

    v = PlantParams().valve_linear
    u, f4, f2 = catalogue_curve(v.du_table, v.flow_table)
    own = {
        "valve_linear.u_curve": tuple(u),
        "valve_linear.flow_4": tuple(f4),
        "valve_linear.flow_2": tuple(f2),
    }
    assert np.array_equal(_prm(**own), _prm())


def test_own_curve_sets_each_port_and_keeps_the_leak_rules():
    prm = _prm(**_own_curve())
    base = k.P_VALVE_L
    a_max = prm[base + k.VB_AMAX]
    a_leak = prm[base + k.VB_ALEAK]
    # the whole dead band [4.5, 5.3] V only leaks, on every path
    for y in (4.55, 5.0, 5.25):
        assert k.valve_areas(prm, base, y) == pytest.approx((a_leak,) * 4, rel=1e-12)
    # above: port 4 from supply with gain 1 /V, port 2 to exhaust with 0.8 of it
    s4, e4, s2, e2 = k.valve_areas(prm, base, 5.8)
    assert s4 == pytest.approx(a_leak + 0.5 * a_max)
    assert e2 == pytest.approx(a_leak + 0.4 * a_max)
    assert e4 == s2 == 0.0  # the closing lands' leak faded out
    # below: gain 0.6 /V from the dead band's lower edge at 4.5 V
    s4, e4, s2, e2 = k.valve_areas(prm, base, 3.5)
    assert e4 == pytest.approx(a_leak + 0.6 * a_max)
    assert s2 == pytest.approx(a_leak + 0.48 * a_max)
    assert s4 == e2 == 0.0


def test_own_curve_drives_the_piston_as_its_null_offset_says():
    """At 5.25 V the catalogue valve extends the piston; one whose dead band reaches
    5.3 V only leaks there: the piston hardly moves."""
    runs = {}
    for name, upd in (("catalogue", {}), ("own", _own_curve())):
        plant = Plant(with_updates(PlantParams(), upd))
        plant.reset(x0=-0.03)
        for _ in range(800):
            plant.step(5.25, 5.0)
        runs[name] = plant.state.x + 0.03
    assert runs["catalogue"] > 5e-3
    assert abs(runs["own"]) < 0.2 * runs["catalogue"]


@pytest.mark.parametrize(
    ("updates", "field", "allowed"),
    [
        ({"valve_linear.flow_4": (-1.0, -1.0, 0.2, 0.0, 1.0, 1.0)}, "flow_4", "non-decreasing"),
        ({"valve_linear.flow_2": (1.3, 1.0, 0.0, 0.0, -1.0, -1.0)}, "flow_2", "[-1.25, 1.25]"),
        (
            {"valve_linear.u_curve": (0.0, 4.0, 3.0, 5.3, 6.3, 10.0)},
            "u_curve",
            "strictly increasing",
        ),
        ({"valve_linear.flow_4": (-1.0, 0.0, 1.0)}, "flow_4", "6 values"),
    ],
)
def test_own_curve_refused_names_the_field_and_the_rule(updates, field, allowed):
    from pneu_msgs_py.params.core import ParamError

    with pytest.raises(ParamError, match=field) as err:
        with_updates(PlantParams(), {**_own_curve(), **updates})
    assert allowed in str(err.value)


def test_full_valve_fills_chamber_1_and_vents_chamber_2():
    p = with_updates(PlantParams(), {"linear.breakaway_ratio": 3.0, "linear.A_f": 200.0})
    plant = Plant(p)  # huge friction: piston stays, watch the pressures
    plant.reset()
    for _ in range(300):
        plant.step(10.0, 5.0)
    s = plant.state
    assert s.p_c1 == pytest.approx(p.supply.p_s_linear, rel=2e-3)
    assert s.p_c2 == pytest.approx(p.ambient.p_a, rel=2e-3)
    plant.reset()
    for _ in range(300):
        plant.step(0.0, 5.0)
    s = plant.state
    assert s.p_c2 == pytest.approx(p.supply.p_s_linear, rel=2e-3)
    assert s.p_c1 == pytest.approx(p.ambient.p_a, rel=2e-3)


def test_centre_leak_settles_between_supply_and_exhaust_within_datasheet():
    p = with_updates(PlantParams(), {"linear.A_f": 200.0, "linear.breakaway_ratio": 3.0})
    plant = Plant(p)
    plant.reset()
    for _ in range(3000):
        plant.step(5.0, 5.0)
    s = plant.state
    for pc in (s.p_c1, s.p_c2):
        assert p.ambient.p_a + 0.2e5 < pc < p.supply.p_s_linear - 0.2e5
    # consumption at 6 bar gauge with both ports blocked: under the 20 l/min maximum
    prm = pack_params(PlantParams())
    base = k.P_VALVE_L
    ps, pa = 7.01325e5, 1.01325e5
    a_in = prm[base + k.VB_ALEAK]
    lo, hi = pa, ps
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        net = iso6358_reference(ps, mid, a_in) - iso6358_reference(mid, pa, a_in)
        lo, hi = (mid, hi) if net > 0 else (lo, mid)
    q_lpm = 2 * iso6358_reference(ps, lo, a_in) / 1.185 * 60000
    assert 3.0 < q_lpm < 20.0


def test_spool_zoh_matches_second_order_step_response():
    wn, z, h = 2 * math.pi * 95, 0.7, 1e-4
    f11, f12, f21, f22, g1, g2 = spool_zoh(wn, z, h)
    s, sd = 0.0, 0.0
    wd = wn * math.sqrt(1 - z * z)
    for i in range(1, 200):
        s, sd = f11 * s + f12 * sd + g1, f21 * s + f22 * sd + g2
        t = i * h
        exact = 1 - math.exp(-z * wn * t) * (
            math.cos(wd * t) + z / math.sqrt(1 - z * z) * math.sin(wd * t)
        )
        assert s == pytest.approx(exact, abs=1e-12)


def test_spool_bandwidth_and_hysteresis_in_plant():
    p = PlantParams()
    plant = Plant(p)
    plant.reset()
    # step 5 -> 7 V: 2nd-order overshoot of zeta = 0.7 (4.6 %) within a few ms
    peak = 0.0
    for _ in range(20):
        plant.step(5.0, 7.0)
        peak = max(peak, plant.state.spool_rotary)
    assert 7.0 + 0.03 < peak < 7.0 + 0.15
    # hysteresis: on a slow ramp the effective opening lags the spool by half the play
    # width, so the up and down sweeps differ by the full width (<= 0.4 % of stroke)
    up, down = {}, {}
    ramp = np.concatenate([np.linspace(5.0, 8.0, 600), np.linspace(8.0, 5.0, 600)])
    for i, u in enumerate(ramp):
        plant.step(5.0, float(u))
        s = plant.state
        if abs(s.spool_rotary - 6.5) < 3e-3:
            (up if i < 600 else down)[i] = s.opening_rotary - s.spool_rotary
    assert up and down
    assert all(v == pytest.approx(-0.5 * p.valve_rotary.hysteresis, abs=1e-9) for v in up.values())
    assert all(v == pytest.approx(0.5 * p.valve_rotary.hysteresis, abs=1e-9) for v in down.values())
