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
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import Any

from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import (
    JOINT_STATE_TOPIC,
    PRESSURE_TOPICS,
    ROTARY_COUNTS_JOINT,
    valve_joint,
)

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
    "sample_from_msgs",
    "command_from_msg",
    "controller_state_from_msg",
    "diag_statuses_from_msg",
    "StampedPoint",
    "fill_joint_trajectory",
    "joint_trajectory_from_msg",
    "fill_sensor_joint_states",
    "sample_to_values",
    "typestore_messages",
    "jazzy_typestore",
    "sample_to_typestore",
    "command_to_typestore",
    "controller_state_to_typestore",
    "diagnostics_to_typestore",
    "joint_trajectory_to_typestore",
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


def _floats(values: Sequence[float]) -> list[float]:
    return [float(v) for v in values]


def fill_joint_state(
    msg: Any,
    stamp_ns: int,
    names: Sequence[str],
    position: Sequence[float] = (),
    velocity: Sequence[float] = (),
    effort: Sequence[float] = (),
    frame_id: str = "",
    array: Callable[[Sequence[float]], Any] = _floats,
) -> Any:
    """Fill a ``sensor_msgs/msg/JointState``; each array empty or one value per name.

    ``array`` converts each float sequence: the default (a list of float) suits
    rclpy; rosbags' typestore classes want ``numpy.asarray(v, dtype=float)``.
    """
    n = len(names)
    for key, arr in (("position", position), ("velocity", velocity), ("effort", effort)):
        if len(arr) not in (0, n):
            raise ValueError(f"JointState.{key}: {len(arr)} values for {n} names")
    fill_header(msg.header, stamp_ns, frame_id)
    msg.name = list(names)
    msg.position = array(position)
    msg.velocity = array(velocity)
    msg.effort = array(effort)
    return msg


def fill_sensor_joint_states(
    linear: Any, rotary: Any, s: SensorSample, array: Callable[[Sequence[float]], Any] = _floats
) -> tuple[Any, Any]:
    """The two JointState messages of a sample (see :mod:`pneu_msgs_py.contract.topics`)."""
    fill_joint_state(linear, s.stamp_ns, ["linear"], position=[s.x], array=array)
    fill_joint_state(
        rotary,
        s.stamp_ns,
        ["rotary", ROTARY_COUNTS_JOINT],
        position=[s.theta, float(s.counts)],
        velocity=[s.omega, math.nan],
        array=array,
    )
    return linear, rotary


def fill_valve_command(
    msg: Any, axis: str, stamp_ns: int, u: float, array: Callable[[Sequence[float]], Any] = _floats
) -> Any:
    """Valve command as JointState: name [<axis>_valve], effort [u V]; stamp = answered sample."""
    return fill_joint_state(msg, stamp_ns, [valve_joint(axis)], effort=[u], array=array)


def fill_controller_state(
    msg: Any,
    stamp_ns: int,
    fields: Sequence[str],
    values: Sequence[float],
    algorithm: str,
    array: Callable[[Sequence[float]], Any] = _floats,
) -> Any:
    """Controller state as JointState: name = fields, position = values, frame_id = algorithm."""
    if len(fields) != len(values):
        raise ValueError(f"controller state: {len(values)} values for {len(fields)} fields")
    return fill_joint_state(msg, stamp_ns, fields, position=values, frame_id=algorithm, array=array)


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


def sample_to_values(
    s: SensorSample,
) -> dict[str, tuple[str, list[str], list[float], list[float]]]:
    """Per sensor topic of a sample: (frame_id, names, position, velocity).

    Pressures have no names and their value in ``position[0]``; joint states
    are laid out as the topic table says (rotary: counts as a second joint).
    """
    out: dict[str, tuple[str, list[str], list[float], list[float]]] = {}
    for topic, (attr, frame) in PRESSURE_TOPICS.items():
        out[topic] = (frame, [], [getattr(s, attr)], [])
    out[JOINT_STATE_TOPIC["linear"]] = ("", ["linear"], [s.x], [])
    out[JOINT_STATE_TOPIC["rotary"]] = (
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


#: One ``trajectory_msgs/JointTrajectoryPoint`` as plain data: (positions, velocities,
#: accelerations, time_from_start in int ns). Effort is not used (pneu's joints are
#: position-controlled); a message's effort entries are ignored.
StampedPoint = tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...], int]


def fill_joint_trajectory(
    msg: Any,
    point_cls: Callable[[], Any],
    stamp_ns: int,
    joint_names: Sequence[str],
    points: Sequence[StampedPoint],
    array: Callable[[Sequence[float]], Any] = _floats,
) -> Any:
    """Fill a ``trajectory_msgs/JointTrajectory``: header.stamp = ``stamp_ns`` (the time the
    trajectory starts), one point per :data:`StampedPoint` (``point_cls()``: an empty
    point; ``array`` as :func:`fill_joint_state`'s)."""
    fill_header(msg.header, stamp_ns)
    msg.joint_names = list(joint_names)
    out = []
    for pos, vel, acc, t_ns in points:
        pt = point_cls()
        pt.positions, pt.velocities, pt.accelerations = array(pos), array(vel), array(acc)
        pt.effort = array(())
        sec, nsec = divmod(int(t_ns), _NS)
        pt.time_from_start.sec = sec
        pt.time_from_start.nanosec = nsec
        out.append(pt)
    msg.points = out
    return msg


