"""The excitation experiment over ROS: ``ros2 launch pneu_control excite.launch.py``.

On the twin (``target:=sim``, lockstep by default: the in-process ``pneu excite``
numbers) or on the rig (``target:=rig``: the driver, realtime)::

    ros2 launch pneu_control excite.launch.py target:=sim axes:=both seed:=0 out:=/tmp/excite
    ros2 launch pneu_control excite.launch.py target:=rig axes:=linear out:=/tmp/rig_excite
    pneu identify /tmp/excite/run.mcap --out plant_identified.yaml

The exciter node answers each sample with the designed valve command
(closed-loop segments included), the logger writes ``<out>/run.mcap`` with the
design in its metadata. On the twin the sim stops after the design (``duration``
= the design's); on the rig stop with Ctrl-C after the design's duration
(printed at start): the driver writes 5 V, the logger finishes the bag.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch_ros.actions import Node
from pneu_msgs_py.nodes.launch_graph import AXES_OF, io_node, launch_description, logger_node

ARGS = [
    ("target", "sim", "sim (the twin, sim node) or rig (the driver)", ["sim", "rig"]),
    ("axes", "both", "excited axes (the others hold 5 V)", list(AXES_OF)),
    ("seed", "0", "design seed (and the twin's noise seed)", None),
    ("level", "full", "full (<= 2 min per axis) or quick (~45 s)", ["full", "quick"]),
    ("mode", "", "lockstep or realtime ('' = lockstep on the sim, realtime on the rig)", ["", "lockstep", "realtime"]),
    ("out", "out/excite", "directory of the bag (run.mcap)", None),
    ("plant_file", "", "the twin's plant.yaml ('' = installed config/plant.yaml)", None),
    ("rig_file", "", "rig YAML ('' = installed config/rig.yaml)", None),
]  # fmt: skip


def _setup(arg: dict[str, str]) -> list:
    from pneu_control.sysid.design import design_for

    config = os.path.join(get_package_share_directory("pneu_control"), "config")
    axes = AXES_OF[arg["axes"]]
    bag = os.path.join(arg["out"], "run.mcap")
    if os.path.exists(bag):  # a run is never overwritten
        raise RuntimeError(f"out: {bag} exists; choose another out:= for this run")
    sim = arg["target"] == "sim"
    mode = arg["mode"] or ("lockstep" if sim else "realtime")
    lockstep = mode == "lockstep"
    duration = max(design_for(a, int(arg["seed"]), arg["level"]).duration_s for a in axes)
    driver = _driver(arg, config, mode, duration)
    exciter = Node(
        package="pneu_control",
        executable="exciter",
        name="pneu_exciter",
        output="screen",
        parameters=[
            {
                "axes": arg["axes"],
                "seed": int(arg["seed"]),
                "level": arg["level"],
                "mode": mode,
                "use_sim_time": lockstep,
            }
        ],
    )
    logger = logger_node(arg["out"], mode)
    return [driver, exciter, logger]


def _driver(arg: dict[str, str], config: str, mode: str, duration: float):
    """The node on the I/O side: the twin (target sim, ending the launch after ``duration``)
    or the rig's driver."""
    common = {
        "safety_file": os.path.join(config, "safety.yaml"),
        "axes": arg["axes"],
    }
    if arg["target"] == "sim":
        return io_node(
            "sim",
            {
                **common,
                "mode": mode,
                "duration_s": float(duration),
                "seed": int(arg["seed"]),
                "safety": True,
                "plant_file": arg["plant_file"] or os.path.join(config, "plant.yaml"),
                # before sample 0: every sensor topic matched (the exciter and the
                # logger take all five) and the logger holding every node's parameters
                "startup.min_subscribers": 2,
                "startup.wait_for_logger": True,
            },
            "excitation finished",
        )
    return io_node(
        "rig", {**common, "rig_file": arg["rig_file"] or os.path.join(config, "rig.yaml")}
    )


def generate_launch_description():
    return launch_description(ARGS, _setup, target=lambda v: v["target"])
