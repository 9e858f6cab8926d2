"""rclpy: the lockstep graph (sim + linear controller + logger) gives the runner's numbers.

Runs on a machine with ROS 2 Jazzy (``source /opt/ros/jazzy/setup.bash`` and
the workspace's ``install/setup.bash``); skipped elsewhere. The three nodes
run in this process on one executor, over the real middleware (the default
RMW), from the same parameters ``sim.launch.py`` gives them.
"""

from __future__ import annotations

import pytest

rclpy = pytest.importorskip("rclpy")

import yaml  # noqa: E402
from pneu_control.analysis.metrics import WindowSpec  # noqa: E402
from pneu_control.analysis.run_analysis import analyze  # noqa: E402
from pneu_control.experiment import session  # noqa: E402
from pneu_control.experiment.runner import run  # noqa: E402

DURATION_S = 5.0
SEED = 3
WINDOW_S = 1.0  # the sine's default window opens at 8 s: use a fixed one inside 5 s
_EXPECTED = (
    "/clock",
    "/pneu/pressure/cylinder_1",
    "/pneu/linear/joint_state",
    "/pneu/rotary/joint_state",
    "/pneu/linear/valve_command",
    "/pneu/linear/controller_state",
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
                "axes": "linear",
                "duration_s": DURATION_S,
                "seed": SEED,
                "safety": True,  # the supervisor of config/safety.yaml, as the runner has it
                "lockstep": {"timeout_s": 10.0},
                "startup": {"min_subscribers": 1},
            }
        },
        "linear_controller": {
            "ros__parameters": {
                "mode": "lockstep",
                "use_sim_time": True,
                "algorithm": "eso_smc",
                "reference": {"kind": "sine", "amplitude": 20.0, "frequency_hz": 0.25},
            }
        },
        "logger": {"ros__parameters": {"out": str(out), "mode": "lockstep", "use_sim_time": True}},
    }
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_lockstep_graph_equals_in_process_runner(ros, tmp_path):
    from pneu_control.nodes.controller_node import ControllerNode
    from pneu_control.nodes.logger_node import LoggerNode
    from pneu_sim.nodes.sim_node import SimNode
    from rclpy.executors import SingleThreadedExecutor

    out = tmp_path / "run"
    cli = ["--ros-args", "--params-file", str(_params_file(tmp_path, out))]
    logger = LoggerNode(cli_args=cli)
    ctrl = ControllerNode("linear", cli_args=cli)
    sim = SimNode(cli_args=cli)
    ex = SingleThreadedExecutor()
    for n in (logger, ctrl, sim):
        ex.add_node(n)
    try:
        ex.spin_until_future_complete(sim.done, timeout_sec=600.0)
        assert sim.done.done(), "lockstep run did not finish"
        counters = sim.done.result()
        assert counters["timeouts.linear"] == 0 and counters["stale.linear"] == 0
        n = round(DURATION_S * 1000)
        import time

        t_end = time.monotonic() + 120.0
        while time.monotonic() < t_end and not (  # the logger's backlog and the parameters
            all(logger.core.counts.get(t, 0) >= n for t in _EXPECTED)
            and {"/pneu_sim", "/linear_controller"} <= set(logger.core.node_params)
        ):
            ex.spin_once(timeout_sec=0.05)
        assert all(logger.core.counts.get(t, 0) == n for t in _EXPECTED), logger.core.counts
    finally:
        logger.core.close()
        for n in (sim, ctrl, logger):
            n.destroy_node()

    spec = session.build_spec(
        axes=("linear",),
        controller="eso_smc",
        reference="sine:amplitude=20.0,frequency_hz=0.25",
        duration_s=DURATION_S,
        seed=SEED,
        window_start_s=WINDOW_S,
    )
    ref = run(spec).metrics["linear"]
    got = analyze(out / "run.mcap", window=WindowSpec(kind="fixed", t_start_s=WINDOW_S))
    m = got.metrics["linear"]
    assert m.n_samples == ref.n_samples > 0
    assert m.e_max == pytest.approx(ref.e_max, abs=1e-9, rel=0)
    assert m.rmse == pytest.approx(ref.rmse, abs=1e-9, rel=0)
    # the logger recorded the graph's parameters as the run config
    assert got.config["seed"] == SEED and got.config["axes"] == ["linear"]
    assert got.config["controllers"]["linear"]["algorithm"] == "eso_smc"
