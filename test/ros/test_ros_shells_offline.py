"""The rclpy node modules themselves, run against an in-memory stand-in for rclpy.

Skipped where real rclpy exists (``test_ros_rclpy_*`` run there instead).
This checks the shells' wiring -- declarations, callbacks, topics, services,
the lockstep handshake, the logger's bag, exit codes -- with the rclpy
semantics listed in ``_fake_rclpy.py``; it cannot check rclpy itself.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import math
from pathlib import Path

import pytest

try:  # the real thing wins: its tests cover this
    importlib.import_module("rclpy")
    pytest.skip("real rclpy present: see test_ros_rclpy_*.py", allow_module_level=True)
except ImportError:
    pass

_spec = importlib.util.spec_from_file_location(
    "_fake_rclpy", Path(__file__).with_name("_fake_rclpy.py")
)
fake = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fake)

from pneu_control.analysis.metrics import WindowSpec  # noqa: E402
from pneu_control.analysis.run_analysis import analyze  # noqa: E402
from pneu_control.experiment import session  # noqa: E402
from pneu_control.experiment.runner import run  # noqa: E402

DURATION_S = 1.0
WINDOW_S = 0.5
FAULT = "sensor_dropout:sensor=x,start_s=0.8,duration_s=0.01"  # the supervisor holds it safe


@pytest.fixture
def world():
    with fake.installed() as w:
        yield w


def _spin_until(ex, cond, timeout_s=120.0):
    import time

    t_end = time.monotonic() + timeout_s
    while not cond() and time.monotonic() < t_end:
        ex.spin_once()
    assert cond()


def test_lockstep_graph_through_the_node_modules_equals_the_runner(world, tmp_path):
    world.overrides.update(
        {
            "/pneu_sim": {
                "mode": "lockstep",
                "axes": "linear",
                "duration_s": DURATION_S,
                "seed": 2,
                "safety": True,  # config/safety.yaml, as the runner
                "startup.min_subscribers": 1,
                "startup.settle_s": 0.0,  # the stand-in matches connections at once
                "faults": FAULT,
            },
            "/linear_controller": {
                "mode": "lockstep",
                "use_sim_time": True,
                "algorithm": "pid",
                "reference.kind": "sine",
                "reference.amplitude": 10.0,
                "reference.frequency_hz": 1.0,
            },
            "/logger": {"out": str(tmp_path), "mode": "lockstep", "use_sim_time": True},
        }
    )
    from pneu_control.nodes.controller_node import ControllerNode
    from pneu_control.nodes.logger_node import LoggerNode
    from pneu_sim.nodes.sim_node import SimNode
    from rclpy.executors import SingleThreadedExecutor

    logger, ctrl = LoggerNode(), ControllerNode("linear")
    sim = SimNode()
    ex = SingleThreadedExecutor()
    for n in (logger, ctrl, sim):
        ex.add_node(n)
    ex.spin_until_future_complete(sim.done, timeout_sec=120.0)
    counters = sim.done.result()
    assert counters["steps"] == 999
    assert counters["timeouts.linear"] == counters["stale.linear"] == 0
    # the logger takes the last messages and has fetched the nodes' parameters
    _spin_until(
        ex,
        lambda: (
            not world.queue and {"/pneu_sim", "/linear_controller"} <= set(logger.core.node_params)
        ),
    )
    logger.core.close()

    spec = session.build_spec(
        axes=("linear",),
        controller="pid",
        reference="sine:amplitude=10.0,frequency_hz=1.0",
        duration_s=DURATION_S,
        seed=2,
        window_start_s=WINDOW_S,
        faults=[FAULT],
    )
    result = run(spec)
    assert result.safety_counters["trips"] >= 1
    ref = result.metrics["linear"]
    res = analyze(tmp_path / "run.mcap", window=WindowSpec(kind="fixed", t_start_s=WINDOW_S))
    assert res.faults == result.fault_intervals
    got = res.metrics["linear"]
    assert got.n_samples == ref.n_samples > 0
    assert got.e_max == pytest.approx(ref.e_max, abs=1e-9, rel=0)
    assert got.rmse == pytest.approx(ref.rmse, abs=1e-9, rel=0)
    assert res.config["seed"] == 2 and res.config["axes"] == ["linear"]
    assert res.config["controllers"]["linear"]["algorithm"] == "pid"
    assert logger.core.counts["/clock"] == 1000


def test_controller_parameters_live(world):
    from pneu_control.nodes.controller_node import ControllerNode
    from pneu_msgs_py.contract.samples import SensorSample
    from pneu_msgs_py.contract.wire import CommandWire, SensorWire
    from rclpy.parameter import Parameter

    ctrl = ControllerNode("linear")
    # what the node publishes: intercept the command publisher (raw CDR bytes)
    sent = []
    cw = CommandWire("linear")
    ctrl.cmd_pub.publish = lambda data: sent.append(
        (*divmod(cw.decode(data)[0], 1_000_000_000), [cw.decode(data)[1]])
    )
    wire = SensorWire()

    def feed(k):
        s = SensorSample(k, k * 1_000_000, 2e5, 2e5, 1.5e5, 1e-4 * k, 0.0, 0.0, 0)
        for t, data in wire.encode(s):
            if t in ctrl.core.topics:
                ctrl._on_sensor(t, data)

    feed(0)
    assert len(sent) == 1 and sent[0][:2] == (0, 0)  # stamped with the sample it answers

    r = ctrl.set_parameters([Parameter("eso_smc.epsilon", value=900)])[
        0
    ]  # INTEGER, as ros2 param set sends
    assert r.successful, r.reason
    assert (
        ctrl.get_parameter("eso_smc.epsilon").value == 900.0
        and ctrl.params.eso_smc.epsilon == 900.0
    )
    assert ctrl.core.controller.params.eso_smc.epsilon != 900.0
    feed(1)
    assert ctrl.core.controller.params.eso_smc.epsilon == 900.0  # at the next sample

    r = ctrl.set_parameters([Parameter("eso_smc.epsilon", value=-1)])[0]
    assert not r.successful and "eso_smc.epsilon" in r.reason and "(0, inf" in r.reason
    assert (
        ctrl.params.eso_smc.epsilon == 900.0
        and ctrl.get_parameter("eso_smc.epsilon").value == 900.0
    )

    r = ctrl.set_parameters([Parameter("sample_time_s", value=0.002)])[0]
    assert not r.successful and "read-only" in r.reason

    T, k = ctrl.params.sample_time_s, ctrl.params.eso_smc.k
    eps = 1.25 / (k * T)
    r = ctrl.set_parameters_atomically([Parameter("eso_smc.epsilon", value=eps)])
    assert not r.successful and "eso_smc.k" in r.reason
    k_new = 0.5 / (eps * T)
    r = ctrl.set_parameters_atomically(
        [Parameter("eso_smc.epsilon", value=eps), Parameter("eso_smc.k", value=k_new)]
    )
    assert r.successful, r.reason
    assert (ctrl.params.eso_smc.epsilon, ctrl.params.eso_smc.k) == (eps, k_new)

    other = "pid" if ctrl.params.algorithm != "pid" else "ladrc"
    assert ctrl.set_parameters([Parameter("algorithm", value=other)])[0].successful
    feed(2)
    assert ctrl.core.controller.algorithm == other
    assert math.isfinite(sent[-1][2][0])


def test_controller_exits_1_with_one_line_on_a_bad_startup_value(world, capsys):
    world.overrides["/linear_controller"] = {"algorithm": "bang_bang"}
    import pneu_control.nodes.controller_node as cn

    assert cn.main_linear() == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "algorithm" in err[0] and "pid" in err[0]


def test_sim_estop_and_reset_services(world):
    world.overrides["/pneu_sim"] = {"mode": "lockstep", "axes": "linear", "safety": True}
    from pneu_sim.nodes.sim_node import SimNode

    sim = SimNode()
    r = world.call("/pneu_sim/estop")
    assert r.success and "5 V" in r.message
    assert sim.supervisor.estopped
    r = world.call("/pneu_sim/reset")
    assert r.success and not sim.supervisor.estopped


def test_driver_without_daq_names_the_device_and_exits_1(world, capsys):
    import pneu_driver.nodes.driver_node as dn

    assert dn.main() == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "'Dev1'" in err[0] and "devices visible:" in err[0]


def test_driver_node_with_the_twin_behind_the_daq_publishes_forwards_and_ends_safe(
    world, tmp_path, monkeypatch
):
    """The driver shell around DriverLoop with ``backend: sim`` (the twin as a simulated card)."""
    import pneu_driver.nodes.driver_node as dn
    from rclpy.executors import SingleThreadedExecutor

    def no_nidaqmx(device):
        raise AssertionError("backend sim must not look for an NI device")

    monkeypatch.setattr(dn, "visible_devices", no_nidaqmx)
    card = tmp_path / "card"
    world.overrides["/pneu_driver"] = {"axes": "linear", "backend": f"sim:card={card}"}
    world.overrides["/linear_controller"] = {"mode": "realtime"}
    from pneu_control.nodes.controller_node import ControllerNode
    from pneu_sim.daq_sim.card import read_card_state

    drv, ctrl = dn.DriverNode(), ControllerNode("linear")
    daq = drv.loop.backend
    ex = SingleThreadedExecutor()
    ex.add_node(drv)
    ex.add_node(ctrl)
    drv.start()
    try:
        _spin_until(ex, lambda: ctrl.core.n_samples >= 50, timeout_s=60.0)
        assert drv.loop.commands._newest["linear"] > 0  # commands reached the loop
        assert drv.stamp_offset_ns is not None
        assert read_card_state(card).do_edges > 0  # the heartbeat runs
        r = world.call("/pneu_driver/estop")
        assert r.success and drv.loop.status()["linear"].state == "SAFE"
        k = daq.reads
        _spin_until(ex, lambda: daq.reads > k + 20, timeout_s=30.0)
        st = read_card_state(card)
        assert (st.ao0_v, st.ao1_v) == (5.0, 5.0)  # e-stopped: the valves get 5 V
        edges = st.do_edges
        _spin_until(ex, lambda: daq.reads > k + 40, timeout_s=30.0)
        assert read_card_state(card).do_edges == edges  # tripped: the heartbeat stopped
    finally:
        drv.loop.stop()
        drv.thread.join(timeout=5.0)
    assert not drv.thread.is_alive() and drv.loop.error is None
    st = read_card_state(card)
    assert (st.ao0_v, st.ao1_v, st.do_level) == (5.0, 5.0, False) and not daq.is_open


def test_sim_open_loop_lockstep_runs_to_its_duration(world):
    world.overrides["/pneu_sim"] = {
        "mode": "lockstep",
        "axes": "none",
        "duration_s": 0.2,
        "startup.min_subscribers": 0,
        "startup.settle_s": 0.0,
    }
    from pneu_sim.nodes.sim_node import SimNode
    from rclpy.executors import SingleThreadedExecutor

    sim = SimNode()
    ex = SingleThreadedExecutor()
    ex.add_node(sim)
    ex.spin_until_future_complete(sim.done, timeout_sec=60.0)
    assert sim.done.result()["steps"] == 199
    assert sim.core.held == {"linear": 5.0, "rotary": 5.0}


def test_run_node_spins_to_the_end_and_leaves_the_rig_safe(world, capsys, monkeypatch):
    """The one main(): executor chosen (no EventsExecutor in the fake: 'auto' -> single), spin
    until the node's done future, safe_shutdown, exit 0."""
    world.overrides["/pneu_sim"] = {
        "mode": "lockstep",
        "axes": "none",
        "duration_s": 0.05,
        "startup.min_subscribers": 0,
        "startup.settle_s": 0.0,
    }
    import pneu_sim.nodes.sim_node as sn

    shut = []
    monkeypatch.setattr(
        sn.SimNode,
        "safe_shutdown",
        lambda self: shut.append((self.core.sample.k, self.get_parameter("executor").value)),
    )
    assert sn.main() == 0
    assert shut == [(49, "")]  # after the last sample, once; the executor parameter declared


