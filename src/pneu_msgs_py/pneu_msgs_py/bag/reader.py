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

from pneu_msgs_py.bag.cdr import CdrDecodeError
from pneu_msgs_py.bag.decode import FIXED_TYPES, ChannelDecoder, Piece
from pneu_msgs_py.bag.errors import (
    BagError,
    EmptyBagError,
    MissingTopicError,
    NotMcapError,
    NotRos2Error,
    TruncatedBagError,
    TruncatedBagWarning,
    UnknownSchemaError,
)
from pneu_msgs_py.bag.mcap_file import CorruptBagError, McapFile, walk_offsets
from pneu_msgs_py.contract.qos import QosProfile, parse_offered_qos_yaml

__all__ = [
    "RunData",
    "TopicArrays",
    "read_run",
    "iter_run",
    "bag_files",
    "KNOWN_TYPES",
    "CorruptBagError",
]

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


def _all_equal(v: np.ndarray, c) -> bool:
    """Every element equals ``c`` (NaN equals NaN)."""
    if c != c:  # NaN
        return bool(np.isnan(v).all())
    return bool((v == c).all())


class _Column:
    """A growing column that stays a single value while the data allow (no memory)."""

    __slots__ = ("arr", "cap", "const", "dtype", "has_const", "n")

    def __init__(self, dtype, capacity: int, n: int = 0, fill=None) -> None:
        self.dtype = np.dtype(dtype)
        self.cap = max(int(capacity), 16)
        self.n = n
        self.arr: np.ndarray | None = None
        self.const = fill
        self.has_const = n > 0

    def _materialize(self, need: int) -> None:
        self.cap = max(self.cap, need)
        arr = np.empty(self.cap, dtype=self.dtype)
        if self.n:
            arr[: self.n] = self.const
        self.arr = arr

    def _ensure(self, need: int) -> None:
        if need > self.cap:
            self.cap = max(need, 2 * self.cap)
            arr = np.empty(self.cap, dtype=self.dtype)
            arr[: self.n] = self.arr[: self.n]
            self.arr = arr

    def append(self, v: np.ndarray) -> None:
        k = len(v)
        if not k:
            return
        if self.arr is None:
            if not self.has_const:
                c = v[0]
                if _all_equal(v, c):
                    self.const, self.has_const = c, True
                    self.n += k
                    return
            elif _all_equal(v, self.const):
                self.n += k
                return
            self._materialize(self.n + k)
        self._ensure(self.n + k)
        self.arr[self.n : self.n + k] = v
        self.n += k

    def append_const(self, c, k: int) -> None:
        if self.arr is None and (
            not self.has_const or self.const == c or (c != c and self.const != self.const)
        ):
            self.const, self.has_const = c, True
            self.n += k
            return
        if self.arr is None:
            self._materialize(self.n + k)
        self._ensure(self.n + k)
        self.arr[self.n : self.n + k] = c
        self.n += k

    def head(self, n: int):
        """The first ``n`` values (an array, or the single value)."""
        return self.arr[:n] if self.arr is not None else self.const

    def result(self) -> np.ndarray:
        """The column; a read-only broadcast view if it held one value throughout."""
        if self.arr is None:
            return np.broadcast_to(np.asarray(self.const, dtype=self.dtype), (self.n,))
        out = self.arr[: self.n]
        if self.cap > self.n + self.n // 8:
            out = out.copy()  # do not keep a large unused capacity alive
        self.arr = None
        return out


def _own_copy(base, n: int, cap: int) -> _Column:
    """A materialised int64 column holding ``base``'s first ``n`` values."""
    col = _Column(np.int64, max(cap, n))
    if n:
        col.arr = np.empty(col.cap, dtype=np.int64)
        col.arr[:n] = base.head(n)
        col.n = n
    return col


class _TimeColumn:
    """An int64 time column that is stored only if it differs from the log time."""

    __slots__ = ("base", "col", "n")

    def __init__(self, base) -> None:
        self.base = base
        self.col: _Column | None = None
        self.n = 0

    def append(self, v: np.ndarray, base_chunk: np.ndarray) -> None:
        if self.col is None:
            if np.array_equal(v, base_chunk):
                self.n += len(v)
                return
            self.col = _own_copy(self.base, self.n, self.base.cap)
        self.col.append(v)
        self.n += len(v)


