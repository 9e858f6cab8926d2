"""ControllerShellCore: the controller node's per-sample work on raw CDR payloads."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pneu_control.bench.shell import bench_shell_us_per_sample
from pneu_control.controller.axis import STATE_FIELDS, AxisController
from pneu_control.controller.params import load_controller_params
from pneu_control.nodes.controller_core import INPUT_TOPICS, ControllerShellCore, SampleAssembler
from pneu_msgs_py.contract.convert import (
    command_from_msg,
    controller_state_from_msg,
    sample_to_typestore,
    typestore_messages,
)
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import TOPIC_BY_NAME
from pneu_msgs_py.contract.wire import SENSOR_TOPICS, SensorWire

TS = typestore_messages()
JS = "sensor_msgs/msg/JointState"
WIRE = SensorWire()


def tick(k: int, x: float = 0.0) -> tuple[SensorSample, dict[str, bytes]]:
    """A sample and its five payloads, serialised by rosbags (= what rclpy puts on the wire)."""
    s = SensorSample(k, k * 1_000_000, 2.0e5 + k, 2.1e5 - k, 1.5e5, x, 0.001 * k, 3.0, 7 * k)
    msgs = sample_to_typestore(s)
    return s, {t: bytes(TS.serialize_cdr(m, TOPIC_BY_NAME[t].ros_type)) for t, m in msgs.items()}


def _decode(data: bytes):
    return TS.deserialize_cdr(data, JS)


def test_each_axis_takes_only_the_topics_its_algorithms_read():
    assert INPUT_TOPICS["linear"] == (
        "/pneu/pressure/cylinder_1",
        "/pneu/pressure/cylinder_2",
        "/pneu/linear/joint_state",
    )
    assert INPUT_TOPICS["rotary"] == ("/pneu/rotary/joint_state",)


@pytest.mark.parametrize("axis", ["linear", "rotary"])
def test_assembler_rebuilds_the_fields_exactly_in_any_topic_order(axis):
    core = ControllerShellCore(axis, load_controller_params(axis))
    s, payloads = tick(3, x=0.0123456789)
    out = None
    for topic in reversed(core.topics):
        assert out is None
        out = core.on_raw(topic, payloads[topic])
    assert out is not None and out.stamp_ns == s.stamp_ns
    taken = {"linear": ("p_c1", "p_c2", "x"), "rotary": ("theta", "omega", "counts")}[axis]
    for f in ("p_c1", "p_c2", "p_m1", "x", "theta", "omega", "counts"):
        if f in taken:
            assert getattr(out, f) == getattr(s, f), f
        elif f != "counts":
            assert math.isnan(getattr(out, f)), f  # not subscribed: no algorithm reads it


def test_lost_message_abandons_the_tick_and_is_counted():
    topics = INPUT_TOPICS["linear"]
    a = SampleAssembler(topics)
    for topic in topics[:-1]:  # the joint state of tick 0 is lost
        assert a.add(topic, 0, {topic: 1.0}) is None
    done = None
    for topic in topics:
        done = a.add(topic, 1_000_000, {topic: 2.0})
    assert done is not None and a.incomplete == 1 and a.emitted == 1
    assert a.add(topics[0], 0, {}) is None  # older than the last tick
    assert a.late == 1


@pytest.mark.parametrize("axis", ["linear", "rotary"])
def test_step_matches_the_core_called_directly_and_answers_in_rosbags_bytes(axis):
    params = load_controller_params(axis)
    core = ControllerShellCore(axis, params)
    ref = AxisController(axis, params)
    for k in range(200):
        s, payloads = tick(k, x=0.001 * math.sin(0.05 * k))
        outs = [core.step_raw(t, payloads[t]) for t in core.topics]
        assert [o is None for o in outs] == [True] * (len(core.topics) - 1) + [False]
        cmd, state = outs[-1]
        u = ref.update(s)
        stamp, u_msg = command_from_msg(_decode(cmd), axis)
        assert stamp == s.stamp_ns and u_msg == u
        st_stamp, alg, values = controller_state_from_msg(_decode(state))
        assert st_stamp == s.stamp_ns and alg == ref.algorithm == params.algorithm
        assert list(values) == list(STATE_FIELDS)
        assert np.array_equal(
            np.array([values[f] for f in STATE_FIELDS]),
            np.array(ref.state_values()),
            equal_nan=True,
        )
    assert core.n_samples == 200 and core.decoder.sensors.fallbacks == 0


def test_state_is_decimated_by_the_sample_clock_and_commands_never_are():
    core = ControllerShellCore("rotary", load_controller_params("rotary"), state_every=10)
    states = []
    for k in range(35):
        _, payloads = tick(k)
        cmd, state = core.step_raw("/pneu/rotary/joint_state", payloads["/pneu/rotary/joint_state"])
        assert cmd is not None
        if state is not None:
            states.append(k)
    assert states == [0, 10, 20, 30]
    with pytest.raises(ValueError, match="state_every"):
        ControllerShellCore("rotary", load_controller_params("rotary"), state_every=0)


def test_diagnostics_report_counts_and_warn_on_lost_ticks_and_bad_payloads():
    core = ControllerShellCore("linear", load_controller_params("linear"))
    (st,) = core.diagnostics("linear_controller")
    assert st.level == 0 and st.message == "waiting for samples"
    _, m0 = tick(0)
    core.on_raw(SENSOR_TOPICS[0], m0[SENSOR_TOPICS[0]])
    _, m1 = tick(1)
    for t in core.topics:
        core.step_raw(t, m1[t])
    core.step_raw(core.topics[0], b"\x00\x01\x00\x00garbage")
    (st,) = core.diagnostics("linear_controller")
    assert st.level == 1 and st.values["incomplete_ticks"] == "1" and st.values["samples"] == "1"
    assert st.values["malformed_payloads"] == "1"
    assert st.values["algorithm"] == core.controller.algorithm
    # no sample since that report: the driver or sim is gone, and the controller says so
    (st,) = core.diagnostics("linear_controller")
    assert st.level == 2 and "driver or sim stopped or is gone; not commanding" in st.message
    _, m2 = tick(2)
    for t in core.topics:
        core.step_raw(t, m2[t])
    (st,) = core.diagnostics("linear_controller")
    assert st.level == 1 and "no samples" not in st.message  # samples again


def test_live_parameter_change_takes_effect_at_the_next_sample():
    from pneu_msgs_py.params.core import with_updates

    params = load_controller_params("linear")
    core = ControllerShellCore("linear", params)
    out = None
    for k in range(50):
        _, payloads = tick(k, x=0.0005 * k)
        for t in core.topics:
            out = core.step_raw(t, payloads[t]) or out
    other = "pid" if params.algorithm != "pid" else "ladrc"
    core.set_params(with_updates(params, {"algorithm": other}))
    assert core.controller.algorithm == params.algorithm  # not before the next sample
    u_before = command_from_msg(_decode(out[0]), "linear")[1]
    _, payloads = tick(50, x=0.025)
    for t in core.topics:
        out = core.step_raw(t, payloads[t]) or out
    assert core.controller.algorithm == other
    assert controller_state_from_msg(_decode(out[1]))[1] == other
    assert command_from_msg(_decode(out[0]), "linear")[1] == u_before  # bumpless
    assert core.diagnostics("n")[0].values["parameter_changes"] == "1"
    neutral = core.neutral_command()
    assert command_from_msg(_decode(neutral), "linear") == (50 * 1_000_000, 5.0)


def test_bench_runs_and_reports_a_positive_figure():
    us = bench_shell_us_per_sample(n=200)
    assert us > 0.0 and math.isfinite(us)
