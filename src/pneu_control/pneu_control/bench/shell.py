"""Micro-benchmark of a controller node's per-sample work without rclpy (not a test)."""

from __future__ import annotations

import math
import time

from pneu_msgs_py.contract.samples import SensorSample

from pneu_control.nodes.controller_core import (
    SENSOR_TOPICS,
    ControllerShellCore,
    _new,
    new_sensor_messages,
)

__all__ = ["bench_shell_us_per_sample"]


def bench_shell_us_per_sample(n: int = 5000, axis: str = "linear") -> float:
    """Microseconds per sample of a controller shell's work, without rclpy.

    Five sensor messages in (rosbags Jazzy classes standing in for rclpy's),
    sample rebuilt, ``AxisController.update`` (the configured algorithm;
    ESO-SMC in config/controllers.yaml) and the command and state messages
    filled. rclpy's own cost (take, deserialise, publish, serialise) is not
    included: that needs ROS (see the README's ROS 2 section).
    """
    from pneu_msgs_py.contract.convert import typestore_messages
    from pneu_sim.nodes.sim_core import fill_sample_messages

    from pneu_control.controller.params import load_controller_params

    types = typestore_messages().types
    core = ControllerShellCore(axis, load_controller_params(axis))
    ticks = []  # built beforehand: only the shell's work is timed
    for k in range(n):
        msgs = new_sensor_messages(types)
        x = 0.02 * math.sin(2.0 * math.pi * 0.25 * k * 1e-3)
        s = SensorSample(k, k * 1_000_000, 2.0e5, 2.1e5, 1.5e5, x, 0.01 * k, 10.0, k)
        fill_sample_messages(msgs, s)
        ticks.append(msgs)
    cmd = _new(types, "sensor_msgs/msg/JointState")
    state = _new(types, "sensor_msgs/msg/JointState")
    step = core.step
    topics = SENSOR_TOPICS
    t0 = time.perf_counter()
    for msgs in ticks:
        for topic in topics:
            step(topic, msgs[topic], cmd, state)
    dt = time.perf_counter() - t0
    if core.n_samples != n:
        raise RuntimeError(f"shell bench: {core.n_samples} of {n} samples computed")
    return dt / n * 1e6
