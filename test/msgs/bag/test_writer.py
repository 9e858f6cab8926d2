"""BagWriter files decode completely and exactly with mcap_ros2 and rosbags."""

import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from pneu_msgs_py.bag.errors import BagWriteError
from pneu_msgs_py.bag.writer import BagWriter
from pneu_msgs_py.contract.convert import DiagStatus
from pneu_msgs_py.contract.qos import parse_offered_qos_yaml
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import DEFAULT_STATE_FIELDS, qos_for
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_JAZZY)
NS = 1_000_000_000
T0 = 1_700_000_000_000_000_000  # epoch-like stamps (beyond 2**53 ns) must stay exact


def make_run(path, n=2500, chunk_size=64 * 1024, switch_at=None, qos="lockstep", **kw):
    """Write a synthetic run; return what was written, for comparison."""
    rng = np.random.default_rng(3)
    truth = {
        "samples": [],
        "cmd": {"linear": [], "rotary": []},
        "state": {"linear": [], "rotary": []},
    }
    with BagWriter(
        path,
        metadata={"pneu.run": {"seed": "3", "config_yaml": "plant: {}\n"}},
        chunk_size=chunk_size,
        qos=qos,
        **kw,
    ) as w:
        for k in range(n):
            t = T0 + k * 1_000_000
            s = SensorSample(
                k,
                t,
                *(rng.normal(3e5, 1e3, 3)),
                rng.normal() * 1e-2,
                k * 1e-3,
                rng.normal(),
                k * 7 - 1000,
            )
            w.write_sample(s)
            truth["samples"].append(s)
            for axis in ("linear", "rotary"):
                u = float(rng.uniform(0, 10))
                w.write_command(axis, t, u, log_time_ns=t + 5000)
                truth["cmd"][axis].append((t, u, t + 5000))
                vals = rng.normal(size=len(DEFAULT_STATE_FIELDS))
                vals[5] = math.nan
                algo = "eso_smc" if switch_at is None or k < switch_at else "ladrc"
                w.write_controller_state(axis, t, vals, algo)
                truth["state"][axis].append((t, algo, vals))
            if k % 1000 == 0:
                w.write_diagnostics(
                    t, [DiagStatus(1, "pneu/sim", "late", "twin", {"late": str(k)})]
                )
            if k % 997 == 0:
                w.write_clock(t)
    return truth


def test_mcap_ros2_decodes_everything_exactly(tmp_path):
    p = tmp_path / "run.mcap"
    truth = make_run(p, switch_at=1234)
    reader = make_reader(open(p, "rb"), decoder_factories=[DecoderFactory()], validate_crcs=True)
    summary = reader.get_summary()
    counts = {
        c.topic: summary.statistics.channel_message_counts[i] for i, c in summary.channels.items()
    }
    assert counts["/pneu/pressure/cylinder_1"] == 2500
    assert counts["/pneu/rotary/controller_state"] == 2500
    assert counts["/diagnostics"] == 3
    assert counts["/clock"] == 3
    assert summary.statistics.chunk_count > 5
    got = {}
    last_t = -1
    for schema, channel, msg, dec in reader.iter_decoded_messages(log_time_order=False):
        assert msg.log_time >= last_t  # the file itself is in log-time order
        last_t = msg.log_time
        assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
        got.setdefault(channel.topic, []).append((msg, dec))
    s = truth["samples"]
    cyl2 = got["/pneu/pressure/cylinder_2"]
    assert [m.log_time for m, _ in cyl2] == [x.stamp_ns for x in s]
    assert [m.publish_time for m, _ in cyl2] == [x.stamp_ns for x in s]
    assert [d.fluid_pressure for _, d in cyl2] == [x.p_c2 for x in s]
    assert {d.header.frame_id for _, d in cyl2} == {"cylinder_2"}
    rot = got["/pneu/rotary/joint_state"]
    assert [d.header.stamp.sec * NS + d.header.stamp.nanosec for _, d in rot] == [
        x.stamp_ns for x in s
    ]
    assert next(list(d.name) for _, d in rot) == ["rotary", "rotary_counts"]
    assert [d.position[1] for _, d in rot] == [float(x.counts) for x in s]
    assert [d.velocity[0] for _, d in rot] == [x.omega for x in s]
    cmd = got["/pneu/rotary/valve_command"]
    assert [
        (d.header.stamp.sec * NS + d.header.stamp.nanosec, d.effort[0], m.log_time) for m, d in cmd
    ] == truth["cmd"]["rotary"]
    st = got["/pneu/linear/controller_state"]
    assert [d.header.frame_id for _, d in st] == [a for _, a, _ in truth["state"]["linear"]]
    np.testing.assert_array_equal(
        np.array([d.position for _, d in st]), np.array([v for _, _, v in truth["state"]["linear"]])
    )
    assert list(st[0][1].name) == list(DEFAULT_STATE_FIELDS)
    diag = got["/diagnostics"][1][1]
    assert diag.status[0].name == "pneu/sim" and diag.status[0].values[0].value == "1000"
    assert next(iter(reader.iter_metadata())).metadata == {
        "seed": "3",
        "config_yaml": "plant: {}\n",
    }


