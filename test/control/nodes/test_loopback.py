"""The lockstep graph's per-sample code over CDR gives the in-process runner's numbers.

The sim shell core and the controller shell cores exchange real Jazzy CDR
bytes (rosbags typestore): everything a ROS lockstep run does except the
middleware. Same spec and seed -> bit-identical samples, states and metrics.
"""

from __future__ import annotations

import numpy as np
import pytest
from pneu_control.experiment import session
from pneu_control.experiment.runner import run
from pneu_control.nodes.loopback import run_loopback
from pneu_driver.safety import SafetyParams, SafetySupervisor


def _assert_identical(a, b, states=True):
    assert a.samples.keys() == b.samples.keys()
    for k in a.samples:
        assert np.array_equal(a.samples[k], b.samples[k], equal_nan=True), k
    for axis in ("linear", "rotary"):  # what the valves got, step by step
        assert np.array_equal(a.applied[axis], b.applied[axis]), axis
    assert a.axes.keys() == b.axes.keys()
    for axis in a.axes:
        for k in a.axes[axis] if states else ():
            assert np.array_equal(a.axes[axis][k], b.axes[axis][k], equal_nan=True), (axis, k)
    assert a.algorithms == b.algorithms
    assert a.metrics.keys() == b.metrics.keys()
    for axis, m in a.metrics.items():  # NaN when a safe interval covers the window (both)
        got = b.metrics[axis]
        assert got.n_samples == m.n_samples
        if m.n_samples:
            assert got.e_max == pytest.approx(m.e_max, abs=1e-9, rel=0)
            assert got.rmse == pytest.approx(m.rmse, abs=1e-9, rel=0)


@pytest.mark.parametrize("controller", ["eso_smc", "pid"])
def test_loopback_equals_runner_both_axes(controller):
    spec = session.build_spec(
        axes=("linear", "rotary"),
        controller=controller,
        sets=[
            "linear.reference.kind=sine",
            "linear.reference.amplitude=20.0",
            "linear.reference.frequency_hz=0.25",
            "rotary.reference.kind=constant",
            "rotary.reference.value=800.0",
        ],
        duration_s=1.0,
        seed=7,
        window_start_s=0.5,
    )
    a = run(spec)
    b = run_loopback(spec)
    _assert_identical(a, b)
    assert a.metrics["linear"].n_samples > 0
    assert b.wire["timeouts.linear"] == 0 and b.wire["stale.rotary"] == 0
    # 5 sensor messages per sample + command and state per axis and sample
    assert b.wire["messages"] == 1000 * (5 + 2 * 2)


def test_loopback_equals_runner_sine_one_axis_other_neutral():
    spec = session.build_spec(
        axes=("linear",),
        controller="eso_smc",
        reference="sine:amplitude=20.0,frequency_hz=0.25",
        duration_s=1.5,
        seed=11,
        window_start_s=1.0,
    )
    a = run(spec)
    b = run_loopback(spec)
    _assert_identical(a, b)
    assert "rotary" not in b.axes


def test_loopback_equals_runner_without_supervisor():
    spec = session.build_spec(
        axes=("linear",),
        controller="eso_smc",
        reference="constant:value=0.0",
        duration_s=0.5,
        seed=5,
        window_start_s=0.2,
        safety=False,
    )
    a = run(spec)
    b = run_loopback(spec)
    assert spec.safety is None and b.safety_counters == {}
    _assert_identical(a, b)


def test_loopback_equals_runner_with_injected_faults_and_supervisor_trips():
    spec = session.build_spec(
        axes=("linear", "rotary"),
        controller="pid",
        sets=["rotary.reference.kind=constant", "rotary.reference.value=300.0"],
        duration_s=0.6,
        seed=9,
        window_start_s=0.1,
        faults=[
            "noise_burst:sensor=p_c1,start_s=0.05,duration_s=0.05",
            "sensor_dropout:sensor=x,start_s=0.12,duration_s=0.01",
            "encoder_missed:start_s=0.2,duration_s=0.05",
            "supply_drop:axis=both,start_s=0.3,duration_s=0.1",
            "valve_stuck:axis=linear,start_s=0.42,duration_s=0.02",
            "controller_nan:axis=rotary,start_s=0.5,duration_s=0.01",
        ],
    )
    a = run(spec)
    b = run_loopback(spec)
    assert a.safety_counters["trips"] > 0  # the dropout and the NaN trip the supervisor
    assert b.safety_counters == a.safety_counters
    assert [(e.stamp_ns, e.axis, e.rule, e.level) for e in b.safety_events] == [
        (e.stamp_ns, e.axis, e.rule, e.level) for e in a.safety_events
    ]
    # samples, valve outputs, metrics identical; controller states too (a NaN command
    # is the published value, the controller core itself is unaffected)
    _assert_identical(a, b, states=False)
    for axis in a.axes:
        for k in a.axes[axis]:
            if k != "u":
                assert np.array_equal(a.axes[axis][k], b.axes[axis][k], equal_nan=True), (axis, k)


class EstopAt:
    """A SafetySupervisor that the operator e-stops at a given sample time."""

    def __init__(self, sup, at_ns):
        self.sup, self.at_ns, self.seen = sup, at_ns, []

    def command(self, axis, u, stamp_ns):
        self.sup.command(axis, u, stamp_ns)

    def check_sample(self, s, volts=None):
        if s.stamp_ns == self.at_ns:
            self.sup.estop("test")
        self.sup.check_sample(s, volts)

    def outputs(self, now_ns):
        out = self.sup.outputs(now_ns)
        self.seen.append((now_ns, out))
        return out


def test_estop_through_the_supervisor_holds_neutral_from_the_next_tick():
    spec = session.build_spec(
        axes=("linear",),
        controller="pid",
        reference="sine:amplitude=20.0,frequency_hz=0.25",
        duration_s=0.3,
        seed=1,
        window_start_s=0.1,
    )
    sup = EstopAt(SafetySupervisor(SafetyParams(), sample_time_s=1e-3), at_ns=200_000_000)
    run_loopback(spec, supervisor=sup)
    before = [u for t, u in sup.seen if 1_000_000 < t < 200_000_000]
    after = [u for t, u in sup.seen if t >= 200_000_000]
    assert any(abs(u[0] - 5.0) > 1e-3 for u in before)  # the controller was driving
    assert after and all(u == (5.0, 5.0) for u in after)
