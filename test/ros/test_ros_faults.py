"""Faults on the ROS side, for real: processes killed, hung and started twice, on Jazzy.

Runs on a machine with ROS 2 Jazzy and this workspace built and sourced (``colcon
build`` + ``source install/setup.bash``); skipped elsewhere. Every case starts the
graph as a user would -- ``ros2 launch pneu_sim sim.launch.py mode:=realtime`` or
``ros2 launch pneu_driver rig.launch.py backend:=sim:card=FILE`` (the driver on the
simulated card), its own process group -- and acts on events, never on a guess of
their timing: a line of the launch's output (``process started with pid [N]``, a
controller's "held safe" / "no samples" line) or a status on ``/diagnostics``, which
this test reads with a node of its own (the sim's clock in its 1 Hz status, the
supervisor's transitions stamped with their sample). What happened is then read from
the bag the graph recorded, and from the simulated card for the rig.

1. A controller process SIGKILLed mid-run (``deployment:=nodes``): the supervisor holds
   its last command ``late_hold_ms``, then its valve at 5 V, and latches the axis within
   ``watchdog_ms`` (+ the tick that sees it) of its last command; the other axis goes
   on, ``/diagnostics`` in the bag says so. A controller restarted with ``ros2 run``
   while the axis is latched commands nothing the valve takes until the operator's
   ``~/reset``, then rejoins without a jump: its first own command within twice the
   controller's own p99 step of the held 5 V (a wound-up controller puts 1.5-5 V
   there: test/control/nodes/test_supervisor_hold.py). Hosted, the controllers are
   threads of the sim's process: killing "a controller process" is killing the sim
   (case 3). Its analogue there is the operator's e-stop and reset: both axes held,
   then both rejoin without a jump.
2. The recorder SIGKILLed (rosbag2 in realtime, the pneu logger in lockstep): the run
   stops (the launch says which process ended and how; every other process ends
   cleanly); what was recorded reads back -- rosbag2's ``bag_0.mcap`` without its
   ``metadata.yaml`` through ``ros2 bag reindex`` + ``ros2 bag info``, ``pneu
   recover`` and the pneu reader; the logger's ``run.mcap.partial`` through ``pneu
   recover``, every sample from the first on.
3. The sim (or the driver on the simulated card) hung (SIGSTOP), then killed: the
   controllers command nothing and say so (ERROR in ``/diagnostics``, one line "no
   samples ... not commanding"); the kill ends the run with a line saying so; the
   card keeps its last outputs and the heartbeat stops (docs/rig.md).
4. ``ros2 param set`` on a controller during a realtime run, two busy processes
   beside it: no supervisor trip, the new value taken at the next sample.
5. The graph started twice on one domain: both sims e-stop, said in one line each, and
   their controllers hold 5 V; a second rig on the same card is refused (one line naming
   the first driver's pid), its launch ends by itself and it never writes the card (the
   first rig's e-stop, and the samples of it the second launch's controllers answered
   meanwhile, are reported: docs/ros2.md).

The separate-process deployment's cases run under the default executor (events): with
``single`` it misses a third of its ticks on two cores (docs/ros2.md), so every case
would be a watchdog trip; the hosted e-stop case runs under both.

Set ``ROS_DOMAIN_ID`` (and ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) to keep these
runs off a shared network.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from pneu_driver.safety import load_safety_params
from pneu_msgs_py.bag.reader import read_run
from pneu_msgs_py.params.paths import config_file

pytest.importorskip("rclpy")  # rclpy-dependent: the rest (ros2, the workspace) in conftest
pytestmark = pytest.mark.ros

WATCHDOG_NS = round(load_safety_params(None).watchdog_ms * 1e6)
T_NS = 1_000_000
GAINS = config_file("controllers_retuned.yaml")  # the sim launch's default (gains:=retuned)
EVENT_S = 120.0  # the longest any event may take to come (start-up on a busy machine)
# Every graph as launched: its nodes set their own priorities (DESIGN §10; the loop at
# SCHED_FIFO 50, the rest of its process and the controllers at 49), no chrt by hand.


# -- processes ------------------------------------------------------------------------
class Proc:
    """A command in its own process group, its output read line by line as it comes."""

    def __init__(self, cmd: list[str], name: str):
        self.name = name
        self.p = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            start_new_session=True,
        )  # fmt: skip
        self.lines: list[str] = []
        self.cv = threading.Condition()
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        for line in self.p.stdout:
            with self.cv:
                self.lines.append(line)
                self.cv.notify_all()
        with self.cv:
            self.cv.notify_all()

    @property
    def out(self) -> str:
        with self.cv:
            return "".join(self.lines)

    def wait_line(self, pattern: str, timeout: float = EVENT_S, after: int = 0) -> re.Match:
        """The first line from ``after`` on that matches ``pattern`` (a regex)."""
        rx = re.compile(pattern)
        deadline = time.monotonic() + timeout
        i = after
        with self.cv:
            while True:
                for j in range(i, len(self.lines)):
                    m = rx.search(self.lines[j])
                    if m:
                        return m
                i = len(self.lines)
                left = deadline - time.monotonic()
                if left <= 0 or (self.p.poll() is not None and not self.reader.is_alive()):
                    pytest.fail(f"{self.name}: no line /{pattern}/:\n{''.join(self.lines)[-4000:]}")
                self.cv.wait(min(left, 1.0))

    def pid_of(self, process: str) -> int:
        """The pid launch reports for ``process`` (``[INFO] [sim_node-1]: process started ...``)."""
        return int(self.wait_line(rf"\[{process}-\d+\]: process started with pid \[(\d+)\]")[1])

    def wait(self, timeout: float = EVENT_S) -> int:
        try:
            rc = self.p.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            pytest.fail(f"{self.name} did not end in {timeout} s:\n{self.out[-4000:]}")
        self.reader.join(30)
        return rc

    def stop(self, timeout: float = 90.0) -> int:
        """Ctrl-C (SIGINT to the launch, which forwards it to each child), then wait."""
        if self.p.poll() is None:
            os.kill(self.p.pid, signal.SIGINT)
        return self.wait(timeout)

    def stop_group(self, timeout: float = 60.0) -> int:
        """SIGINT to the whole group (``ros2 run`` and its node), then wait."""
        if self.p.poll() is None:
            os.killpg(self.p.pid, signal.SIGINT)
        return self.wait(timeout)

    def kill(self) -> None:
        try:
            os.killpg(self.p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.p.wait()


@pytest.fixture
def procs():
    """Everything a case started; whatever is still alive at its end is killed."""
    started: list[Proc] = []
    yield started
    for p in started:
        if p.p.poll() is None:
            p.kill()


def _sim(procs, out: Path, *args: str) -> Proc:
    cmd = ["ros2", "launch", "--noninteractive", "pneu_sim", "sim.launch.py"]
    p = Proc(
        [*cmd, "mode:=realtime", "duration:=0", f"out:={out}", *args], f"sim launch {out.name}"
    )
    procs.append(p)
    return p


def _rig(procs, out: Path, card: Path, *args: str) -> Proc:
    cmd = ["ros2", "launch", "--noninteractive", "pneu_driver", "rig.launch.py"]
    p = Proc(
        [*cmd, f"backend:=sim:card={card}", "gains:=retuned", f"out:={out}", *args],
        f"rig launch {out.name}",
    )
    procs.append(p)
    return p


def _ros2(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    res = subprocess.run(["ros2", *args], capture_output=True, text=True, timeout=timeout)
    return res


def _clean_end(out: str, *names: str) -> None:
    assert "Traceback" not in out, out[-4000:]
    assert "escalating to 'SIGTERM'" not in out, out[-4000:]
    for name in names:
        assert re.search(rf"\[{name}-\d+\]: process has finished cleanly", out), (name, out[-4000:])


# -- /diagnostics, read by a node of the test's own ---------------------------------
class Diagnostics:
    """Every ``/diagnostics`` status as it arrives: (header stamp ns, level, name, message,
    values), and waits on them."""

    def __init__(self):
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        self.ctx = Context()
        rclpy.init(context=self.ctx)
        self.node = rclpy.create_node("fault_test_diagnostics", context=self.ctx)
        self.items: list[tuple[int, int, str, str, dict]] = []
        self.cv = threading.Condition()
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on, qos)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.th = threading.Thread(target=self._spin, daemon=True)
        self.th.start()

    def _spin(self) -> None:
        try:
            while self.ctx.ok():
                self.ex.spin_once(timeout_sec=0.1)
        except Exception:  # the context went away at close()
            pass

    def _on(self, msg) -> None:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        rows = [
            (stamp, int.from_bytes(st.level, "little") if isinstance(st.level, bytes) else int(st.level),
             st.name, st.message, {kv.key: kv.value for kv in st.values})
            for st in msg.status
        ]  # fmt: skip
        with self.cv:
            self.items.extend(rows)
            self.cv.notify_all()

    def wait(self, pred, what: str, timeout: float = EVENT_S, after: int = 0):
        """The first status from index ``after`` on with ``pred(row)``; (index, row)."""
        deadline = time.monotonic() + timeout
        i = after
        with self.cv:
            while True:
                for j in range(i, len(self.items)):
                    if pred(self.items[j]):
                        return j, self.items[j]
                i = len(self.items)
                left = deadline - time.monotonic()
                if left <= 0:
                    seen = "\n".join(f"{r[1]} {r[2]}: {r[3][:120]}" for r in self.items[-30:])
                    pytest.fail(f"no /diagnostics status: {what} in {timeout} s; last:\n{seen}")
                self.cv.wait(min(left, 1.0))

    def sim_time(self, io: str, t_s: float, after: int = 0):
        """Wait until the sim's (or the driver's) 1 Hz status says its clock passed ``t_s``."""
        if io == "pneu_sim":
            return self.wait(
                lambda r: r[2] == "pneu_sim: lockstep" and float(r[4].get("sim_time_s", -1)) >= t_s,
                f"pneu_sim at {t_s:g} s", after=after,
            )  # fmt: skip
        return self.wait(
            lambda r: r[2] == "pneu_driver: loop" and int(r[4].get("cycles", -1)) >= t_s * 1000,
            f"pneu_driver at {t_s:g} s", after=after,
        )  # fmt: skip

    def close(self) -> None:
        self.ex.shutdown()
        self.node.destroy_node()
        self.ctx.try_shutdown()
        self.th.join(5)


@pytest.fixture
def diag():
    d = Diagnostics()
    yield d
    d.close()


def _latches(diag: Diagnostics, axis: str, after: int = 0, until: int | None = None) -> list:
    """The supervisor's ERROR transitions of ``axis`` (a regex; or ``all``) seen so far."""
    with diag.cv:
        return [
            r for r in diag.items[after:until]
            if r[1] == 2 and re.match(rf"pneu_(sim|driver): safety ({axis}|all) \S+$", r[2])
        ]  # fmt: skip


