"""rosbag2's bag metadata (version 9, Jazzy) as the ``rosbag2`` MCAP metadata record holds it."""

from __future__ import annotations

from pneu_msgs_py.bag.chunks import Channel
from pneu_msgs_py.bag.schemas import MESSAGE_ENCODING, TYPE_HASHES

__all__ = ["rosbag2_metadata"]


def rosbag2_metadata(
    channels: list[Channel], file_name: str, t_start: int | None, t_end: int | None, library: str
) -> str:
    """rosbag2's BagMetadata (version 9) as the ``rosbag2`` metadata record holds it.

    ``ros2 bag info/play`` on the loose file read the version from it (so the
    string-coded QoS profiles are decoded as version 9) and take counts,
    times and topics from the summary statistics.
    """
    import yaml

    start = t_start or 0
    duration = (t_end or 0) - start
    count = sum(ch.count for ch in channels)
    info = {
        "version": 9,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": count,
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": ch.topic,
                    "type": ch.ros_type,
                    "serialization_format": MESSAGE_ENCODING,
                    "offered_qos_profiles": [ch.qos.to_dict()],
                    "type_description_hash": TYPE_HASHES.get(ch.ros_type, ""),
                },
                "message_count": ch.count,
            }
            for ch in channels
        ],
        # chunk compression belongs to the storage; rosbag2's own (file/message) is off
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [file_name],
        "files": [
            {
                "path": file_name,
                "starting_time": {"nanoseconds_since_epoch": start},
                "duration": {"nanoseconds": duration},
                "message_count": count,
            }
        ],
        "custom_data": {"writer": library},
        "ros_distro": "jazzy",
    }
    return yaml.safe_dump(info, sort_keys=False, default_flow_style=False)
