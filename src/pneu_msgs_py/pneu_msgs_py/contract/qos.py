"""QoS profiles of pneu's topics, and their rosbag2 ``offered_qos_profiles`` text.

Two run modes:

``realtime`` (the rig, or the twin paced by the wall clock)
    Sensors: the publisher offers reliable, keep last 100; the controllers
    subscribe with the sensor-data profile (best effort, keep last 5): a late
    sample is useless to them, a retransmission would only delay the next
    one, while the recorder subscribes reliable and gets every sample even
    when the machine is busy (measured: a best-effort recorder lost samples
    on a loaded 2-core machine). Keep last 100 is the recorder's slack: a
    reliable writer with keep-last history never blocks the loop.
    Valve commands: the publisher offers reliable, keep last 1; the driver
    subscribes best effort, keep last 1. A reliable publisher is compatible
    with both best-effort and reliable subscriptions (the reverse is not:
    best-effort pub + reliable sub = no data), so the logger can still ask
    for reliable delivery while the driver never gets a command late through
    retransmission: a stale command is worse than a lost one, which the
    driver's watchdog answers with the safe value. Depth 1: only the newest
    command matters.
``lockstep`` (simulation that waits for every controller, nothing may be lost)
    Every data topic is reliable, keep last 1000 (1 s at 1 kHz, so a slow
    logger does not lose samples either), volatile.

Controller state and diagnostics are reliable in both modes (depth 100 / 10).
``/clock`` offers reliable, keep last 1: compatible with rclcpp/rclpy's
``TimeSource`` subscription (best effort, depth 1) and with a reliable logger.

rosbag2 (Jazzy, metadata version 9) stores each channel's offered profiles
as YAML in the MCAP channel metadata ``offered_qos_profiles``;
:func:`offered_qos_yaml` produces exactly what rosbag2_storage's
``serialize_rclcpp_qos_vector`` emits with yaml-cpp (``YAML::Dump``): a block
sequence, policies as lower-case strings, durations as ``{sec, nsec}`` maps
(infinite = ``9223372036 s 854775807 ns``, RMW_DURATION_INFINITE), no
trailing newline.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

__all__ = [
    "QosProfile",
    "DURATION_INFINITE",
    "SENSOR_DATA",
    "SENSOR_PUB",
    "LOCKSTEP",
    "COMMAND_PUB",
    "COMMAND_SUB_REALTIME",
    "STATE",
    "DIAGNOSTICS",
    "CLOCK",
    "MODES",
    "offered_qos_yaml",
    "parse_offered_qos_yaml",
    "compatible",
    "to_rclpy",
]

#: RMW_DURATION_INFINITE as rmw reports it: {sec: INT64_MAX // 1e9, nsec: INT64_MAX % 1e9}.
DURATION_INFINITE = (9223372036, 854775807)

MODES = ("lockstep", "realtime")

_HISTORY = ("system_default", "keep_last", "keep_all")
_RELIABILITY = ("system_default", "reliable", "best_effort")
_DURABILITY = ("system_default", "transient_local", "volatile")
_LIVELINESS = ("system_default", "automatic", "manual_by_topic")


@dataclass(frozen=True)
class QosProfile:
    """One QoS profile, policies named as rmw's short keys (``rmw_qos_*_to_str``)."""

    history: str = "keep_last"
    depth: int = 10
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline: tuple[int, int] = DURATION_INFINITE
    lifespan: tuple[int, int] = DURATION_INFINITE
    liveliness: str = "automatic"
    liveliness_lease_duration: tuple[int, int] = DURATION_INFINITE
    avoid_ros_namespace_conventions: bool = False

    def __post_init__(self) -> None:
        for name, allowed in (
            ("history", _HISTORY),
            ("reliability", _RELIABILITY),
            ("durability", _DURABILITY),
            ("liveliness", _LIVELINESS),
        ):
            if getattr(self, name) not in allowed:
                raise ValueError(f"qos.{name}: {getattr(self, name)!r} refused; allowed: {allowed}")
        if self.depth < 0:
            raise ValueError(f"qos.depth: {self.depth!r} refused; allowed: >= 0")

    def to_dict(self) -> dict[str, Any]:
        """As rosbag2 (v9) lists it in metadata.yaml's ``offered_qos_profiles``."""
        return {
            "history": self.history,
            "depth": self.depth,
            "reliability": self.reliability,
            "durability": self.durability,
            "deadline": {"sec": self.deadline[0], "nsec": self.deadline[1]},
            "lifespan": {"sec": self.lifespan[0], "nsec": self.lifespan[1]},
            "liveliness": self.liveliness,
            "liveliness_lease_duration": {
                "sec": self.liveliness_lease_duration[0],
                "nsec": self.liveliness_lease_duration[1],
            },
            "avoid_ros_namespace_conventions": self.avoid_ros_namespace_conventions,
        }

    def to_yaml(self) -> str:
        """This profile as one yaml-cpp block-sequence item (no trailing newline)."""

        def dur(key: str, d: tuple[int, int]) -> list[str]:
            return [f"{key}:", f"  sec: {d[0]}", f"  nsec: {d[1]}"]

        lines = [
            f"history: {self.history}",
            f"depth: {self.depth}",
            f"reliability: {self.reliability}",
            f"durability: {self.durability}",
            *dur("deadline", self.deadline),
            *dur("lifespan", self.lifespan),
            f"liveliness: {self.liveliness}",
            *dur("liveliness_lease_duration", self.liveliness_lease_duration),
            f"avoid_ros_namespace_conventions: {'true' if self.avoid_ros_namespace_conventions else 'false'}",
        ]
        return "\n".join(("- " if i == 0 else "  ") + ln for i, ln in enumerate(lines))


