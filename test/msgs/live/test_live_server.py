"""The live server speaks Foxglove's WebSocket protocol with the bag's topics, schemas and bytes.

A WebSocket client written from the protocol (``_foxglove_client.py``, the
``websockets`` package) connects to a :class:`LiveServer`, reads the
advertised channels, subscribes and receives the messages of a few control
cycles; the same cycles go through :class:`BagWriter` into an MCAP file read
back with the ``mcap`` reader: same topics, schema names and texts, log times
and payload bytes. Payloads also decode with rosbags' Jazzy typestore to the
values written.
"""

from __future__ import annotations

import importlib.util
import math
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("foxglove")
pytest.importorskip("websockets")

from mcap.reader import make_reader
from pneu_msgs_py.bag import BagWriter, DiagStatus
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import DEFAULT_STATE_FIELDS, TOPIC_BY_NAME
from pneu_msgs_py.live import LiveError, LiveServer, Tee
from pneu_msgs_py.params.core import ParamError
from rosbags.typesys import Stores, get_typestore

_spec = importlib.util.spec_from_file_location(
    "_foxglove_client", Path(__file__).resolve().with_name("_foxglove_client.py")
)
fox = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fox)

TS = get_typestore(Stores.ROS2_JAZZY)
N_STATE = len(DEFAULT_STATE_FIELDS)


def _sample(k: int) -> SensorSample:
    return SensorSample(
        k=k,
        stamp_ns=k * 1_000_000,
        p_c1=3.0e5 + k,
        p_c2=2.5e5 - k,
        p_m1=1.2e5 + 0.5 * k,
        x=0.001 * k,
        theta=0.01 * k,
        omega=80.0 + k,
        counts=40 * k,
    )


def _answers(k: int) -> list:
    state = [float(k * 10 + i) for i in range(N_STATE)]
    state[7] = math.nan  # an algorithm without z3
    return [
        ("linear", 5.0 + 0.01 * k, state, "eso_smc"),
        ("rotary", 6.0 - 0.01 * k, [v + 0.5 for v in state], "pid"),
    ]


DIAG = [DiagStatus(2, "pneu_runner: safety linear watchdog", "no command", "twin", {"age_ms": "6"})]
CYCLES = 12


def _write(sink) -> None:
    for k in range(CYCLES):
        sink.write_cycle(_sample(k), _answers(k))
        if k == 5:
            sink.write_diagnostics(_sample(k).stamp_ns, DIAG)


@pytest.fixture
def server():
    srv = LiveServer(port=0, pace="fast")
    yield srv
    srv.close()


def _subscribe_all(srv: LiveServer) -> fox.FoxgloveClient:
    client = fox.FoxgloveClient(srv.url)
    client.wait_for_channels(srv.topics)
    client.subscribe(srv.topics)
    end = time.monotonic() + 120  # the server applies the subscription asynchronously
    while set(srv.subscribed()) != set(srv.topics) and time.monotonic() < end:
        time.sleep(0.01)
    assert set(srv.subscribed()) == set(srv.topics)
    return client


