"""ros2 launch, for real: every executable under each executor, complete bags, Ctrl-C.

Runs on a machine with ROS 2 Jazzy and this workspace built and sourced
(``colcon build`` + ``source install/setup.bash``); skipped elsewhere. Each
case starts ``ros2 launch pneu_sim sim.launch.py`` as a user would (a
subprocess, its own process group), waits for it to end or stops it with
SIGINT like Ctrl-C, and reads the bag back: ``ros2 bag info`` must open it
and count every message, ``pneu analyze`` (``analyze``) must read it, and in
lockstep the numbers must be the in-process runner's.

Set ``ROS_DOMAIN_ID`` (and ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) to
keep these runs off a shared network.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from pneu_control.analysis.metrics import WindowSpec
from pneu_control.analysis.run_analysis import analyze
from pneu_control.experiment import session
from pneu_control.experiment.runner import run
from pneu_msgs_py.bag.reader import read_run
from pneu_msgs_py.params.paths import config_file

pytest.importorskip("rclpy")  # rclpy-dependent: the rest (ros2, the workspace) in conftest
pytestmark = pytest.mark.ros

EXECUTORS = ["events", "single"]
SENSORS = (
    "/pneu/pressure/cylinder_1",
    "/pneu/pressure/cylinder_2",
    "/pneu/pressure/motor_in",
    "/pneu/linear/joint_state",
    "/pneu/rotary/joint_state",
)


def _launch(args: list[str], timeout_s: float, sigint_after_s: float | None = None):
    """``ros2 launch pneu_sim sim.launch.py ARGS``; returns (returncode, output)."""
    cmd = ["ros2", "launch", "--noninteractive", "pneu_sim", "sim.launch.py", *args]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True
    )
    try:
        if sigint_after_s is not None:
            time.sleep(sigint_after_s)
            # Ctrl-C: every process gets one SIGINT (in a terminal from the terminal, launch
            # then forwards nothing; here --noninteractive launch forwards it to each child)
            os.kill(proc.pid, signal.SIGINT)
        out, _ = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
        pytest.fail(f"launch did not end in {timeout_s} s:\n{out[-3000:]}")
    return proc.returncode, out


def _bag_info(path: Path) -> dict[str, int]:
    """Per-topic message counts as ``ros2 bag info`` prints them."""
    res = subprocess.run(["ros2", "bag", "info", str(path)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    counts = {}
    for line in res.stdout.splitlines():
        if "Topic:" in line and "Count:" in line:
            topic = line.split("Topic:")[1].split("|")[0].strip()
            counts[topic] = int(line.split("Count:")[1].split("|")[0])
    return counts


def _sim_report(out: str) -> tuple[int, dict[str, int]]:
    """(samples, counters) from the sim's last line: ``finished after N samples; {...}``."""
    import ast

    line = next(ln for ln in reversed(out.splitlines()) if "finished after" in ln)
    n = int(line.split("finished after")[1].split()[0])
    report = ast.literal_eval(line.split("samples; ", 1)[1])
    return n, {k: int(v) for k, v in report.items() if str(v).isdigit()}


def _no_tracebacks(out: str) -> None:
    assert "Traceback" not in out, out[-4000:]
    assert "process has died" not in out, out[-4000:]
    assert "escalating to 'SIGTERM'" not in out, out[-4000:]


@pytest.mark.parametrize("executor", EXECUTORS)
def test_lockstep_graph_records_every_sample_and_equals_the_runner(executor, tmp_path):
    out = tmp_path / "run"
    rc, log = _launch(
        [f"executor:={executor}", "axes:=both", "duration:=2", "seed:=4", f"out:={out}"], 300
    )
    assert rc == 0, log[-3000:]
    _no_tracebacks(log)
    assert f"executor: {executor}" in log
    counts = _bag_info(out / "run.mcap")
    for topic in (*SENSORS, "/clock"):
        assert counts[topic] == 2000, (topic, counts)
    for axis in ("linear", "rotary"):
        assert counts[f"/pneu/{axis}/valve_command"] >= 2000
        assert counts[f"/pneu/{axis}/controller_state"] == 2000
    spec = session.build_spec(
        axes=("linear", "rotary"),
        duration_s=2.0,
        seed=4,
        controllers_file=config_file("controllers_retuned.yaml"),  # the sim launch's default
        window_start_s=1.0,
    )
    ref = run(spec).metrics
    got = analyze(out / "run.mcap", window=WindowSpec(kind="fixed", t_start_s=1.0))
    for axis in ("linear", "rotary"):
        assert got.metrics[axis].n_samples == ref[axis].n_samples > 0
        assert got.metrics[axis].e_max == ref[axis].e_max
        assert got.metrics[axis].rmse == ref[axis].rmse


