"""DESIGN §7 metrics: windows, e_max, RMSE (Eq. 37), units, averaging."""

import math

import numpy as np
import pytest
from pneu_control.analysis.metrics import WindowSpec, compute_metrics, moving_average, window_start

T = 1e-3


def grid(duration):
    return np.arange(int(round(duration / T))) * T


def test_sine_window_starts_after_second_period_and_rmse_matches_eq37():
    t = grid(20.0)
    r = 0.02 * np.sin(2 * np.pi * 0.25 * t)
    e = 1e-4 * np.sin(2 * np.pi * 3.0 * t)  # 0.1 mm amplitude error
    e[t < 8.0] = 5e-3  # large transient before the window must not count
    m = compute_metrics("linear", t, r, r - e, WindowSpec(kind="sine", frequency_hz=0.25))
    assert m.window_start_s == pytest.approx(8.0)
    assert m.unit == "mm"
    assert m.e_max == pytest.approx(0.1, rel=1e-3)
    assert m.rmse == pytest.approx(0.1 / math.sqrt(2), rel=1e-3)
    assert m.n_samples == 12000  # 8.000 .. 19.999 s


def test_speed_window_opens_two_seconds_after_first_within_one_percent():
    t = grid(10.0)
    r = np.full_like(t, 800.0 / 9.549296585513721)
    y = r * (1 - np.exp(-t / 0.5))  # reaches 99 % at t = 0.5 ln 100 = 2.303 s
    t_in = 0.5 * math.log(100.0)
    assert window_start(t, r, y, WindowSpec(kind="speed")) == pytest.approx(t_in + 2.0, abs=2 * T)
    m = compute_metrics("rotary", t, r, y, WindowSpec(kind="speed"))
    assert m.unit == "rpm"
    # error at the window start is 800 * exp(-(t_in + 2)/0.5)
    assert m.e_max == pytest.approx(800 * math.exp(-(t_in + 2.0) / 0.5), rel=2e-2)


def test_speed_window_never_opens_gives_nan_not_zero():
    t = grid(3.0)
    r = np.full_like(t, 80.0)
    m = compute_metrics("rotary", t, r, np.zeros_like(t), WindowSpec(kind="speed"))
    assert math.isnan(m.e_max) and m.n_samples == 0


def test_positioning_window_and_exclusion_mask():
    t = grid(10.0)
    r = np.zeros_like(t)
    y = np.zeros_like(t)
    y[(t > 6.0) & (t < 6.1)] = 1e-3  # a 1 mm spike inside the window
    spec = WindowSpec(kind="positioning", t_start_s=5.0)
    assert compute_metrics("linear", t, r, y, spec).e_max == pytest.approx(1.0)
    excl = (t > 5.9) & (t < 6.2)
    assert compute_metrics("linear", t, r, y, spec, exclude=excl).e_max == 0.0


def test_moving_average_is_causal_and_exact():
    y = np.array([0.0, 15.0, 0.0, 15.0, 15.0, 0.0])
    avg = moving_average(y, 2)
    assert np.allclose(avg, [0.0, 7.5, 7.5, 7.5, 15.0, 7.5])
    # quantised speed alternating 795/810 rpm averages to its mean over 10 samples
    q = np.where(np.arange(1000) % 3 == 0, 810.0, 795.0)
    assert np.ptp(moving_average(q, 10)[100:]) <= 1.5 + 1e-9


def test_bad_window_kind_refused():
    with pytest.raises(ValueError, match="window.kind"):
        WindowSpec(kind="bogus")
    with pytest.raises(ValueError, match="frequency_hz"):
        WindowSpec(kind="sine")
    with pytest.raises(ValueError, match="axis"):
        compute_metrics("vertical", grid(1), np.zeros(1000), np.zeros(1000), WindowSpec())


def test_controller_state_fields_are_the_contract_fields():
    import dataclasses

    from pneu_control.controller.axis import STATE_FIELDS, ControllerState
    from pneu_msgs_py.contract.topics import DEFAULT_STATE_FIELDS

    names = tuple(f.name for f in dataclasses.fields(ControllerState) if f.name != "algorithm")
    assert names == STATE_FIELDS == DEFAULT_STATE_FIELDS
