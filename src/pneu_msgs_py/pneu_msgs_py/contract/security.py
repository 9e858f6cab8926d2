"""Who may do what on the graph: SROS2 enclaves and their permissions, from the topic table.

DDS-Security (SROS2) authenticates each process by its enclave's certificate and
lets it publish, subscribe, call and serve only what its signed permissions list.
The graph's permissions are written here once, per *role*, and rendered as an SROS2
policy (``policy.xsd`` 0.2.0) that ``pneu_msgs_py security`` (the shell in
:mod:`pneu_msgs_py.nodes.security`) turns into a keystore (DESIGN §13):

- only the driver / sim (role ``io``) publishes the samples and ``/clock``;
- only the axis' controller (and, for an excitation, the exciter) publishes its
  valve command; the hosted controller manager is both, in one process;
- only the task runner publishes a task's progress (it aborts a task: the e-stop);
- the safety services (``~/estop``, ``~/reset`` of ``/pneu_driver`` and ``/pneu_sim``)
  and the task runner's ``~/start`` / ``~/abort`` are callable only by the operator
  enclaves the user names; parameters (``ros2 param set``) likewise;
- everyone publishes ``/diagnostics``, ``/rosout`` and ``/parameter_events``.

Every topic of :data:`~pneu_msgs_py.contract.topics.TOPICS` has its row in
:data:`TOPIC_ROLES` (a test keeps the two together), so a new topic cannot be
forgotten and is denied by default.
"""

from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass

from pneu_msgs_py.contract.topics import TOPICS, TopicSpec

__all__ = [
    "ENCLAVE_ROOT",
    "ROLES",
    "TOPIC_ROLES",
    "Role",
    "enclave",
    "operator_enclave",
    "EXECUTABLE_ROLE",
    "policy_xml",
    "second_io",
    "select_enclave",
]

ENCLAVE_ROOT = "/pneu"


@dataclass(frozen=True)
class Role:
    """One enclave: the nodes its process holds and what it may do beyond every node's basics."""

    name: str
    nodes: tuple[str, ...]
    serves: tuple[str, ...] = ()  # private services (``~/x``) of its nodes
    calls_all_parameters: bool = False  # the parameter services of every node
    calls: tuple[str, ...] = ()  # services by full name (wildcards allowed)
    publishes: tuple[str, ...] = ()  # topics outside pneu's table it must publish


#: role -> nodes (the process's node names) and services
ROLES: dict[str, Role] = {
    r.name: r
    for r in (
        Role("io", ("pneu_driver", "pneu_sim"), serves=("estop", "reset")),
        Role("linear_controller", ("linear_controller",)),
        Role("rotary_controller", ("rotary_controller",)),
        Role(
            "controller_manager",
            (
                "controller_manager",
                "pneu_driver",
                "pneu_sim",
                "linear_controller",
                "rotary_controller",
            ),
            serves=("estop", "reset"),
        ),
        Role("task_runner", ("task_runner",), serves=("start", "abort")),
        Role("exciter", ("pneu_exciter",)),
        Role("logger", ("logger",), calls_all_parameters=True),
        # ros2 bag record: its node's services (pause, resume, snapshot, split, ...) and
        # rosbag2's split event (Jazzy: the recorder will not start without its publisher)
        Role(
            "recorder",
            ("rosbag2_recorder",),
            serves=("*",),
            publishes=("/events/write_split",),
        ),
    )
}

_CONTROLLER = {"linear": "linear_controller", "rotary": "rotary_controller"}
_READERS = ("logger", "recorder")


def _row(t: TopicSpec) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(publishing roles, subscribing roles) of topic ``t``, by its kind."""
    ctl = ("linear_controller", "rotary_controller", "controller_manager", "task_runner")
    if t.kind in ("pressure", "joint_state"):
        return ("io", "controller_manager"), (*ctl, "exciter", *_READERS)
    if t.kind == "valve_command":
        own = _CONTROLLER[t.axis]
        return (own, "controller_manager", "exciter"), ("io", "controller_manager", *_READERS)
    if t.kind == "controller_state":
        return (_CONTROLLER[t.axis], "controller_manager", "exciter"), _READERS
    if t.kind == "trajectory":  # the task runner, or an operator's own planner
        return ("task_runner", "operator"), (
            "linear_controller",
            "rotary_controller",
            "controller_manager",
            *_READERS,
        )
    if t.kind == "task_progress":
        return ("task_runner",), ("io", "controller_manager", *_READERS)
    if t.kind == "diagnostics":  # the controllers read the supervisor's holds of their axis
        return (*ROLES, "operator"), (*ctl, "operator", *_READERS)
    if t.kind == "clock":
        return ("io", "controller_manager"), (*ROLES, "operator")
    raise KeyError(f"topic {t.name}: kind {t.kind!r} has no permissions row")


#: topic name -> (publishing roles, subscribing roles)
TOPIC_ROLES: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {t.name: _row(t) for t in TOPICS}

_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


def enclave(role: str) -> str:
    """The enclave path of ``role`` (``/pneu/linear_controller``)."""
    return f"{ENCLAVE_ROOT}/{role}"


def operator_enclave(name: str) -> str:
    """An operator's enclave (``/pneu/operator_<name>``; ``name`` a ROS name token)."""
    if not _NAME.match(name):
        raise ValueError(
            f"operator: {name!r} refused; allowed: a name of letters, digits and _ (starting with a letter)"
        )
    return f"{ENCLAVE_ROOT}/operator_{name}"


