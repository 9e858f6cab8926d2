"""Rotary axis: Eq. 6–10 vane motor, valve-fed inlet, silencer exhaust, Gast 1AM figures."""

import math

import numpy as np
import pytest
from pneu_msgs_py.contract.units import RPM_PER_RAD_S
from pneu_msgs_py.params.core import with_updates
from pneu_sim.physics import kernel as k
from pneu_sim.physics.pack import pack_params
from pneu_sim.physics.params import K_SEAL_ESTIMATE, PlantParams
from pneu_sim.physics.plant import Plant


def steady(plant, u_r, t_settle=2.0, t_avg=1.0):
    """Run at constant rotary voltage; return (mean ω, mean Eq. 8 torque) over t_avg."""
    prm = plant._prm
    for _ in range(round(t_settle / plant.T)):
        plant.step(5.0, u_r)
    w, tq = [], []
    for _ in range(round(t_avg / plant.T)):
        plant.step(5.0, u_r)
        s = plant.state
        w.append(s.omega)
        tq.append(k.vane_factor(prm, s.theta) * (s.p_m1 - s.p_m2))
    return float(np.mean(w)), float(np.mean(tq)), np.array(w)


@pytest.mark.parametrize("u_r", [6.0, 7.5])
def test_steady_speed_where_driving_torque_equals_eq9_friction(u_r):
    plant = Plant(with_updates(PlantParams(), {"coupling.k_seal": K_SEAL_ESTIMATE}))
    plant.reset()
    w, torque, _ = steady(plant, u_r)
    rot = plant.params.rotary
    n_rpm = w * RPM_PER_RAD_S
    s, p_a = plant.state, plant.params.ambient.p_a
    T_seal = plant.params.coupling.k_seal * ((s.p_c1 - p_a) + (s.p_c2 - p_a))  # chambers > p_a
    assert 0.0 < T_seal < 0.3 * rot.M_c
    M_f = rot.M_c + T_seal + rot.M_v * n_rpm  # Eq. 9 (M_v per rpm as the paper gives it) + seals
    assert n_rpm > 300
    assert torque == pytest.approx(M_f, rel=0.01)


def test_vane_factor_periodic_in_vane_pitch_and_mean_matches_eq8():
    for z in (4, 6):
        p = with_updates(PlantParams(), {"rotary.n_vanes": z})
        prm = pack_params(p)
        rot = p.rotary
        pitch = 2 * math.pi / z
        th = np.linspace(0.0, 4 * math.pi, 997)
        a = np.array([k.vane_factor(prm, t) for t in th])
        b = np.array([k.vane_factor(prm, t + pitch) for t in th])
        assert np.allclose(a, b, rtol=1e-12, atol=0)
        assert np.ptp(a) > 0.05 * a.mean()  # there is a ripple
        half = np.array([k.vane_factor(prm, t + pitch / 2) for t in th])
        assert not np.allclose(a, half, rtol=1e-3)  # and its period is not shorter
        # sector mean of Eq. 8: ½ L (d² sinc(2π/z) + 2 d R sinc(π/z) + R² − r²)
        d, R, r, L = rot.d_m, rot.R_m, rot.r_m, rot.L_m
        mean = (
            0.5
            * L
            * (
                d * d * math.sin(pitch) / pitch
                + 2 * d * R * math.sin(pitch / 2) / (pitch / 2)
                + R * R
                - r * r
            )
        )
        assert Plant(p).mean_vane_factor() == pytest.approx(mean, rel=1e-6)


def test_torque_ripple_period_matches_vane_count_in_speed():
    for z in (4, 6):
        plant = Plant(with_updates(PlantParams(), {"rotary.n_vanes": z}))
        plant.reset()
        w_mean, _, w = steady(plant, 6.2, t_settle=1.5, t_avg=1.024)
        f_rot = w_mean / (2 * math.pi)
        spec = np.abs(np.fft.rfft(w - w.mean()))
        freqs = np.fft.rfftfreq(len(w), plant.T)
        f_peak = freqs[np.argmax(spec[1:]) + 1]
        assert f_peak == pytest.approx(z * f_rot, abs=2.0)


def test_gast_1am_published_figures():
    # linear torque-speed line through 0.45 hp and 10 000 rpm free speed at 100 psi:
    # stall torque 4 P / ω_free must equal the Eq. 8 mean factor times 100 psi
    plant = Plant(PlantParams())
    P_max = 0.45 * 745.7
    w_free = 10000 / RPM_PER_RAD_S
    dp = 100 * 6894.76
    assert plant.mean_vane_factor() * dp == pytest.approx(4 * P_max / w_free, rel=0.03)


def test_800_rpm_needs_an_opening_well_inside_the_range():
    plant = Plant(PlantParams())
    lo, hi = 5.0, 10.0
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        plant.reset()
        w, _, _ = steady(plant, mid, t_settle=1.5, t_avg=0.3)
        lo, hi = (lo, mid) if w * RPM_PER_RAD_S > 800 else (mid, hi)
    u_800 = 0.5 * (lo + hi)
    assert 5.4 < u_800 < 7.5  # outside the dead band, far from saturation (9.75 V)


def test_inlet_vents_to_atmosphere_below_5V_and_motor_stops():
    plant = Plant(PlantParams())
    plant.reset(omega0=800 / RPM_PER_RAD_S)
    for _ in range(2000):
        plant.step(5.0, 0.0)
    s = plant.state
    p_a = plant.params.ambient.p_a
    assert s.omega == 0.0
    assert s.p_m1 == pytest.approx(p_a, rel=1e-3)
    assert s.p_m2 == pytest.approx(p_a, rel=1e-3)


@pytest.mark.parametrize("k_seal", [0.0, K_SEAL_ESTIMATE])
def test_reset_at_speed_holds_it_against_friction(k_seal):
    plant = Plant(with_updates(PlantParams(), {"coupling.k_seal": k_seal}))
    w0 = 800 / RPM_PER_RAD_S
    sample = plant.reset(omega0=w0)
    assert abs(sample.omega - w0) <= 2 * math.pi / (4 * 1000 * plant.T)
    rot = plant.params.rotary
    s = plant.state
    torque = plant.mean_vane_factor() * (s.p_m1 - s.p_m2)
    p_a = plant.params.ambient.p_a
    T_seal = plant.params.coupling.k_seal * ((s.p_c1 - p_a) + (s.p_c2 - p_a))
    assert torque == pytest.approx(rot.M_c + T_seal + rot.M_v * 800, rel=1e-9)