def _settle(diag: Diagnostics, io: str, t_s: float, after: int = 0) -> int:
    """Wait until ``io``'s clock passes ``t_s`` with no latch since ``after`` (an index).

    On a busy machine the supervisor may trip before any fault is injected (a late tick
    of the loop, a controller kept waiting by other work): the operator resets then, and
    so does this, until a clean 1.5 s (the resets are in the report). Returns the index of
    the status it waited for."""
    for attempt in range(6):
        i, row = diag.sim_time(io, t_s, after=after)
        if not _latches(diag, "linear|rotary", after, i):
            if attempt:
                _report("settled", io=io, resets_for_load_trips=attempt)
            return i
        res = _ros2("service", "call", f"/{io}/reset", "std_srvs/srv/Trigger")
        assert "success=True" in res.stdout, res.stdout + res.stderr
        after, t_s = i, _clock_s(row) + 1.5
    pytest.fail(f"{io}: the supervisor kept tripping before any fault (a loaded machine)")


def _clock_s(row) -> float:
    """The sample clock in a 1 Hz status of the sim (sim_time_s) or the driver (cycles)."""
    v = row[4]
    return float(v["sim_time_s"]) if "sim_time_s" in v else int(v["cycles"]) * 1e-3


# -- the bag ----------------------------------------------------------------------------
def _bag_statuses(bag: Path) -> list[tuple[int, int, str, str]]:
    """(stamp ns, level, name, message) of every /diagnostics status in a bag's .mcap files."""
    from mcap_ros2.reader import read_ros2_messages

    files = [bag] if bag.suffix == ".mcap" else sorted(bag.glob("*.mcap"))
    out = []
    for f in files:
        for m in read_ros2_messages(str(f), topics=["/diagnostics"]):
            h = m.ros_msg.header.stamp
            for st in m.ros_msg.status:
                level = st.level[0] if isinstance(st.level, bytes) else int(st.level)
                out.append((h.sec * 1_000_000_000 + h.nanosec, level, st.name, st.message))
    return out


