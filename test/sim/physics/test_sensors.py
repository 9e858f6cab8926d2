"""Sensors and DAQ: quantisation steps, noise statistics, offsets, encoder counting."""

import math

import numpy as np
import pytest
from pneu_msgs_py.params.core import with_updates
from pneu_sim.physics.params import PlantParams
from pneu_sim.physics.plant import Plant

SEALED = {"valve_linear.leak_fraction": 0.0, "valve_rotary.leak_fraction": 0.0}


def static_samples(n=4000, seed=3, **updates):
    plant = Plant(with_updates(PlantParams(), {**SEALED, **updates}), seed=seed)
    plant.reset(x0=0.0123)
    samples = [plant.step(5.0, 5.0) for _ in range(n)]
    return plant, samples


def test_ao_quantisation_and_clamp():
    plant = Plant(PlantParams())
    daq = plant.params.sensors.daq
    lsb = 2 * daq.ao_range / 2**daq.ao_bits
    for u in (6.12345, 4.00001, 5.0):
        plant.step(u, 7.77777)
        s = plant.state
        for held, cmd in ((s.u_linear, u), (s.u_rotary, 7.77777)):
            code = (held + daq.ao_range) / lsb
            assert code == pytest.approx(round(code), abs=1e-6)
            assert abs(held - cmd) <= lsb / 2 + 1e-12
    plant.step(12.0, -3.0)
    assert 10.0 - lsb <= plant.state.u_linear <= 10.0
    assert plant.state.u_rotary == 0.0
    with pytest.raises(ValueError):
        plant.step(math.nan, 5.0)


def test_pressure_sensor_noise_offset_and_quantisation():
    plant, samples = static_samples()
    p = plant.params
    ps, daq = p.sensors.pressure, p.sensors.daq
    s = plant.state
    lsb_pa = 2 * daq.ai_range_pressure / 2**daq.ai_bits / ps.v_fs * ps.fs
    for name, true in (("p_c1", s.p_c1), ("p_c2", s.p_c2), ("p_m1", s.p_m1)):
        y = np.array([getattr(x, name) for x in samples])
        # on the AI grid
        codes = ((y - p.ambient.p_a) / lsb_pa) + daq.ai_range_pressure / (
            2 * daq.ai_range_pressure / 2**daq.ai_bits
        )
        assert np.allclose(codes, np.round(codes), atol=1e-6)
        # noise statistics: σ as configured (quantisation adds lsb²/12)
        sigma = ps.sigma_v / ps.v_fs * ps.fs
        assert y.std() == pytest.approx(math.sqrt(sigma**2 + lsb_pa**2 / 12), rel=0.06)
        # fixed offset within the accuracy band
        assert abs(y.mean() - true) <= ps.accuracy_fs * ps.fs + 4 * sigma / math.sqrt(len(y))
        assert abs(y.mean() - true) > lsb_pa  # a real sensor sits somewhere in its band


def test_noise_free_sensors_quantise_within_half_lsb():
    updates = {
        "sensors.pressure.sigma_v": 0.0,
        "sensors.pressure.accuracy_fs": 0.0,
        "sensors.laser.sigma_m": 0.0,
    }
    plant, samples = static_samples(n=50, **updates)
    p = plant.params
    daq, ls, ps = p.sensors.daq, p.sensors.laser, p.sensors.pressure
    s = plant.state
    lsb_x = 2 * daq.ai_range_laser / 2**daq.ai_bits / ls.v_fs * ls.range_m
    lsb_p = 2 * daq.ai_range_pressure / 2**daq.ai_bits / ps.v_fs * ps.fs
    assert lsb_x == pytest.approx(4.88e-6, rel=1e-2)  # ≈ 5 µm: far below the laser noise
    last = samples[-1]
    assert abs(last.x - s.x) <= lsb_x / 2 + 1e-12
    assert abs(last.p_c1 - s.p_c1) <= lsb_p / 2 + 1e-9
    assert len({x.x for x in samples}) == 1


def test_laser_noise_statistics():
    plant, samples = static_samples(n=5000, seed=11)
    ls = plant.params.sensors.laser
    x = np.array([s.x for s in samples])
    assert x.std() == pytest.approx(ls.sigma_m, rel=0.05)
    assert x.mean() == pytest.approx(plant.state.x, abs=4 * ls.sigma_m / math.sqrt(len(x)) + 5e-6)
    # white: neighbouring samples uncorrelated
    r1 = np.corrcoef(x[1:], x[:-1])[0, 1]
    assert abs(r1) < 0.05


def test_laser_first_order_response():
    p = with_updates(PlantParams(), {"sensors.laser.sigma_m": 0.0})
    plant = Plant(p)
    plant.reset()
    tau = p.sensors.laser.tau
    xs, xt = [], []
    for _ in range(20):
        xs.append(plant.step(10.0, 5.0).x)
        xt.append(plant.state.x)
    xs, xt = np.array(xs), np.array(xt)
    moving = xt > 0.001
    # the reading trails the true position by about one time constant times the speed
    v = np.gradient(xt, plant.T)
    lag = (xt - xs)[moving] / v[moving]
    assert np.median(lag) == pytest.approx(tau, rel=0.5)


def test_encoder_counts_and_speed_quantisation():
    plant = Plant(PlantParams())
    plant.reset()
    cpr = 4 * plant.params.sensors.encoder.ppr
    q = 2 * math.pi / (cpr * plant.T)  # one count per window: 15 rpm at 1000 P/R, X4
    assert q * 60 / (2 * math.pi) == pytest.approx(15.0)
    prev_theta = plant.state.theta
    errs = []
    for _ in range(1500):
        s = plant.step(5.0, 6.5)
        th = plant.state.theta
        assert s.counts == math.floor(th * cpr / (2 * math.pi))
        assert s.theta == pytest.approx(s.counts * 2 * math.pi / cpr, abs=1e-12)
        n = s.omega / q
        assert n == pytest.approx(round(n), abs=1e-9)
        true_mean = (th - prev_theta) / plant.T  # mean true speed over the window
        errs.append(s.omega - true_mean)
        prev_theta = th
    errs = np.array(errs)
    assert np.max(np.abs(errs)) < q  # bounded by one count per window
    assert np.max(np.abs(errs)) > 0.5 * q  # and the quantisation is real
    assert abs(errs.mean()) < 0.05 * q  # no bias
