"""The topic table (DESIGN §4, final): names, types, units, rates, QoS, content.

Standard ``common_interfaces`` types only; SI units on every topic (REP 103):
m, Pa absolute, rad, rad/s, V, s. The README renders :data:`TOPICS` with
:func:`markdown_table`; the bag writer, the reader and the rclpy shells take
names, types and QoS from here.

Choices made where DESIGN §4 left options open
-----------------------------------------------
Valve command = ``sensor_msgs/msg/JointState`` (name ``<axis>_valve``, the
voltage in ``effort``), not ``std_msgs/msg/Float64MultiArray``: it carries a
header, so ``header.stamp`` = the stamp of the sample the command answers and
the sample-to-command latency is measurable from the bag alone; it is named,
so Foxglove/PlotJuggler plot it by name; it has a fixed layout, so it encodes
and decodes in bulk. Float64MultiArray (ros2_control's forward command
controllers) has no stamp and no names.

Controller state = ``sensor_msgs/msg/JointState`` with ``name`` = the
controller core's ``STATE_FIELDS`` and ``position`` = their values (NaN where
an algorithm has none), the algorithm name in ``header.frame_id``. Stamped,
named, fixed layout, plottable by name; ``control_msgs`` is not in
common_interfaces.

Rotary joint state carries the raw encoder count losslessly as a second joint
``rotary_counts`` whose position is the count as float64 (exact up to 2**53);
its velocity entry is NaN (JointState arrays are empty or one per name).
"""

from __future__ import annotations

from dataclasses import dataclass

from pneu_msgs_py.contract import qos as _q

__all__ = [
    "TopicSpec",
    "TOPICS",
    "TOPIC_BY_NAME",
    "PRESSURE_TOPICS",
    "JOINT_STATE_TOPIC",
    "VALVE_COMMAND_TOPIC",
    "CONTROLLER_STATE_TOPIC",
    "DIAGNOSTICS_TOPIC",
    "CLOCK_TOPIC",
    "TRAJECTORY_TOPIC",
    "TASK_PROGRESS_TOPIC",
    "TRAJECTORY_JOINTS",
    "DEFAULT_STATE_FIELDS",
    "ROTARY_COUNTS_JOINT",
    "valve_joint",
    "qos_for",
    "sub_qos_for",
    "markdown_table",
]

#: Fields of ``/pneu/<axis>/controller_state`` unless the controller core says otherwise.
DEFAULT_STATE_FIELDS: tuple[str, ...] = (
    "t",
    "reference",
    "reference_dot",
    "measured",
    "error",
    "z1",
    "z2",
    "z3",
    "s",
    "u_raw",
    "u_sat",
)

ROTARY_COUNTS_JOINT = "rotary_counts"

#: pressure topic -> (SensorSample attribute, header.frame_id)
PRESSURE_TOPICS: dict[str, tuple[str, str]] = {
    "/pneu/pressure/cylinder_1": ("p_c1", "cylinder_1"),
    "/pneu/pressure/cylinder_2": ("p_c2", "cylinder_2"),
    "/pneu/pressure/motor_in": ("p_m1", "motor_in"),
}
JOINT_STATE_TOPIC = {"linear": "/pneu/linear/joint_state", "rotary": "/pneu/rotary/joint_state"}
VALVE_COMMAND_TOPIC = {
    "linear": "/pneu/linear/valve_command",
    "rotary": "/pneu/rotary/valve_command",
}
CONTROLLER_STATE_TOPIC = {
    "linear": "/pneu/linear/controller_state",
    "rotary": "/pneu/rotary/controller_state",
}
DIAGNOSTICS_TOPIC = "/diagnostics"
CLOCK_TOPIC = "/clock"
#: ``trajectory_msgs/JointTrajectory`` of both joints, as joint_trajectory_controller takes it
TRAJECTORY_TOPIC = "/pneu/joint_trajectory"
TRAJECTORY_JOINTS = ("linear", "rotary")
TASK_PROGRESS_TOPIC = "/pneu/task/progress"


def valve_joint(axis: str) -> str:
    """JointState name of an axis' valve command (``linear_valve``, ``rotary_valve``)."""
    return f"{axis}_valve"


@dataclass(frozen=True)
class TopicSpec:
    """One row of the topic table."""

    name: str
    ros_type: str  # pkg/msg/Type
    unit: str
    rate_hz: float | None  # None: event-driven / low rate
    publisher: str
    subscribers: str
    content: str
    qos_realtime: _q.QosProfile
    qos_lockstep: _q.QosProfile
    # pressure | joint_state | valve_command | controller_state | diagnostics | clock |
    # trajectory | task_progress
    kind: str
    axis: str | None = None


_S = "sensor_msgs/msg/FluidPressure"
_J = "sensor_msgs/msg/JointState"