def test_ctrl_c_while_spinning_ends_the_spin_without_raising_into_a_callback(world, monkeypatch):
    """SIGINT once the node spins: the spin ends at its next slice, safe_shutdown runs, exit 0
    (Python's KeyboardInterrupt used to land inside whatever callback was running)."""
    import os
    import signal

    world.overrides["/pneu_sim"] = {"mode": "lockstep", "axes": "none", "duration_s": 0.0}
    import pneu_sim.nodes.sim_node as sn

    # Python's own handler to start from, whatever an earlier test of this process left
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    shut, ran = [], []

    def watch(self):  # a callback the signal lands in: it runs to its end
        os.kill(os.getpid(), signal.SIGINT)
        ran.append(sum(range(10_000)))  # bytecodes after the signal: where it used to raise

    monkeypatch.setattr(sn.SimNode, "_watch", watch)
    monkeypatch.setattr(sn.SimNode, "safe_shutdown", lambda self: shut.append(True))
    assert sn.main() == 0
    assert ran[:1] == [49_995_000] and shut == [True]
    try:
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored
    finally:
        signal.signal(signal.SIGINT, before)


@pytest.mark.parametrize(
    ("env", "message"),
    [("bogus", "executor: 'bogus' refused; allowed: one of auto, events, single"),
     ("events", "executor: 'events' refused; this rclpy has no rclpy.experimental.EventsExecutor")],
)  # fmt: skip
def test_run_node_refuses_an_executor_it_cannot_give_in_one_line(
    world, capsys, monkeypatch, env, message
):
    world.overrides["/pneu_sim"] = {"mode": "lockstep", "axes": "none", "duration_s": 0.05}
    monkeypatch.setenv("PNEU_EXECUTOR", env)
    import pneu_sim.nodes.sim_node as sn

    shut = []
    monkeypatch.setattr(sn.SimNode, "safe_shutdown", lambda self: shut.append(True))
    assert sn.main() == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sim_node: error: " + message)
    assert shut == [True]  # the node was built: it is still left safe


