"""``ros2 launch pneu_control task.launch.py``, for real: a task over ROS equals ``pneu task``.

Runs on a machine with ROS 2 Jazzy and this workspace built and sourced; skipped
elsewhere. Lockstep under each executor: the task report's segments (status, start, end,
errors) and the bag's joints and valve commands are the in-process run's, bit for bit;
the trajectories are on ``/pneu/joint_trajectory`` as ``ros2 bag info`` counts them.
Ctrl-C mid-task (once the task runner says its second segment started): every process
ends cleanly, the report says ``interrupted``, the bag is complete. ``~/abort`` through
``ros2 service call``: the e-stop takes both valves safe and the task ends ``aborted``.
Both in lockstep: what they check does not depend on the machine's load (a realtime
graph on a loaded 2-core machine may trip the command watchdog: issue 19).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess

import numpy as np
import pytest
from pneu_control.task.session import execute_task, prepare
from pneu_msgs_py.bag.reader import read_run
from pneu_msgs_py.params.paths import config_file

pytest.importorskip("rclpy")  # rclpy-dependent: the rest (ros2, the workspace) in conftest
pytestmark = pytest.mark.ros

TASK = "tasks/coupling_insert_lock.yaml"


def _launch(args: list[str], timeout_s: float, when: str | None = None, act=None):
    """``ros2 launch pneu_control task.launch.py ARGS``; ``act(proc)`` once a line of the
    output contains ``when`` (an event of the run, not a guess of its timing)."""
    import threading

    cmd = ["ros2", "launch", "--noninteractive", "pneu_control", "task.launch.py", *args]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True
    )
    lines: list[str] = []
    seen = threading.Event()

    def read() -> None:
        for line in proc.stdout:
            lines.append(line)
            if when is not None and when in line:
                seen.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        if act is not None:
            assert seen.wait(timeout_s), "".join(lines)[-3000:]
            act(proc)
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        reader.join(10)
        pytest.fail(f"launch did not end in {timeout_s} s:\n{''.join(lines)[-3000:]}")
    reader.join(30)
    return proc.returncode, "".join(lines)


def _clean(out: str) -> None:
    assert "Traceback" not in out, out[-4000:]
    assert "process has died" not in out, out[-4000:]
    assert "escalating to 'SIGTERM'" not in out, out[-4000:]


@pytest.mark.parametrize("executor", ["events", "single"])
def test_a_lockstep_task_over_ros_equals_pneu_task(executor, tmp_path):
    task = config_file(TASK)
    out = tmp_path / "ros"
    rc, log = _launch([f"task:={task}", f"executor:={executor}", f"out:={out}"], 600)
    assert rc == 0, log[-3000:]
    _clean(log)
    _, result, rep = execute_task(prepare(task), tmp_path / "inproc")
    ros = json.loads((out / "task_report.json").read_text())
    assert ros["outcome"] == rep["outcome"] == "completed"
    for a, b in zip(ros["segments"], rep["segments"], strict=True):
        for key in ("status", "t_start_s", "t_end_s", "error_mm", "error_deg"):
            assert a[key] == b[key], (key, a, b)
    run = read_run(out / "run.mcap")
    m = len(result.t)  # the in-process run stops before the sample the task ended at
    assert np.array_equal(run["/pneu/linear/joint_state"]["position"][:m], result.samples["x"])
    assert np.array_equal(run["/pneu/rotary/joint_state"]["rotary"][:m], result.samples["theta"])
    for axis in ("linear", "rotary"):
        assert np.array_equal(
            run[f"/pneu/{axis}/valve_command"]["effort"][:m], result.axes[axis]["u"]
        )
    info = subprocess.run(
        ["ros2", "bag", "info", str(out / "run.mcap")], capture_output=True, text=True
    )
    assert info.returncode == 0, info.stderr
    assert "/pneu/joint_trajectory" in info.stdout and "/pneu/task/progress" in info.stdout


def test_ctrl_c_mid_task_ends_every_process_cleanly_and_reports_interrupted(tmp_path):
    task = config_file("tasks/screw_in.yaml")  # ~14 s of motion: still running at the signal
    out = tmp_path / "rt"

    def ctrl_c(proc):
        os.kill(proc.pid, signal.SIGINT)  # Ctrl-C while the screw segment runs

    rc, log = _launch([f"task:={task}", f"out:={out}"], 600, "start: segment 2", ctrl_c)
    assert rc in (0, 130), log[-3000:]  # launch's own exit status on a SIGINT
    _clean(log)
    rep = json.loads((out / "task_report.json").read_text())
    assert rep["outcome"] == "interrupted"
    assert any(s["status"] == "interrupted" for s in rep["segments"])
    run = read_run(out / "run.mcap")  # finished, not partial
    started = next(s["t_start_s"] for s in rep["segments"] if s["status"] == "interrupted")
    assert len(run["/pneu/linear/joint_state"]) >= round(started * 1000)  # up to the signal


def test_abort_service_takes_both_valves_safe_and_ends_the_task(tmp_path):
    task = config_file("tasks/screw_in.yaml")
    out = tmp_path / "abort"

    def abort(proc):
        res = subprocess.run(
            ["ros2", "service", "call", "/task_runner/abort", "std_srvs/srv/Trigger"],
            capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert "success=True" in res.stdout, res.stdout + res.stderr

    rc, log = _launch([f"task:={task}", f"out:={out}"], 600, "start: segment 2", abort)
    assert rc == 0, log[-3000:]
    _clean(log)
    rep = json.loads((out / "task_report.json").read_text())
    assert rep["outcome"] == "aborted" and rep["reason"] == "service ~/abort"
    from mcap_ros2.reader import read_ros2_messages

    messages = [
        st.message
        for m in read_ros2_messages(str(out / "run.mcap"), topics=["/diagnostics"])
        for st in m.ros_msg.status
    ]
    assert any("task aborted: service ~/abort" in msg for msg in messages), messages[-10:]
