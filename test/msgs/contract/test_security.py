"""The graph's SROS2 policy, read back as SROS2 reads it: who may publish, subscribe, call, serve.

The policy is parsed with an independent XML reader and expanded as sros2's
``permissions.xsl`` expands names (``~/x`` = the profile's node); the properties are
the security claims of DESIGN §13, checked for every topic of the table.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest
from pneu_msgs_py.contract import security as S
from pneu_msgs_py.contract.topics import (
    JOINT_STATE_TOPIC,
    PRESSURE_TOPICS,
    TASK_PROGRESS_TOPIC,
    TOPICS,
    VALVE_COMMAND_TOPIC,
)


def _grants(xml: str) -> dict[str, dict[str, set[str]]]:
    """enclave path -> {publish, subscribe, request, reply} -> fully qualified names."""
    root = ET.fromstring(xml.encode())
    assert root.tag == "policy" and root.get("version") == "0.2.0"
    out = {}
    for enc in root.iter("enclave"):
        g = {"publish": set(), "subscribe": set(), "request": set(), "reply": set()}
        for prof in enc.iter("profile"):
            node, ns = prof.get("node"), prof.get("ns")
            assert ns == "/"
            for group in prof:
                for what, allow in group.attrib.items():
                    assert allow == "ALLOW" and what in g
                    for el in group:
                        name = el.text
                        fq = f"/{node}{name[1:]}" if name.startswith("~") else name
                        assert fq.startswith("/"), fq
                        g[what].add(fq)
        out[enc.get("path")] = g
    return out


def _who(grants, what, name):
    return {path for path, g in grants.items() if name in g[what]}


def test_every_topic_of_the_table_has_its_permissions_row():
    assert set(S.TOPIC_ROLES) == {t.name for t in TOPICS}
    for name, (pubs, subs) in S.TOPIC_ROLES.items():
        assert pubs, name
        for role in (*pubs, *subs):
            assert role in S.ROLES or role == "operator", (name, role)


def test_only_the_axis_controller_commands_its_valve():
    g = _grants(S.policy_xml(("alice",)))
    for axis, topic in VALVE_COMMAND_TOPIC.items():
        other = "rotary" if axis == "linear" else "linear"
        pubs = _who(g, "publish", topic)
        assert pubs == {
            S.enclave(f"{axis}_controller"),
            S.enclave("controller_manager"),
            S.enclave("exciter"),
        }
        assert S.enclave(f"{other}_controller") not in pubs
        assert S.operator_enclave("alice") not in pubs  # an operator never writes a valve
        assert S.enclave("io") in _who(g, "subscribe", topic)


def test_only_the_driver_or_sim_publishes_samples_and_only_the_task_runner_progress():
    g = _grants(S.policy_xml())
    for topic in (*PRESSURE_TOPICS, *JOINT_STATE_TOPIC.values()):
        assert _who(g, "publish", topic) == {S.enclave("io"), S.enclave("controller_manager")}
    assert _who(g, "publish", TASK_PROGRESS_TOPIC) == {S.enclave("task_runner")}


def test_the_safety_services_are_callable_by_the_named_operators_only():
    g = _grants(S.policy_xml(("alice", "bob")))
    for node in ("pneu_driver", "pneu_sim"):
        for srv in ("estop", "reset"):
            name = f"/{node}/{srv}"
            assert _who(g, "request", name) == {
                S.operator_enclave("alice"),
                S.operator_enclave("bob"),
            }
            assert S.enclave("io") in _who(g, "reply", name)
    assert _who(g, "request", "/task_runner/abort") == {
        S.operator_enclave("alice"),
        S.operator_enclave("bob"),
    }
    # without operators nobody may call them
    g0 = _grants(S.policy_xml())
    assert not _who(g0, "request", "/pneu_driver/estop")
    # parameters: the logger reads every node's; operators set them; nobody else
    setp = "/linear_controller/set_parameters"
    assert _who(g, "request", setp) == {
        S.enclave("logger"),
        S.operator_enclave("alice"),
        S.operator_enclave("bob"),
    }


def test_names_and_the_enclave_each_executable_starts_in():
    with pytest.raises(ValueError, match="operator: 'a b' refused"):
        S.operator_enclave("a b")
    env = {"ROS_SECURITY_ENABLE": "true"}
    assert S.select_enclave("linear_controller", env, []) == "/pneu/linear_controller"
    assert env["ROS_SECURITY_ENCLAVE_OVERRIDE"] == "/pneu/linear_controller"
    # the user's choice wins: the variable, or --enclave among the ROS arguments
    env = {"ROS_SECURITY_ENABLE": "true"}
    assert S.select_enclave("sim_node", env, ["x", "--ros-args", "-e", "/mine"]) is None
    assert "ROS_SECURITY_ENCLAVE_OVERRIDE" not in env
    assert S.select_enclave("sim_node", {}, []) is None  # security off: nothing set
    for exe, role in S.EXECUTABLE_ROLE.items():
        assert role in S.ROLES, exe


def test_a_second_driver_or_sim_on_the_domain_is_named(monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", "83")
    assert S.second_io({t: 1 for t in PRESSURE_TOPICS}) is None
    msg = S.second_io({"/pneu/pressure/cylinder_1": 1, "/pneu/linear/joint_state": 3})
    assert "/pneu/linear/joint_state on ROS_DOMAIN_ID 83 (2 more" in msg and "e-stop" in msg
