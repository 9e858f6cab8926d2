"""Sensor faults on the twin, in-process, through the runner's safety supervisor.

Each test injects one fault at 0.5 s for 0.5 s into a closed-loop run
(re-tuned ESO-SMC; linear sine 20 mm / 0.25 Hz, rotary 800 rpm) and asserts
the fault table's properties: detected within the stated cycles, valves
written safe within 2 cycles of detection, no overtravel past the soft limit,
the bag complete by our reader and by ``mcap_ros2``, the axis safe at the end.
"""

from __future__ import annotations

import numpy as np
from pneu_control.experiment.fault_table import Scenario, run_scenario

F = "start_s=0.5,duration_s=0.5"
K0 = 500  # first faulty sample (T = 1 ms)


def _check_caught(row, rule: str, max_delay: int) -> None:
    assert row.rule == rule, row
    assert 0 <= row.detection_cycles <= max_delay, row
    assert row.safe_cycles is not None and row.safe_cycles <= 2, row
    assert row.bag_complete, row.note
    assert row.end_state == "SAFE (latched)", row


def test_laser_dropout_is_caught_in_the_same_cycle(tmp_path):
    row = run_scenario(
        Scenario(f"sensor_dropout:sensor=x,{F}", ("linear",), 1.5), tmp_path, compare=False
    )
    _check_caught(row, "non_finite", 0)
    assert row.overtravel_mm == 0.0
    res = row.result
    # the NaN reached the bag as it was read, and the valve held 5 V from that tick on
    assert np.isnan(res.samples["x"][K0]) and np.isfinite(res.samples["x"][K0 - 1])
    assert np.all(res.applied["linear"][K0:] == 5.0)
    assert np.all(np.isfinite(res.applied["linear"]))


def test_encoder_dropout_makes_only_the_rotary_axis_safe(tmp_path):
    row = run_scenario(
        Scenario(f"sensor_dropout:sensor=encoder,{F}", ("linear", "rotary"), 1.5),
        tmp_path,
        compare=False,
    )
    _check_caught(row, "non_finite", 0)
    res = row.result
    assert np.all(res.applied["rotary"][K0:] == 5.0)
    assert np.any(res.applied["linear"][K0:] != 5.0)  # the linear axis keeps tracking
    assert row.overspeed_rpm == 0.0


def test_stuck_laser_is_caught_after_stuck_ms(tmp_path):
    row = run_scenario(
        Scenario(f"stuck_sensor:sensor=x,{F}", ("linear",), 1.5), tmp_path, compare=False
    )
    # bit-identical for > stuck_ms = 250 ms: the 251st identical sample after the first
    _check_caught(row, "stuck", 251)
    assert row.detection_cycles == 251
    # 250 ms is long for a position sensor: frozen at 0.5 s (sine rising), the piston
    # reaches the end stop before the rule trips (reported in the fault table); it never
    # goes beyond it, and the valve is held closed from detection on
    assert row.peak_x_mm <= 75.0 + 1e-6
    assert np.all(row.result.applied["linear"][K0 + 251 :] == 5.0)
    # frozen value: exactly the reading at k0, for the whole fault
    x = row.result.samples["x"]
    assert np.all(x[K0 : K0 + 500] == x[K0]) and x[K0 + 500] != x[K0]


def test_stuck_pressure_sensor_makes_its_axis_safe(tmp_path):
    row = run_scenario(
        Scenario(f"stuck_sensor:sensor=p_c1,{F}", ("linear",), 1.5), tmp_path, compare=False
    )
    _check_caught(row, "stuck", 251)
    assert row.detection_cycles == 251


def test_noise_burst_on_the_laser_is_caught_within_20_cycles(tmp_path):
    # sigma 3 V on the laser (0-5 V, AI range ±5 V): each sample leaves the live range or
    # the stroke with probability ≥ 0.4, so 20 clean samples in a row have p < 4e-5 (a noisy x
    # beyond the soft limit trips stroke_limit first, as a piston there would)
    row = run_scenario(
        Scenario(f"noise_burst:sensor=x,sigma_v=3.0,{F}", ("linear",), 1.5), tmp_path
    )
    assert row.rule in ("live_range", "position_range", "stroke_limit")
    _check_caught(row, row.rule, 20)
    assert row.overtravel_mm == 0.0


def test_broken_laser_wire_is_caught_at_once_and_the_unprotected_run_hits_the_stop(tmp_path):
    row = run_scenario(Scenario(f"broken_wire:sensor=x,{F}", ("linear",), 1.5), tmp_path)
    # -5 V is outside the laser's live range and x = -80 mm beyond the stroke: both trip
    assert row.rule in ("live_range", "position_range")
    _check_caught(row, row.rule, 0)
    assert row.overtravel_mm == 0.0
    # the laser reads -5 V (AI range) = x of -80 mm: without the supervisor the controller
    # drives the piston into the + end stop (75 mm)
    assert row.peak_x_mm_unprotected > 74.0
    assert row.peak_x_mm < 30.0


def test_broken_pressure_wire_is_caught_at_once(tmp_path):
    row = run_scenario(
        Scenario(f"broken_wire:sensor=p_m1,{F}", ("rotary",), 1.5), tmp_path, compare=False
    )
    _check_caught(row, "live_range", 0)
    assert row.overspeed_rpm == 0.0


def test_a_cut_wire_reading_zero_volts_is_only_caught_as_a_frozen_value(tmp_path):
    # 0 V on a 0–10 V gauge sensor is atmospheric pressure: plausible, inside the live
    # range. The twin injects a noise-free 0 V, so the stuck rule catches it after
    # stuck_ms; on the rig, AI noise on the open input may keep it from ever tripping.
    row = run_scenario(
        Scenario(f"broken_wire:sensor=p_c1,volts=0,{F}", ("linear",), 1.5), tmp_path, compare=False
    )
    # while valve #1 vents chamber 1 (below 5 V − the band) a 0 V reading is what a live
    # sensor shows (atmosphere): the stuck clock stands still then, so the cut wire trips
    # after 250 ms not vented in all (the supervisor at sample k reads the output of k − 1)
    band = row.result.spec.safety.stall_band_v
    vented = row.result.applied["linear"] < 5.0 - band
    k, not_vented = K0, 0
    while not_vented <= 250:
        k += 1
        not_vented += not vented[k - 1]
    assert k - K0 > 251  # the sine's valve vented chamber 1 meanwhile: later than 251
    _check_caught(row, "stuck", k - K0)
    assert row.detection_cycles == k - K0
