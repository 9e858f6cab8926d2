"""What ``sim.launch.py`` and ``rig.launch.py`` share: arguments, controllers and recording.

The two launch files differ only in what drives the rig (the sim node or
the driver node). Everything else is built here once (``pneu_control``'s
executables are named as strings, so that neither pneu_sim nor pneu_driver
imports pneu_control, DESIGN §2):

- ``deployment:=nodes`` -- one controller node per active axis, separate
  processes talking over topics; ``deployment:=hosted`` -- the hard-1 kHz
  deployment: ``pneu_control controller_manager`` runs the sim's or the
  driver's loop and the controller cores in one process (the nodes keep
  their names, parameters and topics);
- recording: ``recorder:=rosbag2`` (``ros2 bag record -s mcap`` with QoS
  overrides from the topic table, into ``<out>/bag``; the logger node adds the
  run metadata beside it) or ``recorder:=pneu`` (the logger node writes
  ``<out>/run.mcap`` itself); ``auto`` = pneu in lockstep, rosbag2 in realtime;
- ``executor:=events|single|auto`` for every node (default: each node's own);
- the run ends with the process on the I/O side (the sim, the driver, the hosted
  manager) and with any recording process (``ros2 bag record``, the logger): a run whose
  record stopped is stopped, not left moving unrecorded (:func:`exit_action`: one line
  says which process ended, how, and what it means; the others then stop cleanly).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pneu_msgs_py.params.spec import parse_spec

__all__ = [
    "AXES_OF",
    "GAIN_FILES",
    "common_parameters",
    "controller_node",
    "controller_and_logger_nodes",
    "controller_overrides",
    "exit_action",
    "io_exit",
    "IO_SIGTERM_TIMEOUT",
    "hosted_manager",
    "recorder_choice",
    "rosbag2_qos_overrides",
    "rosbag2_recorder",
    "launch_arguments",
    "io_node",
    "launch_description",
    "realtime_priority",
    "security_actions",
    "logger_node",
    "reference_overrides",
]

GAIN_FILES = {"paper": "controllers.yaml", "retuned": "controllers_retuned.yaml"}
AXES_OF = {"linear": ("linear",), "rotary": ("rotary",), "both": ("linear", "rotary")}
ALGORITHM_CHOICES = ["", "pid", "ladrc", "eso_smc", "eso_smc_plus"]


def launch_arguments(gains_default: str, gains_why: str) -> list[tuple[str, str, str, list | None]]:
    """(name, default, description, choices) of the arguments both launch files take."""
    return [
        (
            "deployment",
            "nodes",
            "nodes: a process per controller, over topics; hosted: the controllers run inside "
            "the 1 kHz loop's process (hard real time, like ros2_control's controller manager)",
            ["nodes", "hosted"],
        ),
        (
            "recorder",
            "auto",
            "rosbag2: ros2 bag record into <out>/bag (+ run metadata); pneu: the logger node "
            "writes <out>/run.mcap; auto: pneu in lockstep, rosbag2 in realtime",
            ["auto", "pneu", "rosbag2"],
        ),
        (
            "executor",
            "",
            "rclpy executor of every node: events, single or auto ('' = each node's default)",
            ["", "events", "single", "auto"],
        ),
        (
            "state_rate_hz",
            "0",
            "controller_state rate (0 = every tick in lockstep, 100 Hz in realtime)",
            None,
        ),
        (
            "controller",
            "",
            "algorithm of every active controller (pid, ladrc, eso_smc, eso_smc_plus); "
            "'' = the gain file's",
            ALGORITHM_CHOICES,
        ),
        (
            "reference",
            "",
            "reference of every active axis, KIND[:key=value,...] in mm / rpm; '' = the gain file's",
            None,
        ),
        (
            "gains",
            gains_default,
            "controller gain set: paper (controllers.yaml) or retuned (controllers_retuned.yaml); "
            f"default: {gains_why}",
            list(GAIN_FILES),
        ),
        ("linear_reference", "", "reference of the linear axis only (wins over reference)", None),
        ("rotary_reference", "", "reference of the rotary axis only (wins over reference)", None),
        ("axes", "both", "active axes (the others hold 5 V)", list(AXES_OF)),
        (
            "rt_priority",
            "50",
            "realtime: SCHED_FIFO priority of the 1 kHz loop thread; every other thread of its "
            "process and the controllers' processes run one below, their memory locked (0 = "
            "normal scheduling; an account without the privilege: one line, then normal)",
            None,
        ),
    ]


def reference_overrides(text: str, field: str = "reference") -> dict[str, Any]:
    """``sine:amplitude=20`` -> ``{"reference.kind": "sine", "reference.amplitude": 20.0}``.

    Numbers become floats: the reference parameters are doubles, and a ROS
    double parameter refuses an integer.
    """
    if not text:
        return {}
    kind, values = parse_spec(text, field)
    out: dict[str, Any] = {"reference.kind": kind}
    for key, v in values.items():
        number = isinstance(v, (int, float)) and not isinstance(v, bool)
        out[f"reference.{key}"] = float(v) if number else v
    return out


def common_parameters(arg: dict[str, str]) -> dict[str, Any]:
    """Parameters every node of the graph takes from the launch arguments."""
    return {"executor": arg["executor"]} if arg["executor"] else {}


def controller_overrides(arg: dict[str, str], axis: str, mode: str) -> dict[str, Any]:
    """A controller node's parameters from the launch arguments (on top of the gain file)."""
    rt = int(arg["rt_priority"])
    over: dict[str, Any] = {
        "mode": mode,
        "use_sim_time": mode == "lockstep",
        "state_rate_hz": float(arg["state_rate_hz"]),
        "rt_priority": rt - 1 if mode == "realtime" and rt > 1 else 0,
        **common_parameters(arg),
    }
    if arg["controller"]:
        over["algorithm"] = arg["controller"]
    over.update(reference_overrides(arg["reference"]))
    over.update(reference_overrides(arg[f"{axis}_reference"], f"{axis}_reference"))
    return over


