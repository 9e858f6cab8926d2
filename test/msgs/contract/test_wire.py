"""Raw CDR on the wire: our bytes are what rosbags (= rclpy) serialises, and back."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pneu_msgs_py.contract.convert import (
    command_to_typestore,
    controller_state_to_typestore,
    sample_to_typestore,
    typestore_messages,
)
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import DEFAULT_STATE_FIELDS, TOPIC_BY_NAME
from pneu_msgs_py.contract.wire import (
    SENSOR_TOPICS,
    CommandWire,
    SensorWire,
    StateWire,
    clock_bytes,
)

TS = typestore_messages()
S = SensorSample(7, 12_345_678_901, 2.1e5, 1.9e5, 3.3e5, -0.0123, 4.5, 83.7, 2865)


def _ser(msg, ros_type):
    return bytes(TS.serialize_cdr(msg, ros_type))


def test_sensor_payloads_are_rosbags_bytes_and_decode_back():
    wire = SensorWire({"/pneu/pressure/cylinder_1": 4.0})
    ref = sample_to_typestore(S)
    ref["/pneu/pressure/cylinder_1"].variance = 4.0
    got = dict(wire.encode(S))
    assert tuple(got) == SENSOR_TOPICS
    for topic, data in got.items():
        assert data == _ser(ref[topic], TOPIC_BY_NAME[topic].ros_type), topic
    fields = {}
    for topic, data in got.items():
        stamp, vals = wire.decode(topic, data)
        assert stamp == S.stamp_ns
        fields.update(vals)
    assert fields == {
        "p_c1": S.p_c1, "p_c2": S.p_c2, "p_m1": S.p_m1, "x": S.x,
        "theta": S.theta, "omega": S.omega, "counts": float(S.counts),
    }  # fmt: skip
    assert wire.fallbacks == 0


def test_a_foreign_but_valid_joint_state_is_decoded_by_the_general_parser():
    js = TS.types["sensor_msgs/msg/JointState"]
    hdr = TS.types["std_msgs/msg/Header"](
        stamp=TS.types["builtin_interfaces/msg/Time"](sec=3, nanosec=5), frame_id="base"
    )
    msg = js(
        header=hdr,
        name=["extra", "rotary_counts", "rotary"],
        position=np.array([1.0, 99.0, 0.25]),
        velocity=np.array([0.0, math.nan, -3.5]),
        effort=np.zeros(0),
    )
    wire = SensorWire()
    stamp, vals = wire.decode("/pneu/rotary/joint_state", _ser(msg, "sensor_msgs/msg/JointState"))
    assert stamp == 3_000_000_005
    assert vals == {"theta": 0.25, "counts": 99.0, "omega": -3.5}
    assert wire.fallbacks == 1
    with pytest.raises(ValueError, match="malformed"):
        wire.decode("/pneu/rotary/joint_state", b"\x00\x01\x00\x00\x01")
    with pytest.raises(ValueError, match="no position for joint 'linear'"):
        wire.decode("/pneu/linear/joint_state", _ser(msg, "sensor_msgs/msg/JointState"))


def test_commands_states_and_clock_are_rosbags_bytes():
    for axis in ("linear", "rotary"):
        cw = CommandWire(axis)
        data = cw.encode(S.stamp_ns, 6.25)
        assert data == _ser(command_to_typestore(axis, S.stamp_ns, 6.25), TOPIC_BY_NAME[
            f"/pneu/{axis}/valve_command"].ros_type)  # fmt: skip
        assert cw.decode(data) == (S.stamp_ns, 6.25)
    other = CommandWire("rotary").encode(1, 5.0)
    with pytest.raises(ValueError, match="linear_valve"):
        CommandWire("linear").decode(other)
    values = tuple(float(i) for i in range(len(DEFAULT_STATE_FIELDS)))
    sw = StateWire(DEFAULT_STATE_FIELDS)
    ref = controller_state_to_typestore(S.stamp_ns, DEFAULT_STATE_FIELDS, values, "eso_smc")
    assert sw.encode(S.stamp_ns, values, "eso_smc") == _ser(ref, "sensor_msgs/msg/JointState")
    clock = TS.types["rosgraph_msgs/msg/Clock"](
        clock=TS.types["builtin_interfaces/msg/Time"](sec=12, nanosec=345_678_901)
    )
    assert clock_bytes(S.stamp_ns) == _ser(clock, "rosgraph_msgs/msg/Clock")