class _SharedLogTime:
    """A topic's log times kept as a view of another topic's while they are identical.

    At 1 kHz every topic of a cycle carries the same stamp: one array serves them all.
    The master topic's chunk is appended first (see :func:`_add_results`).
    """

    __slots__ = ("cap", "col", "master", "n")

    def __init__(self, master: _Column, capacity: int) -> None:
        self.master = master
        self.col: _Column | None = None
        self.n = 0
        self.cap = max(int(capacity), 16)

    def append(self, v: np.ndarray) -> None:
        k = len(v)
        if self.col is None:
            m = self.master
            if m.n >= self.n + k and (
                np.array_equal(m.arr[self.n : self.n + k], v)
                if m.arr is not None
                else _all_equal(v, m.const)
            ):
                self.n += k
                return
            self.col = _own_copy(m, self.n, self.cap)
        self.col.append(v)
        self.n += k

    def head(self, n: int):
        return self.col.head(n) if self.col is not None else self.master.head(n)


def _merge_pieces(pieces: list[Piece]) -> Piece:
    """Several pieces of one chunk and channel -> one, in message-index order."""
    # pieces in order of their first message, so names and fields are first-seen ordered
    pieces = sorted(pieces, key=lambda p: int(p.order_key.min()) if len(p) else 0)
    key = np.concatenate([p.order_key for p in pieces])
    order = np.argsort(key, kind="stable")
    keys: list[str] = []
    names: list[str] = []
    for p in pieces:
        keys += [k for k in p.fields if k not in keys]
        names += [nm for nm in p.names if nm not in names]
    fields = {
        k: np.concatenate([p.fields.get(k, np.full(len(p), np.nan)) for p in pieces])[order]
        for k in keys
    }
    frames = [
        fr
        for p in pieces
        for fr in (p.frame_ids if len(p.frame_ids) == len(p) else p.frame_ids * len(p))
    ]
    objects = None
    if any(p.objects is not None for p in pieces):
        objs = [o for p in pieces for o in (p.objects or [None] * len(p))]
        objects = [objs[i] for i in order]
    return Piece(
        np.concatenate([p.log_time for p in pieces])[order],
        np.concatenate([p.publish_time for p in pieces])[order],
        np.concatenate([p.stamp for p in pieces])[order],
        fields,
        [frames[i] for i in order],
        tuple(names),
        objects,
        key[order],
    )


class _Collector:
    """One topic's columns, filled chunk by chunk (preallocated from the file's statistics)."""

    def __init__(
        self,
        topic: str,
        ros_type: str,
        qos: list[QosProfile],
        capacity: int,
        master: _Collector | None = None,
    ) -> None:
        self.topic = topic
        self.ros_type = ros_type
        self.qos = qos
        self.capacity = capacity
        self.master = master
        self.log = (
            _Column(np.int64, capacity) if master is None else _SharedLogTime(master.log, capacity)
        )
        self.pub = _TimeColumn(self.log)
        self.stamp = _TimeColumn(self.log)
        self.fields: dict[str, _Column] = {}
        self.codes = _Column(np.int32, capacity)
        self.frames: list[str] = []
        self.names: list[str] = []
        self.objects: list | None = None
        self.n = 0
        self.sorted = True
        self.last = None

    def add(self, pieces: list[Piece]) -> None:
        if not pieces:
            return
        p = pieces[0] if len(pieces) == 1 else _merge_pieces(pieces)
        k = len(p)
        if not k:
            return
        lt = p.log_time
        if self.sorted and (
            (self.last is not None and lt[0] < self.last)
            or (k > 1 and bool((lt[1:] < lt[:-1]).any()))
        ):
            self.sorted = False
        self.last = int(lt[-1]) if self.last is None else max(self.last, int(lt[-1]))
        self.log.append(lt)
        self.pub.append(p.publish_time, lt)
        self.stamp.append(p.stamp, lt)
        for nm in p.names:
            if nm not in self.names:
                self.names.append(nm)
        for key, v in p.fields.items():
            col = self.fields.get(key)
            if col is None:
                col = self.fields[key] = _Column(np.float64, self.capacity, self.n, np.nan)
            col.append(v)
        for key, col in self.fields.items():
            if key not in p.fields:
                col.append_const(np.nan, k)
        if len(p.frame_ids) == 1:
            fr = p.frame_ids[0]
            if fr not in self.frames:
                self.frames.append(fr)
            self.codes.append_const(self.frames.index(fr), k)
        else:
            for fr in dict.fromkeys(p.frame_ids):
                if fr not in self.frames:
                    self.frames.append(fr)
            idx = {fr: i for i, fr in enumerate(self.frames)}
            self.codes.append(np.array([idx[f] for f in p.frame_ids], dtype=np.int32))
        if p.objects is not None:
            if self.objects is None:
                self.objects = [None] * self.n
            self.objects.extend(p.objects)
        elif self.objects is not None:
            self.objects.extend([None] * k)
        self.n += k

    def log_result(self, master_log: np.ndarray | None) -> np.ndarray:
        """The log-time array (a prefix view of the master's if shared throughout)."""
        if isinstance(self.log, _SharedLogTime):
            if self.log.col is not None:
                return self.log.col.result()
            return master_log[: self.n]
        return self.log.result()

    def build(self, log_t: np.ndarray) -> TopicArrays:
        pub = log_t if self.pub.col is None else self.pub.col.result()
        stamp = log_t if self.stamp.col is None else self.stamp.col.result()
        fields = {k: c.result() for k, c in self.fields.items()}
        codes = self.codes.result() if len(self.frames) > 1 else None
        objects = self.objects
        if not self.sorted:
            order = np.argsort(log_t, kind="stable")
            pub_alias, stamp_alias = pub is log_t, stamp is log_t
            log_t = log_t[order]
            pub = log_t if pub_alias else pub[order]
            stamp = log_t if stamp_alias else stamp[order]
            fields = {k: v[order] for k, v in fields.items()}
            codes = None if codes is None else codes[order]
            objects = None if objects is None else [objects[i] for i in order]
        _aliases(self.ros_type, self.names, fields)
        return TopicArrays(
            self.topic,
            self.ros_type,
            stamp,
            log_t,
            pub,
            fields,
            tuple(self.frames),
            codes,
            tuple(self.names),
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


def _check_channel(f: McapFile, cid: int) -> tuple[str, str | None]:
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


@dataclass
class _Ctx:
    want: set[str] | None
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    warn: list[str] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)
    seen: set[str] = field(default_factory=set)
    # topic -> (ros type, qos, capacity hint)
    topics: dict[str, tuple[str, list[QosProfile], int]] = field(default_factory=dict)
    truncated: list[str] = field(default_factory=list)