def test_live_messages_are_the_bag_records(server, tmp_path):
    client = _subscribe_all(server)
    assert client.server_info["op"] == "serverInfo"
    assert server.url == f"ws://127.0.0.1:{server.port}" and server.port > 0
    bag_path = tmp_path / "run.mcap"
    with BagWriter(bag_path) as bag:
        _write(Tee(bag, server))
    server.close()  # the client sees the connection close after the last message
    got = client.messages()
    client.close()

    with open(bag_path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        bag = [
            (ch.topic, m.log_time, m.publish_time, m.data) for _, ch, m in reader.iter_messages()
        ]
    # channels: same topics, types and schema texts as the bag's
    schemas = {ch.topic: summary.schemas[ch.schema_id] for ch in summary.channels.values()}
    for topic, schema in schemas.items():
        adv = client.channels[topic]
        assert (adv["encoding"], adv["schemaEncoding"]) == ("cdr", "ros2msg")
        assert adv["schemaName"] == schema.name == TOPIC_BY_NAME[topic].ros_type
        assert adv["schema"] == schema.data.decode()
    assert set(client.channels) == set(schemas)  # both axes, sensors, diagnostics
    # messages: the bag's records, byte for byte, at the same log time, in cycle order
    assert sorted(got) == sorted((t, lt, data) for t, lt, _, data in bag)
    assert all(lt == pt for _, lt, pt, _ in bag)
    assert len(got) == CYCLES * 9 + 1


def test_live_payloads_decode_to_the_values_written(server):
    client = _subscribe_all(server)
    server.write_cycle(_sample(3), _answers(3))
    server.write_diagnostics(7, DIAG)
    msgs = client.messages(until_closed=False, count=10)
    by = {}
    for topic, log_time, payload in msgs:
        ros_type = client.channels[topic]["schemaName"]
        by[topic] = (log_time, TS.deserialize_cdr(payload, ros_type))
    s = _sample(3)
    t, m = by["/pneu/linear/joint_state"]
    assert t == s.stamp_ns and list(m.name) == ["linear"] and m.position.tolist() == [s.x]
    _, m = by["/pneu/rotary/joint_state"]
    assert list(m.name) == ["rotary", "rotary_counts"]
    assert m.position.tolist() == [s.theta, float(s.counts)] and m.velocity[0] == s.omega
    _, m = by["/pneu/pressure/cylinder_2"]
    assert m.fluid_pressure == s.p_c2 and m.header.frame_id == "cylinder_2"
    _, m = by["/pneu/rotary/valve_command"]
    assert list(m.name) == ["rotary_valve"] and m.effort.tolist() == [6.0 - 0.03]
    _, m = by["/pneu/linear/controller_state"]
    assert tuple(m.name) == DEFAULT_STATE_FIELDS and m.header.frame_id == "eso_smc"
    assert m.position[1] == 31.0 and math.isnan(m.position[7])
    t, m = by["/diagnostics"]
    assert t == 7 and m.status[0].name == DIAG[0].name and m.status[0].level == 2
    assert [(kv.key, kv.value) for kv in m.status[0].values] == [("age_ms", "6")]
    client.close()


def test_realtime_pacing_sleeps_until_each_stamp_is_due():
    now = [10_000_000_000]
    slept = []

    def sleep(s):
        slept.append(s)
        now[0] += int(round(s * 1e9))

    with LiveServer(port=0, pace="realtime", clock_ns=lambda: now[0], sleep=sleep) as srv:
        for k in range(10):  # the writer itself takes no time: every 2 ms it is 2 ms ahead
            srv.write_cycle(_sample(k), ())
        assert slept == pytest.approx([0.002, 0.002, 0.002, 0.002])
        now[0] += 50_000_000  # a writer 50 ms behind is not held back
        srv.write_cycle(_sample(10), ())
        assert len(slept) == 4
    with LiveServer(port=0, pace="fast", clock_ns=lambda: now[0], sleep=sleep) as srv:
        for k in range(10):
            srv.write_cycle(_sample(k), ())
    assert len(slept) == 4


def test_only_the_active_axes_and_no_state_for_open_loop():
    with LiveServer(port=0, axes=("rotary",), controller_state=False) as srv:
        assert srv.topics == (
            "/pneu/pressure/cylinder_1",
            "/pneu/pressure/cylinder_2",
            "/pneu/pressure/motor_in",
            "/pneu/linear/joint_state",
            "/pneu/rotary/joint_state",
            "/pneu/rotary/valve_command",
            "/diagnostics",
        )
        with pytest.raises(ValueError, match="axis: 'linear' refused"):
            srv.write_command("linear", 0, 5.0)


def test_port_in_use_is_one_line_naming_it(server):
    with pytest.raises(LiveError, match=rf"--live: {server.port} refused; .*in use.*--live 0"):
        LiveServer(port=server.port)


@pytest.mark.parametrize("host", ["nohost.invalid", "999.1.1.1", "192.0.2.1"])
def test_a_host_not_of_this_machine_is_refused_naming_live_host(host):
    """An unknown name, an invalid address, an address of another machine: the line names
    --live-host (it said 'live view: cannot serve on ...')."""
    with pytest.raises(LiveError, match=rf"^--live-host: '{host}' refused; allowed: a name"):
        LiveServer(port=0, host=host)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"port": 70000}, "live.port: 70000 refused"),
        ({"port": -1}, "live.port: -1 refused"),
        ({"pace": "slow"}, "live.pace: 'slow' refused; allowed: realtime | fast"),
        ({"axes": ("linear", "z")}, "live.axes"),
    ],
)
def test_bad_options_are_refused_before_serving(kwargs, match):
    with pytest.raises(ParamError, match=match):
        LiveServer(**kwargs)


def test_without_foxglove_sdk_one_line_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "foxglove", None)  # import foxglove -> ImportError
    with pytest.raises(LiveError) as err:
        LiveServer(port=0)
    assert "\n" not in str(err.value)
    assert "needs the foxglove-sdk package: python3 -m pip install" in str(err.value)
