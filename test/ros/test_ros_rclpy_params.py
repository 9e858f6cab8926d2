"""rclpy: live parameter changes on a controller node (accepted, refused, as a set, dumped).

Runs on a machine with ROS 2 Jazzy; skipped elsewhere. Sets go through the
node's parameter *services* (what ``ros2 param set`` and
``ros2 service call .../set_parameters_atomically`` use), from a second node.
"""

from __future__ import annotations

import pytest

rclpy = pytest.importorskip("rclpy")

import yaml  # noqa: E402
from pneu_msgs_py.contract.samples import SensorSample  # noqa: E402


@pytest.fixture
def ros():
    rclpy.init()
    yield
    rclpy.try_shutdown()


@pytest.fixture
def graph(ros):
    from pneu_control.nodes.controller_node import ControllerNode
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter_client import AsyncParameterClient

    ctrl = ControllerNode("linear")
    user = Node("pneu_test_user")
    ex = SingleThreadedExecutor()
    ex.add_node(ctrl)
    ex.add_node(user)
    client = AsyncParameterClient(user, "/linear_controller")
    assert client.wait_for_services(timeout_sec=10.0)

    def call(future):
        ex.spin_until_future_complete(future, timeout_sec=10.0)
        assert future.done()
        return future.result()

    yield ctrl, client, call
    user.destroy_node()
    ctrl.destroy_node()


def _feed_one_sample(ctrl, k=0):
    """The node's raw sensor callback with the payloads the sim node publishes."""
    from pneu_msgs_py.contract.wire import SensorWire

    s = SensorSample(k, k * 1_000_000, 2e5, 2e5, 1.5e5, 0.0, 0.0, 0.0, 0)
    for t, data in SensorWire().encode(s):
        if t in ctrl.core.topics:
            ctrl._on_sensor(t, data)


def test_set_integer_value_on_double_parameter_takes_effect_at_next_sample(graph):
    from rclpy.parameter import Parameter

    ctrl, client, call = graph
    res = call(
        client.set_parameters([Parameter("eso_smc.epsilon", value=900)])
    )  # like `ros2 param set ... 900`
    assert res.results[0].successful, res.results[0].reason
    assert ctrl.get_parameter("eso_smc.epsilon").value == 900.0
    assert ctrl.params.eso_smc.epsilon == 900.0
    assert ctrl.core.controller.params.eso_smc.epsilon != 900.0  # pending until a sample
    _feed_one_sample(ctrl)
    assert ctrl.core.controller.params.eso_smc.epsilon == 900.0


def test_out_of_range_refused_with_range_and_old_value_kept(graph):
    from rclpy.parameter import Parameter

    ctrl, client, call = graph
    before = ctrl.params
    res = call(client.set_parameters([Parameter("eso_smc.epsilon", value=-1.0)]))
    r = res.results[0]
    assert not r.successful
    assert "eso_smc.epsilon" in r.reason and "(0, inf" in r.reason
    assert (
        ctrl.params is before
        and ctrl.get_parameter("eso_smc.epsilon").value == before.eso_smc.epsilon
    )


def test_read_only_refused(graph):
    from rclpy.parameter import Parameter

    _ctrl, client, call = graph
    res = call(client.set_parameters([Parameter("sample_time_s", value=0.002)]))
    assert not res.results[0].successful and "read-only" in res.results[0].reason


def test_set_valid_only_together_is_validated_as_a_whole(graph):
    from rclpy.parameter import Parameter

    ctrl, client, call = graph
    T = ctrl.params.sample_time_s
    k = ctrl.params.eso_smc.k
    eps = 1.25 / (k * T)  # ε·k·T = 1.25 >= 1: refused alone
    k_new = 0.5 / (eps * T)  # with this k, ε·k·T = 0.5: fine together
    r = call(client.set_parameters_atomically([Parameter("eso_smc.epsilon", value=eps)])).result
    assert not r.successful and "eso_smc.k" in r.reason
    r = call(
        client.set_parameters_atomically(
            [Parameter("eso_smc.epsilon", value=eps), Parameter("eso_smc.k", value=k_new)]
        )
    ).result
    assert r.successful, r.reason
    assert (ctrl.params.eso_smc.epsilon, ctrl.params.eso_smc.k) == (eps, k_new)


def test_algorithm_switch_is_live(graph):
    from rclpy.parameter import Parameter

    ctrl, client, call = graph
    other = "pid" if ctrl.params.algorithm != "pid" else "ladrc"
    r = call(client.set_parameters([Parameter("algorithm", value=other)])).results[0]
    assert r.successful, r.reason
    _feed_one_sample(ctrl)
    assert ctrl.core.controller.algorithm == other
    r = call(client.set_parameters([Parameter("algorithm", value="bang_bang")])).results[0]
    assert not r.successful and "pid" in r.reason


def test_param_dump_is_accepted_back_as_params_file(graph, tmp_path):
    """What `ros2 param dump` prints (ros2param/verb/dump.py, Jazzy) re-loads with --params-file."""
    from pneu_control.nodes.controller_node import ControllerNode
    from rclpy.parameter import Parameter, parameter_value_to_python

    ctrl, client, call = graph
    call(client.set_parameters([Parameter("eso_smc.epsilon", value=950.0)]))
    names = sorted(call(client.list_parameters()).result.names)
    values = [parameter_value_to_python(v) for v in call(client.get_parameters(names)).values]
    dump: dict = {}
    for name, value in zip(names, values):
        d = dump
        *head, last = name.split(".")
        for part in head:
            d = d.setdefault(part, {})
        d[last] = value
    path = tmp_path / "dump.yaml"
    path.write_text(
        yaml.dump({"/linear_controller": {"ros__parameters": dump}}, default_flow_style=False)
    )
    again = ControllerNode("linear", cli_args=["--ros-args", "--params-file", str(path)])
    try:
        assert again.params == ctrl.params
        assert again.params.eso_smc.epsilon == 950.0
    finally:
        again.destroy_node()
