"""``ros2 run pneu_control controller_manager``: hard 1 kHz, the controllers in the loop's process.

What ros2_control's controller manager does, for this rig: one process, one
1 kHz loop -- the sim node's realtime loop (``backend: sim``) or the driver's
DAQ loop (``backend: rig``) -- that calls the controller cores directly with
each sample, with no middleware between sample and command. Every node keeps
its name, its parameters and its topics:

- ``/pneu_sim`` or ``/pneu_driver``: the sensor topics, ``/diagnostics``,
  ``~/estop`` and ``~/reset``, as in the separate-process graph;
- ``/linear_controller``, ``/rotary_controller`` (the active axes):
  ``ros2 param set /linear_controller eso_smc.epsilon 900`` still retunes
  live (validated as one set, bumpless); they publish their valve commands
  and controller states for monitoring and bags.

Parameters reach each node by its name (a params file with sections
``pneu_sim:`` / ``pneu_driver:`` / ``linear_controller:`` ...; ``/**:`` for
all), and ``backend`` chooses the loop. Recording is unchanged (``ros2 bag
record`` and the logger node run beside it).
"""

from __future__ import annotations

import sys

from pneu_msgs_py.nodes.run import run_node

__all__ = ["main", "make_nodes"]

BACKENDS = ("sim", "rig")


def make_nodes(args=None) -> list:
    """The loop's node (first) and one hosted controller node per active axis."""
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.node import Node

    from pneu_control.nodes.controller_node import ControllerNode

    boot = Node("controller_manager", cli_args=args)
    try:
        boot.declare_parameter(
            "backend",
            "sim",
            ParameterDescriptor(
                description="the 1 kHz loop: sim (the twin, realtime) or rig (the DAQ driver)",
                additional_constraints="one of " + ", ".join(BACKENDS),
                read_only=True,
            ),
        )
        backend = boot.get_parameter("backend").value
    finally:
        boot.destroy_node()
    if backend not in BACKENDS:
        raise ValueError(f"backend: {backend!r} refused; allowed: one of {', '.join(BACKENDS)}")
    if backend == "sim":
        from pneu_sim.nodes.sim_node import SimNode

        host = SimNode(hosted=True)
        axes = host.axes
    else:
        from pneu_driver.nodes.driver_node import DriverNode

        host = DriverNode(hosted=True)
        axes = host.loop.expected_axes
    try:
        controllers = [ControllerNode(axis, hosted=True) for axis in axes]
    except Exception:
        host.destroy_node()
        raise
    host.hosts = tuple(controllers)
    return [host, *controllers]


def main(args=None) -> int:
    """``controller_manager``: the loop's node and the active axes' hosted controllers in one
    process; the exit code."""
    return run_node("controller_manager", lambda: make_nodes(args), args)


if __name__ == "__main__":
    sys.exit(main())
