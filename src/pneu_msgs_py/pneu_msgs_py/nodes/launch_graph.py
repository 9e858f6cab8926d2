"""What ``sim.launch.py`` and ``rig.launch.py`` share: arguments, controllers and the logger.

The two launch files differ only in what drives the rig (the sim node or
the driver node). Everything downstream of the sensor topics -- one
controller node per active axis (``pneu_control``'s executables, named
here as strings so that neither pneu_sim nor pneu_driver imports
pneu_control, DESIGN §2) and the logger -- is built here once.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pneu_msgs_py.params.spec import parse_spec

__all__ = [
    "AXES_OF",
    "GAIN_FILES",
    "controller_and_logger_nodes",
    "launch_arguments",
    "launch_description",
    "reference_overrides",
]

GAIN_FILES = {"paper": "controllers.yaml", "retuned": "controllers_retuned.yaml"}
AXES_OF = {"linear": ("linear",), "rotary": ("rotary",), "both": ("linear", "rotary")}
ALGORITHM_CHOICES = ["", "pid", "ladrc", "eso_smc", "eso_smc_plus"]


def launch_arguments(gains_default: str, gains_why: str) -> list[tuple[str, str, str, list | None]]:
    """(name, default, description, choices) of the arguments both launch files take."""
    return [
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


def controller_and_logger_nodes(
    arg: dict[str, str], config_dir: str, *, mode: str, out: str
) -> list[Any]:
    """One controller node per active axis (``arg["axes"]``) and the logger."""
    from launch_ros.actions import Node

    lockstep = mode == "lockstep"
    nodes = []
    for axis in AXES_OF[arg["axes"]]:
        over: dict[str, Any] = {"mode": mode, "use_sim_time": lockstep}
        if arg["controller"]:
            over["algorithm"] = arg["controller"]
        over.update(reference_overrides(arg["reference"]))
        over.update(reference_overrides(arg[f"{axis}_reference"], f"{axis}_reference"))
        nodes.append(
            Node(
                package="pneu_control",
                executable=f"{axis}_controller",
                name=f"{axis}_controller",
                output="screen",
                parameters=[f"{config_dir}/{GAIN_FILES[arg['gains']]}", over],
            )
        )
    nodes.append(
        Node(
            package="pneu_control",
            executable="logger",
            name="logger",
            output="screen",
            parameters=[{"out": out, "mode": mode, "use_sim_time": lockstep}],
        )
    )
    return nodes


def launch_description(
    args: list[tuple[str, str, str, list | None]], setup: Callable[[dict[str, str]], list[Any]]
) -> Any:
    """A LaunchDescription declaring ``args``; ``setup(values)`` returns the actions to start."""
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument, OpaqueFunction
    from launch.substitutions import LaunchConfiguration

    def _setup(context):
        return setup({name: LaunchConfiguration(name).perform(context) for name, *_ in args})

    return LaunchDescription(
        [
            DeclareLaunchArgument(name, default_value=default, description=desc, choices=choices)
            for name, default, desc, choices in args
        ]
        + [OpaqueFunction(function=_setup)]
    )