def _bag_info(path: Path) -> dict[str, int]:
    res = _ros2("bag", "info", str(path))
    assert res.returncode == 0, res.stdout + res.stderr
    counts = {}
    for line in res.stdout.splitlines():
        if "Topic:" in line and "Count:" in line:
            topic = line.split("Topic:")[1].split("|")[0].strip()
            counts[topic] = int(line.split("Count:")[1].split("|")[0])
    return counts


def _pneu(*args: str) -> subprocess.CompletedProcess:
    return _ros2("run", "pneu_control", "pneu", *args, timeout=300)


def _report(name: str, **figures) -> None:
    """The measured figures of a case, in the test's output (-s) and the pytest log."""
    print(f"[faults] {name}: " + ", ".join(f"{k}={v}" for k, v in figures.items()), file=sys.stderr)


# -- 1. a controller SIGKILLed, restarted, acknowledged --------------------------------
def test_a_killed_controller_is_held_safe_and_a_restarted_one_rejoins_after_reset(
    procs, diag, tmp_path
):
    out = tmp_path / "run"
    g = _sim(procs, out, "deployment:=nodes")
    linear_pid = g.pid_of("linear_controller")
    mark = _settle(diag, "pneu_sim", 3.0)
    os.kill(linear_pid, signal.SIGKILL)
    i, trip = diag.wait(
        lambda r: r[1] == 2 and r[2] == "pneu_sim: safety linear watchdog", "linear watchdog trip",
        after=mark,
    )  # fmt: skip
    g.wait_line(rf"\[linear_controller-\d+\]: process has died \[pid {linear_pid}, exit code -9")
    i, _ = diag.sim_time("pneu_sim", trip[0] * 1e-9 + 2.0, after=i)  # the rotary axis goes on
    with diag.cv:  # the late commands' hold (late_policy): from before the kill to now
        sims = [
            (j, r[4]) for j, r in enumerate(diag.items[: i + 1]) if r[2] == "pneu_sim: lockstep"
        ]
    before = [v for j, v in sims if j < mark][-1]
    late = {
        k: int(sims[-1][1].get(f"linear.{k}", 0)) - int(before.get(f"linear.{k}", 0))
        for k in ("late_ticks", "held_ticks")
    }
    restarted = Proc(
        ["ros2", "run", "pneu_control", "linear_controller", "--ros-args",
         "--params-file", str(GAINS), "-p", "mode:=realtime"],
        "restarted linear controller",
    )  # fmt: skip
    procs.append(restarted)
    restarted.wait_line(r"valve held safe by the supervisor \(watchdog\)")
    diag.sim_time("pneu_sim", trip[0] * 1e-9 + 4.0, after=i)  # it has been commanding a while
    res = _ros2("service", "call", "/pneu_sim/reset", "std_srvs/srv/Trigger")
    assert "success=True" in res.stdout, res.stdout + res.stderr
    i, reset = diag.wait(lambda r: r[2] == "pneu_sim: safety all reset", "the reset", after=i)
    restarted.wait_line(r"released by the supervisor; rejoining bumplessly")
    i, _ = diag.sim_time("pneu_sim", reset[0] * 1e-9 + 2.0, after=i)
    rotary_latches = _latches(diag, "rotary", mark)
    assert g.stop() == 0, g.out[-3000:]
    assert restarted.stop_group() == 0, restarted.out[-3000:]
    _clean_end(g.out, "sim_node", "rotary_controller", "recorder", "logger")
    assert "Traceback" not in restarted.out, restarted.out[-3000:]

    data = read_run(out / "bag")
    cmd = data["/pneu/linear/valve_command"]
    stamp, u = cmd.stamp_ns, cmd["effort"]
    before = stamp <= trip[0]
    last = int(stamp[before].max())  # the killed controller's last command answered this sample
    to_safe_ns = trip[0] - last
    assert to_safe_ns <= WATCHDOG_NS + 2 * T_NS, to_safe_ns  # held within the watchdog
    statuses = _bag_statuses(out / "bag")
    assert any(
        s[2] == "pneu_sim: safety linear watchdog"
        and "linear valve safe until acknowledged" in s[3]
        for s in statuses
    )  # the bag says what happened
    # the other axis went on: its commands kept coming after the kill, and the kill did not
    # trip it (on a busy machine the rotary axis may trip on its own later: reported)
    assert not [r for r in rotary_latches if abs(r[0] - trip[0]) <= 50 * T_NS], rotary_latches
    rot = data["/pneu/rotary/valve_command"].stamp_ns
    after_kill = np.unique(rot[(rot > trip[0]) & (rot <= reset[0])])
    span = (reset[0] - trip[0]) // T_NS
    assert len(after_kill) >= 0.9 * span, (len(after_kill), span)
    # the restarted controller: nothing of it reached the valve before the reset (the
    # supervisor kept the latch: SAFE watchdog in every 1 Hz status until then)
    latched = [s for s in statuses if s[2] == "pneu_sim: safety linear" and s[3] == "SAFE"]
    assert latched, "no SAFE status of the linear axis in the bag"
    ours = (stamp > last + WATCHDOG_NS) & (stamp <= reset[0])
    held = u[ours][-200:]  # the last 0.2 s before the reset: it knew it was held
    assert np.all(held == 5.0), held
    # the rejoin: its first own command after the reset within one of its own steps of 5 V
    run = (stamp > last - 1000 * T_NS) & (stamp <= last)  # its last second: no latch in it
    steps = np.abs(np.diff(u[run]))
    normal = 2.0 * float(np.percentile(steps, 99))  # its own steps (p99), twice
    later = np.flatnonzero((stamp > reset[0]) & (u != 5.0))
    assert len(later), "no command of the restarted controller after the reset"
    first = later[0]
    jump = abs(float(u[first]) - 5.0)
    assert jump <= normal, (jump, normal)
    _report(
        "controller SIGKILL (nodes)",
        to_safe_ms=to_safe_ns / 1e6,
        rotary_commands_after=f"{len(after_kill)}/{span}",
        rejoin_jump_v=round(jump, 4),
        own_step_bound_v=round(normal, 4),
        rejoin_after_reset_ms=(int(stamp[first]) - reset[0]) / 1e6,
        rotary_load_trips=len(rotary_latches),
        linear_ticks_around_the_kill=late,
    )


