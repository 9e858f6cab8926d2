"""read_run: exact round trip of our files, rosbags-written bags, every bad-input error."""

import math
import shutil
import warnings

import numpy as np
import pytest
from pneu_msgs_py.bag import (
    BagError,
    EmptyBagError,
    MissingTopicError,
    NotMcapError,
    NotRos2Error,
    TruncatedBagError,
    TruncatedBagWarning,
    UnknownSchemaError,
)
from pneu_msgs_py.bag.reader import read_run
from pneu_msgs_py.bag.writer import BagWriter
from pneu_msgs_py.bench.bag import write_synthetic_run
from pneu_msgs_py.contract.topics import DEFAULT_STATE_FIELDS

T0 = 1_700_000_000_000_000_000
N = 3000
LIN_CS = "/pneu/linear/controller_state"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    p = tmp_path_factory.mktemp("bag") / "run.mcap"
    v = write_synthetic_run(
        p,
        N,
        seed=5,
        t0_ns=T0,
        diag_every=700,
        clock=True,
        switch_at=1234,
        command_delay_ns=3000,
        chunk_size=96 * 1024,
    )
    return p, v


def assert_same(a, b):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_round_trip_exact(run):
    p, v = run
    d = read_run(p)
    assert d.warnings == [] and d.skipped == {}
    assert d.metadata["pneu.run"] == {"seed": "5", "config_yaml": "synthetic: true\n"}
    st = v["stamp_ns"]
    for topic, key in (
        ("/pneu/pressure/cylinder_1", "p_c1"),
        ("/pneu/pressure/cylinder_2", "p_c2"),
        ("/pneu/pressure/motor_in", "p_m1"),
    ):
        ta = d[topic]
        assert ta.stamp_ns.dtype == np.int64
        assert_same(ta.stamp_ns, st)
        assert_same(ta.log_time_ns, st)
        assert_same(ta["fluid_pressure"], v[key])
        assert_same(ta["variance"], np.zeros(N))
        assert ta.frame_ids == (topic.rsplit("/", 1)[1],)
    lin = d["/pneu/linear/joint_state"]
    assert_same(lin["position"], v["x"])
    assert lin.names == ("linear",) and "velocity" not in lin
    rot = d["/pneu/rotary/joint_state"]
    assert_same(rot["rotary"], v["theta"])
    assert_same(rot["velocity"], v["omega"])
    assert_same(rot["rotary_counts"].astype(np.int64), v["counts"])
    assert np.isnan(rot["rotary_counts.velocity"]).all()
    for axis in ("linear", "rotary"):
        cmd = d[f"/pneu/{axis}/valve_command"]
        assert_same(cmd.stamp_ns, st)
        assert_same(cmd.log_time_ns, st + 3000)  # latency visible: log time vs answered stamp
        assert_same(cmd["effort"], v[f"u_{axis}"])
        assert_same(cmd[f"{axis}_valve"], v[f"u_{axis}"])
        cs = d[f"/pneu/{axis}/controller_state"]
        assert cs.names == DEFAULT_STATE_FIELDS
        for j, f in enumerate(DEFAULT_STATE_FIELDS):
            assert_same(cs[f], v[f"state_{axis}"][:, j])
    cs = d[LIN_CS]
    assert cs.frame_ids == ("eso_smc", "ladrc")
    fr = cs.frame_id
    assert (fr[:1234] == "eso_smc").all() and (fr[1234:] == "ladrc").all()
    clk = d["/clock"]
    assert_same(clk.stamp_ns, st)
    diag = d["/diagnostics"]
    assert len(diag) == math.ceil(N / 700)
    assert diag.objects[1][0].values == {"late_cycles": str(700 // 7)}
    assert_same(diag.stamp_ns, st[::700])
    assert d["/pneu/pressure/cylinder_1"].qos[0].reliability == "reliable"


def test_topic_selection_and_missing(run):
    p, _ = run
    d = read_run(p, [LIN_CS])
    assert list(d.topics) == [LIN_CS]
    with pytest.raises(MissingTopicError, match="/pneu/yaw/joint_state") as ei:
        read_run(p, ["/pneu/yaw/joint_state"])
    assert str(p) in str(ei.value) and "\n" not in str(ei.value)
    with pytest.raises(MissingTopicError):
        d["/pneu/rotary/joint_state"]


def test_agrees_with_mcap_ros2_decoder(run):
    """Independent decode of the same file gives the same arrays."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    p, _ = run
    d = read_run(p, [LIN_CS, "/pneu/rotary/joint_state"])
    ref = {LIN_CS: [], "/pneu/rotary/joint_state": []}
    with open(p, "rb") as f:
        r = make_reader(f, decoder_factories=[DecoderFactory()])
        for _s, ch, m, dec in r.iter_decoded_messages(topics=list(ref)):
            ref[ch.topic].append((m.log_time, list(dec.position), list(dec.velocity)))
    cs = d[LIN_CS]
    assert_same(cs.log_time_ns, [x[0] for x in ref[LIN_CS]])
    assert_same(np.column_stack([cs[f] for f in DEFAULT_STATE_FIELDS]), [x[1] for x in ref[LIN_CS]])
    rot = d["/pneu/rotary/joint_state"]
    assert_same(rot["velocity"], [x[2][0] for x in ref["/pneu/rotary/joint_state"]])


def _rosbags_bag(dirpath, v, n):
    """The same topics written by rosbags' rosbag2 Writer (mcap storage, version 9)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    T = ts.types
    NS = 1_000_000_000

    def hdr(t, frame=""):
        return T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=t // NS, nanosec=t % NS), frame_id=frame
        )

    def js(t, names, pos=(), vel=(), eff=(), frame=""):
        f = lambda a: np.array(a, dtype=np.float64)  # noqa: E731
        return T["sensor_msgs/msg/JointState"](
            header=hdr(t, frame), name=list(names), position=f(pos), velocity=f(vel), effort=f(eff)
        )

    FP, JS = "sensor_msgs/msg/FluidPressure", "sensor_msgs/msg/JointState"
    with Writer(dirpath, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = {
            "p1": w.add_connection("/pneu/pressure/cylinder_1", FP, typestore=ts),
            "lin": w.add_connection("/pneu/linear/joint_state", JS, typestore=ts),
            "rot": w.add_connection("/pneu/rotary/joint_state", JS, typestore=ts),
            "cmd": w.add_connection("/pneu/linear/valve_command", JS, typestore=ts),
            "cs": w.add_connection(LIN_CS, JS, typestore=ts),
            "log": w.add_connection("/rosout", "rcl_interfaces/msg/Log", typestore=ts),
        }
        for k in range(n):
            t = int(v["stamp_ns"][k])
            p1 = T[FP](header=hdr(t, "cylinder_1"), fluid_pressure=v["p_c1"][k], variance=0.0)
            w.write(c["p1"], t, ts.serialize_cdr(p1, FP))
            w.write(c["lin"], t, ts.serialize_cdr(js(t, ["linear"], [v["x"][k]]), JS))
            rot = js(
                t,
                ["rotary", "rotary_counts"],
                [v["theta"][k], float(v["counts"][k])],
                [v["omega"][k], math.nan],
            )
            w.write(c["rot"], t, ts.serialize_cdr(rot, JS))
            cmd = js(t, ["linear_valve"], eff=[v["u_linear"][k]])
            w.write(c["cmd"], t, ts.serialize_cdr(cmd, JS))
            algo = "eso_smc" if k < 1234 else "ladrc"
            cs = js(t, DEFAULT_STATE_FIELDS, v["state_linear"][k], frame=algo)
            w.write(c["cs"], t, ts.serialize_cdr(cs, JS))
            if k % 1000 == 0:
                log = T["rcl_interfaces/msg/Log"](
                    stamp=hdr(t).stamp, level=20, name="n", msg="m", file="f", function="g", line=1
                )
                w.write(c["log"], t, ts.serialize_cdr(log, "rcl_interfaces/msg/Log"))


def test_rosbags_rosbag2_directory_reads_to_same_arrays(run, tmp_path):
    p, v = run
    n = 1500
    bagdir = tmp_path / "rb2"
    _rosbags_bag(bagdir, v, n)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        d = read_run(bagdir)
    assert d.skipped == {"/rosout": "rcl_interfaces/msg/Log"}
    ours = read_run(p)
    for topic in (
        "/pneu/pressure/cylinder_1",
        "/pneu/linear/joint_state",
        "/pneu/rotary/joint_state",
        "/pneu/linear/valve_command",
        LIN_CS,
    ):
        a, b = d[topic], ours[topic]
        assert_same(a.stamp_ns, b.stamp_ns[:n])
        assert_same(a.log_time_ns, b.stamp_ns[:n])
        assert set(a.fields) == set(b.fields)
        for k in a.fields:
            assert_same(a[k], b[k][:n])
        assert a.frame_ids == b.frame_ids
    assert_same(d[LIN_CS].frame_id, ours[LIN_CS].frame_id[:n])
    with pytest.raises(UnknownSchemaError, match="/rosout"):
        read_run(bagdir, ["/rosout"])


def test_truncated_file_yields_complete_chunks(run, tmp_path):
    p, v = run
    data = p.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.warns(TruncatedBagWarning, match="truncated"):
        d = read_run(cut)
    n = len(d["/pneu/pressure/cylinder_1"])
    assert 0 < n < N
    assert_same(d["/pneu/pressure/cylinder_1"]["fluid_pressure"], v["p_c1"][:n])
    cs = d[LIN_CS]
    assert_same(cs["reference"], v["state_linear"][: len(cs), 1])
    assert any("truncated" in w for w in d.warnings)
    assert d.metadata["pneu.run"]["seed"] == "5"  # metadata written at start survives
    with pytest.raises(TruncatedBagError):
        read_run(cut, strict=True)


_CHILD = """
import os, signal, sys
from pneu_msgs_py.bag.writer import BagWriter
from pneu_msgs_py.contract.samples import SensorSample
w = BagWriter(sys.argv[1], chunk_size=8 * 1024, metadata={"pneu.run": {"seed": "1"}})
if sys.argv[2] == "term":  # what the runner does: close() on SIGTERM
    signal.signal(signal.SIGTERM, lambda *a: (w.close(), sys.exit(0)))
for k in range(2000):
    w.write_sample(SensorSample(k, k * 1_000_000, 1.0 * k, 2.0, 3.0, 0.0, 0.0, 0.0, k))
    if k == 1777:
        os.kill(os.getpid(), signal.SIGKILL if sys.argv[2] == "kill" else signal.SIGTERM)
    w.write_command("linear", k * 1_000_000, 5.0)
"""


def _child(path, how):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-c", _CHILD, str(path), how], check=False)


def test_hard_kill_leaves_complete_chunks_readable(tmp_path):
    p = tmp_path / "killed.mcap"
    assert _child(p, "kill").returncode == -9
    assert not p.exists()  # a killed writer leaves the clearly named partial file only
    with pytest.raises(NotMcapError, match=r"killed\.mcap\.partial is there"):
        read_run(p)
    with pytest.warns(TruncatedBagWarning):
        d = read_run(p.with_name("killed.mcap.partial"))
    n = len(d["/pneu/pressure/cylinder_1"])
    assert 1000 < n <= 1778
    assert_same(d["/pneu/pressure/cylinder_1"]["fluid_pressure"], np.arange(n, dtype=float))
    assert len(d["/pneu/linear/valve_command"]) == n
    assert d.metadata["pneu.run"] == {"seed": "1"}


def test_sigterm_then_close_finalises_the_file(tmp_path):
    from mcap.reader import make_reader

    p = tmp_path / "term.mcap"
    assert _child(p, "term").returncode == 0
    with open(p, "rb") as f:
        stats = make_reader(f).get_summary().statistics
    counts = sorted(stats.channel_message_counts.values())
    assert counts[-1] == 1778 and counts[0] == 1777  # the command of cycle 1777 never came
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        d = read_run(p)
    assert_same(d["/pneu/pressure/motor_in"].stamp_ns, np.arange(1778) * 1_000_000)


@pytest.mark.parametrize("size", [4, 12, 30])
def test_truncated_before_first_chunk(run, tmp_path, size):
    cut = tmp_path / "tiny.mcap"
    cut.write_bytes(run[0].read_bytes()[:size])
    with pytest.raises(TruncatedBagError) as ei:
        read_run(cut)
    assert str(cut) in str(ei.value)


def test_not_mcap(tmp_path):
    p = tmp_path / "x.mcap"
    p.write_text("hello world, not a bag\n")
    with pytest.raises(NotMcapError, match="not an MCAP file"):
        read_run(p)
    with pytest.raises(NotMcapError, match="no such file"):
        read_run(tmp_path / "nope.mcap")
    (tmp_path / "emptydir").mkdir()
    with pytest.raises(NotMcapError, match="neither metadata.yaml"):
        read_run(tmp_path / "emptydir")


def test_not_ros2_profile(tmp_path):
    from mcap.writer import Writer

    p = tmp_path / "json.mcap"
    with open(p, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="test")
        sid = w.register_schema("x", "jsonschema", b"{}")
        cid = w.register_channel("/a", "json", sid)
        w.add_message(cid, 0, b"{}", 0)
        w.finish()
    with pytest.raises(NotRos2Error, match="profile"):
        read_run(p)


def test_empty_bag(tmp_path):
    p = tmp_path / "empty.mcap"
    BagWriter(p).close()
    with pytest.raises(EmptyBagError, match="no messages"):
        read_run(p)


def test_sqlite_rosbag2_dir_is_not_mcap(tmp_path):
    d = tmp_path / "bag"
    d.mkdir()
    (d / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: sqlite3\n"
        "  relative_file_paths: [bag_0.db3]\n"
    )
    with pytest.raises(NotMcapError, match="sqlite3"):
        read_run(d)


def test_errors_are_bag_errors_with_one_line():
    for cls in (
        NotMcapError,
        NotRos2Error,
        TruncatedBagError,
        MissingTopicError,
        UnknownSchemaError,
        EmptyBagError,
    ):
        e = cls("/x/y.mcap", "the problem")
        assert isinstance(e, BagError)
        assert str(e) == "/x/y.mcap: the problem"


def test_a_run_directory_whose_rosbag2_recorder_was_killed_reads_its_bag(run, tmp_path):
    """``out/bag`` without metadata.yaml (``ros2 bag record`` SIGKILLed): ``out`` still stands
    for it, with the note."""
    (tmp_path / "out" / "bag").mkdir(parents=True)
    shutil.copy(run[0], tmp_path / "out" / "bag" / "bag_0.mcap")
    with pytest.warns(UserWarning, match="no metadata.yaml"):
        data = read_run(tmp_path / "out", [LIN_CS])
    assert len(data[LIN_CS]) == N


def test_bag_directory_of_our_file(run, tmp_path):
    """A rosbag2-style directory holding our .mcap (no metadata.yaml) is read with a note."""
    d = tmp_path / "dir"
    d.mkdir()
    shutil.copy(run[0], d / "run_0.mcap")
    with pytest.warns(UserWarning, match="no metadata.yaml"):
        data = read_run(d, [LIN_CS])
    assert len(data[LIN_CS]) == N
