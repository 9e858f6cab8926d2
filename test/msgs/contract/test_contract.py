"""Topic table, QoS profiles and their rosbag2 text, conversions against rosbags' Jazzy types."""

import math

import numpy as np
import pytest
import yaml
from pneu_msgs_py.bag.schemas import MSG_DEFINITIONS, TYPE_HASHES
from pneu_msgs_py.contract import qos as Q
from pneu_msgs_py.contract.cdr import fluid_pressure_layout, joint_state_layout
from pneu_msgs_py.contract.convert import (
    DiagStatus,
    command_from_msg,
    command_to_typestore,
    controller_state_from_msg,
    controller_state_to_typestore,
    diag_statuses_from_msg,
    diagnostics_to_typestore,
    fill_controller_state,
    sample_from_msgs,
    sample_to_typestore,
    stamp_to_ns,
)
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import (
    DEFAULT_STATE_FIELDS,
    TOPIC_BY_NAME,
    TOPICS,
    markdown_table,
    qos_for,
    sub_qos_for,
)
from rosbags.rosbag2.metadata import parse_qos
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_JAZZY)

# What rosbag2 Jazzy (yaml-cpp YAML::Dump of the Rosbag2QoS node, metadata v9) writes for
# rclcpp::SensorDataQoS as reported by the graph (infinite durations = RMW_DURATION_INFINITE).
SENSOR_DATA_ROSBAG2 = """- history: keep_last
  depth: 5
  reliability: best_effort
  durability: volatile
  deadline:
    sec: 9223372036
    nsec: 854775807
  lifespan:
    sec: 9223372036
    nsec: 854775807
  liveliness: automatic
  liveliness_lease_duration:
    sec: 9223372036
    nsec: 854775807
  avoid_ros_namespace_conventions: false"""


def test_topic_table_is_complete_and_standard():
    assert len(TOPICS) == 13 == len(TOPIC_BY_NAME)
    for t in TOPICS:
        assert t.name.startswith("/")
        assert t.ros_type in MSG_DEFINITIONS  # common_interfaces types we can write
        assert t.ros_type in TYPE_HASHES
        assert t.kind in (
            "pressure",
            "joint_state",
            "valve_command",
            "controller_state",
            "diagnostics",
            "clock",
            "trajectory",
            "task_progress",
        )
    table = markdown_table()
    for t in TOPICS:
        assert f"`{t.name}`" in table
    assert table.count("\n") == len(TOPICS) + 1


def test_type_hashes_match_rosbags():
    for t, h in TYPE_HASHES.items():
        assert TS.hash_rihs01(t) == h


def test_offered_qos_yaml_is_rosbag2_text():
    assert Q.offered_qos_yaml([Q.SENSOR_DATA]) == SENSOR_DATA_ROSBAG2
    two = Q.offered_qos_yaml([Q.SENSOR_DATA, Q.COMMAND_PUB])
    assert two.startswith(SENSOR_DATA_ROSBAG2 + "\n- history: keep_last\n  depth: 1\n")
    # an independent parser (rosbags' rosbag2 metadata reader) reads the same policies
    for p in (Q.SENSOR_DATA, Q.LOCKSTEP, Q.COMMAND_PUB, Q.STATE, Q.CLOCK):
        (r,) = parse_qos(Q.offered_qos_yaml([p]))
        assert r.history.name.lower() == p.history and r.depth == p.depth
        assert r.reliability.name.lower() == p.reliability
        assert r.durability.name.lower() == p.durability
        assert (r.deadline.sec, r.deadline.nsec) == Q.DURATION_INFINITE
        assert Q.parse_offered_qos_yaml(Q.offered_qos_yaml([p])) == [p]
    assert yaml.safe_load(SENSOR_DATA_ROSBAG2)[0] == Q.SENSOR_DATA.to_dict()


def test_parse_v8_integer_coded_qos():
    v8 = SENSOR_DATA_ROSBAG2.replace("keep_last", "1").replace("best_effort", "2")
    v8 = v8.replace("volatile", "2").replace("automatic", "1")
    assert Q.parse_offered_qos_yaml(v8) == [Q.SENSOR_DATA]


def test_qos_choices_are_compatible_pairs():
    # realtime: commands offered reliable depth 1, driver takes them best effort depth 1
    assert Q.compatible(Q.COMMAND_PUB, Q.COMMAND_SUB_REALTIME)
    assert Q.compatible(Q.COMMAND_PUB, Q.STATE)  # a reliable logger still connects
    # the trap the table avoids: best-effort publisher, reliable subscriber
    assert not Q.compatible(Q.SENSOR_DATA, Q.LOCKSTEP)
    assert Q.compatible(Q.SENSOR_DATA, Q.SENSOR_DATA)
    # /clock offered reliable serves rclpy's TimeSource (best effort, depth 1)
    assert Q.compatible(Q.CLOCK, Q.QosProfile(depth=1, reliability="best_effort"))
    for t in TOPICS:
        lock = qos_for(t.name, "lockstep")
        assert lock.reliability == "reliable"  # lockstep loses nothing
        rt = qos_for(t.name, "realtime")
        sub = sub_qos_for(t.name, "realtime")
        assert Q.compatible(rt, sub)  # the graph's own consumers connect
        assert Q.compatible(rt, Q.QosProfile(depth=100, reliability="reliable"))  # recorders too
        if t.kind in ("pressure", "joint_state"):
            assert rt == Q.SENSOR_PUB and sub == Q.SENSOR_DATA
    with pytest.raises(ValueError, match="qos mode"):
        qos_for("/clock", "fast")
    with pytest.raises(ValueError, match="reliability"):
        Q.QosProfile(reliability="sometimes")


