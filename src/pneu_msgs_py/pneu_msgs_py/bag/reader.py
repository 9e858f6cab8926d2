"""Read a pneu run (``.mcap`` file or rosbag2 directory) into numpy arrays.

>>> data = read_run("run.mcap")
>>> js = data.topics["/pneu/linear/joint_state"]
>>> js.stamp_ns, js["position"]                       # int64 ns, float64 m
>>> cs = data.topics["/pneu/linear/controller_state"]
>>> cs["reference"] - cs["measured"]                  # by controller-state field name
>>> data.metadata["pneu.run"]["seed"]

Field names per type
--------------------
FluidPressure
    ``fluid_pressure``, ``variance``
JointState
    ``<joint>.position``, ``<joint>.velocity``, ``<joint>.effort`` for every
    joint and array present; ``<joint>`` alone = its position (or its effort if
    it has no position: valve commands); ``position``, ``velocity``, ``effort``
    = those of the first joint. A joint missing in some messages is NaN there.
Clock
    no fields (``stamp_ns`` is the clock)
DiagnosticArray
    no fields; ``objects`` holds one ``list[DiagStatus]`` per message

Every topic also has ``stamp_ns`` (header stamp), ``log_time_ns`` and
``publish_time_ns`` (MCAP record times), all int64, and ``frame_id``.
Messages are in log-time order.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..qos import QosProfile, parse_offered_qos_yaml
from .cdr import CdrDecodeError
from .decode import FIXED_TYPES, ChannelDecoder, Piece
from .errors import (
    BagError,
    EmptyBagError,
    MissingTopicError,
    NotMcapError,
    NotRos2Error,
    TruncatedBagError,
    TruncatedBagWarning,
    UnknownSchemaError,
)
from .mcap_file import CorruptBagError, McapFile, walk_offsets

__all__ = ["RunData", "TopicArrays", "read_run", "bag_files", "KNOWN_TYPES", "CorruptBagError"]

KNOWN_TYPES = (*FIXED_TYPES, "diagnostic_msgs/msg/DiagnosticArray")


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


def bag_files(path: str | os.PathLike) -> tuple[list[Path], list[str]]:
    """The MCAP files of a path: itself, or a rosbag2 directory's ``relative_file_paths``."""
    p = Path(path)
    warn: list[str] = []
    if p.is_dir():
        meta = p / "metadata.yaml"
        if meta.is_file():
            import yaml

            try:
                info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
            except Exception as e:
                raise NotMcapError(p, f"unreadable metadata.yaml ({type(e).__name__})") from None
            storage = info.get("storage_identifier", "")
            if storage != "mcap":
                raise NotMcapError(p, f"rosbag2 storage is {storage!r}, not 'mcap'")
            files = [p / f for f in info.get("relative_file_paths", [])]
            missing = [str(f.name) for f in files if not f.is_file()]
            if missing:
                raise NotMcapError(p, f"bag file(s) listed in metadata.yaml missing: {missing}")
        else:
            files = sorted(p.glob("*.mcap"))
            if not files:
                raise NotMcapError(p, "directory has neither metadata.yaml nor .mcap files")
            warn.append(
                f"{p}: no metadata.yaml (recording interrupted?); read {len(files)} .mcap file(s)"
            )
        if not files:
            raise EmptyBagError(p, "rosbag2 directory lists no files")
        return files, warn
    if not p.exists():
        raise NotMcapError(p, "no such file or directory")
    return [p], warn


