"""SROS2 for real: a secured graph takes no valve command from a process without its credentials.

On the Jazzy build (rmw_cyclonedds_cpp with the DDS-Security plugins): ``pneu security``
makes the keystore; its policy is valid against sros2's schema and its signed
permissions grant the linear valve command to the linear controller's enclave (and the
hosted manager's and the exciter's) only. Then ``ros2 launch pneu_sim sim.launch.py
keystore:=...`` runs in lockstep beside a rogue process that answers every sample it
sees with 10 V and sprays 10 V commands for every stamp of the run: secured, the run is
the in-process runner's bit for bit (the rogue moved nothing) and another enclave's
credentials cannot even create the publisher; unsecured, the same rogue changes the run
(the test can fail).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pneu_control.experiment import session
from pneu_control.experiment.runner import run
from pneu_msgs_py.bag.reader import read_run
from pneu_msgs_py.contract.security import enclave
from pneu_msgs_py.params.paths import config_file

pytest.importorskip("rclpy")  # rclpy-dependent: the rest (ros2, the workspace) in conftest
pytestmark = pytest.mark.ros("sros2")

_UNSECURED = ("ROS_SECURITY_ENABLE", "ROS_SECURITY_STRATEGY", "ROS_SECURITY_KEYSTORE")

_ROGUE = r"""
import sys, rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

rclpy.init()
node = Node(sys.argv[1] if len(sys.argv) > 1 else "rogue")
try:
    pub = node.create_publisher(JointState, "/pneu/linear/valve_command", 10)
except Exception as err:
    print("publisher refused:", type(err).__name__, flush=True)
    sys.exit(0)
print("publisher created", flush=True)

def cmd(stamp_ns):
    m = JointState()
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(stamp_ns, 10**9)
    m.name = ["linear_valve"]
    m.effort = [10.0]
    return m

be = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
node.create_subscription(JointState, "/pneu/linear/joint_state",
    lambda s: pub.publish(cmd(s.header.stamp.sec * 10**9 + s.header.stamp.nanosec)), be)
k = [0]
def spray():
    for _ in range(50):
        pub.publish(cmd(k[0] * 10**6))
        k[0] = (k[0] + 1) % 3000
