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

import contextlib
import os
import struct
import warnings
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from pneu_msgs_py.bag.cdr import CdrDecodeError
from pneu_msgs_py.bag.columns import Collector
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
from pneu_msgs_py.bag.run_data import RunData, TopicArrays
from pneu_msgs_py.contract.qos import QosProfile, parse_offered_qos_yaml

__all__ = [
    "SIDECAR",
    "RunData",
    "TopicArrays",
    "read_run",
    "iter_run",
    "bag_files",
    "KNOWN_TYPES",
    "CorruptBagError",
]

KNOWN_TYPES = (*FIXED_TYPES, "diagnostic_msgs/msg/DiagnosticArray")
#: The run metadata a ROS run recorded by ``ros2 bag record`` carries beside its files:
#: ``{record name: {key: value}}`` as JSON, written by the logger node into the bag directory.
SIDECAR = "pneu_metadata.json"


def bag_files(path: str | os.PathLike) -> tuple[list[Path], list[str]]:
    """The MCAP files of a path: itself, or a rosbag2 directory's ``relative_file_paths``.

    A run directory (``out`` of a launch or of ``pneu run``) stands for its bag:
    ``run.mcap``, or the rosbag2 directory ``bag`` -- also one whose recorder was killed
    before it wrote ``metadata.yaml`` (its ``.mcap`` files read, with a note).
    """
    p = Path(path)
    warn: list[str] = []
    if p.is_dir() and not (p / "metadata.yaml").is_file():
        if (p / "run.mcap").is_file():
            return [p / "run.mcap"], warn
        inner = p / "bag"
        if (inner / "metadata.yaml").is_file() or (
            not any(p.glob("*.mcap")) and inner.is_dir() and any(inner.glob("*.mcap"))
        ):
            p = inner
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
        partial = p.with_name(p.name + ".partial")
        if partial.is_file():
            raise NotMcapError(
                p,
                f"no such file; {partial} is there (a recording that was cut short: "
                f"pneu recover {partial} --out NEW.mcap)",
            )
        raise NotMcapError(p, "no such file or directory")
    return [p], warn


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
    damaged: int = 0  # chunks skipped as unreadable


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
        read: dict[int, int] = {}
        lost_unknown = False
        for chunk in f.iter_chunks():
            if chunk.problem:
                n = None if chunk.lost is None else sum(chunk.lost.values())
                lost_unknown |= n is None
                ctx.damaged += 1
                ctx.warn.append(
                    f"{path}: {chunk.problem}: chunk skipped, "
                    + ("messages in it lost (count unknown)" if n is None else f"{n} messages lost")
                )
                continue
            out = []
            for cid, pieces in _decode_chunk(chunk, decoder, f, path, ctx):
                out.append((f.channels[cid].topic, pieces))
                read[cid] = read.get(cid, 0) + sum(len(p) for p in pieces)
            yield out
        if f.message_counts and not f.truncated:
            wanted = [c for c in f.message_counts if decoders.get(c) is not None]
            lost = sum(max(0, f.message_counts[c] - read.get(c, 0)) for c in wanted)
            if lost:
                total = sum(f.message_counts[c] for c in wanted)
                ctx.warn.append(
                    f"{path}: {lost} of {total} messages lost in damaged chunks "
                    "(counted against the file's statistics)"
                )
        for name, md in f.metadata.items():  # after the scan: it finds them as it goes
            ctx.metadata.setdefault(name, {}).update(md)
        ctx.warn.extend(f"{path}: {w}" for w in f.warnings)
        if f.truncated:
            ctx.truncated.append(str(path))


def _merge_sidecar(files: list[Path], ctx: _Ctx) -> None:
    """Metadata records of the :data:`SIDECAR` beside the files (a ros2 bag record run)."""
    side = files[0].parent / SIDECAR if files else None
    if side is None or not side.is_file():
        return
    import json

    try:
        records = json.loads(side.read_text(encoding="utf-8"))
        ok = isinstance(records, dict) and all(
            isinstance(r, dict) and all(isinstance(v, str) for v in r.values())
            for r in records.values()
        )
    except (OSError, ValueError) as err:
        ctx.warn.append(f"{side}: unreadable run metadata ({err}); ignored")
        return
    if not ok:
        ctx.warn.append(f"{side}: not {{record: {{key: str}}}} JSON; ignored")
        return
    for name, rec in records.items():
        ctx.metadata.setdefault(name, rec)


