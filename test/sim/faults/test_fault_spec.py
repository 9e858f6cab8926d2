"""Fault specs: parsing, validation, timing, DAQ scaling, determinism (pneu_sim.faults.injection)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pneu_msgs_py.params.core import ParamError
from pneu_sim.faults.injection import (
    FAULT_NAMES,
    FaultInjector,
    FaultSpec,
    SensorScaling,
    parse_fault,
)
from pneu_sim.physics.plant import Plant
from pneu_sim.physics.plant_file import load_plant


def test_parse_defaults_and_params():
    f = parse_fault("controller_silent")
    assert (f.name, f.start_s, f.duration_s, f.params.axis) == (
        "controller_silent",
        1.0,
        1.0,
        "both",
    )
    g = parse_fault("noise_burst: sensor=p_m1, sigma_v=0.5, start_s=2, duration_s=0.25")
    assert (g.params.sensor, g.params.sigma_v, g.start_s, g.duration_s) == ("p_m1", 0.5, 2.0, 0.25)
    assert parse_fault(g.label + ",start_s=2,duration_s=0.25") == g
    assert FaultSpec.from_dict(g.to_dict()) == g
    assert len(FAULT_NAMES) == 10


@pytest.mark.parametrize(
    "text, key",
    [
        ("nope", "--fault"),
        ("stuck_sensor:sensor=q", "stuck_sensor.sensor"),
        ("noise_burst:sensor=encoder", "noise_burst.sensor"),
        ("supply_drop:factor=0", "supply_drop.factor"),
        ("supply_drop:factor=1", "supply_drop.factor"),
        ("added_mass:mass_kg=-1", "added_mass.mass_kg"),
        ("added_mass:weight=1", "added_mass.weight"),
        ("controller_nan:duration_s=0", "controller_nan.duration_s"),
        ("controller_nan:start_s=-1", "controller_nan.start_s"),
        ("controller_nan:axis", "--fault controller_nan"),
    ],
)
def test_bad_faults_name_the_field(text, key):
    with pytest.raises(ParamError) as err:
        parse_fault(text)
    assert err.value.key == key


def test_scaling_round_trips_the_twins_sensor_values():
    pp = load_plant()
    sc = SensorScaling(pp)
    plant = Plant(pp, seed=3)
    s = plant.reset(x0=0.03)
    for _ in range(50):
        s = plant.step(6.0, 7.0)
    v = sc.volts(s)
    for name, volts in zip(("p_c1", "p_c2", "p_m1", "x"), v):
        assert sc.to_si(name, volts) == pytest.approx(getattr(s, name), abs=1e-9)
    assert v[3] == pytest.approx(2.5 + s.x / 0.032)  # rig.yaml: 0.032 m/V about 2.5 V
    assert v[0] == pytest.approx((s.p_c1 - 101325.0) / 1e5)  # rig.yaml: 1e5 Pa/V from p_a
    assert sc.clip("x", -10.0) == -5.0 and sc.clip("p_c1", -10.0) == -10.0


def _samples(faults, n=400, seed=0):
    plant = Plant(load_plant(), seed=seed)
    inj = FaultInjector(faults, plant, seed=seed)
    s = plant.reset()
    out = []
    for k in range(n):
        s, volts = inj.sample(k, s)
        out.append((s.x, s.p_c1, s.omega, s.counts, volts))
        s = plant.step(*inj.valves(k, 5.0, 8.0))
    return out, plant


def test_faults_act_exactly_in_their_window_and_are_deterministic():
    f = ["noise_burst:sensor=p_c1,sigma_v=1,start_s=0.1,duration_s=0.05"]
    a, _ = _samples(f)
    b, _ = _samples(f)
    clean, _ = _samples([])
    assert a == b  # same seed, same noise
    diff = [k for k in range(400) if a[k][1] != clean[k][1]]
    assert diff[0] == 100 and diff[-1] == 149 and len(diff) == 50


def test_plant_faults_are_swapped_in_and_out():
    plant = Plant(load_plant())
    inj = FaultInjector(["added_mass:mass_kg=1.5,start_s=0.002,duration_s=0.002"], plant)
    M = plant.params.linear.M
    s = plant.reset()
    seen = []
    for k in range(6):
        inj.sample(k, s)
        seen.append(plant.params.linear.M)
        s = plant.step(5.0, 5.0)
    assert seen == [M, M, M + 1.5, M + 1.5, M, M]


def test_missed_counts_are_lost_for_good_and_speed_follows_the_counts():
    faults = ["encoder_missed:fraction=0.5,start_s=0.2,duration_s=0.1"]
    a, _ = _samples(faults)
    clean, _ = _samples([])
    lost = clean[299][3] - a[299][3]
    assert lost == pytest.approx(0.5 * (clean[299][3] - clean[199][3]), abs=1)
    assert clean[399][3] - a[399][3] == lost  # not caught up after the fault
    cpr_per_s = 4000 * 1e-3 / (2 * math.pi)
    assert a[250][2] * cpr_per_s == pytest.approx(a[250][3] - a[249][3])


def test_valve_stuck_overrides_the_written_voltage():
    plant = Plant(load_plant())
    inj = FaultInjector(["valve_stuck:axis=rotary,volts=9,start_s=0,duration_s=0.001"], plant)
    assert inj.valves(0, 5.0, 5.0) == (5.0, 9.0)
    assert inj.valves(1, 5.0, 5.0) == (5.0, 5.0)


def test_dropout_is_nan_and_counts_are_held():
    a, _ = _samples(["sensor_dropout:sensor=encoder,start_s=0.1,duration_s=0.01"])
    assert all(np.isnan(a[k][2]) for k in range(100, 110))
    assert {a[k][3] for k in range(99, 110)} == {a[99][3]}
    assert np.isfinite(a[110][2])