class _Collector:
    """Pieces of one topic across chunks and files."""

    def __init__(self, topic: str, ros_type: str, qos: list[QosProfile]) -> None:
        self.topic = topic
        self.ros_type = ros_type
        self.qos = qos
        self.pieces: list[tuple[int, Piece]] = []  # (base key, piece)
        self.n = 0
        self.chunks = 0

    def add(self, pieces: list[Piece], n_msgs: int) -> None:
        for pc in pieces:
            self.pieces.append((self.n, pc))
        self.n += n_msgs
        self.chunks += 1

    def build(self) -> TopicArrays:
        pcs = [pc for _, pc in self.pieces]
        if not pcs:
            z = np.zeros(0, dtype=np.int64)
            return TopicArrays(self.topic, self.ros_type, z, z, z, {}, (), None, qos=self.qos)
        log_t = np.concatenate([p.log_time for p in pcs])
        need_sort = len(pcs) != self.chunks or bool(np.any(np.diff(log_t) < 0))
        order = None
        if need_sort:
            key = np.concatenate([base + p.order_key for base, p in self.pieces])
            order = np.lexsort((key, log_t))

        def cat(arrs: list[np.ndarray]) -> np.ndarray:
            a = arrs[0] if len(arrs) == 1 else np.concatenate(arrs)
            return a if order is None else a[order]

        stamp = cat([p.stamp for p in pcs])
        pub = cat([p.publish_time for p in pcs])
        log_t = log_t if order is None else log_t[order]
        if len(pcs) == 1 and order is None:
            stamp = pcs[0].stamp
        # fields: union, NaN where a piece lacks one
        names: list[str] = []
        for p in pcs:
            for nm in p.names:
                if nm not in names:
                    names.append(nm)
        keys: list[str] = []
        for p in pcs:
            for k in p.fields:
                if k not in keys:
                    keys.append(k)
        fields: dict[str, np.ndarray] = {}
        for k in keys:
            fields[k] = cat(
                [p.fields[k] if k in p.fields else np.full(len(p), np.nan) for p in pcs]
            )
        # frame ids as categorical codes
        frames: list[str] = []
        codes = []
        for p in pcs:
            ids = []
            for fr in dict.fromkeys(p.frame_ids):
                if fr not in frames:
                    frames.append(fr)
            if len(p.frame_ids) == 1:
                codes.append(np.full(len(p), frames.index(p.frame_ids[0]), dtype=np.int32))
            else:
                ids = np.array([frames.index(f) for f in p.frame_ids], dtype=np.int32)
                codes.append(ids)
        frame_code = cat(codes) if len(frames) > 1 else None
        objects = None
        if any(p.objects is not None for p in pcs):
            objects = [o for p in pcs for o in (p.objects or [])]
            if order is not None:
                objects = [objects[i] for i in order]
        _aliases(self.ros_type, names, fields)
        return TopicArrays(
            self.topic,
            self.ros_type,
            stamp,
            log_t,
            pub,
            fields,
            tuple(frames),
            frame_code,
            tuple(names),
            objects,
            self.qos,
        )


def _aliases(ros_type: str, names: list[str], fields: dict[str, np.ndarray]) -> None:
    if ros_type != "sensor_msgs/msg/JointState":
        return
    for nm in names:
        for k in ("position", "effort", "velocity"):
            if f"{nm}.{k}" in fields and nm not in fields:
                fields[nm] = fields[f"{nm}.{k}"]
    if names:
        for k in ("position", "velocity", "effort"):
            if f"{names[0]}.{k}" in fields and k not in fields:
                fields[k] = fields[f"{names[0]}.{k}"]


def _check_channel(path: str, f: McapFile, cid: int) -> tuple[str, str | None]:
    """(ros type, None) or (type, reason it cannot be decoded)."""
    ch = f.channels[cid]
    sch = f.schemas.get(ch.schema_id)
    if sch is None:
        return "?", f"channel {ch.topic} has no schema"
    if ch.message_encoding != "cdr":
        return sch.name, f"message encoding {ch.message_encoding!r}, not 'cdr'"
    if sch.encoding not in ("ros2msg", "ros2idl"):
        return sch.name, f"schema encoding {sch.encoding!r}, not 'ros2msg'"
    if sch.name not in KNOWN_TYPES:
        return sch.name, f"type {sch.name} has no pneu decoder"
    return sch.name, None