@pytest.mark.parametrize("executor", ["events", "single"])
def test_hosted_estop_and_reset_hold_both_axes_and_they_rejoin_without_a_jump(
    executor, procs, diag, tmp_path
):
    """Hosted: the controllers run inside the sim's process (a SIGKILL of it is case 3); the
    operator's e-stop then reset holds both axes at 5 V and both rejoin without a jump."""
    out = tmp_path / "run"
    g = _sim(procs, out, "deployment:=hosted", f"executor:={executor}")
    i = _settle(diag, "pneu_sim", 3.0)
    res = _ros2("service", "call", "/pneu_sim/estop", "std_srvs/srv/Trigger")
    assert "success=True" in res.stdout, res.stdout + res.stderr
    i, stop = diag.wait(lambda r: r[2] == "pneu_sim: safety all estop", "the e-stop", after=i)
    i, _ = diag.sim_time("pneu_sim", stop[0] * 1e-9 + 2.0, after=i)
    res = _ros2("service", "call", "/pneu_sim/reset", "std_srvs/srv/Trigger")
    assert "success=True" in res.stdout, res.stdout + res.stderr
    i, reset = diag.wait(lambda r: r[2] == "pneu_sim: safety all reset", "the reset", after=i)
    for axis in ("linear", "rotary"):
        g.wait_line(rf"{axis}: released by the supervisor; rejoining bumplessly")
    diag.sim_time("pneu_sim", reset[0] * 1e-9 + 2.0, after=i)
    assert g.stop() == 0, g.out[-3000:]
    _clean_end(g.out, "controller_manager", "recorder", "logger")
    data = read_run(out / "bag")
    figures = {}
    for axis in ("linear", "rotary"):
        cmd = data[f"/pneu/{axis}/valve_command"]
        stamp, u = cmd.stamp_ns, cmd["effort"]
        steps = np.abs(np.diff(u[(stamp > stop[0] - 1000 * T_NS) & (stamp < stop[0])]))
        normal = 2.0 * float(np.percentile(steps, 99))  # its own steps (p99), twice
        held = u[(stamp > stop[0] + 200 * T_NS) & (stamp <= reset[0])]
        assert len(held) and np.all(held == 5.0), (axis, held[held != 5.0][:10])
        later = np.flatnonzero((stamp > reset[0]) & (u != 5.0))
        jump = abs(float(u[later[0]]) - 5.0)
        assert jump <= normal, (axis, jump, normal)
        figures[f"{axis}_jump_v"] = round(jump, 4)
        figures[f"{axis}_own_step_bound_v"] = round(normal, 4)
    _report(f"hosted e-stop + reset ({executor})", **figures)


