"""The data every core exchanges: one sensor sample, one valve command.

These are the ROS-free twins of the topics in :mod:`pneu_msgs_py.contract.topics`.
The driver, the simulator, the controllers, the runner and the bag writer
all speak them; conversions to and from ROS messages live in
:mod:`pneu_msgs_py.contract.convert`.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SensorSample", "AXES", "NEUTRAL_V", "U_MIN_V", "U_MAX_V"]

AXES = ("linear", "rotary")
NEUTRAL_V = 5.0  # MPYE closed centre
U_MIN_V = 0.0
U_MAX_V = 10.0


@dataclass(slots=True)
class SensorSample:
    """Everything the DAQ reads at tick ``k`` (SI, pressures absolute).

    ``omega`` is what a real driver can know: encoder counts over the last
    sample period, so it is quantised (2*pi / (4*ppr*T) per count).
    """

    k: int  # sample index since start
    stamp_ns: int  # sample time, int nanoseconds (sim: k * T)
    p_c1: float  # cylinder chamber 1 (cap side), Pa abs
    p_c2: float  # cylinder chamber 2 (rod side), Pa abs
    p_m1: float  # motor inlet chamber, Pa abs
    x: float  # piston displacement, m, 0 = mid-stroke, + = extending
    theta: float  # motor angle from encoder counts, rad
    omega: float  # motor speed from counts per period, rad/s
    counts: int  # raw X4 encoder count (cumulative)
