"""Bulk CDR layouts: bytes identical to rosbags and mcap_ros2, and decoded back exactly."""

import math

import numpy as np
import pytest
from mcap_ros2._dynamic import serialize_dynamic
from pneu_msgs_py.bag.cdr import (
    CdrDecodeError,
    clock_layout,
    fluid_pressure_layout,
    joint_state_layout,
    layout_of,
    parse_fixed,
)
from pneu_msgs_py.bag.schemas import MSG_DEFINITIONS
from pneu_msgs_py.contract.topics import DEFAULT_STATE_FIELDS
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_JAZZY)
T = TS.types
NS = 1_000_000_000


def _hdr(stamp_ns, frame_id):
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=stamp_ns // NS, nanosec=stamp_ns % NS),
        frame_id=frame_id,
    )


def _mcap_ros2_bytes(ros_type, msg_dict):
    enc = serialize_dynamic(ros_type, MSG_DEFINITIONS[ros_type])[ros_type]
    return bytes(enc(msg_dict))


STAMPS = [0, 1, 999_999_999, 1_000_000_000, 1_700_000_000_123_456_789]


@pytest.mark.parametrize("frame", ["cylinder_1", "motor_in", "", "ab", "abc", "abcd"])
@pytest.mark.parametrize("stamp", STAMPS)
def test_fluid_pressure_bytes_match_rosbags_and_mcap_ros2(frame, stamp):
    L = fluid_pressure_layout(frame)
    p, var = 201325.5, 12.25
    ref = bytes(
        TS.serialize_cdr(
            T["sensor_msgs/msg/FluidPressure"](
                header=_hdr(stamp, frame), fluid_pressure=p, variance=var
            ),
            "sensor_msgs/msg/FluidPressure",
        )
    )
    ref2 = _mcap_ros2_bytes(
        "sensor_msgs/msg/FluidPressure",
        {
            "header": {"stamp": {"sec": stamp // NS, "nanosec": stamp % NS}, "frame_id": frame},
            "fluid_pressure": p,
            "variance": var,
        },
    )
    assert ref == ref2
    assert L.encode(stamp, [p, var]) == ref
    assert L.encode_many(np.array([stamp]), np.array([[p, var]]))[0].tobytes() == ref


def _js(stamp, frame, names, pos, vel, eff):
    return T["sensor_msgs/msg/JointState"](
        header=_hdr(stamp, frame),
        name=list(names),
        position=np.array(pos, dtype=np.float64),
        velocity=np.array(vel, dtype=np.float64),
        effort=np.array(eff, dtype=np.float64),
    )


CASES = [
    # names, frame, position?, velocity?, effort?
    (["linear"], "", True, False, False),
    (["rotary", "rotary_counts"], "", True, True, False),
    (["linear_valve"], "", False, False, True),
    (list(DEFAULT_STATE_FIELDS), "eso_smc", True, False, False),
    (list(DEFAULT_STATE_FIELDS), "pid", True, False, False),
    (["a", "bb", "ccc"], "x", True, True, True),
    ([], "", False, False, False),
]


@pytest.mark.parametrize("names,frame,pos,vel,eff", CASES)
def test_joint_state_bytes_match_rosbags_and_mcap_ros2(names, frame, pos, vel, eff):
    rng = np.random.default_rng(7)
    L = joint_state_layout(names, position=pos, velocity=vel, effort=eff, frame_id=frame)
    n = 4
    stamps = np.array(STAMPS[:n], dtype=np.int64)
    vals = rng.normal(size=(n, len(L.value_names))) * 1e3
    if vals.size:
        vals[0, 0] = math.nan  # NaN payloads go through unchanged
    rows = L.encode_many(stamps, vals)
    k = len(names)
    for i in range(n):
        v = list(vals[i])
        p_ = v[:k] if pos else []
        v = v[k:] if pos else v
        ve = v[:k] if vel else []
        v = v[k:] if vel else v
        ef = v[:k] if eff else []
        st = int(stamps[i])
        ref = bytes(
            TS.serialize_cdr(_js(st, frame, names, p_, ve, ef), "sensor_msgs/msg/JointState")
        )
        ref2 = _mcap_ros2_bytes(
            "sensor_msgs/msg/JointState",
            {
                "header": {"stamp": {"sec": st // NS, "nanosec": st % NS}, "frame_id": frame},
                "name": list(names),
                "position": p_,
                "velocity": ve,
                "effort": ef,
            },
        )
        assert ref == ref2
        assert rows[i].tobytes() == ref
        assert L.encode(st, vals[i]) == ref
    # and back
    assert L.matches(rows).all()
    st2, vals2 = L.decode_many(rows)
    assert np.array_equal(st2, stamps)
    for j, name in enumerate(L.value_names):
        np.testing.assert_array_equal(vals2[name], vals[:, j])


def test_clock_bytes_match_rosbags():
    L = clock_layout()
    for st in STAMPS:
        ref = bytes(
            TS.serialize_cdr(
                T["rosgraph_msgs/msg/Clock"](
                    clock=T["builtin_interfaces/msg/Time"](sec=st // NS, nanosec=st % NS)
                ),
                "rosgraph_msgs/msg/Clock",
            )
        )
        assert L.encode(st) == ref


def test_parse_and_layout_of_roundtrip():
    names = ["rotary", "rotary_counts"]
    L = joint_state_layout(names, position=True, velocity=True, frame_id="f")
    data = L.encode(123, [1.5, 42.0, -3.0, math.nan])
    parsed = parse_fixed("sensor_msgs/msg/JointState", data)
    assert parsed["name"] == names and parsed["frame_id"] == "f"
    assert parsed["position"] == [1.5, 42.0] and parsed["effort"] == []
    assert layout_of("sensor_msgs/msg/JointState", parsed) == L


def test_matches_rejects_other_constant_bytes():
    a = joint_state_layout(["ab"], frame_id="pid")
    b = joint_state_layout(["cd"], frame_id="pid")  # same size, other name
    rows = b.encode_many(np.array([1, 2]), np.array([[1.0], [2.0]]))
    assert a.size == b.size
    assert not a.matches(rows).any()
    assert b.matches(rows).all()


@pytest.mark.parametrize(
    "data",
    [b"", b"\x00\x01\x00", b"\x07\x07\x00\x00" + b"\x00" * 8, b"\x00\x01\x00\x00" + b"\x00" * 6],
)
def test_parse_rejects_malformed(data):
    with pytest.raises(CdrDecodeError):
        parse_fixed("sensor_msgs/msg/FluidPressure", data)


def test_value_count_checked():
    with pytest.raises(ValueError, match="3 values"):
        fluid_pressure_layout("x").encode(0, [1.0, 2.0, 3.0])
