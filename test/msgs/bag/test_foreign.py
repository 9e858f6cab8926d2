"""Files pneu did not write: irregular interleaving, odd layouts, no index, no chunks.

Each file is written with the mcap library (payloads from rosbags' serializer)
and read by read_run; the result must equal what mcap_ros2's decoder gives,
message by message.
"""

import math

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer
from mcap_ros2.decoder import DecoderFactory
from pneu_msgs_py.bag.reader import iter_run, read_run
from pneu_msgs_py.bag.schemas import MSG_DEFINITIONS
from pneu_msgs_py.contract.qos import SENSOR_DATA, offered_qos_yaml
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_JAZZY)
T = TS.types
NS = 1_000_000_000
JS, FP = "sensor_msgs/msg/JointState", "sensor_msgs/msg/FluidPressure"


def _hdr(t, frame=""):
    return T["std_msgs/msg/Header"](
        stamp=T["builtin_interfaces/msg/Time"](sec=t // NS, nanosec=t % NS), frame_id=frame
    )


def _js(t, names, pos=(), vel=(), eff=(), frame=""):
    def f(a):
        return np.array(a, dtype=np.float64)

    return T[JS](
        header=_hdr(t, frame), name=list(names), position=f(pos), velocity=f(vel), effort=f(eff)
    )


def _messages(seed=11, n=1500):
    """(topic, type, log_time, payload) in log-time order, irregular rates and layouts."""
    rng = np.random.default_rng(seed)
    out = []
    t = 10**18
    for k in range(n):
        t += int(rng.integers(1, 3_000_000))
        p = T[FP](
            header=_hdr(t, f"s{k % 3}"), fluid_pressure=float(rng.normal(1e5, 10)), variance=0.5
        )
        out.append(("/p", FP, t, p))
        if rng.random() < 0.6:  # joints appear, vanish, change order
            names = ["a", "b"] if rng.random() < 0.7 else ["b"]
            pos = rng.normal(size=len(names))
            vel = rng.normal(size=len(names)) if rng.random() < 0.5 else []
            out.append(("/js", JS, t + 1, _js(t, names, pos, vel)))
        if rng.random() < 0.3:  # malformed for bulk decoding: 2 positions for 1 name
            out.append(("/odd", JS, t + 2, _js(t, ["c"], [1.0 * k, 2.0 * k])))
        if rng.random() < 0.2:
            c = T["rosgraph_msgs/msg/Clock"](clock=_hdr(t).stamp)
            out.append(("/clock", "rosgraph_msgs/msg/Clock", t + 3, c))
    return out


def _write(path, msgs, **kw):
    with open(path, "wb") as f:
        w = Writer(f, **kw)
        w.start(profile="ros2", library="test")
        sids, cids = {}, {}
        for topic, ros_type, _t, _m in msgs:
            if ros_type not in sids:
                sids[ros_type] = w.register_schema(
                    ros_type, "ros2msg", MSG_DEFINITIONS[ros_type].encode()
                )
            if topic not in cids:
                cids[topic] = w.register_channel(
                    topic,
                    "cdr",
                    sids[ros_type],
                    {"offered_qos_profiles": offered_qos_yaml([SENSOR_DATA])},
                )
        for i, (topic, ros_type, t, m) in enumerate(msgs):
            w.add_message(cids[topic], t, bytes(TS.serialize_cdr(m, ros_type)), t - 7, sequence=i)
        w.finish()


def _reference(path):
    ref = {}
    with open(path, "rb") as f:
        for _s, ch, m, d in make_reader(
            f, decoder_factories=[DecoderFactory()]
        ).iter_decoded_messages():
            ref.setdefault(ch.topic, []).append((m.log_time, m.publish_time, d))
    return ref


def _stamp(d):
    s = d.header.stamp if hasattr(d, "header") else d.clock
    return s.sec * NS + s.nanosec


KINDS = {
    "indexed": dict(chunk_size=4096, compression=CompressionType.ZSTD),
    "lz4": dict(chunk_size=20000, compression=CompressionType.LZ4),
    "no_index": dict(chunk_size=4096, index_types=IndexType.NONE),
    "unchunked": dict(use_chunking=False),
}


@pytest.mark.parametrize("kind", list(KINDS))
def test_foreign_file_matches_mcap_ros2(tmp_path, kind):
    p = tmp_path / f"{kind}.mcap"
    _write(p, _messages(), **KINDS[kind])
    ref = _reference(p)
    d = read_run(p)
    assert set(d.topics) == set(ref)
    for topic, items in ref.items():
        ta = d[topic]
        assert len(ta) == len(items)
        np.testing.assert_array_equal(ta.log_time_ns, [x[0] for x in items])
        np.testing.assert_array_equal(ta.publish_time_ns, [x[1] for x in items])
        np.testing.assert_array_equal(ta.stamp_ns, [_stamp(x[2]) for x in items])
        if topic == "/p":
            np.testing.assert_array_equal(
                ta["fluid_pressure"], [x[2].fluid_pressure for x in items]
            )
            assert list(ta.frame_id) == [x[2].header.frame_id for x in items]
        if topic == "/js":
            for j in ("a", "b"):
                for key in ("position", "velocity"):
                    exp = []
                    for x in items:
                        names, arr = list(x[2].name), list(getattr(x[2], key))
                        exp.append(arr[names.index(j)] if j in names and arr else math.nan)
                    np.testing.assert_array_equal(ta[f"{j}.{key}"], exp)
            assert ta.names == ("a", "b")
        if topic == "/odd":  # not bulk-decodable: the per-message path keeps what fits
            np.testing.assert_array_equal(ta["c.position"], [x[2].position[0] for x in items])


def test_iter_run_batches_equal_read_run(tmp_path):
    p = tmp_path / "a.mcap"
    _write(p, _messages(n=3000), **KINDS["indexed"])
    whole = read_run(p)
    batches = list(iter_run(p, batch_chunks=3))
    assert len(batches) > 3
    for topic, ta in whole.topics.items():
        parts = [b.topics[topic] for b in batches if topic in b.topics]
        np.testing.assert_array_equal(
            np.concatenate([x.log_time_ns for x in parts]), ta.log_time_ns
        )
        for key in ta.fields:
            if ta.names and "." not in key:
                continue  # aliases ("position" = first joint) may name another joint per batch
            got = np.concatenate([x[key] if key in x else np.full(len(x), np.nan) for x in parts])
            np.testing.assert_array_equal(got, ta[key])