def _file_chunks(path: Path, ctx: _Ctx) -> Iterator[list[tuple[str, list[Piece]]]]:
    """Per chunk of one MCAP file: [(topic, pieces)] of the wanted, decodable channels."""
    with McapFile(path) as f:
        decoders: dict[int, ChannelDecoder | None] = {}

        def decoder(cid: int) -> ChannelDecoder | None:
            if cid in decoders:
                return decoders[cid]
            ch = f.channels.get(cid)
            dec = None
            if ch is not None:
                ctx.seen.add(ch.topic)
                if ctx.want is None or ch.topic in ctx.want:
                    ros_type, why = _check_channel(f, cid)
                    if why is not None:
                        if ctx.want is not None:
                            raise UnknownSchemaError(path, f"topic {ch.topic}: {why}")
                        ctx.skipped[ch.topic] = ros_type
                    else:
                        known = ctx.topics.get(ch.topic)
                        count = (f.message_counts or {}).get(cid, 0)
                        if known is None:
                            qos: list[QosProfile] = []
                            try:
                                qos = parse_offered_qos_yaml(
                                    ch.metadata.get("offered_qos_profiles", "")
                                )
                            except Exception:
                                ctx.warn.append(
                                    f"{path}: {ch.topic}: unreadable offered_qos_profiles"
                                )
                            ctx.topics[ch.topic] = (ros_type, qos, count)
                        elif known[0] != ros_type:
                            raise UnknownSchemaError(
                                path, f"topic {ch.topic} has types {known[0]} and {ros_type}"
                            )
                        else:
                            ctx.topics[ch.topic] = (known[0], known[1], known[2] + count)
                        dec = ChannelDecoder(ros_type)
            decoders[cid] = dec
            return dec

        for cid in f.channels:
            decoder(cid)
        for chunk in f.iter_chunks():
            offsets = chunk.offsets
            if offsets is None:
                offsets = walk_offsets(chunk.data)
            out = []
            for cid, offs in offsets.items():
                dec = decoder(cid)
                if dec is None:
                    if cid not in f.channels:
                        ctx.warn.append(f"{path}: messages on unknown channel id {cid} skipped")
                    continue
                ch = f.channels[cid]
                try:
                    out.append((ch.topic, dec.decode(chunk.data, offs)))
                except CdrDecodeError as e:
                    raise CorruptBagError(path, f"topic {ch.topic}: {e}") from None
            yield out
        for name, md in f.metadata.items():  # after the scan: it finds them as it goes
            ctx.metadata.setdefault(name, {}).update(md)
        ctx.warn.extend(f"{path}: {w}" for w in f.warnings)
        if f.truncated:
            ctx.truncated.append(str(path))


def _finish(path, ctx: _Ctx, collectors: dict[str, _Collector], strict: bool) -> RunData:
    if strict and ctx.truncated:
        raise TruncatedBagError(ctx.truncated[0], "file is truncated (strict mode)")
    if ctx.want is not None:
        missing = sorted(ctx.want - ctx.seen)
        if missing:
            raise MissingTopicError(
                path, f"topic(s) {', '.join(missing)} not in bag; has {', '.join(sorted(ctx.seen))}"
            )
    return RunData(ctx.metadata, _build_all(collectors), ctx.warn, str(path), ctx.skipped)


