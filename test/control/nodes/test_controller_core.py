"""ControllerShellCore: the controller node's per-sample work, with Jazzy message classes."""

from __future__ import annotations

import math

import numpy as np
from pneu_control.bench.shell import bench_shell_us_per_sample
from pneu_control.controller.axis import STATE_FIELDS, AxisController
from pneu_control.controller.params import load_controller_params
from pneu_control.nodes.controller_core import (
    SENSOR_TOPICS,
    ControllerShellCore,
    SampleAssembler,
    _new,
    new_sensor_messages,
)
from pneu_msgs_py.contract.convert import (
    command_from_msg,
    controller_state_from_msg,
    typestore_messages,
)
from pneu_msgs_py.contract.samples import SensorSample
from pneu_sim.nodes.sim_core import fill_sample_messages

TYPES = typestore_messages().types
JS = "sensor_msgs/msg/JointState"


def tick(k: int, x: float = 0.0) -> tuple[SensorSample, dict]:
    s = SensorSample(k, k * 1_000_000, 2.0e5 + k, 2.1e5 - k, 1.5e5, x, 0.001 * k, 3.0, 7 * k)
    msgs = new_sensor_messages(TYPES)
    fill_sample_messages(msgs, s)
    return s, msgs


def test_assembler_rebuilds_the_sample_exactly_in_any_topic_order():
    core = ControllerShellCore("linear", load_controller_params("linear"))
    s, msgs = tick(3, x=0.0123456789)
    out = None
    for topic in reversed(SENSOR_TOPICS):
        assert out is None
        out = core.on_message(topic, msgs[topic])
    assert out is not None
    for f in ("stamp_ns", "p_c1", "p_c2", "p_m1", "x", "theta", "omega", "counts"):
        assert getattr(out, f) == getattr(s, f), f


def test_lost_message_abandons_the_tick_and_is_counted():
    a = SampleAssembler()
    _, m0 = tick(0)
    _, m1 = tick(1)
    for topic in SENSOR_TOPICS[:-1]:  # rotary joint state of tick 0 lost
        assert a.add(topic, m0[topic]) is None
    done = None
    for topic in SENSOR_TOPICS:
        done = a.add(topic, m1[topic])
    assert done is not None and a.incomplete == 1 and a.emitted == 1
    assert a.add(SENSOR_TOPICS[0], m0[SENSOR_TOPICS[0]]) is None  # older than the last tick
    assert a.late == 1


def test_step_matches_the_core_called_directly_and_fills_both_messages():
    params = load_controller_params("linear")
    core = ControllerShellCore("linear", params)
    ref = AxisController("linear", params)
    cmd, state = _new(TYPES, JS), _new(TYPES, JS)
    for k in range(200):
        s, msgs = tick(k, x=0.001 * math.sin(0.05 * k))
        computed = [core.step(t, msgs[t], cmd, state) for t in SENSOR_TOPICS]
        assert computed == [False] * 4 + [True]
        u = ref.update(s)
        stamp, u_msg = command_from_msg(cmd, "linear")
        assert stamp == s.stamp_ns and u_msg == u
        st_stamp, alg, values = controller_state_from_msg(state)
        assert st_stamp == s.stamp_ns and alg == ref.algorithm == params.algorithm
        assert list(values) == list(STATE_FIELDS)
        assert np.array_equal(
            np.array([values[f] for f in STATE_FIELDS]),
            np.array(ref.state_values()),
            equal_nan=True,
        )
    assert core.n_samples == 200


def test_diagnostics_report_counts_and_warn_on_lost_ticks():
    core = ControllerShellCore("rotary", load_controller_params("rotary"))
    (st,) = core.diagnostics("rotary_controller")
    assert st.level == 0 and st.message == "waiting for samples"
    _, m0 = tick(0)
    core.on_message(SENSOR_TOPICS[0], m0[SENSOR_TOPICS[0]])
    _, m1 = tick(1)
    cmd, state = _new(TYPES, JS), _new(TYPES, JS)
    for t in SENSOR_TOPICS:
        core.step(t, m1[t], cmd, state)
    (st,) = core.diagnostics("rotary_controller")
    assert st.level == 1 and st.values["incomplete_ticks"] == "1" and st.values["samples"] == "1"
    assert st.values["algorithm"] == core.controller.algorithm


def test_live_parameter_change_takes_effect_at_the_next_sample():
    from pneu_msgs_py.params.core import with_updates

    params = load_controller_params("linear")
    core = ControllerShellCore("linear", params)
    cmd, state = _new(TYPES, JS), _new(TYPES, JS)
    for k in range(50):
        _, msgs = tick(k, x=0.0005 * k)
        for t in SENSOR_TOPICS:
            core.step(t, msgs[t], cmd, state)
    other = "pid" if params.algorithm != "pid" else "ladrc"
    core.set_params(with_updates(params, {"algorithm": other}))
    assert core.controller.algorithm == params.algorithm  # not before the next sample
    u_before = command_from_msg(cmd, "linear")[1]
    _, msgs = tick(50, x=0.025)
    for t in SENSOR_TOPICS:
        core.step(t, msgs[t], cmd, state)
    assert core.controller.algorithm == other
    assert controller_state_from_msg(state)[1] == other
    assert command_from_msg(cmd, "linear")[1] == u_before  # bumpless: first command = last
    assert core.diagnostics("n")[0].values["parameter_changes"] == "1"


def test_bench_runs_and_reports_a_positive_figure():
    us = bench_shell_us_per_sample(n=200)
    assert us > 0.0 and math.isfinite(us)
