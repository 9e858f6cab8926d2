"""test/ros: a module that starts the graph skips without rclpy (``pytest.importorskip``) and marks
itself ``pytestmark = pytest.mark.ros``
(``pytest.mark.ros("sros2")``: more modules it needs). Such a test needs rclpy, the ``ros2``
CLI and this workspace built and sourced (``colcon build`` + ``source install/setup.bash``);
without them it is skipped with the reason, checked once per session.
"""

from __future__ import annotations

import functools
import importlib.util
import shutil
import subprocess

import pytest


@functools.cache
def _missing(modules: tuple[str, ...]) -> str | None:
    """Why the graph cannot be started here, or None."""
    for name in ("rclpy", *modules):
        if importlib.util.find_spec(name) is None:
            return f"could not import {name!r} (ROS 2 not sourced)"
    if shutil.which("ros2") is None:
        return "ros2 CLI not on PATH"
    prefix = subprocess.run(["ros2", "pkg", "prefix", "pneu_sim"], capture_output=True)
    if prefix.returncode != 0:
        return "pneu packages not built/sourced (colcon build)"
    return None


def pytest_collection_modifyitems(config, items):
    for item in items:
        mark = item.get_closest_marker("ros")
        if mark is not None and (reason := _missing(tuple(mark.args))):
            item.add_marker(pytest.mark.skip(reason=reason))