# -- 2. the recorder killed -----------------------------------------------------------
@pytest.mark.parametrize("deployment", ["nodes", "hosted"])
def test_a_killed_rosbag2_recorder_stops_the_run_and_its_bag_reads_back(
    deployment, procs, diag, tmp_path
):
    out = tmp_path / "run"
    g = _sim(procs, out, f"deployment:={deployment}")
    pid = g.pid_of("recorder")
    _, at = diag.sim_time("pneu_sim", 3.0)
    os.kill(pid, signal.SIGKILL)
    g.wait_line(r"recorder \(ros2 bag record\) ended \(killed by signal 9\) before the run did")
    rc = g.wait()  # launch's own exit status after a process died: reported
    sim = "controller_manager" if deployment == "hosted" else "sim_node"
    others = (sim, "logger") + (
        ("linear_controller", "rotary_controller") if deployment == "nodes" else ()
    )
    _clean_end(g.out, *others)
    bag = out / "bag"
    assert not (bag / "metadata.yaml").exists()  # rosbag2 was killed before writing it
    assert (bag / "pneu_metadata.json").is_file()  # the logger, stopped cleanly, wrote its part
    mcap_file = bag / "bag_0.mcap"
    # pneu's reader takes the directory as it is (a warning: no metadata.yaml)
    data = read_run(bag)
    n_read = len(data["/pneu/linear/joint_state"])
    # pneu recover: a complete, indexed copy that ros2 bag info counts
    res = _pneu("recover", str(mcap_file), "--out", str(tmp_path / "recovered.mcap"))
    assert res.returncode == 0, res.stdout + res.stderr
    counts = _bag_info(tmp_path / "recovered.mcap")
    assert counts["/pneu/linear/joint_state"] == n_read
    # rosbag2's own way back: reindex writes metadata.yaml, ros2 bag info then opens the bag
    res = _ros2("bag", "reindex", str(bag), "-s", "mcap")
    assert res.returncode == 0, res.stdout + res.stderr
    n_reindexed = _bag_info(bag)["/pneu/linear/joint_state"]
    assert 0 < n_reindexed <= n_read  # (measured: rosbag2 may stop earlier than pneu's reader)
    # what was recorded: samples from the first on, up to near the kill
    stamps = data["/pneu/linear/joint_state"].stamp_ns
    assert n_read > 0 and int(stamps.min()) < 1_000 * T_NS
    lost_s = float(at[4]["sim_time_s"]) - int(stamps.max()) * 1e-9
    _report(
        f"rosbag2 recorder SIGKILL ({deployment})",
        samples_read=n_read,
        reindexed=n_reindexed,
        last_sample_s=round(int(stamps.max()) * 1e-9, 3),
        sim_time_at_kill_s=at[4]["sim_time_s"],
        unflushed_before_kill_s=round(lost_s, 3),
        launch_rc=rc,
    )