def _read_file(
    path: Path,
    want: set[str] | None,
    collectors: dict[str, _Collector],
    metadata: dict[str, dict[str, str]],
    warn: list[str],
    skipped: dict[str, str],
    seen_topics: set[str],
) -> bool:
    """Read one MCAP file into the collectors; return True if it was truncated."""
    with McapFile(path) as f:
        decoders: dict[int, ChannelDecoder | None] = {}

        def decoder(cid: int) -> ChannelDecoder | None:
            if cid in decoders:
                return decoders[cid]
            ch = f.channels.get(cid)
            dec = None
            if ch is not None:
                seen_topics.add(ch.topic)
                if want is None or ch.topic in want:
                    ros_type, why = _check_channel(str(path), f, cid)
                    if why is not None:
                        if want is not None:
                            raise UnknownSchemaError(path, f"topic {ch.topic}: {why}")
                        skipped[ch.topic] = ros_type
                    else:
                        col = collectors.get(ch.topic)
                        if col is None:
                            qos = []
                            try:
                                qos = parse_offered_qos_yaml(
                                    ch.metadata.get("offered_qos_profiles", "")
                                )
                            except Exception:
                                warn.append(f"{path}: {ch.topic}: unreadable offered_qos_profiles")
                            collectors[ch.topic] = _Collector(ch.topic, ros_type, qos)
                        elif col.ros_type != ros_type:
                            raise UnknownSchemaError(
                                path, f"topic {ch.topic} has types {col.ros_type} and {ros_type}"
                            )
                        dec = ChannelDecoder(ros_type)
            decoders[cid] = dec
            return dec

        for cid in f.channels:
            decoder(cid)
        for chunk in f.iter_chunks():
            offsets = chunk.offsets
            if offsets is None:
                offsets = walk_offsets(chunk.data)
            for cid, offs in offsets.items():
                dec = decoder(cid)
                if dec is None:
                    if cid not in f.channels:
                        warn.append(f"{path}: messages on unknown channel id {cid} skipped")
                    continue
                ch = f.channels[cid]
                try:
                    pieces = dec.decode(chunk.data, offs)
                except CdrDecodeError as e:
                    raise CorruptBagError(path, f"topic {ch.topic}: {e}") from None
                collectors[ch.topic].add(pieces, len(offs))
        for name, md in f.metadata.items():  # after the scan: it finds them as it goes
            metadata.setdefault(name, {}).update(md)
        warn.extend(f"{path}: {w}" for w in f.warnings)
        return f.truncated


def read_run(
    path: str | os.PathLike, topics: Iterable[str] | None = None, *, strict: bool = False
) -> RunData:
    """Read a run into numpy arrays per topic and field, plus the metadata records.

    Parameters
    ----------
    path : ``.mcap`` file or rosbag2 directory (``metadata.yaml`` + ``.mcap`` files)
    topics : topics to read (default: every topic of a type pneu decodes; others
        are listed in ``RunData.skipped``)
    strict : raise :class:`TruncatedBagError` instead of warning on a truncated file

    Raises
    ------
    NotMcapError, NotRos2Error, TruncatedBagError, MissingTopicError,
    UnknownSchemaError, EmptyBagError, CorruptBagError
        all subclasses of :class:`BagError`; ``str(err)`` is one line naming the file.
    """
    files, warn = bag_files(path)
    want = None if topics is None else set(topics)
    collectors: dict[str, _Collector] = {}
    metadata: dict[str, dict[str, str]] = {}
    skipped: dict[str, str] = {}
    seen: set[str] = set()
    for fpath in files:
        truncated = _read_file(fpath, want, collectors, metadata, warn, skipped, seen)
        if truncated:
            if strict:
                raise TruncatedBagError(fpath, "file is truncated (strict mode)")
    if want is not None:
        missing = sorted(want - seen)
        if missing:
            raise MissingTopicError(
                path, f"topic(s) {', '.join(missing)} not in bag; has {', '.join(sorted(seen))}"
            )
    out = {t: c.build() for t, c in collectors.items()}
    total = sum(len(a) for a in out.values())
    if total == 0:
        if any("truncated" in w for w in warn):
            raise TruncatedBagError(path, "file is truncated before its first complete chunk")
        what = "on the requested topics" if want is not None else "at all"
        raise EmptyBagError(path, f"bag holds no messages {what}")
    for w in warn:
        warnings.warn(w, TruncatedBagWarning if "truncated" in w else UserWarning, stacklevel=2)
    return RunData(metadata, out, warn, str(path), skipped)


def iter_topic_names(path: str | os.PathLike) -> Iterator[tuple[str, str]]:
    """(topic, type) of every channel (reads only the summary or scans)."""
    files, _ = bag_files(path)
    for fpath in files:
        with McapFile(fpath) as f:
            for ch in f.channels.values():
                sch = f.schemas.get(ch.schema_id)
                yield ch.topic, sch.name if sch else "?"


__all__ += ["iter_topic_names", "BagError", "NotRos2Error"]