def _add_results(
    results: list[tuple[str, list[Piece]]],
    collectors: dict[str, _Collector],
    ctx: _Ctx,
    capacity: int | None,
) -> None:
    """Add one chunk's decoded pieces; the first collector is the log-time master."""
    master = next(iter(collectors.values()), None)
    if master is None:  # the busiest topic of the first chunk becomes the master
        results = sorted(results, key=lambda r: -sum(len(p) for p in r[1]))
    elif len(results) > 1:
        results = sorted(results, key=lambda r: r[0] != master.topic)  # master first
    for topic, pieces in results:
        col = collectors.get(topic)
        if col is None:
            ros_type, qos, cap = ctx.topics[topic]
            cap = cap if capacity is None else capacity
            col = collectors[topic] = _Collector(topic, ros_type, qos, cap, master)
            master = master or col
        col.add(pieces)


def _build_all(collectors: dict[str, _Collector]) -> dict[str, TopicArrays]:
    out: dict[str, TopicArrays] = {}
    master_log = None
    for t, c in collectors.items():
        log_t = c.log_result(master_log)
        if c.master is None:
            master_log = log_t
        out[t] = c.build(log_t)
    return out


def _emit_warnings(ws: list[str]) -> None:
    for w in ws:
        warnings.warn(w, TruncatedBagWarning if "truncated" in w else UserWarning, stacklevel=3)


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

    Columns that hold one value throughout (a variance of 0, a NaN observer
    state) are returned as read-only broadcast views, and ``stamp_ns`` /
    ``publish_time_ns`` are the ``log_time_ns`` array itself when equal to it.

    Raises
    ------
    NotMcapError, NotRos2Error, TruncatedBagError, MissingTopicError,
    UnknownSchemaError, EmptyBagError, CorruptBagError
        all subclasses of :class:`BagError`; ``str(err)`` is one line naming the file.
    """
    files, warn = bag_files(path)
    ctx = _Ctx(None if topics is None else set(topics), warn=warn)
    collectors: dict[str, _Collector] = {}
    for fpath in files:
        for results in _file_chunks(fpath, ctx):
            _add_results(results, collectors, ctx, None)
        for topic, (ros_type, qos, _cap) in ctx.topics.items():
            if topic not in collectors:  # a channel without messages
                collectors[topic] = _Collector(topic, ros_type, qos, 0)
    data = _finish(path, ctx, collectors, strict)
    if data.message_count == 0:
        if ctx.truncated:
            raise TruncatedBagError(path, "file is truncated before its first complete chunk")
        what = "on the requested topics" if ctx.want is not None else "at all"
        raise EmptyBagError(path, f"bag holds no messages {what}")
    _emit_warnings(data.warnings)
    return data


def iter_run(
    path: str | os.PathLike,
    topics: Iterable[str] | None = None,
    *,
    batch_chunks: int = 32,
    strict: bool = False,
) -> Iterator[RunData]:
    """Stream a run in batches of ``batch_chunks`` chunks (bounded memory).

    Each batch is a :class:`RunData` for the messages of those chunks, in
    log-time order within the batch; batches follow the file order. The last
    batch carries the metadata and warnings. Same errors as :func:`read_run`.
    """
    files, warn = bag_files(path)
    ctx = _Ctx(None if topics is None else set(topics), warn=warn)
    collectors: dict[str, _Collector] = {}
    total = 0
    n_chunks = 0
    pending = None
    for fpath in files:
        for results in _file_chunks(fpath, ctx):
            _add_results(results, collectors, ctx, 1024 * batch_chunks)
            n_chunks += 1
            if n_chunks % batch_chunks == 0:
                if pending is not None:
                    yield pending
                pending = RunData({}, _build_all(collectors), [], str(path))
                total += pending.message_count
                collectors = {}
    last = _finish(path, ctx, collectors, strict)
    total += last.message_count
    if pending is not None:
        if last.message_count:
            yield pending
            pending = last
        else:
            pending.metadata, pending.warnings, pending.skipped = (
                last.metadata,
                last.warnings,
                last.skipped,
            )
    else:
        pending = last
    if total == 0:
        if ctx.truncated:
            raise TruncatedBagError(path, "file is truncated before its first complete chunk")
        raise EmptyBagError(path, "bag holds no messages")
    _emit_warnings(pending.warnings)
    yield pending


def iter_topic_names(path: str | os.PathLike) -> Iterator[tuple[str, str]]:
    """(topic, type) of every channel (reads only the summary or scans)."""
    files, _ = bag_files(path)
    for fpath in files:
        with McapFile(fpath) as f:
            for ch in f.channels.values():
                sch = f.schemas.get(ch.schema_id)
                yield ch.topic, sch.name if sch else "?"


__all__ += ["iter_topic_names", "BagError", "NotRos2Error"]