class FakeRclpyQos:
    """Stands in for rclpy.qos: enum classes with get_from_short_key."""

    class _E:
        def __init__(self, key):
            self.key = key

        @classmethod
        def get_from_short_key(cls, key):
            return (cls.__name__, key)

    class HistoryPolicy(_E): ...

    class ReliabilityPolicy(_E): ...

    class DurabilityPolicy(_E): ...

    class QoSProfile:
        def __init__(self, **kw):
            self.kw = kw


def test_to_rclpy_maps_short_keys():
    q = Q.to_rclpy(Q.SENSOR_DATA, FakeRclpyQos)
    assert q.kw["depth"] == 5
    assert q.kw["reliability"] == ("ReliabilityPolicy", "best_effort")
    assert q.kw["history"] == ("HistoryPolicy", "keep_last")


SAMPLE = SensorSample(
    k=7,
    stamp_ns=1_700_000_000_123_456_789,
    p_c1=3.1e5,
    p_c2=2.2e5,
    p_m1=4.4e5,
    x=-0.0125,
    theta=12.5,
    omega=-83.7,
    counts=2**40 + 3,
)


def test_sample_round_trip_through_typestore_messages_and_cdr():
    msgs = sample_to_typestore(SAMPLE, variance=4.0)
    back = sample_from_msgs(
        7,
        *(
            msgs[t]
            for t in (
                "/pneu/pressure/cylinder_1",
                "/pneu/pressure/cylinder_2",
                "/pneu/pressure/motor_in",
                "/pneu/linear/joint_state",
                "/pneu/rotary/joint_state",
            )
        ),
    )
    assert back == SAMPLE
    # the objects serialise to the very bytes the bulk writer produces
    fp = msgs["/pneu/pressure/cylinder_2"]
    assert bytes(TS.serialize_cdr(fp, fp.__msgtype__)) == fluid_pressure_layout(
        "cylinder_2"
    ).encode(SAMPLE.stamp_ns, [SAMPLE.p_c2, 4.0])
    rot = msgs["/pneu/rotary/joint_state"]
    L = joint_state_layout(["rotary", "rotary_counts"], position=True, velocity=True)
    ref = L.encode(SAMPLE.stamp_ns, [SAMPLE.theta, float(SAMPLE.counts), SAMPLE.omega, math.nan])
    assert bytes(TS.serialize_cdr(rot, rot.__msgtype__)) == ref


def test_command_and_controller_state_round_trip():
    m = command_to_typestore("rotary", 123_000_000_001, 7.25)
    assert list(m.name) == ["rotary_valve"] and len(m.position) == 0
    assert command_from_msg(m, "rotary") == (123_000_000_001, 7.25)
    with pytest.raises(ValueError, match="linear_valve"):
        command_from_msg(m, "linear")
    vals = np.arange(len(DEFAULT_STATE_FIELDS), dtype=float)
    cs = controller_state_to_typestore(5, DEFAULT_STATE_FIELDS, vals, "ladrc")
    st, algo, d = controller_state_from_msg(cs)
    assert (st, algo) == (5, "ladrc")
    assert list(d) == list(DEFAULT_STATE_FIELDS) and d["u_sat"] == vals[-1]
    with pytest.raises(ValueError, match="3 values"):
        fill_controller_state(cs, 0, DEFAULT_STATE_FIELDS, [1.0, 2.0, 3.0], "pid")


def test_diagnostics_round_trip():
    sts = [
        DiagStatus(2, "pneu/driver: watchdog", "tripped", "PCI-6221", {"trips": "3", "ms": "2.5"}),
        DiagStatus(0, "pneu/sim", ""),
    ]
    m = diagnostics_to_typestore(2_000_000_001, sts)
    assert stamp_to_ns(m.header.stamp) == 2_000_000_001
    raw = bytes(TS.serialize_cdr(m, m.__msgtype__))
    back = diag_statuses_from_msg(TS.deserialize_cdr(raw, m.__msgtype__))
    assert back == sts
    with pytest.raises(ValueError, match="level"):
        DiagStatus(4, "x")
    with pytest.raises(TypeError, match="must be str"):
        DiagStatus(0, "x", values={"n": 3})


def test_sample_to_values_matches_the_writer_layout():
    from pneu_msgs_py.contract.convert import fill_joint_state, sample_to_values, typestore_messages

    vals = sample_to_values(SAMPLE)
    assert vals["/pneu/pressure/motor_in"] == ("motor_in", [], [SAMPLE.p_m1], [])
    frame, names, pos, vel = vals["/pneu/rotary/joint_state"]
    ts = typestore_messages()
    msg = sample_to_typestore(SAMPLE)["/pneu/rotary/joint_state"]
    fill_joint_state(msg, SAMPLE.stamp_ns, names, pos, vel, frame_id=frame, array=np.asarray)
    L = joint_state_layout(["rotary", "rotary_counts"], position=True, velocity=True)
    assert bytes(ts.serialize_cdr(msg, msg.__msgtype__)) == L.encode(SAMPLE.stamp_ns, pos + vel)
