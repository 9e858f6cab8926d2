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

import yaml
from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

ARGS = (
    (
        "controller",
        "",
        "algorithm of every active controller (pid, ladrc, eso_smc, eso_smc_plus); '' = controllers.yaml",
    ),
    (
        "reference",
        "",
        "reference of every active axis, KIND[:key=value,...] in mm / rpm; '' = controllers.yaml",
    ),
    (
        "gains",
        "retuned",
        "controller gain set: paper (controllers.yaml) or retuned (controllers_retuned.yaml); "
        "default: the twin's re-tuned set (the paper's linear ESO-SMC and rotary gains limit-cycle on the twin)",
    ),
    ("linear_reference", "", "reference of the linear axis only (wins over reference)"),
    ("rotary_reference", "", "reference of the rotary axis only (wins over reference)"),
    ("axes", "both", "active axes (the others hold 5 V)"),
    ("mode", "lockstep", "lockstep (deterministic, /clock) or realtime (wall clock, 1 kHz)"),
    ("duration", "20.0", "simulated seconds, then everything stops (0 = run until Ctrl-C)"),
    ("seed", "0", "noise seed of the twin"),
    ("out", "out/ros", "directory of the bag (run.mcap)"),
    ("safety", "true", "SafetySupervisor between commands and plant, as on the rig"),
    ("faults", "", "injected faults, ';'-separated NAME[:key=value,...] (as pneu run --fault)"),
)


GAIN_FILES = {"paper": "controllers.yaml", "retuned": "controllers_retuned.yaml"}


def reference_overrides(text: str) -> dict:
    """``sine:amplitude=20,frequency_hz=0.25`` -> ``{"reference.kind": "sine", ...}`` (numbers as float)."""
    if not text:
        return {}
    kind, _, rest = text.partition(":")
    out = {"reference.kind": kind.strip()}
    for part in filter(None, (p.strip() for p in rest.split(","))):
        key, sep, value = part.partition("=")
        if not sep:
            raise ValueError(f"reference: {part!r} refused; allowed: key=value")
        v = yaml.safe_load(value)
        out[f"reference.{key.strip()}"] = (
            float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v
        )
    return out


def _setup(context):
    arg = {name: LaunchConfiguration(name).perform(context) for name, _, _ in ARGS}
    axes = {"linear": ("linear",), "rotary": ("rotary",), "both": ("linear", "rotary")}[arg["axes"]]
    mode = arg["mode"]
    lockstep = mode == "lockstep"
    config = os.path.join(get_package_share_directory("pneu_sim"), "config")
    sim = Node(
        package="pneu_sim",
        executable="sim_node",
        name="pneu_sim",
        output="screen",
        parameters=[
            {
                "mode": mode,
                "axes": arg["axes"],
                "duration_s": float(arg["duration"]),
                "seed": int(arg["seed"]),
                "safety": arg["safety"] == "true",
                "plant_file": os.path.join(config, "plant.yaml"),
                "safety_file": os.path.join(config, "safety.yaml"),
                "faults": arg["faults"],
                "lockstep.min_subscribers": len(axes) + 1,  # the controllers and the logger
            }
        ],
        on_exit=[Shutdown(reason="simulation finished")],
    )
    nodes = [sim]
    for axis in axes:
        over = {"mode": mode, "use_sim_time": lockstep}
        if arg["controller"]:
            over["algorithm"] = arg["controller"]
        over.update(reference_overrides(arg["reference"]))
        over.update(reference_overrides(arg[f"{axis}_reference"]))
        nodes.append(
            Node(
                package="pneu_control",
                executable=f"{axis}_controller",
                name=f"{axis}_controller",
                output="screen",
                parameters=[os.path.join(config, GAIN_FILES[arg["gains"]]), over],
            )
        )
    nodes.append(
        Node(
            package="pneu_control",
            executable="logger",
            name="logger",
            output="screen",
            parameters=[{"out": arg["out"], "mode": mode, "use_sim_time": lockstep}],
        )
    )
    return nodes


CHOICES = {
    "axes": ["linear", "rotary", "both"],
    "mode": ["lockstep", "realtime"],
    "controller": ["", "pid", "ladrc", "eso_smc", "eso_smc_plus"],
    "gains": ["paper", "retuned"],
    "safety": ["true", "false"],
}


def generate_launch_description():
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                name, default_value=default, description=desc, choices=CHOICES.get(name)
            )
            for name, default, desc in ARGS
        ]
        + [OpaqueFunction(function=_setup)]
    )
