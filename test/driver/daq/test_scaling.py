"""DAQ scaling (volts/counts ↔ SI) and the rig parameter file, without nidaqmx."""

import math
from pathlib import Path

import pytest
from pneu_driver.daq.rig import RigParams, load_rig_params
from pneu_driver.daq.scaling import (
    RawSample,
    Scaler,
    angle_rad,
    ao_volts,
    laser_volts,
    position_m,
    pressure_pa,
    pressure_volts,
    unwrap_counts,
)
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.params.core import ParamError, from_dict

CONFIG = Path(__file__).resolve().parents[3] / "config"


def test_rig_yaml_is_the_documented_default():
    rig = load_rig_params(CONFIG / "rig.yaml")
    # the file states the defaults, plus SCHED_FIFO for the rig's loop thread
    assert load_rig_params(CONFIG / "rig.yaml", overrides={"loop.rt_priority": 0}) == RigParams()
    assert rig.loop.rt_priority == 50
    assert rig.device == "Dev1"
    assert (rig.channels.p_c1, rig.channels.laser, rig.channels.encoder) == ("ai0", "ai3", "ctr0")
    assert rig.encoder.counts_per_rev == 4000
    assert rig.period_ns == 1_000_000


def test_huba_gauge_volts_to_absolute_pa():
    rig = RigParams()
    s = rig.p_c1
    assert pressure_pa(0.0, s, rig.p_atm_pa) == pytest.approx(101325.0)
    assert pressure_pa(10.0, s, rig.p_atm_pa) == pytest.approx(101325.0 + 1.0e6)  # 10 bar gauge
    assert pressure_pa(2.0, s, rig.p_atm_pa) == pytest.approx(301325.0)  # 0.2 MPa gauge supply
    for p in (101325.0, 250000.0, 501325.0):
        assert pressure_pa(pressure_volts(p, s, rig.p_atm_pa), s, rig.p_atm_pa) == pytest.approx(p)


def test_laser_volts_to_metres_around_mid_stroke():
    rig = from_dict(RigParams, {"laser": {"offset_m": 0.002}}, strict=False)
    las = rig.laser
    assert position_m(2.5, las) == pytest.approx(0.002)
    assert position_m(5.0, las) - position_m(0.0, las) == pytest.approx(0.160)  # 200 ± 80 mm range
    assert position_m(laser_volts(-0.0381, las), las) == pytest.approx(-0.0381)
    flipped = from_dict(RigParams, {"laser": {"m_per_v": -0.032}}, strict=False).laser
    assert position_m(3.0, flipped) == pytest.approx(-0.016)


def test_encoder_angle_and_unwrapping():
    assert angle_rad(4000, 4000) == pytest.approx(2 * math.pi)
    assert angle_rad(-1000, 4000) == pytest.approx(-math.pi / 2)
    # unsigned 32-bit register rolls over forwards and backwards
    assert unwrap_counts(2**32 - 10, 5) == 2**32 + 5
    assert unwrap_counts(3, 2**32 - 2) == -2
    # signed readings (DAQmx ticks may come back negative) give the same cumulative count
    assert unwrap_counts(-5, -7) == -7
    assert unwrap_counts(10**12, (10**12 + 37) % 2**32) == 10**12 + 37
    assert (
        unwrap_counts(0, 2**15 + 1, bits=16) == -(2**15) + 1
    )  # more than half the range: backwards


def test_ao_clamp_is_the_last_line_of_defence():
    ao = RigParams().ao
    assert ao_volts(7.5, ao) == 7.5
    assert ao_volts(12.0, ao) == 10.0
    assert ao_volts(-1.0, ao) == 0.0
    assert ao_volts(math.nan, ao) == 5.0
    assert ao_volts(math.inf, ao) == 5.0


def test_scaler_sample_and_quantised_speed():
    rig = RigParams()
    sc = Scaler(rig)
    v = (2.0, 1.0, 3.0, 2.5)
    s0 = sc.sample(0, 0, RawSample(v, 100))
    assert isinstance(s0, SensorSample)
    assert (s0.k, s0.stamp_ns, s0.counts, s0.omega) == (0, 0, 100, 0.0)
    assert s0.p_c1 == pytest.approx(301325.0) and s0.p_m1 == pytest.approx(401325.0)
    assert s0.x == pytest.approx(0.0)
    s1 = sc.sample(1, 1_000_000, RawSample(v, 101))
    # one count per 1 ms at 4000 counts/rev = 15 rpm = pi/2 rad/s
    assert s1.omega == pytest.approx(math.pi / 2)
    s3 = sc.sample(3, 3_000_000, RawSample(v, 103))  # a missed tick: the speed is per elapsed time
    assert s3.omega == pytest.approx(math.pi / 2)
    assert s3.theta == pytest.approx(2 * math.pi * 103 / 4000)
    back = sc.raw(s3)
    assert back.counts == 103
    assert back.volts == pytest.approx(v)


def test_rig_params_refused_with_the_field_named():
    with pytest.raises(
        ParamError,
        match=r"channels.p_c2: 'ai0' refused; allowed: a channel not already used by p_c1",
    ):
        from_dict(RigParams, {"channels": {"p_c2": "ai0"}}, strict=False)
    with pytest.raises(ParamError, match=r"channels.encoder: 'ai5' refused"):
        from_dict(RigParams, {"channels": {"encoder": "ai5"}}, strict=False)
    with pytest.raises(ParamError, match=r"loop.command_deadline_us: 1000.0 refused"):
        from_dict(RigParams, {"loop": {"command_deadline_us": 1000.0}}, strict=False)
    with pytest.raises(
        ParamError, match=r"loop.timing: 'fast' refused; allowed: one of hardware, software"
    ):
        from_dict(RigParams, {"loop": {"timing": "fast"}}, strict=False)
    with pytest.raises(ParamError, match=r"ao.safe_v: 11.0 refused"):
        from_dict(RigParams, {"ao": {"safe_v": 11.0}}, strict=False)
    with pytest.raises(ParamError, match=r"laser.m_per_v: 0.0 refused"):
        from_dict(RigParams, {"laser": {"m_per_v": 0.0}}, strict=False)
    with pytest.raises(ParamError, match=r"bogus"):
        from_dict(RigParams, {"bogus": 1}, strict=False)


def test_overrides_apply_as_one_set(tmp_path):
    import yaml
    from pneu_msgs_py.params.paths import config_file

    data = yaml.safe_load(config_file("rig.yaml").read_text())
    data["device"], data["loop"]["timing"] = "PXI1Slot2", "software"
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(data))
    rig = load_rig_params(path, overrides={"loop.spin_us": 100.0})
    assert rig.device == "PXI1Slot2"
    assert rig.loop.timing == "software" and rig.loop.spin_us == 100.0
    with pytest.raises(ParamError, match="loop.spin_us"):
        load_rig_params(path, overrides={"loop.spin_us": -1.0})