def test_a_killed_pneu_logger_stops_a_lockstep_run_and_pneu_recover_reads_it(procs, diag, tmp_path):
    out = tmp_path / "run"
    cmd = ["ros2", "launch", "--noninteractive", "pneu_sim", "sim.launch.py"]
    g = Proc([*cmd, "mode:=lockstep", "duration:=600", f"out:={out}"], "lockstep launch")
    procs.append(g)
    pid = g.pid_of("logger")
    _, at = diag.sim_time("pneu_sim", 2.0)
    os.kill(pid, signal.SIGKILL)
    g.wait_line(r"logger ended \(killed by signal 9\) before the run did: run stopped")
    rc = g.wait()
    _clean_end(g.out, "sim_node", "linear_controller", "rotary_controller")
    partial = out / "run.mcap.partial"
    assert partial.is_file() and not (out / "run.mcap").exists()
    res = _pneu("recover", str(partial), "--out", str(out / "run.mcap"))
    assert res.returncode == 0, res.stdout + res.stderr
    counts = _bag_info(out / "run.mcap")
    data = read_run(out / "run.mcap")
    js = data["/pneu/linear/joint_state"].stamp_ns
    n = len(js)
    # lockstep: every sample from the first, none missing, up to the last chunk written
    assert n > 0 and np.array_equal(js, np.arange(n) * T_NS)
    assert counts["/pneu/linear/joint_state"] == n
    line = next((ln for ln in res.stdout.splitlines() if "recovered" in ln), res.stdout)
    _report(
        "pneu logger SIGKILL (lockstep)",
        samples_recovered=n,
        sim_time_at_kill_s=at[4]["sim_time_s"],
        recover=line.split(" from ")[0],
        launch_rc=rc,
    )


# -- 3. the sim / driver hung, then killed ---------------------------------------------
@pytest.mark.parametrize("deployment", ["nodes", "hosted"])
def test_a_hung_then_killed_sim_leaves_the_controllers_silent_and_saying_so(
    deployment, procs, diag, tmp_path
):
    out = tmp_path / "run"
    g = _sim(procs, out, f"deployment:={deployment}")
    name = "controller_manager" if deployment == "hosted" else "sim_node"
    pid = g.pid_of(name)
    diag.sim_time("pneu_sim", 3.0)
    mark = len(diag.items)
    os.kill(pid, signal.SIGSTOP)
    t_stop = time.monotonic()
    try:
        if deployment == "nodes":
            for axis in ("linear", "rotary"):
                g.wait_line(
                    rf"\[{axis}_controller\]: no samples since the last report .* not commanding"
                )
                diag.wait(
                    lambda r, a=axis: r[1] == 2 and r[2] == f"{a}_controller: {a} controller",
                    f"{axis} controller ERROR", after=mark,
                )  # fmt: skip
            said_s = time.monotonic() - t_stop
    finally:
        os.kill(pid, signal.SIGKILL)  # (a stopped process takes SIGKILL as it is)
    g.wait_line(r"pneu_sim ended \(killed by signal 9\) before the run did: run stopped")
    g.wait()
    _clean_end(g.out, "recorder", "logger", *(
        ("linear_controller", "rotary_controller") if deployment == "nodes" else ()))  # fmt: skip
    data = read_run(out / "bag")  # complete: the recorder was stopped cleanly
    last_sample = int(data["/pneu/linear/joint_state"].stamp_ns.max())
    for axis in ("linear", "rotary"):  # nothing commanded after the last sample
        assert int(data[f"/pneu/{axis}/valve_command"].stamp_ns.max()) <= last_sample
    if deployment == "nodes":
        statuses = _bag_statuses(out / "bag")
        assert any(s[1] == 2 and "not commanding" in s[3] for s in statuses)
        _report("sim SIGSTOP then SIGKILL (nodes)", controllers_said_it_s=round(said_s, 2))


