"""A task over ROS: ``ros2 launch pneu_control task.launch.py task:=FILE``.

On the twin (``target:=sim``, lockstep by default: the numbers of ``pneu task``) or on
the rig (``target:=rig``: the driver, realtime)::

    ros2 launch pneu_control task.launch.py task:=$(ros2 pkg prefix pneu_control)/share/pneu_control/config/tasks/coupling_insert_lock.yaml out:=/tmp/task
    ros2 launch pneu_control task.launch.py task:=my_task.yaml target:=rig autostart:=false out:=/tmp/rig_task
    ros2 service call /task_runner/start std_srvs/srv/Trigger     # autostart:=false
    ros2 service call /task_runner/abort std_srvs/srv/Trigger     # both valves safe

The task is checked before anything starts, as ``pneu task`` checks it (one line naming
the segment and field). Nodes: the sim (the task's plumbing and initial loads, written
to ``<out>/task_plant.yaml``) or the driver, with the supervisor's values the task was
checked against (``<out>/task_safety.yaml``); one controller per axis with the task's
controller settings (rotary ``rotary_control: angle``); the task runner (trajectories on
``/pneu/joint_trajectory``, progress on ``/pneu/task/progress``); the logger
(``<out>/run.mcap``). The task runner writes ``<out>/task_report.json|md``; on the twin
the run ends with the task, on the rig stop with Ctrl-C after it (the driver writes 5 V,
the logger finishes the bag).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch_ros.actions import Node
from pneu_msgs_py.nodes.launch_graph import (
    controller_node,
    io_node,
    launch_description,
    logger_node,
)

ARGS = [
    ("task", "", "the task YAML (config/tasks/*.yaml; format: pneu_control/task/program.py)", None),
    ("target", "sim", "sim (the twin, sim node) or rig (the driver)", ["sim", "rig"]),
    ("mode", "", "lockstep or realtime ('' = lockstep on the sim, realtime on the rig)", ["", "lockstep", "realtime"]),
    ("plumbing", "", "rotary plumbing: paper or bidirectional ('' = the task's, else the plant's)", ["", "paper", "bidirectional"]),
    ("autostart", "true", "start at the first sample (false: on ~/start of /task_runner)", ["true", "false"]),
    ("executor", "", "rclpy executor of every node: events, single or auto ('' = each node's default)", ["", "events", "single", "auto"]),
    ("seed", "0", "the twin's noise seed", None),
    ("out", "out/task", "directory of the bag (run.mcap) and the task report", None),
    ("plant_file", "", "the twin's plant.yaml ('' = installed config/plant.yaml)", None),
    ("rig_file", "", "rig YAML ('' = installed config/rig.yaml)", None),
]  # fmt: skip


def _setup(arg: dict[str, str]) -> list:
    import yaml
    from pneu_control.task.session import prepare
    from pneu_msgs_py.params.core import to_dict
    from pneu_msgs_py.params.ros import values_to_overrides
    from pneu_sim.physics.plant_file import dump_plant_yaml

    config = os.path.join(get_package_share_directory("pneu_control"), "config")
    if not arg["task"]:
        raise RuntimeError("task: '' refused; allowed: a task YAML file (task:=FILE)")
    out = arg["out"]
    for name in (
        "run.mcap",
        "task_report.json",
        "task_report.md",
        "task_plant.yaml",
        "task_safety.yaml",
    ):
        if os.path.exists(os.path.join(out, name)):  # a run is never overwritten
            raise RuntimeError(f"out: {os.path.join(out, name)} exists; choose another out:=")
    sim = arg["target"] == "sim"
    mode = arg["mode"] or ("lockstep" if sim else "realtime")
    lockstep = mode == "lockstep"
    plant_file = arg["plant_file"] or os.path.join(config, "plant.yaml")
    safety_file = os.path.join(config, "safety.yaml")
    prepared = prepare(
        arg["task"],
        plant_file=plant_file,
        safety_file=safety_file,
        seed=int(arg["seed"]),
        plumbing=arg["plumbing"] or None,
    )
    common = {"executor": arg["executor"]} if arg["executor"] else {}
    # the supervisor's and the twin's values the task was checked against, for the run
    os.makedirs(out, exist_ok=True)
    task_safety = os.path.join(out, "task_safety.yaml")
    with open(task_safety, "w", encoding="utf-8") as fh:
        yaml.safe_dump(to_dict(prepared.spec.safety), fh, sort_keys=False)
    io_params = {"axes": "both", "safety_file": task_safety, **common}
    if sim:
        task_plant = os.path.join(out, "task_plant.yaml")
        with open(task_plant, "w", encoding="utf-8") as fh:
            fh.write(dump_plant_yaml(prepared.spec.plant))
        io = io_node(
            "sim",
            {
                **io_params,
                "mode": mode,
                "duration_s": float(prepared.spec.duration_s),
                "seed": int(arg["seed"]),
                "safety": True,
                "plant_file": task_plant,
                "task.wait": lockstep,  # the task runner answers every sample, as in process
                "task.ends_run": True,
                # before sample 0: the sensor topics matched by the controllers, the task
                # runner and the logger; the logger holding every node's parameters
                "startup.min_subscribers": 2,
                "startup.wait_for_logger": True,
            },
            "task finished",
        )
    else:
        io = io_node(
            "rig", {**io_params, "rig_file": arg["rig_file"] or os.path.join(config, "rig.yaml")}
        )
    controllers = [
        controller_node(
            axis,
            [
                {
                    **values_to_overrides(prepared.spec.controllers[axis]),
                    "mode": mode,
                    "use_sim_time": lockstep,
                    **common,
                }
            ],
        )
        for axis in ("linear", "rotary")
    ]
    task = Node(
        package="pneu_control",
        executable="task_runner",
        name="task_runner",
        output="screen",
        parameters=[
            {
                "task_file": os.path.abspath(arg["task"]),
                "plant_file": plant_file,
                "safety_file": safety_file,
                "plumbing": arg["plumbing"],
                "mode": mode,
                "autostart": arg["autostart"] == "true",
                "out": out,
                "use_sim_time": lockstep,
                **common,
            }
        ],
        sigterm_timeout="10",  # the report is written at shutdown
    )
    return [io, *controllers, task, logger_node(out, mode, "pneu", common)]


def generate_launch_description():
    return launch_description(ARGS, _setup, target=lambda v: v["target"])
