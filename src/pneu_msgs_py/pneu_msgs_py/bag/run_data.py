"""A run read back: per-topic arrays (:class:`TopicArrays`) and the whole run (:class:`RunData`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pneu_msgs_py.bag.errors import MissingTopicError
from pneu_msgs_py.contract.qos import QosProfile

__all__ = ["RunData", "TopicArrays"]


@dataclass
class TopicArrays:
    """All messages of one topic as arrays (see module docstring for field names)."""

    topic: str
    ros_type: str
    stamp_ns: np.ndarray
    log_time_ns: np.ndarray
    publish_time_ns: np.ndarray
    fields: dict[str, np.ndarray]
    frame_ids: tuple[str, ...]  # distinct frame ids, in order of first appearance
    frame_code: np.ndarray | None  # index into frame_ids per message (None: only one)
    names: tuple[str, ...] = ()  # JointState joint names (union, first-seen order)
    objects: list | None = None
    qos: list[QosProfile] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.log_time_ns)

    def __getitem__(self, key: str) -> np.ndarray:
        if key in ("stamp_ns", "log_time_ns", "publish_time_ns"):
            return getattr(self, key)
        try:
            return self.fields[key]
        except KeyError:
            raise KeyError(
                f"{self.topic} has no field {key!r}; fields: {sorted(self.fields)}"
            ) from None

    def __contains__(self, key: object) -> bool:
        return key in self.fields or key in ("stamp_ns", "log_time_ns", "publish_time_ns")

    def keys(self) -> list[str]:
        return ["stamp_ns", "log_time_ns", "publish_time_ns", *self.fields]

    @property
    def frame_id(self) -> np.ndarray:
        """Per-message header.frame_id (str array)."""
        fr = np.array(self.frame_ids or ("",))
        if self.frame_code is None:
            return np.repeat(fr[:1], len(self))
        return fr[self.frame_code]


@dataclass
class RunData:
    """A run read back: metadata records, per-topic arrays, warnings."""

    metadata: dict[str, dict[str, str]]
    topics: dict[str, TopicArrays]
    warnings: list[str] = field(default_factory=list)
    path: str = ""
    skipped: dict[str, str] = field(default_factory=dict)  # topic -> type not decoded

    def __getitem__(self, topic: str) -> TopicArrays:
        try:
            return self.topics[topic]
        except KeyError:
            raise MissingTopicError(
                self.path, f"topic {topic} not read; topics: {', '.join(sorted(self.topics))}"
            ) from None

    @property
    def message_count(self) -> int:
        return sum(len(t) for t in self.topics.values())