@pytest.mark.parametrize("deployment", ["nodes", "hosted"])
def test_a_killed_driver_leaves_the_card_at_its_last_outputs_and_the_heartbeat_stopped(
    deployment, procs, diag, tmp_path
):
    from pneu_sim.daq_sim.card import read_card_state

    out, card = tmp_path / "rig", tmp_path / "card"
    g = _rig(procs, out, card, f"deployment:={deployment}")
    name = "controller_manager" if deployment == "hosted" else "driver_node"
    pid = g.pid_of(name)
    mark = _settle(diag, "pneu_driver", 3.0)  # the rig trips at start-up: an operator resets
    os.kill(pid, signal.SIGSTOP)
    t_stop = time.monotonic()
    try:
        if deployment == "nodes":
            g.wait_line(
                r"\[linear_controller\]: no samples since the last report .* not commanding"
            )
            diag.wait(
                lambda r: r[1] == 2 and r[2] == "linear_controller: linear controller",
                "linear controller ERROR", after=mark,
            )  # fmt: skip
        said_s = time.monotonic() - t_stop
    finally:
        os.kill(pid, signal.SIGKILL)  # (a stopped process takes SIGKILL as it is)
    g.wait_line(r"pneu_driver ended \(killed by signal 9\) before the run did: run stopped")
    held = read_card_state(card)
    g.wait()
    _clean_end(g.out, "recorder", "logger")
    later = read_card_state(card)
    assert held.pid == pid  # the killed process drove the card
    assert later == held  # nobody wrote it since: the last outputs stay
    assert later.do_edges > 1000  # the heartbeat ran (after the reset), and stands still now
    _report(
        f"driver SIGSTOP then SIGKILL ({deployment})",
        card_ao_v=(round(later.ao0_v, 3), round(later.ao1_v, 3)),
        heartbeat_edges=later.do_edges,
        controllers_said_it_s=round(said_s, 2) if deployment == "nodes" else "-",
    )


# -- 4. a parameter set under load ---------------------------------------------------------
@pytest.mark.parametrize("deployment", ["nodes", "hosted"])
def test_a_parameter_set_under_load_takes_effect_without_a_supervisor_trip(
    deployment, procs, diag, tmp_path
):
    """Two busy processes beside the graph; ``ros2 param set`` on the linear controller: no
    trip from the set's start to a second after the core applied it (the validation runs on
    the thread that answers the samples), and the value is the controller's from then on.
    Trips elsewhere in the run (other work on a shared machine) are reported."""
    from pneu_control.controller.params import load_controller_params

    base = load_controller_params("linear", GAINS)
    assert base.algorithm == "eso_smc"
    new_eps = round(base.eso_smc.epsilon * 1.25, 3)
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        out = tmp_path / "run"
        # as launched: the nodes' own priorities (the loop at SCHED_FIFO 50, the rest at 49)
        g = _sim(procs, out, f"deployment:={deployment}")
        _settle(diag, "pneu_sim", 3.0)
        mark = len(diag.items)
        res = _ros2("param", "set", "/linear_controller", "eso_smc.epsilon", str(new_eps))
        assert "Set parameter successful" in res.stdout, res.stdout + res.stderr
        i, _ = diag.wait(
            lambda r: r[2] == "linear_controller: linear controller"
            and r[4].get("parameter_changes") == "1",
            "the change applied by the controller core", after=mark,
        )  # fmt: skip
        i, _ = diag.sim_time("pneu_sim", 0.0, after=i + 1)
        diag.sim_time("pneu_sim", _clock_s(diag.items[i]) + 1.5, after=i)
        trips = _latches(diag, "linear|rotary", mark)
        got = _ros2("param", "get", "/linear_controller", "eso_smc.epsilon")
        assert g.stop() == 0, g.out[-3000:]
    finally:
        for b in busy:
            b.kill()
            b.wait()
    assert str(new_eps) in got.stdout, got.stdout
    with diag.cv:  # the sim's last 1 Hz status: its counters over the run
        counters = next(r[4] for r in reversed(diag.items) if r[2] == "pneu_sim: lockstep")
    sidecar = json.loads((out / "bag" / "pneu_metadata.json").read_text())
    changes = json.loads(sidecar["pneu.param_changes"]["changes_json"])
    change = [c for c in changes if c["name"] == "eso_smc.epsilon" and c["value"] == new_eps]
    assert change, changes
    # when the node took the set (its /parameter_events stamp, wall clock) on the sample clock:
    # from the sim's 1 Hz status just before it (wall stamp, sim_time_s)
    t_set = change[0]["stamp_ns"]
    with diag.cv:
        ref = [r for r in diag.items if r[2] == "pneu_sim: lockstep" and r[0] <= t_set][-1]
    at = float(ref[4]["sim_time_s"]) * 1e9 + (t_set - ref[0])
    window = (at - 50 * T_NS, at + 1000 * T_NS)  # the set, and the second after it
    during = [r for r in trips if window[0] <= r[0] <= window[1]]
    _report(
        f"param set under load ({deployment})",
        trips_in_window=len(during),
        window_s=(round(window[0] * 1e-9, 3), round(window[1] * 1e-9, 3)),
        trips_elsewhere=len(trips) - len(during),
        missed=(counters.get("missed.linear"), counters.get("missed.rotary")),
        skipped_ticks=counters.get("skipped_ticks"),
        sim_time_s=counters.get("sim_time_s"),
    )
    assert not during, during