def recorder_choice(arg: dict[str, str], mode: str) -> str:
    """pneu or rosbag2 (``auto``: pneu in lockstep, rosbag2 in realtime)."""
    choice = arg["recorder"]
    if choice == "auto":
        return "pneu" if mode == "lockstep" else "rosbag2"
    return choice


def controller_and_logger_nodes(
    arg: dict[str, str], config_dir: str, *, mode: str, out: str
) -> list[Any]:
    """One controller node per active axis (``deployment:=nodes``), the recorder and the logger."""
    import os

    recorder = recorder_choice(arg, mode)
    bag = os.path.join(out, "bag" if recorder == "rosbag2" else "run.mcap")
    if os.path.exists(bag):  # a run is never overwritten
        raise RuntimeError(f"out: {bag} exists; choose another out:= for this run")
    nodes = []
    if arg["deployment"] == "nodes":
        for axis in AXES_OF[arg["axes"]]:
            nodes.append(
                controller_node(
                    axis,
                    [
                        f"{config_dir}/{GAIN_FILES[arg['gains']]}",
                        controller_overrides(arg, axis, mode),
                    ],
                )
            )
    if recorder == "rosbag2":
        rt = int(arg.get("rt_priority", "0"))
        prio = rt - RECORDER_BELOW if mode == "realtime" and rt > RECORDER_BELOW else 0
        nodes.append(rosbag2_recorder(out, mode, prio))
    nodes.append(logger_node(out, mode, recorder, common_parameters(arg)))
    return nodes


def controller_node(axis: str, parameters: list) -> Any:
    """The ``<axis>_controller`` node (its own process) with ``parameters`` (files, dicts)."""
    from launch_ros.actions import Node

    return Node(
        package="pneu_control",
        executable=f"{axis}_controller",
        name=f"{axis}_controller",
        output="screen",
        parameters=parameters,
    )


