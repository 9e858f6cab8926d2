"""``pneu run --live`` and ``pneu sim --live``: a Foxglove WebSocket client receives the run.

The command runs as a user runs it (a subprocess, ``--live 0`` = any free
port, the ``ws://`` URL read from its stderr, ``--live-wait`` so it starts
once the client subscribed); the client (``test/msgs/live/_foxglove_client.py``,
written from the protocol with the ``websockets`` package) subscribes to every
advertised topic and reads until the server closes at the end of the run.
``pneu run``: every message received is a record of the run's bag, byte for
byte at the same log time, on the same topics. ``pneu sim``: the messages
decode (rosbags' typestore) to the rows of ``sim.csv``.
"""

from __future__ import annotations

import csv
import importlib.util
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("foxglove")
pytest.importorskip("websockets")

from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore

_path = Path(__file__).resolve().parents[2] / "msgs" / "live" / "_foxglove_client.py"
_spec = importlib.util.spec_from_file_location("_foxglove_client", _path)
fox = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fox)

TS = get_typestore(Stores.ROS2_JAZZY)
SENSORS = [
    "/pneu/pressure/cylinder_1",
    "/pneu/pressure/cylinder_2",
    "/pneu/pressure/motor_in",
    "/pneu/linear/joint_state",
    "/pneu/rotary/joint_state",
]
_URL = re.compile(r"live view: (ws://\S+) ")


def _start(tmp_path: Path, args: list[str]) -> tuple[subprocess.Popen, str, Path]:
    """Start ``pneu ARGS``; return the process, the URL it prints and its stderr file."""
    err_path = tmp_path / "stderr.txt"
    with open(tmp_path / "stdout.txt", "w") as out, open(err_path, "w") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "pneu_control.cli.main", *args],
            stdout=out,
            stderr=err,
            env=dict(os.environ),
        )
    deadline = time.monotonic() + 300  # imports and numba's cache on a loaded machine
    while time.monotonic() < deadline:
        m = _URL.search(err_path.read_text())
        if m:
            return proc, m.group(1), err_path
        if proc.poll() is not None:
            pytest.fail(f"pneu exited {proc.returncode}: {err_path.read_text()}")
        time.sleep(0.05)
    proc.kill()
    pytest.fail("no 'live view: ws://...' line")


def _receive(url: str, topics: list[str]) -> tuple[dict, list]:
    client = fox.FoxgloveClient(url)
    try:
        channels = client.wait_for_channels(topics)
        client.subscribe(list(channels))
        return dict(channels), client.messages()  # until the run ends and the server closes
    finally:
        client.close()


def test_pneu_run_live_serves_the_bag_records(tmp_path):
    out = tmp_path / "run"
    args = ["run", "--axis", "linear", "--duration", "0.3", "--out", str(out)]
    args += ["--fault", "controller_silent:axis=linear,start_s=0.1,duration_s=0.05"]
    args += ["--live", "0", "--live-pace", "realtime", "--live-wait", "300"]
    proc, url, err = _start(tmp_path, args)
    assert re.fullmatch(r"ws://127\.0\.0\.1:\d+", url) and not url.endswith(":0")
    expected = [
        *SENSORS,
        "/pneu/linear/valve_command",
        "/pneu/linear/controller_state",
        "/diagnostics",
    ]
    channels, got = _receive(url, expected)
    assert proc.wait(timeout=300) == 3, err.read_text()  # exit 3: the silenced axis went safe
    assert set(channels) == set(expected)  # the active axis only, as in the bag
    assert "foxglove_linear.json" in err.read_text()  # the layout to import is named

    with open(out / "run.mcap", "rb") as fh:
        reader = make_reader(fh)
        bag, schemas = set(), {}
        for schema, ch, m in reader.iter_messages():
            bag.add((ch.topic, m.log_time, m.data))
            schemas[ch.topic] = (schema.name, schema.data.decode())
    assert {t for t, _, _ in bag} == set(expected)
    for topic, ch in channels.items():  # same types and schema texts as the bag
        assert (ch["schemaName"], ch["schema"]) == schemas[topic]
    received = set(got)
    assert received <= set(bag), "a live message that is not a bag record"
    assert {t for t, _, _ in received} == set(expected)  # incl. the watchdog's diagnostics
    last = max(lt for _, lt, _ in bag)
    for topic in expected[:-1]:  # paced at real time, the viewer kept up to the last cycle
        assert (topic, last) in {(t, lt) for t, lt, _ in received}, topic


def test_pneu_sim_live_serves_the_open_loop_samples(tmp_path):
    out = tmp_path / "sim"
    args = ["sim", "--duration", "0.3", "--linear-voltage", "6.5", "--rotary-voltage", "7"]
    args += ["--out", str(out), "--no-plot"]
    args += ["--live", "0", "--live-pace", "fast", "--live-wait", "300"]
    proc, url, err = _start(tmp_path, args)
    expected = [*SENSORS, "/pneu/linear/valve_command", "/pneu/rotary/valve_command"]
    channels, got = _receive(url, expected)
    assert proc.wait(timeout=300) == 0, err.read_text()
    assert set(channels) == {*expected, "/diagnostics"}  # open loop: no controller state

    with open(out / "sim.csv", newline="") as fh:
        rows = {round(float(r["t_s"]) * 1e9): r for r in csv.DictReader(fh)}
    seen = set()
    for topic, log_time, payload in got:
        msg = TS.deserialize_cdr(payload, channels[topic]["schemaName"])
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        assert stamp == log_time
        row = rows[stamp]
        if topic == "/pneu/linear/joint_state":
            assert msg.position[0] == float(row["x_m"])
        elif topic == "/pneu/rotary/joint_state":
            assert msg.velocity[0] == float(row["omega_rad_s"])
            assert msg.position[1] == float(row["counts"])
        elif topic == "/pneu/pressure/cylinder_1":
            assert msg.fluid_pressure == float(row["p_c1_Pa"])
        elif topic.endswith("valve_command"):
            assert msg.effort[0] == {"linear": 6.5, "rotary": 7.0}[msg.name[0][: -len("_valve")]]
        seen.add(topic)
    assert seen == set(expected)
