"""Conversions between pneu's core data and ROS 2 messages.

Two kinds of message objects share the same field names: rclpy's generated
classes (in the rclpy shells) and the rosbags Jazzy typestore classes (in
tests and offline tools). The ``fill_*`` functions take the *message object*
(or its class) as an argument, so nothing here imports rclpy; the
``*_from_msg(s)`` functions only read attributes, so they work on both.

Times are int nanoseconds; ``builtin_interfaces/Time`` holds (sec, nanosec).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from .samples import SensorSample
from .topics import PRESSURE_TOPICS, ROTARY_COUNTS_JOINT, valve_joint

__all__ = [
    "DiagStatus",
    "DIAG_LEVELS",
    "stamp_to_ns",
    "fill_stamp",
    "fill_header",
    "fill_fluid_pressure",
    "fill_joint_state",
    "fill_valve_command",
    "fill_controller_state",
    "fill_diagnostic_array",
    "sample_to_values",
    "sample_from_msgs",
    "command_from_msg",
    "controller_state_from_msg",
    "diag_statuses_from_msg",
    "typestore_messages",
]

#: DiagnosticStatus levels (diagnostic_msgs: byte OK=0 WARN=1 ERROR=2 STALE=3).
DIAG_LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}
_NS = 1_000_000_000


@dataclass(frozen=True)
class DiagStatus:
    """One ``diagnostic_msgs/msg/DiagnosticStatus`` without ROS."""

    level: int  # 0 OK, 1 WARN, 2 ERROR, 3 STALE
    name: str
    message: str = ""
    hardware_id: str = ""
    values: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.level not in DIAG_LEVELS:
            raise ValueError(f"DiagStatus.level: {self.level!r} refused; allowed: 0, 1, 2, 3")
        for k, v in self.values.items():
            if not isinstance(k, str) or not isinstance(v, str):
                raise TypeError(f"DiagStatus.values[{k!r}]: keys and values must be str")


def stamp_to_ns(stamp: Any) -> int:
    """``builtin_interfaces/Time`` (rclpy or rosbags) -> int ns."""
    return int(stamp.sec) * _NS + int(stamp.nanosec)


def fill_stamp(stamp: Any, stamp_ns: int) -> Any:
    """Write int ns into an existing ``builtin_interfaces/Time`` object."""
    sec, nsec = divmod(int(stamp_ns), _NS)
    stamp.sec = sec
    stamp.nanosec = nsec
    return stamp


def fill_header(header: Any, stamp_ns: int, frame_id: str = "") -> Any:
    fill_stamp(header.stamp, stamp_ns)
    header.frame_id = frame_id
    return header


def fill_fluid_pressure(
    msg: Any, stamp_ns: int, pressure_pa: float, frame_id: str, variance: float = 0.0
) -> Any:
    """Fill a ``sensor_msgs/msg/FluidPressure`` (Pa absolute, variance Pa^2)."""
    fill_header(msg.header, stamp_ns, frame_id)
    msg.fluid_pressure = float(pressure_pa)
    msg.variance = float(variance)
    return msg


def fill_joint_state(
    msg: Any,
    stamp_ns: int,
    names: Sequence[str],
    position: Sequence[float] = (),
    velocity: Sequence[float] = (),
    effort: Sequence[float] = (),
    frame_id: str = "",
) -> Any:
    """Fill a ``sensor_msgs/msg/JointState``; each array empty or one value per name.

    Arrays are assigned as lists of float (rclpy accepts lists and
    ``array('d')``; rosbags wants numpy arrays -- use :func:`typestore_messages`).
    """
    n = len(names)
    for key, arr in (("position", position), ("velocity", velocity), ("effort", effort)):
        if len(arr) not in (0, n):
            raise ValueError(f"JointState.{key}: {len(arr)} values for {n} names")
    fill_header(msg.header, stamp_ns, frame_id)
    msg.name = list(names)
    msg.position = [float(v) for v in position]
    msg.velocity = [float(v) for v in velocity]
    msg.effort = [float(v) for v in effort]
    return msg


def fill_valve_command(msg: Any, axis: str, stamp_ns: int, u: float) -> Any:
    """Valve command as JointState: name [<axis>_valve], effort [u V]; stamp = answered sample."""
    return fill_joint_state(msg, stamp_ns, [valve_joint(axis)], effort=[u])


def fill_controller_state(
    msg: Any, stamp_ns: int, fields: Sequence[str], values: Sequence[float], algorithm: str
) -> Any:
    """Controller state as JointState: name = fields, position = values, frame_id = algorithm."""
    if len(fields) != len(values):
        raise ValueError(f"controller state: {len(values)} values for {len(fields)} fields")
    return fill_joint_state(msg, stamp_ns, fields, position=values, frame_id=algorithm)


def fill_diagnostic_array(
    msg: Any, status_cls: Any, key_value_cls: Any, stamp_ns: int, statuses: Sequence[DiagStatus]
) -> Any:
    """Fill a ``diagnostic_msgs/msg/DiagnosticArray`` from :class:`DiagStatus` items.

    ``status_cls`` / ``key_value_cls`` are the DiagnosticStatus / KeyValue classes.
    """
    fill_header(msg.header, stamp_ns, "")
    out = []
    for st in statuses:
        m = status_cls()
        m.level = bytes([st.level]) if isinstance(m.level, bytes) else st.level
        m.name = st.name
        m.message = st.message
        m.hardware_id = st.hardware_id
        kvs = []
        for k, v in st.values.items():
            kv = key_value_cls()
            kv.key = k
            kv.value = v
            kvs.append(kv)
        m.values = kvs
        out.append(m)
    msg.status = out
    return msg


def sample_to_values(s: SensorSample) -> dict[str, tuple[str, list[str], list[float], list[float]]]:
    """Per topic of the sample: (frame_id, names, position, velocity) (pressures: value in position)."""
    out: dict[str, tuple[str, list[str], list[float], list[float]]] = {}
    for topic, (attr, frame) in PRESSURE_TOPICS.items():
        out[topic] = (frame, [], [getattr(s, attr)], [])
    out["/pneu/linear/joint_state"] = ("", ["linear"], [s.x], [])
    out["/pneu/rotary/joint_state"] = (
        "",
        ["rotary", ROTARY_COUNTS_JOINT],
        [s.theta, float(s.counts)],
        [s.omega, math.nan],
    )
    return out


def sample_from_msgs(
    k: int,
    p_c1: Any,
    p_c2: Any,
    p_m1: Any,
    linear: Any,
    rotary: Any,
) -> SensorSample:
    """Rebuild a :class:`SensorSample` from the five sensor messages of one tick.

    ``p_*`` are FluidPressure messages, ``linear``/``rotary`` JointState
    messages as :func:`fill_joint_state` makes them. The stamp is the linear
    joint state's. Raises ValueError if a joint name is missing.
    """

    def pos(msg: Any, name: str) -> float:
        names = list(msg.name)
        if name not in names:
            raise ValueError(f"JointState has no joint {name!r} (names {names})")
        return float(msg.position[names.index(name)])

    def vel(msg: Any, name: str) -> float:
        names = list(msg.name)
        if len(msg.velocity) != len(names):
            raise ValueError(f"JointState has no velocity for {name!r}")
        return float(msg.velocity[names.index(name)])

    counts_f = pos(rotary, ROTARY_COUNTS_JOINT)
    return SensorSample(
        k=int(k),
        stamp_ns=stamp_to_ns(linear.header.stamp),
        p_c1=float(p_c1.fluid_pressure),
        p_c2=float(p_c2.fluid_pressure),
        p_m1=float(p_m1.fluid_pressure),
        x=pos(linear, "linear"),
        theta=pos(rotary, "rotary"),
        omega=vel(rotary, "rotary"),
        counts=int(counts_f),
    )


def command_from_msg(msg: Any, axis: str) -> tuple[int, float]:
    """(stamp_ns of the answered sample, u [V]) from a valve-command JointState."""
    names = list(msg.name)
    j = valve_joint(axis)
    if j not in names or len(msg.effort) != len(names):
        raise ValueError(f"valve command has no effort for {j!r} (names {names})")
    return stamp_to_ns(msg.header.stamp), float(msg.effort[names.index(j)])


def controller_state_from_msg(msg: Any) -> tuple[int, str, dict[str, float]]:
    """(stamp_ns, algorithm, {field: value}) from a controller-state JointState."""
    return (
        stamp_to_ns(msg.header.stamp),
        str(msg.header.frame_id),
        {n: float(v) for n, v in zip(msg.name, msg.position)},
    )


def diag_statuses_from_msg(msg: Any) -> list[DiagStatus]:
    """:class:`DiagStatus` items from a DiagnosticArray (rclpy or rosbags)."""
    out = []
    for st in msg.status:
        level = st.level
        if isinstance(level, bytes | bytearray):
            level = level[0]
        out.append(
            DiagStatus(
                level=int(level),
                name=str(st.name),
                message=str(st.message),
                hardware_id=str(st.hardware_id),
                values={str(kv.key): str(kv.value) for kv in st.values},
            )
        )
    return out


_TYPESTORE: Any = None


def _typestore() -> Any:
    global _TYPESTORE
    if _TYPESTORE is None:
        from rosbags.typesys import Stores, get_typestore

        _TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
    return _TYPESTORE


def typestore_messages() -> Any:
    """The rosbags Jazzy typestore (lazily created; for tests and offline tools)."""
    return _typestore()