def exit_action(process: str, finished: str | None, meaning: str = "") -> Callable:
    """``on_exit`` of a process whose end ends the run: the launch shuts down -- with reason
    ``finished`` on a clean exit (None: any exit of ``process`` stops the run); after a crash
    or a kill (a non-zero exit code, a signal) one ERROR line first: which process, how it
    ended, ``meaning`` (what that leaves behind). Nothing while the launch is already
    shutting down (Ctrl-C, the run's end)."""

    def on_exit(event: Any, context: Any) -> list | None:
        from launch.actions import Shutdown
        from launch.logging import get_logger

        if context.is_shutdown:
            return None
        rc = event.returncode
        if rc == 0:
            return [Shutdown(reason=finished or f"{process} stopped")]
        how = f"killed by signal {-rc}" if rc is not None and rc < 0 else f"exit code {rc}"
        line = f"{process} ended ({how}) before the run did: run stopped" + (
            f"; {meaning}" if meaning else ""
        )
        get_logger("launch").error(line)
        return [Shutdown(reason=line)]

    return on_exit


#: what a killed I/O process leaves behind (:func:`exit_action`'s ``meaning``)
SIM_DIED = "the twin is gone: the controllers get no samples and command nothing"
DRIVER_DIED = (
    "the DAQ loop is gone: the card keeps driving its last outputs and the heartbeat "
    "stopped (the watchdog relay drops the air: docs/rig.md)"
)


#: SIGINT -> SIGTERM of the processes that hold many reliable writers (the sim, the driver,
#: the hosted manager): a recorder killed earlier stays matched until its DDS lease ends, and
#: rmw_cyclonedds lingers 1 s per writer on deletion for its unacknowledged samples --
#: measured 5-7 s for the sim's shutdown after a SIGKILLed ``ros2 bag record`` (its loop,
#: and the valves, stopped first); launch's default 5 s then escalated to SIGTERM.
IO_SIGTERM_TIMEOUT = "20"


def io_exit(target: str) -> Callable:
    """``on_exit`` of the I/O side of ``target`` (sim or rig): its end ends the run."""
    if target == "sim":
        return exit_action("pneu_sim", "simulation finished", SIM_DIED)
    return exit_action("pneu_driver", "driver stopped", DRIVER_DIED)


def io_node(target: str, params: dict[str, Any], finished: str = "driver stopped") -> Any:
    """The node on the I/O side, its exit ending the launch: the twin (``target`` sim, the
    ``pneu_sim`` sim node; ``finished`` says why it ended) or the rig (the driver node)."""
    from launch_ros.actions import Node

    sim = target == "sim"
    return Node(
        package="pneu_sim" if sim else "pneu_driver",
        executable="sim_node" if sim else "driver_node",
        name="pneu_sim" if sim else "pneu_driver",
        output="screen",
        parameters=[params],
        sigterm_timeout=IO_SIGTERM_TIMEOUT,
        on_exit=exit_action(
            "pneu_sim" if sim else "pneu_driver",
            finished if sim else "driver stopped",
            SIM_DIED if sim else DRIVER_DIED,
        ),
    )


def logger_node(out: str, mode: str, recorder: str = "pneu", extra: dict | None = None) -> Any:
    """The logger node: ``<out>/run.mcap`` (recorder pneu) or the run metadata beside
    rosbag2's ``<out>/bag``."""
    from launch_ros.actions import Node

    return Node(
        package="pneu_control",
        executable="logger",
        name="logger",
        output="screen",
        parameters=[
            {
                "out": out,
                "mode": mode,
                "use_sim_time": mode == "lockstep",
                "recorder": recorder,
                "bag_name": "bag" if recorder == "rosbag2" else "run.mcap",
                **(extra or {}),
            }
        ],
        sigterm_timeout="15",  # the run's metadata is written at shutdown
        on_exit=exit_action(
            "logger",
            None,
            f"what it recorded is in {out}/run.mcap.partial (pneu recover)"
            if recorder == "pneu"
            else "the run's metadata (pneu_metadata.json) is lost",
        ),
    )