@pytest.mark.parametrize("deployment", ["nodes", "hosted"])
@pytest.mark.parametrize("executor", EXECUTORS)
def test_realtime_graph_records_with_rosbag2_and_the_run_metadata(executor, deployment, tmp_path):
    out = tmp_path / "run"
    rc, log = _launch(
        [
            f"executor:={executor}",
            f"deployment:={deployment}",
            "mode:=realtime",
            "axes:=both",
            "duration:=5",
            f"out:={out}",
        ],
        300,
    )
    assert rc == 0, log[-3000:]
    _no_tracebacks(log)
    counts = _bag_info(out / "bag")
    samples, c = _sim_report(log)
    published = samples - c["skipped_ticks"]  # ticks the loop was too late to publish
    assert samples == 5000 and published > 0
    for topic in SENSORS:
        assert counts[topic] == published, (topic, counts)  # every sample published was recorded
    for axis in ("linear", "rotary"):
        # every command the sim applied was recorded (and at most one per sample + the last word)
        applied = samples - c[f"missed.{axis}"]
        assert applied <= counts[f"/pneu/{axis}/valve_command"] <= published + 1
        # 100 Hz: every 10th tick the controller answered (a loaded machine makes it miss some)
        assert (
            counts[f"/pneu/{axis}/controller_state"] >= counts[f"/pneu/{axis}/valve_command"] // 20
        )
    data = read_run(out / "bag")
    assert "pneu.run" in data.metadata  # the logger's sidecar
    res = analyze(out)
    assert res.config["axes"] == ["linear", "rotary"] and res.config["mode"] == "realtime"


@pytest.mark.parametrize("executor", EXECUTORS)
def test_ctrl_c_ends_every_node_cleanly_with_a_complete_bag(executor, tmp_path):
    out = tmp_path / "run"
    rc, log = _launch(
        [f"executor:={executor}", "mode:=realtime", "duration:=0", f"out:={out}"],
        120,
        sigint_after_s=25.0,
    )
    _no_tracebacks(log)
    assert rc == 0, log[-3000:]
    assert (out / "bag" / "metadata.yaml").is_file()  # rosbag2 finished the bag
    assert (out / "bag" / "pneu_metadata.json").is_file()  # the logger finished its part
    counts = _bag_info(out / "bag")
    assert counts["/pneu/linear/joint_state"] > 0
    for name in ("sim_node", "linear_controller", "rotary_controller", "logger", "recorder"):
        assert f"[{name}-" in log and "process has finished cleanly" in log


@pytest.mark.parametrize("deployment", ["nodes", "hosted"])
@pytest.mark.parametrize("executor", EXECUTORS)
def test_rig_launch_on_the_simulated_card_runs_and_stops_cleanly(executor, deployment, tmp_path):
    """The driver node (or the controller manager with the driver's loop) on ``backend:=sim``."""
    out = tmp_path / "rig"
    rc, log = _launch_rig(
        [
            f"executor:={executor}",
            f"deployment:={deployment}",
            f"backend:=sim:card={tmp_path / 'card'}",
            "gains:=retuned",
            f"out:={out}",
        ],
        sigint_after_s=30.0,
    )
    _no_tracebacks(log)
    assert rc == 0, log[-3000:]
    assert f"executor: {executor}" in log
    counts = _bag_info(out / "bag")
    n = counts["/pneu/linear/joint_state"]
    assert n > 1000
    # every sample on every sensor topic, between the first and the last sample the recorder
    # had on all five (before: its subscriptions are matched one by one as discovery finds
    # them; after: the Ctrl-C reaches the recorder and the driver at different times)
    data = read_run(out / "bag")
    stamps = {t: data[t].stamp_ns for t in SENSORS}
    lo, hi = max(int(s.min()) for s in stamps.values()), min(int(s.max()) for s in stamps.values())
    inner = {t: s[(s >= lo) & (s <= hi)] for t, s in stamps.items()}
    for topic in SENSORS:
        assert np.array_equal(inner[topic], inner[SENSORS[0]]), (topic, counts)
        assert len(inner[topic]) > 1000, (topic, counts)
    assert counts["/pneu/linear/valve_command"] > 0  # (how many: a busy machine loses ticks)
    from pneu_sim.daq_sim.card import read_card_state

    card = read_card_state(tmp_path / "card")
    assert (card.ao0_v, card.ao1_v) == (5.0, 5.0)  # valves safe at the end
    assert not card.do_level and card.do_edges > 0  # the heartbeat ran, and ended low


def _launch_rig(args: list[str], sigint_after_s: float):
    cmd = ["ros2", "launch", "--noninteractive", "pneu_driver", "rig.launch.py", *args]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True
    )
    time.sleep(sigint_after_s)
    os.kill(proc.pid, signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=90)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
        pytest.fail(f"rig launch did not end after Ctrl-C:\n{out[-3000:]}")
    return proc.returncode, out
