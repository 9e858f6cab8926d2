"""Twin + controllers + logger: ``ros2 launch pneu_sim sim.launch.py``.

Example (the paper's sine experiment, 20 s, lockstep, bag in /tmp/run)::

    ros2 launch pneu_sim sim.launch.py controller:=eso_smc axes:=linear \\
        reference:=sine:amplitude=20,frequency_hz=0.25 mode:=lockstep duration:=20 out:=/tmp/run

Arguments (``ros2 launch pneu_sim sim.launch.py --show-args``): controller,
reference / linear_reference / rotary_reference (``KIND[:key=value,...]`` in
paper units, as ``pneu run --reference``), axes, mode, duration, seed, out,
safety, faults. Parameter files come from this package's installed ``config/``.
When the sim has published ``duration`` seconds it exits and the whole
launch shuts down; the logger then finishes ``<out>/run.mcap``.
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
    *launch_arguments(
        "retuned",
        "the twin's re-tuned set (the paper's linear ESO-SMC and rotary gains limit-cycle on the twin)",
    ),
    (
        "mode",
        "lockstep",
        "lockstep (deterministic, /clock) or realtime (wall clock, 1 kHz)",
        ["lockstep", "realtime"],
    ),
    ("duration", "20.0", "simulated seconds, then everything stops (0 = run until Ctrl-C)", None),
    ("seed", "0", "noise seed of the twin", None),
    ("out", "out/ros", "directory of the bag (run.mcap)", None),
    (
        "safety",
        "true",
        "SafetySupervisor between commands and plant, as on the rig",
        ["true", "false"],
    ),
    (
        "faults",
        "",
        "injected faults, ';'-separated NAME[:key=value,...] (as pneu run --fault)",
        None,
    ),
]


def _setup(arg: dict[str, str]) -> list:
    config = os.path.join(get_package_share_directory("pneu_sim"), "config")
    hosted = arg["deployment"] == "hosted"
    if hosted and arg["mode"] != "realtime":
        raise RuntimeError("deployment:=hosted runs in real time: add mode:=realtime")
    params = {
        "mode": arg["mode"],
        "axes": arg["axes"],
        "duration_s": float(arg["duration"]),
        "seed": int(arg["seed"]),
        "safety": arg["safety"] == "true",
        "plant_file": os.path.join(config, "plant.yaml"),
        "safety_file": os.path.join(config, "safety.yaml"),
        "faults": arg["faults"],
        "realtime.rt_priority": int(arg["rt_priority"]),
        # before sample 0: every sensor topic matched by its subscribers (the controllers
        # take 3 / 1 of the 5 topics, so at least the recorder or the logger)
        "startup.min_subscribers": 1,
        "startup.wait_for_logger": True,  # the run's metadata needs every node's parameters
    }
    exit_action = io_exit("sim")
    if hosted:
        sim = hosted_manager(arg, config, "sim", "pneu_sim", params, on_exit=exit_action)
    else:
        sim = Node(
            package="pneu_sim",
            executable="sim_node",
            name="pneu_sim",
            output="screen",
            parameters=[{**params, **common_parameters(arg)}],
            sigterm_timeout=IO_SIGTERM_TIMEOUT,
            on_exit=exit_action,
        )
    return [sim, *controller_and_logger_nodes(arg, config, mode=arg["mode"], out=arg["out"])]


def generate_launch_description():
    return launch_description(ARGS, _setup)