def test_rosbags_anyreader_decodes_everything(tmp_path):
    p = tmp_path / "run.mcap"
    truth = make_run(p, n=1500, qos="realtime")
    with AnyReader([p], default_typestore=TS) as r:
        conns = {c.topic: c for c in r.connections}
        assert conns["/pneu/linear/joint_state"].msgtype == "sensor_msgs/msg/JointState"
        assert conns["/pneu/pressure/motor_in"].msgcount == 1500
        xs = []
        for c, t, raw in r.messages(connections=[conns["/pneu/linear/joint_state"]]):
            m = r.deserialize(raw, c.msgtype)
            xs.append((t, m.position[0]))
        assert xs == [(s.stamp_ns, s.x) for s in truth["samples"]]
        n = sum(1 for c, t, raw in r.messages() if r.deserialize(raw, c.msgtype) is not None)
        assert n == 1500 * 9 + 2 + 2
        q = conns["/pneu/pressure/cylinder_1"].ext.offered_qos_profiles[0]
        assert q.reliability.name == "RELIABLE" and q.depth == 100  # realtime sensor publisher


def test_schema_texts_are_jazzy_definitions(tmp_path):
    p = tmp_path / "run.mcap"
    make_run(p, n=50)
    summary = make_reader(open(p, "rb")).get_summary()
    assert len(summary.schemas) == 4
    for sch in summary.schemas.values():
        assert sch.encoding == "ros2msg"
        assert sch.data.decode() == TS.generate_msgdef(sch.name, ros_version=2)[0]


def test_channel_qos_metadata_is_rosbag2_yaml(tmp_path):
    p = tmp_path / "run.mcap"
    make_run(p, n=20, qos="realtime")
    summary = make_reader(open(p, "rb")).get_summary()
    for ch in summary.channels.values():
        text = ch.metadata["offered_qos_profiles"]
        assert parse_offered_qos_yaml(text) == [qos_for(ch.topic, "realtime")]
        assert not text.endswith("\n")


def test_writer_errors(tmp_path):
    with pytest.raises(BagWriteError, match="compression"):
        BagWriter(tmp_path / "a.mcap", compression="bz2")
    with pytest.raises(BagWriteError, match="cannot open"):
        BagWriter(tmp_path / "no" / "dir" / "a.mcap")
    w = BagWriter(tmp_path / "b.mcap")
    with pytest.raises(BagWriteError, match="values must be str"):
        w.add_metadata("pneu.run", {"seed": 3})
    with pytest.raises(ValueError, match="axis"):
        w.write_command("yaw", 0, 5.0)
    with pytest.raises(ValueError, match="11 fields"):
        w.write_controller_state("linear", 0, [1.0, 2.0], "pid")
    with pytest.raises(BagWriteError, match="negative time"):
        w.write_serialized("/x", "std_msgs/msg/Empty", b"\x00\x01\x00\x00", -1, 0)
    w.write_command("linear", -5, 5.0)
    with pytest.raises(BagWriteError, match="negative time"):
        w.flush()
    w.close()
    w.close()  # idempotent
    with pytest.raises(BagWriteError, match="closed"):
        w.write_command("linear", 0, 5.0)
    assert Path(w.path).stat().st_size > 0


def test_empty_writer_gives_valid_file(tmp_path):
    p = tmp_path / "e.mcap"
    BagWriter(p).close()
    r = make_reader(open(p, "rb"))
    assert r.get_summary().statistics.message_count == 0
    assert list(r.iter_messages()) == []


def test_rosbag2_metadata_record_and_type_hashes(tmp_path):
    """What `ros2 bag info/play` read from a loose file besides the summary."""
    import yaml

    p = tmp_path / "run.mcap"
    make_run(p, n=300, qos="realtime")
    with open(p, "rb") as f:
        r = make_reader(f)
        summary = r.get_summary()
        recs = {m.name: m.metadata for m in r.iter_metadata()}
    info = yaml.safe_load(recs["rosbag2"]["serialized_metadata"])
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["relative_file_paths"] == ["run.mcap"]
    st = summary.statistics
    assert info["message_count"] == st.message_count
    assert info["starting_time"]["nanoseconds_since_epoch"] == st.message_start_time
    by_topic = {c.topic: c for c in summary.channels.values()}
    for t in info["topics_with_message_count"]:
        tm = t["topic_metadata"]
        ch = by_topic[tm["name"]]
        assert t["message_count"] == st.channel_message_counts[ch.id]
        assert tm["type"] == summary.schemas[ch.schema_id].name
        assert tm["offered_qos_profiles"] == [qos_for(tm["name"], "realtime").to_dict()]
        assert ch.metadata["topic_type_hash"] == TS.hash_rihs01(tm["type"])
        assert tm["type_description_hash"] == ch.metadata["topic_type_hash"]
