"""Micro-benchmark of a controller node's per-sample work without rclpy (not a test)."""

from __future__ import annotations

import math
import time

from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.wire import SensorWire

from pneu_control.controller.params import load_controller_params
from pneu_control.nodes.controller_core import ControllerShellCore

__all__ = ["bench_shell_us_per_sample"]


def bench_shell_us_per_sample(n: int = 5000, axis: str = "linear") -> float:
    """Microseconds per sample of a controller shell's work, without rclpy.

    The axis' input payloads in (raw CDR bytes, as the sim node publishes
    them), sample rebuilt, ``AxisController.update`` (the configured
    algorithm; ESO-SMC in config/controllers.yaml) and the command and state
    payloads encoded. rclpy's own cost (take, publish) is not included: that
    needs ROS (``bench_ros``).
    """
    core = ControllerShellCore(axis, load_controller_params(axis))
    wire = SensorWire()
    ticks = []  # built beforehand: only the shell's work is timed
    for k in range(n):
        x = 0.02 * math.sin(2.0 * math.pi * 0.25 * k * 1e-3)
        s = SensorSample(k, k * 1_000_000, 2.0e5, 2.1e5, 1.5e5, x, 0.01 * k, 10.0, k)
        ticks.append([(t, d) for t, d in wire.encode(s) if t in core.topics])
    step = core.step_raw
    t0 = time.perf_counter()
    for payloads in ticks:
        for topic, data in payloads:
            step(topic, data)
    dt = time.perf_counter() - t0
    if core.n_samples != n:
        raise RuntimeError(f"shell bench: {core.n_samples} of {n} samples computed")
    return dt / n * 1e6