def joint_trajectory_from_msg(msg: Any) -> tuple[int, tuple[str, ...], list[StampedPoint]]:
    """(header.stamp ns, joint names, points) of a JointTrajectory (rclpy or rosbags)."""
    points = [
        (
            tuple(float(v) for v in p.positions),
            tuple(float(v) for v in p.velocities),
            tuple(float(v) for v in p.accelerations),
            stamp_to_ns(p.time_from_start),
        )
        for p in msg.points
    ]
    return stamp_to_ns(msg.header.stamp), tuple(str(n) for n in msg.joint_names), points


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


@cache
def jazzy_typestore() -> Any:
    """The rosbags Jazzy typestore (created once, on first use)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def typestore_messages() -> Any:
    """The rosbags Jazzy typestore, created once on first use (one instance for every user)."""
    return jazzy_typestore()


def _np_array(values: Sequence[float]) -> Any:
    import numpy as np

    return np.asarray(values, dtype=np.float64)


def _ts_new(ros_type: str) -> Any:
    """An empty rosbags message of ``ros_type`` (fields zero / empty)."""
    ts = jazzy_typestore()
    T = ts.types
    time = T["builtin_interfaces/msg/Time"]
    header = T["std_msgs/msg/Header"]
    if ros_type == "sensor_msgs/msg/FluidPressure":
        return T[ros_type](
            header=header(stamp=time(sec=0, nanosec=0), frame_id=""),
            fluid_pressure=0.0,
            variance=0.0,
        )
    if ros_type == "sensor_msgs/msg/JointState":
        e = _np_array(())
        return T[ros_type](
            header=header(stamp=time(sec=0, nanosec=0), frame_id=""),
            name=[],
            position=e,
            velocity=e,
            effort=e,
        )
    if ros_type == "diagnostic_msgs/msg/DiagnosticArray":
        return T[ros_type](header=header(stamp=time(sec=0, nanosec=0), frame_id=""), status=[])
    if ros_type == "rosgraph_msgs/msg/Clock":
        return T[ros_type](clock=time(sec=0, nanosec=0))
    if ros_type == "trajectory_msgs/msg/JointTrajectory":
        return T[ros_type](
            header=header(stamp=time(sec=0, nanosec=0), frame_id=""), joint_names=[], points=[]
        )
    if ros_type == "trajectory_msgs/msg/JointTrajectoryPoint":
        e = _np_array(())
        dur = T["builtin_interfaces/msg/Duration"](sec=0, nanosec=0)
        return T[ros_type](
            positions=e, velocities=e, accelerations=e, effort=e, time_from_start=dur
        )
    raise KeyError(ros_type)


def sample_to_typestore(s: SensorSample, variance: float = 0.0) -> dict[str, Any]:
    """The five sensor messages of a sample as rosbags Jazzy objects, keyed by topic."""
    out: dict[str, Any] = {}
    for topic, (attr, frame) in PRESSURE_TOPICS.items():
        out[topic] = fill_fluid_pressure(
            _ts_new("sensor_msgs/msg/FluidPressure"), s.stamp_ns, getattr(s, attr), frame, variance
        )
    lin, rot = fill_sensor_joint_states(
        _ts_new("sensor_msgs/msg/JointState"), _ts_new("sensor_msgs/msg/JointState"), s, _np_array
    )
    out[JOINT_STATE_TOPIC["linear"]] = lin
    out[JOINT_STATE_TOPIC["rotary"]] = rot
    return out


def command_to_typestore(axis: str, stamp_ns: int, u: float) -> Any:
    """A valve command as a rosbags JointState."""
    return fill_valve_command(_ts_new("sensor_msgs/msg/JointState"), axis, stamp_ns, u, _np_array)


def controller_state_to_typestore(
    stamp_ns: int, fields: Sequence[str], values: Sequence[float], algorithm: str
) -> Any:
    """A controller state as a rosbags JointState."""
    return fill_controller_state(
        _ts_new("sensor_msgs/msg/JointState"), stamp_ns, fields, values, algorithm, _np_array
    )


def joint_trajectory_to_typestore(
    stamp_ns: int, joint_names: Sequence[str], points: Sequence[StampedPoint]
) -> Any:
    """A JointTrajectory as a rosbags object."""
    return fill_joint_trajectory(
        _ts_new("trajectory_msgs/msg/JointTrajectory"),
        lambda: _ts_new("trajectory_msgs/msg/JointTrajectoryPoint"),
        stamp_ns,
        joint_names,
        points,
        _np_array,
    )


def diagnostics_to_typestore(stamp_ns: int, statuses: Sequence[DiagStatus]) -> Any:
    """A DiagnosticArray as a rosbags object."""
    T = jazzy_typestore().types
    return fill_diagnostic_array(
        _ts_new("diagnostic_msgs/msg/DiagnosticArray"),
        lambda: T["diagnostic_msgs/msg/DiagnosticStatus"](
            level=0, name="", message="", hardware_id="", values=[]
        ),
        lambda: T["diagnostic_msgs/msg/KeyValue"](key="", value=""),
        stamp_ns,
        statuses,
    )
