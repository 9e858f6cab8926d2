"""ROS 2 Jazzy message definitions (``ros2msg`` schema text) for pneu's topics.

MCAP's ROS 2 profile stores, per schema, the top-level ``.msg`` text followed
by each dependency as a separator line of exactly 80 ``=``, a line
``MSG: pkg/Type`` and that type's text (depth-first, each type once). The
texts below are the Jazzy definitions without comments, in the order
``rosbags``' ``generate_msgdef(typename, ros_version=2)`` emits them; the test
suite checks them byte for byte against the rosbags Jazzy typestore.
"""

from __future__ import annotations

__all__ = [
    "MSG_DEFINITIONS",
    "TYPE_HASHES",
    "SCHEMA_ENCODING",
    "MESSAGE_ENCODING",
    "PROFILE",
    "msgdef",
]

PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"

_SEP = "=" * 80 + "\n"

# Bodies of single types (no dependencies), Jazzy, comments stripped.
_BODIES: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "sensor_msgs/FluidPressure": "std_msgs/Header header\nfloat64 fluid_pressure\nfloat64 variance\n",
    "sensor_msgs/JointState": (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\n"
        "float64[] velocity\nfloat64[] effort\n"
    ),
    "rosgraph_msgs/Clock": "builtin_interfaces/Time clock\n",
    "diagnostic_msgs/KeyValue": "string key\nstring value\n",
    "diagnostic_msgs/DiagnosticStatus": (
        "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\nbyte level\nstring name\n"
        "string message\nstring hardware_id\ndiagnostic_msgs/KeyValue[] values\n"
    ),
    "diagnostic_msgs/DiagnosticArray": (
        "std_msgs/Header header\ndiagnostic_msgs/DiagnosticStatus[] status\n"
    ),
    "builtin_interfaces/Duration": "int32 sec\nuint32 nanosec\n",
    "trajectory_msgs/JointTrajectoryPoint": (
        "float64[] positions\nfloat64[] velocities\nfloat64[] accelerations\n"
        "float64[] effort\nbuiltin_interfaces/Duration time_from_start\n"
    ),
    "trajectory_msgs/JointTrajectory": (
        "std_msgs/Header header\nstring[] joint_names\n"
        "trajectory_msgs/JointTrajectoryPoint[] points\n"
    ),
}

# Dependencies in depth-first first-use order.
_DEPS: dict[str, tuple[str, ...]] = {
    "builtin_interfaces/Time": (),
    "std_msgs/Header": ("builtin_interfaces/Time",),
    "sensor_msgs/FluidPressure": ("std_msgs/Header",),
    "sensor_msgs/JointState": ("std_msgs/Header",),
    "rosgraph_msgs/Clock": ("builtin_interfaces/Time",),
    "diagnostic_msgs/KeyValue": (),
    "diagnostic_msgs/DiagnosticStatus": ("diagnostic_msgs/KeyValue",),
    "diagnostic_msgs/DiagnosticArray": ("std_msgs/Header", "diagnostic_msgs/DiagnosticStatus"),
    "builtin_interfaces/Duration": (),
    "trajectory_msgs/JointTrajectoryPoint": ("builtin_interfaces/Duration",),
    "trajectory_msgs/JointTrajectory": ("std_msgs/Header", "trajectory_msgs/JointTrajectoryPoint"),
}


def _short(ros_type: str) -> str:
    """``sensor_msgs/msg/JointState`` -> ``sensor_msgs/JointState``."""
    parts = ros_type.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return f"{parts[0]}/{parts[2]}"
    return ros_type


def _flatten(short: str, seen: list[str]) -> None:
    for dep in _DEPS[short]:
        if dep not in seen:
            seen.append(dep)
            _flatten(dep, seen)


def msgdef(ros_type: str) -> str:
    """Full ``ros2msg`` text of ``ros_type`` (``pkg/msg/Type``), dependencies included.

    Raises
    ------
    KeyError
        If ``ros_type`` is not one of pneu's message types.
    """
    short = _short(ros_type)
    if short not in _BODIES:
        raise KeyError(f"no message definition for {ros_type!r}")
    deps: list[str] = []
    _flatten(short, deps)
    text = _BODIES[short]
    for dep in deps:
        text += _SEP + f"MSG: {dep}\n" + _BODIES[dep]
    return text


#: ``pkg/msg/Type`` -> full definition text, for every type pneu writes.
MSG_DEFINITIONS: dict[str, str] = {
    t: msgdef(t)
    for t in (
        "sensor_msgs/msg/FluidPressure",
        "sensor_msgs/msg/JointState",
        "rosgraph_msgs/msg/Clock",
        "diagnostic_msgs/msg/DiagnosticArray",
        "trajectory_msgs/msg/JointTrajectory",
    )
}


#: RIHS01 type description hashes (REP 2011) of the Jazzy types, as rosbag2 stores them in
#: the channel metadata ``topic_type_hash``; checked against rosbags' ``hash_rihs01``.
TYPE_HASHES: dict[str, str] = {
    "sensor_msgs/msg/FluidPressure": (
        "RIHS01_22dfb2b145a0bd5a31a1ac3882a1b32148b51d9b2f3bab250290d66f3595bc32"
    ),
    "sensor_msgs/msg/JointState": (
        "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e"
    ),
    "rosgraph_msgs/msg/Clock": (
        "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564"
    ),
    "diagnostic_msgs/msg/DiagnosticArray": (
        "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e"
    ),
    "trajectory_msgs/msg/JointTrajectory": (
        "RIHS01_179b33eba59d676f6d967ac71fe35e7ca2f64b2f3928f4a018cec115e213796e"
    ),
}