SENSOR_DATA = QosProfile(history="keep_last", depth=5, reliability="best_effort")
SENSOR_PUB = QosProfile(history="keep_last", depth=100, reliability="reliable")
LOCKSTEP = QosProfile(history="keep_last", depth=1000, reliability="reliable")
COMMAND_PUB = QosProfile(history="keep_last", depth=1, reliability="reliable")
COMMAND_SUB_REALTIME = QosProfile(history="keep_last", depth=1, reliability="best_effort")
STATE = QosProfile(history="keep_last", depth=100, reliability="reliable")
DIAGNOSTICS = QosProfile(history="keep_last", depth=10, reliability="reliable")
CLOCK = QosProfile(history="keep_last", depth=1, reliability="reliable")
TRAJECTORY = QosProfile(history="keep_last", depth=10, reliability="reliable")  # rclpy's default


def offered_qos_yaml(profiles: Iterable[QosProfile]) -> str:
    """rosbag2's ``offered_qos_profiles`` text for a list of publisher profiles."""
    profiles = list(profiles)
    if not profiles:
        return "[]"  # YAML::Dump of an empty sequence node
    return "\n".join(p.to_yaml() for p in profiles)


def parse_offered_qos_yaml(text: str) -> list[QosProfile]:
    """Inverse of :func:`offered_qos_yaml` (also reads rosbag2's int-coded v8 form)."""
    import yaml

    items = yaml.safe_load(text) or []
    out = []
    for it in items:

        def pol(key: str, names: tuple[str, ...], it=it) -> str:
            v = it[key]
            return names[v] if isinstance(v, int) and 0 <= v < len(names) else str(v)

        out.append(
            QosProfile(
                history=pol("history", _HISTORY),
                depth=int(it["depth"]),
                reliability=pol("reliability", _RELIABILITY),
                durability=pol("durability", _DURABILITY),
                deadline=(int(it["deadline"]["sec"]), int(it["deadline"]["nsec"])),
                lifespan=(int(it["lifespan"]["sec"]), int(it["lifespan"]["nsec"])),
                liveliness=pol("liveliness", _LIVELINESS),
                liveliness_lease_duration=(
                    int(it["liveliness_lease_duration"]["sec"]),
                    int(it["liveliness_lease_duration"]["nsec"]),
                ),
                avoid_ros_namespace_conventions=bool(it["avoid_ros_namespace_conventions"]),
            )
        )
    return out


def compatible(pub: QosProfile, sub: QosProfile) -> bool:
    """DDS request/offer rule for the policies pneu sets (reliability, durability).

    A best-effort publisher cannot serve a reliable subscription; a volatile
    publisher cannot serve a transient-local subscription.
    """
    if pub.reliability == "best_effort" and sub.reliability == "reliable":
        return False
    return not (pub.durability == "volatile" and sub.durability == "transient_local")


def to_rclpy(profile: QosProfile, qos_module: Any) -> Any:
    """Build an ``rclpy.qos.QoSProfile``; pass ``rclpy.qos`` in (no rclpy import here)."""
    q = qos_module
    return q.QoSProfile(
        history=q.HistoryPolicy.get_from_short_key(profile.history),
        depth=profile.depth,
        reliability=q.ReliabilityPolicy.get_from_short_key(profile.reliability),
        durability=q.DurabilityPolicy.get_from_short_key(profile.durability),
    )