def _decode_chunk(chunk, decoder, f: McapFile, path: Path, ctx: _Ctx):
    """(channel id, pieces) of one chunk; undecodable messages are skipped with a warning."""
    offsets = chunk.offsets if chunk.offsets is not None else walk_offsets(chunk.data)
    if any(cid not in f.channels for cid in offsets):
        f.definitions_in(chunk.data)  # some writers put schemas and channels in chunks
    for cid, offs in offsets.items():
        dec = decoder(cid)
        if dec is None:
            if cid not in f.channels:
                ctx.warn.append(f"{path}: messages on unknown channel id {cid} skipped")
            continue
        try:
            yield cid, dec.decode(chunk.data, offs)
            continue
        except Exception as e:  # CdrDecodeError, or a malformed message in any decoder
            why = f"{type(e).__name__}: {e}" if not isinstance(e, CdrDecodeError) else str(e)
        if chunk.offsets is not None:  # a damaged message index: walk the records instead
            walked = walk_offsets(chunk.data).get(cid)
            if walked is not None:
                try:
                    yield cid, dec.decode(chunk.data, walked)
                    continue
                except Exception:
                    pass
        ctx.warn.append(
            f"{path}: {len(offs)} {f.channels[cid].topic} message(s) in the chunk at byte "
            f"{chunk.where} undecodable ({why}): skipped"
        )


def _finish(path, ctx: _Ctx, collectors: dict[str, Collector], strict: bool) -> RunData:
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
    collectors: dict[str, Collector],
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
            col = collectors[topic] = Collector(topic, ros_type, qos, cap, master)
            master = master or col
        col.add(pieces)


def _build_all(collectors: dict[str, Collector]) -> dict[str, TopicArrays]:
    out: dict[str, TopicArrays] = {}
    master_log = None
    for t, c in collectors.items():
        log_t = c.log_result(master_log)
        if c.master is None:
            master_log = log_t
        out[t] = c.build(log_t)
    return out


@contextlib.contextmanager
def _damage_as_bag_error(path) -> Iterator[None]:
    """Damage no check above foresaw still ends as one line naming the file, never a traceback."""
    try:
        yield
    except BagError:
        raise
    except (
        IndexError,
        KeyError,
        ValueError,
        TypeError,
        OverflowError,
        struct.error,
        MemoryError,
    ) as err:
        raise CorruptBagError(
            path, f"damaged: {type(err).__name__}: {' '.join(str(err).split())}"
        ) from None


def _foreign(ctx: _Ctx) -> str:
    """What a bag without readable pneu messages holds, in one line."""
    types = {t: ty for t, (ty, _q, _c) in ctx.topics.items()} | ctx.skipped
    listed = ", ".join(f"{t} ({types[t]})" for t in sorted(types)[:8])
    if len(types) > 8:
        listed += f", ... ({len(types)} topics)"
    if not any(t.startswith("/pneu/") for t in types):
        return f"not a pneu run: no /pneu topics; found {listed}"
    return f"no messages of a type pneu reads; found {listed}"


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
    collectors: dict[str, Collector] = {}
    with _damage_as_bag_error(path):
        for fpath in files:
            for results in _file_chunks(fpath, ctx):
                _add_results(results, collectors, ctx, None)
            for topic, (ros_type, qos, _cap) in ctx.topics.items():
                if topic not in collectors:  # a channel without messages
                    collectors[topic] = Collector(topic, ros_type, qos, 0)
        _merge_sidecar(files, ctx)
        data = _finish(path, ctx, collectors, strict)
    if data.message_count == 0:
        if ctx.truncated:
            raise TruncatedBagError(path, "file is truncated before its first complete chunk")
        if ctx.damaged:
            raise CorruptBagError(
                path,
                f"no readable messages: {ctx.damaged} damaged chunk(s) skipped, none left "
                "(pneu recover cannot help either)",
            )
        if ctx.want is None and ctx.skipped:
            raise EmptyBagError(path, _foreign(ctx))
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
    collectors: dict[str, Collector] = {}
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
    _merge_sidecar(files, ctx)
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
