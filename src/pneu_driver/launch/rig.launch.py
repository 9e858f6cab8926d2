"""The rig: driver + controllers + logger, ``ros2 launch pneu_driver rig.launch.py``.

Example::

    ros2 launch pneu_driver rig.launch.py controller:=eso_smc axes:=linear \\
        reference:=sine:amplitude=20,frequency_hz=0.25 out:=/tmp/rig_run
    ros2 launch pneu_driver rig.launch.py backend:=sim gains:=retuned   # rehearsal, no hardware

Everything runs in realtime (wall clock, the DAQ's sample clock paces the
driver); stop with Ctrl-C -- the driver writes 5 V to both valves, the
logger finishes ``<out>/run.mcap``. If the driver stops (no DAQ, an error)
the whole launch shuts down. Parameter files come from this package's
installed ``config/`` (rig.yaml, safety.yaml, controllers.yaml).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch_ros.actions import Node
from pneu_msgs_py.nodes.launch_graph import (
    IO_SIGTERM_TIMEOUT,
    common_parameters,
    controller_and_logger_nodes,
    hosted_manager,
    io_exit,
    launch_arguments,
    launch_description,
)

ARGS = [
    *launch_arguments("paper", "the paper's gains, tuned on the authors' rig"),
    ("out", "out/rig", "directory of the bag (run.mcap)", None),
    ("rig_file", "", "rig YAML ('' = installed config/rig.yaml)", None),
    (
        "backend",
        "nidaqmx",
        "the DAQ: nidaqmx (the PCI-6221) or sim[:seed=0,card=FILE,stall_at_s=S,stall_ms=MS] "
        "(the twin as a simulated card: a rehearsal without hardware)",
        None,
    ),
]


def _setup(arg: dict[str, str]) -> list:
    config = os.path.join(get_package_share_directory("pneu_driver"), "config")
    params = {
        "rig_file": arg["rig_file"] or os.path.join(config, "rig.yaml"),
        "safety_file": os.path.join(config, "safety.yaml"),
        "axes": arg["axes"],
        "backend": arg["backend"],
        "rt_priority": int(arg["rt_priority"]),  # the loop; the process's other threads one below
    }
    exit_action = io_exit("rig")
    if arg["deployment"] == "hosted":
        driver = hosted_manager(arg, config, "rig", "pneu_driver", params, on_exit=exit_action)
    else:
        driver = Node(
            package="pneu_driver",
            executable="driver_node",
            name="pneu_driver",
            output="screen",
            parameters=[{**params, **common_parameters(arg)}],
            sigterm_timeout=IO_SIGTERM_TIMEOUT,
            on_exit=exit_action,
        )
    return [driver, *controller_and_logger_nodes(arg, config, mode="realtime", out=arg["out"])]


def generate_launch_description():
    return launch_description(ARGS, _setup, target="rig")