def hosted_manager(
    arg: dict[str, str],
    config_dir: str,
    backend: str,
    host_node: str,
    host_params: dict,
    **node_kwargs: Any,
) -> Any:
    """``deployment:=hosted``: the controller manager process (loop + controllers).

    Parameters go to each node of that process by name, in a params file
    written next to nothing else: ``<host_node>``, ``linear_controller``,
    ``rotary_controller`` sections on top of the gain file.
    """
    import tempfile

    import yaml
    from launch_ros.actions import Node

    doc = {
        "controller_manager": {"ros__parameters": {"backend": backend}},
        host_node: {"ros__parameters": {**host_params, **common_parameters(arg)}},
    }
    for axis in AXES_OF[arg["axes"]]:
        doc[f"{axis}_controller"] = {"ros__parameters": controller_overrides(arg, axis, "realtime")}
    fd, path = tempfile.mkstemp(prefix="pneu_hosted_", suffix=".yaml")
    with open(fd, "w", encoding="utf-8") as fh:
        yaml.safe_dump(doc, fh)
    return Node(
        package="pneu_control",
        executable="controller_manager",
        output="screen",
        parameters=[f"{config_dir}/{GAIN_FILES[arg['gains']]}", path],
        sigterm_timeout=IO_SIGTERM_TIMEOUT,
        **node_kwargs,
    )


def rosbag2_qos_overrides(mode: str) -> dict[str, dict[str, Any]]:
    """``--qos-profile-overrides-path`` content: each pneu topic with the QoS it is offered
    (a recorder that subscribes before the publishers exist would otherwise pick rosbag2's
    default, reliable, which a best-effort sensor publisher cannot serve)."""
    from pneu_msgs_py.contract.topics import TOPICS, qos_for

    out = {}
    for t in TOPICS:
        q = qos_for(t.name, mode)
        out[t.name] = {
            "history": q.history,
            "depth": max(q.depth, 100),  # the recorder's queue: room for a scheduling hiccup
            "reliability": q.reliability,
            "durability": q.durability,
        }
    return out


#: the recorder's SCHED_FIFO priority below the loop's: above other work (at normal priority
#: it dropped a third of the samples beside a busy machine), below every control thread
RECORDER_BELOW = 10


def rosbag2_recorder(out: str, mode: str, rt_priority: int = 0) -> Any:
    """``ros2 bag record -s mcap`` of every pneu topic into ``<out>/bag`` (at SCHED_FIFO
    ``rt_priority`` when > 0: :func:`pneu_msgs_py.lifecycle.realtime.exec_at`)."""
    import os
    import sys

    import yaml
    from launch.actions import ExecuteProcess

    from pneu_msgs_py.contract.topics import TOPICS

    os.makedirs(out, exist_ok=True)
    qos_file = os.path.join(out, "recorder_qos.yaml")
    with open(qos_file, "w", encoding="utf-8") as fh:
        yaml.safe_dump(rosbag2_qos_overrides(mode), fh)
    cmd = ["ros2", "bag", "record", "-s", "mcap", "-o", os.path.join(out, "bag")]
    cmd += ["--qos-profile-overrides-path", qos_file, "--max-cache-size", str(64 << 20)]
    cmd += ["--disable-keyboard-controls", "--topics", *(t.name for t in TOPICS)]
    if rt_priority > 0:
        wrap = [sys.executable, "-m", "pneu_msgs_py.lifecycle.realtime", str(rt_priority), "--"]
        cmd = wrap + cmd
    from pneu_msgs_py.contract.security import enclave

    return ExecuteProcess(
        cmd=cmd,
        name="recorder",
        # with security on, ros2 bag record starts in the recorder's enclave
        additional_env={"ROS_SECURITY_ENCLAVE_OVERRIDE": enclave("recorder")},
        output="screen",
        sigterm_timeout="20",  # flush the cache and write the summary before any SIGKILL
        sigkill_timeout="10",
        on_exit=exit_action(
            "recorder (ros2 bag record)",
            None,
            f"what it wrote is in {os.path.join(out, 'bag')} (no metadata.yaml: ros2 bag "
            "reindex, or pneu recover on its .mcap)",
        ),
    )