# -- 5. the graph twice on one domain ---------------------------------------------------------
def test_a_second_sim_on_the_domain_makes_both_estop(procs, diag, tmp_path):
    a = _sim(procs, tmp_path / "a", "deployment:=hosted")
    diag.sim_time("pneu_sim", 2.0)
    t0 = time.monotonic()
    b = _sim(procs, tmp_path / "b", "deployment:=hosted")
    line = r"another driver or sim publishes \S+ on ROS_DOMAIN_ID \d+ .*two graphs on one domain; e-stop latched"
    a.wait_line(line)
    a_s = time.monotonic() - t0
    b.wait_line(line)
    i, _ = diag.wait(lambda r: r[2] == "pneu_sim: safety all estop", "an e-stop")
    diag.wait(lambda r: r[2] == "pneu_sim: safety all estop", "the other e-stop", after=i + 1)
    assert a.stop() == 0 and b.stop() == 0
    for p in (a, b):
        _clean_end(p.out, "controller_manager", "recorder", "logger")
    for run in ("a", "b"):
        statuses = _bag_statuses(tmp_path / run / "bag")
        stop = [
            s for s in statuses if s[2] == "pneu_sim: safety all estop" and "two graphs" in s[3]
        ]
        assert stop, run
        data = read_run(tmp_path / run / "bag")
        for axis in ("linear", "rotary"):  # its controllers commanded the held 5 V from then on
            cmd = data[f"/pneu/{axis}/valve_command"]
            after = cmd["effort"][cmd.stamp_ns > stop[0][0] + 200 * T_NS]
            assert len(after) and np.all(after == 5.0), (run, axis, after[after != 5.0][:5])
    _report("second sim on the domain (hosted)", first_estop_after_second_start_s=round(a_s, 2))


@pytest.mark.parametrize("deployment", ["nodes", "hosted"])
def test_a_second_rig_on_the_same_card_is_refused_and_never_writes_it(
    deployment, procs, diag, tmp_path
):
    """B on A's card: B's driver is refused in one line naming A's driver, B's launch ends by
    itself, the card is A's throughout and ends at 5 V. What else A saw is reported: its
    e-stop when its 1 Hz graph check caught B's driver while it lived, and -- separate
    processes -- samples of A's answered twice (B's controllers answered A's samples until B's
    launch stopped them: ``publisher_trip: true`` in safety.yaml trips on that)."""
    from pneu_sim.daq_sim.card import read_card_state

    card = tmp_path / "card"
    a = _rig(procs, tmp_path / "a", card, f"deployment:={deployment}")
    name = "controller_manager" if deployment == "hosted" else "driver_node"
    a_pid = a.pid_of(name)
    diag.sim_time("pneu_driver", 2.0)
    t0 = time.monotonic()
    b = _rig(procs, tmp_path / "b", card, f"deployment:={deployment}")
    b.wait_line(rf"device .*: in use by another pneu driver \(pid {a_pid}\); one driver per card")
    b.wait_line(r"pneu_driver ended \(exit code 1\) before the run did: run stopped")
    b.wait()
    b_lived_s = time.monotonic() - t0
    assert read_card_state(card).pid == a_pid  # only A ever drove the card
    diag.sim_time("pneu_driver", 0.0, after=len(diag.items))  # A's next 1 Hz status
    assert a.stop() == 0, a.out[-3000:]
    _clean_end(a.out, name, "recorder", "logger")
    assert "Traceback" not in b.out, b.out[-3000:]
    state = read_card_state(card)
    assert state.pid == a_pid and (state.ao0_v, state.ao1_v) == (5.0, 5.0)
    statuses = _bag_statuses(tmp_path / "a" / "bag")
    estop = any(s[2] == "pneu_driver: safety all estop" and "two graphs" in s[3] for s in statuses)
    data = read_run(tmp_path / "a" / "bag")
    twice = {}
    for axis in ("linear", "rotary"):
        _, n = np.unique(data[f"/pneu/{axis}/valve_command"].stamp_ns, return_counts=True)
        twice[axis] = int((n[:-1] > 1).sum())  # (the last: the controllers' neutral last word)
    if deployment == "hosted":  # B's controllers live in B's manager: they never saw A's samples
        assert twice == {"linear": 0, "rotary": 0}, twice
    _report(
        f"second rig on the card ({deployment})",
        b_refused_and_ended_s=round(b_lived_s, 2),
        a_estopped=estop,
        a_samples_answered_twice=twice,
    )