def test_a_task_through_the_node_modules_equals_pneu_task(world, tmp_path):
    """Task runner, sim, both controllers and the logger over the stand-in: the task's
    segments end at the same samples, the bag's joints and commands are the in-process
    run's (to the sample the task ended), the report is written."""
    import numpy as np
    from pneu_control.task.session import execute_task, prepare
    from pneu_msgs_py.bag.reader import read_run
    from pneu_msgs_py.params.paths import config_file
    from pneu_msgs_py.params.ros import values_to_overrides

    task = config_file("tasks/coupling_insert_lock.yaml")
    prepared = prepare(task)
    plant = tmp_path / "task_plant.yaml"
    from pneu_sim.physics.plant_file import dump_plant_yaml

    plant.write_text(dump_plant_yaml(prepared.spec.plant))
    import yaml
    from pneu_msgs_py.params.core import to_dict

    safety = tmp_path / "task_safety.yaml"  # what task.launch.py writes
    safety.write_text(yaml.safe_dump(to_dict(prepared.spec.safety), sort_keys=False))
    ros_out = tmp_path / "ros"
    world.overrides.update(
        {
            "/pneu_sim": {
                "mode": "lockstep",
                "axes": "both",
                "duration_s": prepared.spec.duration_s,
                "plant_file": str(plant),
                "safety_file": str(safety),
                "task.wait": True,
                "task.ends_run": True,
                "startup.min_subscribers": 1,
                "startup.settle_s": 0.0,
            },
            **{
                f"/{axis}_controller": {
                    **values_to_overrides(prepared.spec.controllers[axis]),
                    "mode": "lockstep",
                    "use_sim_time": True,
                }
                for axis in ("linear", "rotary")
            },
            "/task_runner": {"task_file": str(task), "mode": "lockstep", "out": str(ros_out)},
            "/logger": {"out": str(ros_out), "mode": "lockstep", "use_sim_time": True},
        }
    )
    from pneu_control.nodes.controller_node import ControllerNode
    from pneu_control.nodes.logger_node import LoggerNode
    from pneu_control.nodes.task_node import TaskRunnerNode
    from pneu_sim.nodes.sim_node import SimNode
    from rclpy.executors import SingleThreadedExecutor

    logger = LoggerNode()
    nodes = [logger, ControllerNode("linear"), ControllerNode("rotary"), TaskRunnerNode()]
    sim = SimNode()
    ex = SingleThreadedExecutor()
    for n in (*nodes, sim):
        ex.add_node(n)
    ex.spin_until_future_complete(sim.done, timeout_sec=300.0)
    counters = sim.done.result()
    assert counters["timeouts.linear"] == counters["timeouts.rotary"] == 0
    _spin_until(ex, lambda: not world.queue and nodes[3].done.done())
    logger.core.close()

    _, result, rep = execute_task(prepare(task), tmp_path / "inproc")
    ros_rep = json.loads((ros_out / "task_report.json").read_text())
    assert ros_rep["outcome"] == rep["outcome"] == "completed", (
        ros_rep["reason"],
        ros_rep["safety_events"],
    )
    for a, b in zip(ros_rep["segments"], rep["segments"]):
        assert (a["status"], a["t_start_s"], a["t_end_s"]) == (
            b["status"],
            b["t_start_s"],
            b["t_end_s"],
        )
        assert a["error_mm"] == b["error_mm"] and a["error_deg"] == b["error_deg"]
    run = read_run(ros_out / "run.mcap")
    m = len(result.t)  # the in-process run stops before the sample the task ended at
    assert np.array_equal(run["/pneu/linear/joint_state"]["position"][:m], result.samples["x"])
    assert np.array_equal(run["/pneu/rotary/joint_state"]["rotary"][:m], result.samples["theta"])
    for axis in ("linear", "rotary"):
        got = run[f"/pneu/{axis}/valve_command"]["effort"][:m]
        assert np.array_equal(got, result.axes[axis]["u"])
    from mcap_ros2.reader import read_ros2_messages  # an independent reader of the new topics

    per_topic = {}
    for m_ in read_ros2_messages(str(ros_out / "run.mcap")):
        per_topic[m_.channel.topic] = per_topic.get(m_.channel.topic, 0) + 1
    assert per_topic["/pneu/joint_trajectory"] == len(prepared.program.segments)
    assert per_topic["/pneu/task/progress"] >= m  # one answer per sample
