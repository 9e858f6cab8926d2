"""ExciterShellCore: the exciter node's per-sample work on raw CDR payloads."""

from __future__ import annotations

import json

import numpy as np
from pneu_control.controller.axis import STATE_FIELDS
from pneu_control.nodes.exciter_core import ExciterShellCore
from pneu_control.sysid.design import design_for
from pneu_control.sysid.exciter import ALGORITHM, Exciter
from pneu_msgs_py.contract.convert import (
    command_from_msg,
    controller_state_from_msg,
    sample_to_typestore,
    typestore_messages,
)
from pneu_msgs_py.contract.samples import NEUTRAL_V, SensorSample
from pneu_msgs_py.contract.topics import TOPIC_BY_NAME
from pneu_msgs_py.contract.wire import SENSOR_TOPICS

TS = typestore_messages()
JS = "sensor_msgs/msg/JointState"


def payloads(s: SensorSample) -> dict[str, bytes]:
    """The five sensor payloads of ``s``, serialised by rosbags (= rclpy's wire bytes)."""
    msgs = sample_to_typestore(s)
    return {t: bytes(TS.serialize_cdr(m, TOPIC_BY_NAME[t].ros_type)) for t, m in msgs.items()}


def test_answers_every_complete_tick_with_the_exciters_command_in_rosbags_bytes():
    core = ExciterShellCore(("linear", "rotary"), seed=3, level="quick")
    refs = {a: Exciter(design_for(a, 3, "quick")) for a in ("linear", "rotary")}
    assert set(core.topics) == set(SENSOR_TOPICS)
    rng = np.random.default_rng(0)
    for k in range(300):
        s = SensorSample(k, k * 1_000_000, 2e5, 2e5, 1e5, 0.05 + 1e-3 * rng.standard_normal(),
                         0.01 * k, 5.0 + rng.standard_normal(), 3 * k)  # fmt: skip
        got = None
        for topic in reversed(SENSOR_TOPICS):  # any order completes the tick once
            assert got is None
            got = core.on_raw(topic, payloads(s)[topic])
        assert got is not None and got.stamp_ns == s.stamp_ns
        answers = core.answer(got)
        assert [a for a, _, _ in answers] == ["linear", "rotary"]
        for axis, cmd, state in answers:
            u_ref = refs[axis].update(s)
            assert command_from_msg(TS.deserialize_cdr(cmd, JS), axis) == (s.stamp_ns, u_ref)
            stamp, alg, values = controller_state_from_msg(TS.deserialize_cdr(state, JS))
            assert (stamp, alg, list(values)) == (s.stamp_ns, ALGORITHM, list(STATE_FIELDS))
    assert core.n_samples == 300 and core.last_stamp_ns == 299_000_000
    assert json.loads(core.designs_json()).keys() == {"linear", "rotary"}


def test_neutral_last_word_only_after_a_sample_and_malformed_payloads_are_counted():
    core = ExciterShellCore(("rotary",), seed=0, level="quick")
    assert core.neutral_commands(NEUTRAL_V) == []
    assert core.on_raw(SENSOR_TOPICS[0], b"\x00\x01\x00\x00garbage") is None
    s = SensorSample(0, 5_000_000, 2e5, 2e5, 1e5, 0.0, 0.0, 0.0, 0)
    for topic, data in payloads(s).items():
        core.on_raw(topic, data)
    [(axis, data)] = core.neutral_commands(NEUTRAL_V)
    assert axis == "rotary"
    assert command_from_msg(TS.deserialize_cdr(data, JS), axis) == (5_000_000, NEUTRAL_V)
    [diag] = core.diagnostics("pneu_exciter")
    assert diag.level == 1 and diag.values["malformed_payloads"] == "1"
