"""rclpy: the excitation over ROS (sim + exciter + logger, lockstep) is the in-process one.

Runs on a machine with ROS 2 Jazzy (skipped elsewhere). The three nodes run
in this process on one executor over the real middleware, with the
parameters ``excite.launch.py`` gives them; the logger's bag must hold the
in-process ``pneu excite`` samples and voltages exactly, and the design,
read back by ``pneu identify``'s loader from the logger's record of the
exciter's parameters.
"""

from __future__ import annotations

import pytest

rclpy = pytest.importorskip("rclpy")

import numpy as np  # noqa: E402
import yaml  # noqa: E402
from pneu_control.sysid.design import design_for  # noqa: E402
from pneu_control.sysid.excite import excitation_spec  # noqa: E402
from pneu_control.sysid.record import load_record  # noqa: E402
from pneu_sim.physics.plant_file import load_plant  # noqa: E402

DURATION_S = 4.0  # the first segments: quiet, then closed-loop moves and a pulse
SEED = 5
_EXPECTED = (
    "/pneu/linear/joint_state",
    "/pneu/rotary/joint_state",
    "/pneu/linear/valve_command",
    "/pneu/rotary/valve_command",
)


@pytest.fixture
def ros():
    rclpy.init()
    yield
    rclpy.try_shutdown()


def _params_file(tmp_path, out):
    doc = {
        "pneu_sim": {
            "ros__parameters": {
                "mode": "lockstep",
                "axes": "both",
                "duration_s": DURATION_S,
                "seed": SEED,
                "safety": True,
                "startup": {"min_subscribers": 2, "timeout_s": 10.0, "wait_for_logger": True},
            }
        },
        "pneu_exciter": {
            "ros__parameters": {
                "axes": "both",
                "seed": SEED,
                "level": "quick",
                "mode": "lockstep",
                "use_sim_time": True,
            }
        },
        "logger": {
            "ros__parameters": {
                "out": str(out),
                "mode": "lockstep",
                "use_sim_time": True,
                "recorder": "pneu",
                "bag_name": "run.mcap",
            }
        },
    }
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_lockstep_excitation_equals_in_process(ros, tmp_path):
    import time

    from pneu_control.nodes.exciter_node import ExciterNode
    from pneu_control.nodes.logger_node import LoggerNode
    from pneu_sim.nodes.sim_node import SimNode
    from rclpy.executors import SingleThreadedExecutor

    out = tmp_path / "run"
    cli = ["--ros-args", "--params-file", str(_params_file(tmp_path, out))]
    logger = LoggerNode(cli_args=cli)
    exciter = ExciterNode(cli_args=cli)
    sim = SimNode(cli_args=cli)
    ex = SingleThreadedExecutor()
    for n in (logger, exciter, sim):
        ex.add_node(n)
    try:
        ex.spin_until_future_complete(sim.done, timeout_sec=600.0)
        assert sim.done.done(), "lockstep run did not finish"
        counters = sim.done.result()
        assert counters["timeouts.linear"] == 0 and counters["timeouts.rotary"] == 0
        n = round(DURATION_S * 1000)
        t_end = time.monotonic() + 120.0
        while time.monotonic() < t_end and not (
            all(logger.core.counts.get(t, 0) >= n for t in _EXPECTED)
            and "/pneu_exciter" in logger.core.node_params
        ):
            ex.spin_once(timeout_sec=0.05)
        assert all(logger.core.counts.get(t, 0) == n for t in _EXPECTED), logger.core.counts
    finally:
        logger.core.close()
        for node in (sim, exciter, logger):
            node.destroy_node()

    rec = load_record(out / "run.mcap")
    assert rec.designs == {a: design_for(a, SEED, "quick") for a in ("linear", "rotary")}
    from pneu_control.experiment.runner import run

    spec = excitation_spec(("linear", "rotary"), load_plant(), seed=SEED, level="quick")
    from dataclasses import replace

    ref = run(replace(spec, duration_s=DURATION_S))
    m = min(rec.n, len(ref.t))
    assert m >= n - 1
    for k in ("x", "p_c1", "p_c2", "p_m1", "omega"):
        assert np.array_equal(rec.y[k][:m], ref.samples[k][:m]), k
    for axis in ("linear", "rotary"):
        assert np.array_equal(rec.u[axis][:m], ref.applied[axis][:m]), axis
        assert np.ptp(rec.u[axis][:m]) > 0.1  # it excited