TOPICS: tuple[TopicSpec, ...] = (
    *(
        TopicSpec(
            name,
            _S,
            "Pa (absolute)",
            1000.0,
            "driver / sim",
            "controllers, logger",
            f"{frame.replace('_', ' ')} pressure; header.frame_id = {frame!r}, "
            "variance = sensor noise variance [Pa^2] or 0",
            _q.SENSOR_PUB,
            _q.LOCKSTEP,
            "pressure",
        )
        for name, (_, frame) in PRESSURE_TOPICS.items()
    ),
    TopicSpec(
        JOINT_STATE_TOPIC["linear"],
        _J,
        "m",
        1000.0,
        "driver / sim",
        "linear controller, logger",
        "name ['linear'], position [x] (0 = mid-stroke, + = extending); velocity, effort empty",
        _q.SENSOR_PUB,
        _q.LOCKSTEP,
        "joint_state",
        "linear",
    ),
    TopicSpec(
        JOINT_STATE_TOPIC["rotary"],
        _J,
        "rad, rad/s, counts",
        1000.0,
        "driver / sim",
        "rotary controller, logger",
        "name ['rotary', 'rotary_counts'], position [theta, encoder count as float64], "
        "velocity [omega from counts per period, NaN]; effort empty",
        _q.SENSOR_PUB,
        _q.LOCKSTEP,
        "joint_state",
        "rotary",
    ),
    *(
        TopicSpec(
            VALVE_COMMAND_TOPIC[axis],
            _J,
            "V",
            1000.0,
            f"{axis} controller",
            "driver / sim, logger",
            f"name ['{valve_joint(axis)}'], effort [u] (0-10 V, 5 V = closed centre); "
            "header.stamp = stamp of the sample it answers",
            _q.COMMAND_PUB,
            _q.LOCKSTEP,
            "valve_command",
            axis,
        )
        for axis in ("linear", "rotary")
    ),
    *(
        TopicSpec(
            CONTROLLER_STATE_TOPIC[axis],
            _J,
            "SI per field (s, m or rad/s, V)",
            1000.0,
            f"{axis} controller",
            "logger",
            "name = controller STATE_FIELDS (t, reference, reference_dot, measured, error, "
            "z1, z2, z3, s, u_raw, u_sat), position = values (NaN where the algorithm has "
            "none); header.frame_id = algorithm",
            _q.STATE,
            _q.LOCKSTEP,
            "controller_state",
            axis,
        )
        for axis in ("linear", "rotary")
    ),
    TopicSpec(
        DIAGNOSTICS_TOPIC,
        "diagnostic_msgs/msg/DiagnosticArray",
        "-",
        1.0,
        "all nodes",
        "logger, rqt_robot_monitor",
        "status[]: level (0 OK, 1 WARN, 2 ERROR, 3 STALE), name, message, hardware_id, "
        "values (key/value strings): late cycles, watchdog trips, saturation",
        _q.DIAGNOSTICS,
        _q.DIAGNOSTICS,
        "diagnostics",
    ),
    TopicSpec(
        TRAJECTORY_TOPIC,
        "trajectory_msgs/msg/JointTrajectory",
        "m, rad, s",
        None,
        "task runner (or any user)",
        "controllers, logger",
        "joint_names ⊆ ['linear', 'rotary'] (a controller takes its own joint); points: "
        "positions [x, theta], optional velocities and accelerations (one per joint or "
        "none), time_from_start from header.stamp (0 = the controller's next sample); "
        "first and last point at rest. Rotary: rotary_control angle only",
        _q.TRAJECTORY,
        _q.LOCKSTEP,
        "trajectory",
    ),
    TopicSpec(
        TASK_PROGRESS_TOPIC,
        "diagnostic_msgs/msg/DiagnosticArray",
        "-",
        None,
        "task runner",
        "sim / driver, logger",
        "one status 'task: NAME', level 0/1 (timeout)/2 (aborted); values event (tick, "
        "idle, start, reached, timeout, aborted, end), index, segment, outcome, reason, "
        "load.* (SI); header.stamp = the sample it answers. Lockstep: one per sample "
        "(the sim waits for it); aborted: the sim / driver e-stop",
        _q.STATE,
        _q.LOCKSTEP,
        "task_progress",
    ),
    TopicSpec(
        CLOCK_TOPIC,
        "rosgraph_msgs/msg/Clock",
        "s",
        1000.0,
        "sim (lockstep only)",
        "all nodes (use_sim_time)",
        "simulation time",
        _q.CLOCK,
        _q.CLOCK,
        "clock",
    ),
)

TOPIC_BY_NAME: dict[str, TopicSpec] = {t.name: t for t in TOPICS}


def qos_for(topic: str, mode: str) -> _q.QosProfile:
    """Publisher QoS of ``topic`` in run mode ``mode`` (``lockstep`` | ``realtime``)."""
    if mode not in _q.MODES:
        raise ValueError(f"qos mode: {mode!r} refused; allowed: {_q.MODES}")
    spec = TOPIC_BY_NAME.get(topic)
    if spec is None:
        return _q.QosProfile()  # rclpy default (reliable, keep last 10, volatile)
    return spec.qos_lockstep if mode == "lockstep" else spec.qos_realtime


def sub_qos_for(topic: str, mode: str) -> _q.QosProfile:
    """Subscription QoS of the graph's own consumers (controllers, sim, driver) in ``mode``.

    Realtime: sensors best effort, keep last 5 (a late sample is useless to a
    controller), valve commands best effort, keep last 1 (the driver's
    watchdog answers a lost one); both compatible with the reliable
    publishers, so recorders can still ask for reliable delivery. Otherwise
    the publisher's profile.
    """
    spec = TOPIC_BY_NAME.get(topic)
    if mode == "realtime" and spec is not None:
        if spec.kind in ("pressure", "joint_state"):
            return _q.SENSOR_DATA
        if spec.kind == "valve_command":
            return _q.COMMAND_SUB_REALTIME
    return qos_for(topic, mode)


def markdown_table() -> str:
    """The topic table as Markdown (for the README)."""

    def q(p: _q.QosProfile) -> str:
        return f"{p.reliability}, {p.history} {p.depth}, {p.durability}"

    rows = [
        "| topic | type | unit | rate | publisher → subscribers | QoS realtime | QoS lockstep | content |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for t in TOPICS:
        rate = f"{t.rate_hz:g} Hz" if t.rate_hz else "event"
        rows.append(
            f"| `{t.name}` | `{t.ros_type}` | {t.unit} | {rate} | {t.publisher} → "
            f"{t.subscribers} | {q(t.qos_realtime)} | {q(t.qos_lockstep)} | {t.content} |"
        )
    return "\n".join(rows)