#: the graph's executables (``run_node``'s names) -> their role
EXECUTABLE_ROLE = {
    "driver_node": "io",
    "sim_node": "io",
    "linear_controller": "linear_controller",
    "rotary_controller": "rotary_controller",
    "controller_manager": "controller_manager",
    "task_runner": "task_runner",
    "exciter": "exciter",
    "logger": "logger",
}


def select_enclave(executable: str, env: dict, argv: list[str]) -> str | None:
    """With security on (``ROS_SECURITY_ENABLE=true``), start ``executable`` in its role's
    enclave: sets ``ROS_SECURITY_ENCLAVE_OVERRIDE`` in ``env`` unless the user chose one
    (that variable, or ``--enclave``/``-e`` among the ROS arguments); the enclave set, or None."""
    if env.get("ROS_SECURITY_ENABLE", "").lower() != "true":
        return None
    if env.get("ROS_SECURITY_ENCLAVE_OVERRIDE"):
        return None
    if "--ros-args" in argv:
        ros = argv[argv.index("--ros-args") + 1 :]
        if "--enclave" in ros or "-e" in ros:
            return None
    role = EXECUTABLE_ROLE.get(executable)
    if role is None:
        return None
    env["ROS_SECURITY_ENCLAVE_OVERRIDE"] = enclave(role)
    return env["ROS_SECURITY_ENCLAVE_OVERRIDE"]


_PARAM_SERVICES = (
    "describe_parameters",
    "get_parameter_types",
    "get_parameters",
    "get_type_description",
    "list_parameters",
    "set_parameters",
    "set_parameters_atomically",
)
_ALL_NODES = sorted({n for r in ROLES.values() for n in r.nodes})


def _topics(parent: ET.Element, attr: str, names: list[str]) -> None:
    if names:
        el = ET.SubElement(parent, "topics", {attr: "ALLOW"})
        for n in names:
            ET.SubElement(el, "topic").text = n


def _services(parent: ET.Element, attr: str, names: list[str]) -> None:
    if names:
        el = ET.SubElement(parent, "services", {attr: "ALLOW"})
        for n in names:
            ET.SubElement(el, "service").text = n


def _profile(
    profiles: ET.Element, node: str, role: str, serves: tuple[str, ...], calls: list[str]
) -> None:
    """One node's profile: the role's topics, the node's basics, its services."""
    p = ET.SubElement(profiles, "profile", {"ns": "/", "node": node})
    pub = sorted(name for name, (pubs, _) in TOPIC_ROLES.items() if role in pubs)
    pub += ROLES[role].publishes if role in ROLES else ()
    sub = sorted(name for name, (_, subs) in TOPIC_ROLES.items() if role in subs)
    _topics(p, "publish", [*pub, "/parameter_events", "/rosout"])
    _topics(p, "subscribe", [*sub, "/parameter_events"])
    _services(p, "reply", [f"~/{s}" for s in (*_PARAM_SERVICES, *serves)])
    _services(p, "request", calls)


def _all_parameter_services() -> list[str]:
    return [f"/{n}/{s}" for n in _ALL_NODES for s in _PARAM_SERVICES]


def policy_xml(operators: tuple[str, ...] = ()) -> str:
    """The SROS2 policy (version 0.2.0) of the graph's enclaves and of ``operators``.

    An operator (``ros2 param set``, ``ros2 service call .../estop``, a trajectory of
    its own) may call the safety and task services and every node's parameters and
    publish a trajectory; nobody else calls them. Names are SROS2 names (``~/`` =
    the profile's node).
    """
    root = ET.Element("policy", {"version": "0.2.0"})
    encl = ET.SubElement(root, "enclaves")
    for r in ROLES.values():
        e = ET.SubElement(encl, "enclave", {"path": enclave(r.name)})
        profiles = ET.SubElement(e, "profiles")
        calls = [*(_all_parameter_services() if r.calls_all_parameters else ()), *r.calls]
        for node in r.nodes:
            _profile(profiles, node, r.name, r.serves, calls)
    safety = [f"/{n}/{s}" for n in ROLES["io"].nodes for s in ROLES["io"].serves]
    task = [f"/task_runner/{s}" for s in ROLES["task_runner"].serves]
    for name in operators:
        e = ET.SubElement(encl, "enclave", {"path": operator_enclave(name)})
        profiles = ET.SubElement(e, "profiles")
        # the operator's command-line tools each start a node of their own name: any node
        _profile(profiles, "*", "operator", (), [*safety, *task, *_all_parameter_services()])
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def second_io(sample_publishers: dict[str, int]) -> str | None:
    """Another driver or sim on this domain? ``sample_publishers``: the publisher count the
    graph shows on each sample topic (this node's own included). A sentence saying so, or None.

    Two graphs on one domain would feed each one's controllers the other's samples; the
    node that sees it latches its e-stop (DESIGN §13).
    """
    extra = {t: n - 1 for t, n in sample_publishers.items() if n > 1}
    if not extra:
        return None
    domain = os.environ.get("ROS_DOMAIN_ID", "0")
    worst = max(extra, key=extra.get)
    return (
        f"another driver or sim publishes {worst} on ROS_DOMAIN_ID {domain} "
        f"({extra[worst]} more publisher(s)): two graphs on one domain; e-stop latched"
    )
