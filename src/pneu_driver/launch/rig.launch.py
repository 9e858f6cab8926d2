"""The rig: driver + controllers + logger, ``ros2 launch pneu_driver rig.launch.py``.

Example::

    ros2 launch pneu_driver rig.launch.py controller:=eso_smc axes:=linear \\
        reference:=sine:amplitude=20,frequency_hz=0.25 out:=/tmp/rig_run

Everything runs in realtime (wall clock, the DAQ's sample clock paces the
driver); stop with Ctrl-C -- the driver writes 5 V to both valves, the
logger finishes ``<out>/run.mcap``. If the driver stops (no DAQ, an error)
the whole launch shuts down. Parameter files come from this package's
installed ``config/`` (rig.yaml, safety.yaml, controllers.yaml).
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
        "paper",
        "controller gain set: paper (controllers.yaml) or retuned (controllers_retuned.yaml); "
        "default: the paper's gains, tuned on the authors' rig",
    ),
    ("linear_reference", "", "reference of the linear axis only (wins over reference)"),
    ("rotary_reference", "", "reference of the rotary axis only (wins over reference)"),
    ("axes", "both", "axes with a controller (the driver holds the others at 5 V)"),
    ("out", "out/rig", "directory of the bag (run.mcap)"),
    ("rig_file", "", "rig YAML ('' = installed config/rig.yaml)"),
)
CHOICES = {
    "axes": ["linear", "rotary", "both"],
    "controller": ["", "pid", "ladrc", "eso_smc", "eso_smc_plus"],
    "gains": ["paper", "retuned"],
}


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
    config = os.path.join(get_package_share_directory("pneu_driver"), "config")
    nodes = [
        Node(
            package="pneu_driver",
            executable="driver_node",
            name="pneu_driver",
            output="screen",
            parameters=[
                {
                    "rig_file": arg["rig_file"] or os.path.join(config, "rig.yaml"),
                    "safety_file": os.path.join(config, "safety.yaml"),
                    "axes": arg["axes"],
                }
            ],
            on_exit=[Shutdown(reason="driver stopped")],
        )
    ]
    for axis in axes:
        over = {"mode": "realtime", "use_sim_time": False}
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
            parameters=[{"out": arg["out"], "mode": "realtime", "use_sim_time": False}],
        )
    )
    return nodes


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