KEYSTORE_ARG = (
    "keystore",
    "",
    "SROS2 keystore made by `pneu security` ('' = unsecured): every process in its role's "
    "enclave, ROS_SECURITY_STRATEGY=Enforce (a process without valid credentials is refused)",
    None,
)


def security_actions(keystore: str, target: str) -> list[Any]:
    """The environment of every process of the launch: secured by ``keystore`` (enforced), or
    unsecured -- then the twin (``target`` sim) discovers on localhost only unless the user
    chose a range, and the rig says in one line that anyone on the network may command it."""
    import os
    import sys

    from launch.actions import SetEnvironmentVariable

    from pneu_msgs_py.contract.security import ROLES, enclave

    if keystore:
        missing = [
            enclave(r)
            for r in ROLES
            if not os.path.isfile(
                os.path.join(keystore, "enclaves", enclave(r).lstrip("/"), "permissions.p7s")
            )
        ]
        if missing:
            raise RuntimeError(
                f"keystore: {keystore} refused; allowed: a keystore made by `pneu security` "
                f"(missing enclaves: {', '.join(missing)})"
            )
        return [
            SetEnvironmentVariable("ROS_SECURITY_KEYSTORE", os.path.abspath(keystore)),
            SetEnvironmentVariable("ROS_SECURITY_ENABLE", "true"),
            SetEnvironmentVariable("ROS_SECURITY_STRATEGY", "Enforce"),
        ]
    secured = os.environ.get("ROS_SECURITY_ENABLE", "").lower() == "true"
    rng = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "")
    if target == "sim" and not rng:
        return [SetEnvironmentVariable("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")]
    if target == "rig" and not secured and rng != "LOCALHOST":
        print(
            "[WARN] rig graph unsecured and discoverable beyond this host "
            f"(ROS_AUTOMATIC_DISCOVERY_RANGE={rng or 'SUBNET (default)'}): any process on "
            "the network can command the valves; use keystore:= (pneu security) or "
            "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST",
            file=sys.stderr,
        )
    return []


def realtime_priority(arg: dict[str, str]) -> int:
    """The graph's loop priority (``rt_priority``, realtime only), checked once for the whole
    launch: without the privilege, one line says what could not be set and what that costs,
    and the graph runs at normal priority (no node repeats it)."""
    import sys

    from pneu_msgs_py.lifecycle.realtime import missing_line, privilege

    text = arg["rt_priority"]
    try:
        rt = int(text)
    except ValueError:
        rt = -1
    if not 0 <= rt <= 98:
        raise RuntimeError(f"rt_priority: {text!r} refused; allowed: an integer 0..98")
    if arg.get("mode", "realtime") != "realtime" or rt == 0:
        return rt
    priv = privilege()
    line = missing_line(rt, priv, who="the graph")
    if line:
        print("[WARN] " + line, file=sys.stderr)
    return rt if priv.fifo(rt) else 0


def launch_description(
    args: list[tuple[str, str, str, list | None]],
    setup: Callable[[dict[str, str]], list[Any]],
    target: str | Callable[[dict[str, str]], str] = "sim",
) -> Any:
    """A LaunchDescription declaring ``args`` and ``keystore``; ``setup(values)`` returns the
    actions to start, after :func:`security_actions` for the ``target`` (sim or rig, or a
    function of the values)."""
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument, OpaqueFunction
    from launch.substitutions import LaunchConfiguration

    args = [*args, KEYSTORE_ARG]

    def _setup(context):
        values = {name: LaunchConfiguration(name).perform(context) for name, *_ in args}
        io = target(values) if callable(target) else target
        if "rt_priority" in values:  # the graphs with a 1 kHz loop (sim, rig)
            values["rt_priority"] = str(realtime_priority(values))
        return [*security_actions(values["keystore"], io), *setup(values)]

    return LaunchDescription(
        [
            DeclareLaunchArgument(name, default_value=default, description=desc, choices=choices)
            for name, default, desc, choices in args
        ]
        + [OpaqueFunction(function=_setup)]
    )