node.create_timer(0.001, spray)
rclpy.spin(node)
"""


def _env(secure: bool, keystore: Path | None = None, enclave_path: str | None = None) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in _UNSECURED}
    env.pop("ROS_SECURITY_ENCLAVE_OVERRIDE", None)
    if secure:
        env.update(
            ROS_SECURITY_ENABLE="true",
            ROS_SECURITY_STRATEGY="Enforce",
            ROS_SECURITY_KEYSTORE=str(keystore),
        )
        if enclave_path:
            env["ROS_SECURITY_ENCLAVE_OVERRIDE"] = enclave_path
    return env


@pytest.fixture(scope="module")
def keystore(tmp_path_factory):
    keys = tmp_path_factory.mktemp("sros2") / "keys"
    res = subprocess.run(
        [sys.executable, "-m", "pneu_control.cli.main", "security", str(keys), "--operator", "op"],
        capture_output=True,
        text=True,
        env=_env(False),
    )
    assert res.returncode == 0, res.stderr
    return keys


def test_the_keystore_holds_a_valid_policy_and_permissions_as_the_topic_table_says(keystore):
    from lxml import etree
    from sros2.policy import get_policy_schema

    schema = etree.XMLSchema(etree.parse(str(get_policy_schema("policy.xsd"))))
    schema.assertValid(etree.parse(str(keystore / "pneu_policy.xml")))
    topic = "rt/pneu/linear/valve_command"
    for role in ("io", "linear_controller", "rotary_controller", "logger", "task_runner"):
        perm = etree.parse(str(keystore / "enclaves" / "pneu" / role / "permissions.xml"))
        published = {t.text for t in perm.iterfind(".//allow_rule/publish/topics/topic")}
        subscribed = {t.text for t in perm.iterfind(".//allow_rule/subscribe/topics/topic")}
        assert (topic in published) == (role == "linear_controller"), role
        assert (topic in subscribed) == (role in ("io", "logger")), role
        ids = {d.text for d in perm.iterfind(".//domains/id")}
        assert ids == {os.environ.get("ROS_DOMAIN_ID", "0")}
        assert (perm.getroot().find(".//grant/default").text) == "DENY"


def _run_with_rogue(tmp_path: Path, keystore: Path | None, rogue_enclave: str | None = None):
    out = tmp_path / "run"
    args = ["axes:=linear", "duration:=2", "seed:=4", f"out:={out}"]
    args += [f"keystore:={keystore}"] if keystore else []
    rogue = subprocess.Popen(
        [sys.executable, "-c", _ROGUE],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=_env(rogue_enclave is not None, keystore, rogue_enclave),
    )
    try:
        line = rogue.stdout.readline()
        proc = subprocess.run(
            ["ros2", "launch", "--noninteractive", "pneu_sim", "sim.launch.py", *args],
            capture_output=True,
            text=True,
            timeout=600,
            env=_env(False),  # keystore:= secures the graph by itself
        )
    finally:
        rogue.send_signal(signal.SIGINT)
        try:
            rogue.wait(timeout=30)
        except subprocess.TimeoutExpired:
            rogue.kill()
    return proc, line, out


def _runner_x() -> np.ndarray:
    spec = session.build_spec(
        axes=("linear",),
        duration_s=2.0,
        seed=4,
        controllers_file=config_file("controllers_retuned.yaml"),  # the sim launch's default
    )
    return np.asarray(run(spec).samples["x"])


def _bag_x(out: Path) -> np.ndarray:
    data = read_run(out / "run.mcap")
    return np.asarray(data["/pneu/linear/joint_state"]["position"]).reshape(-1)


def test_a_secured_graph_takes_no_command_from_an_unauthenticated_process(tmp_path, keystore):
    proc, line, out = _run_with_rogue(tmp_path, keystore)
    assert "publisher created" in line  # the rogue ran, unsecured
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    x = _bag_x(out)
    want = _runner_x()
    assert len(x) == len(want) == 2000
    assert np.array_equal(x, want)  # bit for bit: the rogue's 10 V never reached the sim


def test_another_enclaves_credentials_cannot_publish_a_valve_command(tmp_path, keystore):
    env = _env(True, keystore, enclave("rotary_controller"))
    res = subprocess.run(
        # named as the enclave's node, so the node itself may start; its publisher may not
        [sys.executable, "-c", _ROGUE, "rotary_controller"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert "publisher refused" in res.stdout, res.stdout + res.stderr


def test_unsecured_the_same_rogue_moves_the_valve(tmp_path):
    """The control: without a keystore the rogue's commands reach the sim."""
    _proc, line, out = _run_with_rogue(tmp_path, None)
    assert "publisher created" in line
    x = _bag_x(out) if (out / "run.mcap").exists() else np.array([])
    assert len(x) != 2000 or not np.array_equal(x, _runner_x())


@pytest.mark.parametrize("deployment", ["nodes", "hosted"])
def test_a_secured_realtime_graph_is_recorded_by_rosbag2(tmp_path, keystore, deployment):
    """Realtime runs are recorded by ``ros2 bag record`` in the recorder's enclave: its
    permissions must cover what rosbag2 itself publishes (before: it exited at start and the
    bag held no message)."""
    out = tmp_path / "run"
    proc = subprocess.run(
        [
            "ros2",
            "launch",
            "--noninteractive",
            "pneu_sim",
            "sim.launch.py",
            "mode:=realtime",
            "axes:=both",
            "duration:=3",
            f"deployment:={deployment}",
            f"keystore:={keystore}",
            f"out:={out}",
        ],
        capture_output=True,
        text=True,
        timeout=600,
        env=_env(False),
    )
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0 and "process has died" not in log, log[-3000:]
    data = read_run(out / "bag")
    for topic in ("/pneu/linear/joint_state", "/pneu/linear/valve_command"):
        assert len(data[topic]) > 1000, (topic, log[-2000:])
