"""LoggerCore: raw CDR from the (loopback) graph -> an MCAP the project's analysis reads.

The bytes are those of the lockstep graph's messages (rosbags Jazzy CDR, as
rclpy hands them to a ``raw=True`` subscription); the node parameters are
what the logger would fetch from the running nodes.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from pneu_control.analysis.run_analysis import analyze
from pneu_control.experiment import session
from pneu_control.experiment.runner import run
from pneu_control.nodes.logger_core import (
    LOGGED_TOPICS,
    LoggerCore,
    run_config_from_params,
    stamp_from_cdr,
)
from pneu_control.nodes.loopback import run_loopback
from pneu_msgs_py.contract.convert import typestore_messages
from pneu_msgs_py.contract.topics import TOPIC_BY_NAME
from pneu_msgs_py.params.ros import values_to_overrides
from rosbags.highlevel import AnyReader

TS = typestore_messages()
T = TS.types


def _time(ns):
    return T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def _header(ns, frame=""):
    return T["std_msgs/msg/Header"](stamp=_time(ns), frame_id=frame)


@pytest.mark.parametrize("stamp_ns", [0, 1_000_000, 1_234_567_890_123, 2**31 * 10**9 - 1])
def test_stamp_from_cdr_reads_header_and_clock_stamps(stamp_ns):
    msgs = {
        "sensor_msgs/msg/FluidPressure": T["sensor_msgs/msg/FluidPressure"](
            header=_header(stamp_ns, "cylinder_1"), fluid_pressure=2e5, variance=0.0
        ),
        "sensor_msgs/msg/JointState": T["sensor_msgs/msg/JointState"](
            header=_header(stamp_ns),
            name=["linear"],
            position=np.array([0.01]),
            velocity=np.zeros(0),
            effort=np.zeros(0),
        ),
        "rosgraph_msgs/msg/Clock": T["rosgraph_msgs/msg/Clock"](clock=_time(stamp_ns)),
        "diagnostic_msgs/msg/DiagnosticArray": T["diagnostic_msgs/msg/DiagnosticArray"](
            header=_header(stamp_ns), status=[]
        ),
    }
    for ros_type, msg in msgs.items():
        assert stamp_from_cdr(TS.serialize_cdr(msg, ros_type)) == stamp_ns, ros_type
        assert stamp_from_cdr(TS.serialize_cdr(msg, ros_type, little_endian=False)) == stamp_ns
    with pytest.raises(ValueError, match="no stamp"):
        stamp_from_cdr(b"\x00\x01\x00\x00")


def test_logged_topics_are_the_topic_table():
    assert {t for t, _ in LOGGED_TOPICS} == set(TOPIC_BY_NAME)
    assert dict(LOGGED_TOPICS)["/clock"] == "rosgraph_msgs/msg/Clock"


FAULT = "sensor_dropout:sensor=x,start_s=1.2,duration_s=0.02"


def _graph_params(spec):
    params = {
        f"/{axis}_controller": {**values_to_overrides(p), "use_sim_time": True, "mode": "lockstep"}
        for axis, p in spec.controllers.items()
    }
    params["/pneu_sim"] = {
        "seed": spec.seed,
        "duration_s": spec.duration_s,
        "x0": spec.x0,
        "plant_file": "",
        "mode": "lockstep",
        "safety": True,
        "safety_file": "",
        "faults": FAULT,
        "faults_file": "",
    }
    params["/logger"] = {"out": "/tmp/x", "use_sim_time": True}
    return params


def test_logger_bag_gives_the_runners_metrics_through_the_projects_analysis(tmp_path):
    spec = session.build_spec(
        axes=("linear", "rotary"),
        controller="eso_smc",
        sets=[
            "linear.reference.kind=sine",
            "linear.reference.amplitude=5.0",
            "linear.reference.frequency_hz=2.0",
            "rotary.reference.kind=sine",
            "rotary.reference.amplitude=100.0",
            "rotary.reference.frequency_hz=2.0",
        ],
        duration_s=1.5,
        seed=4,
        faults=[FAULT],
    )
    ref = run(spec)
    assert ref.safety_counters["trips"] >= 1  # the dropout holds the linear valve safe
    path = tmp_path / "run.mcap"
    log = LoggerCore(path, mode="lockstep")
    for node, values in _graph_params(spec).items():
        log.set_node_params(node, values)
    log.on_parameter_event(123, "/linear_controller", {"eso_smc.epsilon": 1200.0})
    run_loopback(
        spec, tap=lambda topic, ros_type, data: log.on_message(topic, ros_type, data, -1, -1)
    )
    log.close()
    log.close()  # idempotent

    res = analyze(path)
    assert set(res.metrics) == {"linear", "rotary"}
    assert res.faults == ref.fault_intervals  # injected + safe intervals, as the runner marks them
    for axis, m in ref.metrics.items():
        assert m.n_samples > 0
        got = res.metrics[axis]
        assert got.n_samples == m.n_samples
        assert got.window_start_s == m.window_start_s
        assert got.e_max == pytest.approx(m.e_max, abs=1e-9, rel=0)
        assert got.rmse == pytest.approx(m.rmse, abs=1e-9, rel=0)
    assert res.traces["linear"].algorithm == "eso_smc"
    assert res.config["seed"] == 4 and res.config["source"] == "sim"
    assert res.config["controllers"]["rotary"]["reference"]["amplitude"] == 100.0
    assert res.config["plant"]  # the sim's plant.yaml, as the runner records it

    # an independent reader: every topic, log time = the message stamp (runner layout)
    with AnyReader([path]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert topics["/pneu/linear/valve_command"] == "sensor_msgs/msg/JointState"
        assert topics["/clock"] == "rosgraph_msgs/msg/Clock"
        n = 0
        for conn, t_log, raw in reader.messages():
            if conn.topic == "/pneu/linear/joint_state":
                msg = reader.deserialize(raw, conn.msgtype)
                assert t_log == msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
                n += 1
        assert n == 1500
    assert log.counts["/pneu/pressure/motor_in"] == 1500 and log.bad == 0

    from pneu_msgs_py.bag.reader import read_run

    meta = read_run(path).metadata
    assert json.loads(meta["pneu.params/linear_controller"]["eso_smc.epsilon"]) == 1200.0
    assert json.loads(meta["pneu.params/pneu_sim"]["seed"]) == 4
    changes = json.loads(meta["pneu.param_changes"]["changes_json"])
    assert changes == [
        {"stamp_ns": 123, "node": "/linear_controller", "name": "eso_smc.epsilon", "value": 1200.0}
    ]


def test_realtime_mode_keeps_receive_and_source_times(tmp_path):
    path = tmp_path / "rt.mcap"
    log = LoggerCore(path, mode="realtime")
    msg = T["rosgraph_msgs/msg/Clock"](clock=_time(5))
    log.on_message(
        "/clock",
        "rosgraph_msgs/msg/Clock",
        bytes(TS.serialize_cdr(msg, "rosgraph_msgs/msg/Clock")),
        900,
        800,
    )
    log.close()
    with AnyReader([path]) as reader:
        ((_conn, t_log, _raw),) = list(reader.messages())
        assert t_log == 900


def test_run_config_without_controllers_or_with_a_bad_set_reports_problems():
    cfg = run_config_from_params({"/pneu_driver": {"axes": "both"}})
    assert cfg["axes"] == [] and cfg["source"] == "rig"
    cfg = run_config_from_params({"/linear_controller": {"algorithm": "bang_bang"}})
    assert cfg["axes"] == [] and "algorithm" in cfg["problems"][0]
