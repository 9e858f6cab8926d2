"""The MCAP container of a bag: records, chunks, indexes, summary and footer (ROS 2 profile).

:class:`McapContainer` owns the file. It registers schemas and channels
(channel metadata ``offered_qos_profiles`` and ``topic_type_hash`` as
rosbag2 Jazzy writes them), writes metadata records at once, writes each
chunk of :class:`~pneu_msgs_py.bag.chunks.Batch` es compressed, with its
message indexes, and flushes it to the OS (a hard kill loses at most the
chunk being buffered), and at :meth:`~McapContainer.finish` writes the
summary (schemas, channels, statistics, chunk and metadata indexes, summary
offsets) and the footer.

The file is written as ``NAME.partial`` (created exclusively: a second
writer, or one killed before it finished, is never overwritten) and renamed
to ``NAME`` by :meth:`~McapContainer.close` after :meth:`~McapContainer.finish`
(atomic): a ``.mcap`` is always a finished bag, a ``.mcap.partial`` one that
was cut short (``pneu recover`` makes it whole).
"""

from __future__ import annotations

import errno
import os
import zlib
from collections.abc import Mapping
from pathlib import Path

from mcap import records as M

from pneu_msgs_py.bag import mcap_records as R
from pneu_msgs_py.bag.chunks import Batch, Channel, interleave
from pneu_msgs_py.bag.errors import BagWriteError
from pneu_msgs_py.bag.schemas import (
    MESSAGE_ENCODING,
    MSG_DEFINITIONS,
    PROFILE,
    SCHEMA_ENCODING,
    TYPE_HASHES,
)
from pneu_msgs_py.contract.qos import offered_qos_yaml
from pneu_msgs_py.contract.topics import qos_for

__all__ = ["COMPRESSIONS", "PARTIAL_SUFFIX", "McapContainer"]

COMPRESSIONS = ("zstd", "lz4", "none")
PARTIAL_SUFFIX = ".partial"  # the same convention as pneu_msgs_py.lifecycle.outputs


def _schema(sid: int, ros_type: str, text: bytes) -> bytes:
    return R.record_bytes(M.Schema(id=sid, data=text, encoding=SCHEMA_ENCODING, name=ros_type))


class McapContainer:
    """One MCAP file being written (see the module docstring). ``qos_mode``: which
    publisher QoS (:func:`pneu_msgs_py.contract.topics.qos_for`) the channels record;
    ``partial``: the temporary name, if not ``NAME.partial`` (that is the input being read)."""

    def __init__(
        self, path: Path, library: str, compression: str, qos_mode: str, partial: Path | None = None
    ) -> None:
        self.path = path
        self.qos_mode = qos_mode
        if compression == "zstd":
            import zstandard

            self._compress = zstandard.ZstdCompressor(level=1).compress
        elif compression == "lz4":
            import lz4.frame

            self._compress = lz4.frame.compress
        else:
            self._compress = None
        self._comp_name = "" if compression == "none" else compression
        self.partial_path = partial or path.with_name(path.name + PARTIAL_SUFFIX)
        self.finished = False
        try:
            self._f = open(self.partial_path, "xb")
        except FileExistsError:
            raise BagWriteError(
                self.partial_path,
                "exists: another writer is writing this bag, or one was killed before it "
                "finished (pneu recover it, or remove it)",
            ) from None
        except OSError as e:
            raise BagWriteError(self.path, f"cannot open for writing: {e.strerror}") from None
        self._pos = 0
        self._crc = 0
        self.schemas: dict[str, tuple[int, bytes]] = {}
        self._schema_text: dict[str, bytes] = {}
        self.channels: dict[str, Channel] = {}
        self._chunk_indexes: list[M.ChunkIndex] = []
        self._metadata_indexes: list[M.MetadataIndex] = []
        self._n_metadata = 0
        self.t_start: int | None = None
        self.t_end: int | None = None
        self._write(R.MAGIC + R.record_bytes(M.Header(profile=PROFILE, library=library)))

    def _write(self, data: bytes) -> None:
        try:
            self._f.write(data)
        except OSError as e:  # a full disk, a file-size limit: one line naming the bag
            full = e.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT)
            why = " (a full disk or a file-size limit)" if full else ""
            raise BagWriteError(self.path, f"write failed: {e.strerror or e}{why}") from None
        self._crc = zlib.crc32(data, self._crc)
        self._pos += len(data)

    def channel(
        self,
        topic: str,
        ros_type: str,
        *,
        schema_text: bytes | None = None,
        channel_metadata: Mapping[str, str] | None = None,
    ) -> Channel:
        """The channel of ``topic`` (created on first use). ``schema_text`` and
        ``channel_metadata`` carry a foreign bag's own definition and QoS (pneu recover)."""
        ch = self.channels.get(topic)
        if ch is not None:
            if ch.ros_type != ros_type:
                raise BagWriteError(
                    self.path, f"topic {topic} already has type {ch.ros_type}, not {ros_type}"
                )
            return ch
        if ros_type not in self.schemas:
            sid = len(self.schemas) + 1
            if schema_text is None:
                # foreign type via write_serialized: definition unknown here
                schema_text = MSG_DEFINITIONS.get(ros_type, "").encode("utf-8")
            self._schema_text[ros_type] = schema_text
            self.schemas[ros_type] = (sid, _schema(sid, ros_type, schema_text))
        sid = self.schemas[ros_type][0]
        cid = len(self.channels) + 1
        qos = qos_for(topic, self.qos_mode)
        ch = Channel(cid, topic, ros_type, sid, qos)
        # the two channel metadata keys rosbag2 (Jazzy) writes
        meta = (
            dict(channel_metadata)
            if channel_metadata is not None
            else {
                "offered_qos_profiles": offered_qos_yaml([qos]),
                "topic_type_hash": TYPE_HASHES.get(ros_type, ""),
            }
        )
        ch.record = R.record_bytes(
            M.Channel(
                id=cid, topic=topic, message_encoding=MESSAGE_ENCODING, metadata=meta, schema_id=sid
            )
        )
        self.channels[topic] = ch
        return ch

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """An MCAP metadata record (all keys and values str), written immediately."""
        if not isinstance(name, str) or not name:
            raise BagWriteError(self.path, f"metadata name {name!r}: need a non-empty str")
        for k, v in data.items():
            if not isinstance(k, str) or not isinstance(v, str):
                raise BagWriteError(
                    self.path, f"metadata {name}[{k!r}]: keys and values must be str, got {v!r}"
                )
        self._write_metadata(name, dict(data))
        self._f.flush()

    def _write_metadata(self, name: str, data: dict[str, str]) -> None:
        rec = R.record_bytes(M.Metadata(name=name, metadata=data))
        self._metadata_indexes.append(M.MetadataIndex(offset=self._pos, length=len(rec), name=name))
        self._n_metadata += 1
        self._write(rec)

    def write_chunk(self, batches: list[Batch]) -> None:
        """One chunk of ``batches`` with its message indexes and chunk index; flushed to the OS."""
        for b in batches:
            if len(b.log_times) and int(b.log_times.min()) < 0:
                raise BagWriteError(
                    self.path, f"{b.channel.topic}: negative time {int(b.log_times.min())} ns"
                )
        data, offsets = interleave(batches)
        # schema / channel records of channels first used in this chunk
        head = []
        for b in batches:
            ch = b.channel
            if not ch.emitted:
                sid, srec = self.schemas[ch.ros_type]
                if srec:
                    head.append(srec)
                    self.schemas[ch.ros_type] = (sid, b"")  # emitted
                head.append(ch.record)
                ch.emitted = True
        if head:
            self._write(b"".join(head))
        t_min = int(min(b.log_times.min() for b in batches))
        t_max = int(max(b.log_times.max() for b in batches))
        self.t_start = t_min if self.t_start is None else min(self.t_start, t_min)
        self.t_end = t_max if self.t_end is None else max(self.t_end, t_max)
        raw = memoryview(data)
        crc = zlib.crc32(raw)
        comp = self._compress(raw) if self._compress else bytes(raw)
        chunk_start = self._pos
        crec = R.record_bytes(
            M.Chunk(
                compression=self._comp_name,
                data=comp,
                message_end_time=t_max,
                message_start_time=t_min,
                uncompressed_crc=crc,
                uncompressed_size=len(raw),
            )
        )
        self._write(crec)
        mi_start = self._pos
        mi_offsets: dict[int, int] = {}
        mi = []
        pos = self._pos
        for b in sorted(batches, key=lambda b: b.channel.id):
            rec = R.message_index(b.channel.id, b.log_times, offsets[id(b)])
            mi_offsets[b.channel.id] = pos
            pos += len(rec)
            mi.append(rec)
        self._write(b"".join(mi))
        self._f.flush()
        self._chunk_indexes.append(
            M.ChunkIndex(
                chunk_length=len(crec),
                chunk_start_offset=chunk_start,
                compression=self._comp_name,
                compressed_size=len(comp),
                message_end_time=t_max,
                message_index_length=self._pos - mi_start,
                message_index_offsets=mi_offsets,
                message_start_time=t_min,
                uncompressed_size=len(raw),
            )
        )

    def finish(self, rosbag2_yaml: str) -> None:
        """The ``rosbag2`` metadata record, data end, summary and footer; then close the file."""
        # channels that never got a message still need their records for the summary
        for ch in self.channels.values():
            if not ch.emitted:
                sid, srec = self.schemas[ch.ros_type]
                if srec:
                    self._write(srec)
                    self.schemas[ch.ros_type] = (sid, b"")
                self._write(ch.record)
                ch.emitted = True
        self._write_metadata("rosbag2", {"serialized_metadata": rosbag2_yaml})
        self._write(R.record_bytes(M.DataEnd(data_section_crc=self._crc)))
        summary_start = self._pos
        summary_crc = 0
        groups: list[tuple[int, int, int]] = []

        def group(op: int, recs: list) -> None:
            nonlocal summary_crc
            if not recs:
                return
            blob = b"".join(r if isinstance(r, bytes) else R.record_bytes(r) for r in recs)
            groups.append((op, self._pos, len(blob)))
            self._f.write(blob)
            summary_crc = zlib.crc32(blob, summary_crc)
            self._pos += len(blob)

        schema_recs = []
        for ros_type, (sid, _) in sorted(self.schemas.items(), key=lambda kv: kv[1][0]):
            text = self._schema_text[ros_type]
            schema_recs.append(_schema(sid, ros_type, text))
        group(R.Op.SCHEMA, schema_recs)
        group(R.Op.CHANNEL, [ch.record for ch in self.channels.values()])
        n_msgs = sum(ch.count for ch in self.channels.values())
        stats = M.Statistics(
            attachment_count=0,
            channel_count=len(self.channels),
            channel_message_counts={ch.id: ch.count for ch in self.channels.values()},
            chunk_count=len(self._chunk_indexes),
            message_count=n_msgs,
            message_end_time=self.t_end or 0,
            message_start_time=self.t_start or 0,
            metadata_count=self._n_metadata,
            schema_count=len(self.schemas),
        )
        group(R.Op.STATISTICS, [stats])
        group(R.Op.CHUNK_INDEX, self._chunk_indexes)
        group(R.Op.METADATA_INDEX, self._metadata_indexes)
        summary_offset_start = self._pos
        so = b"".join(
            R.record_bytes(M.SummaryOffset(group_opcode=op, group_start=at, group_length=n))
            for op, at, n in groups
        )
        self._f.write(so)
        summary_crc = zlib.crc32(so, summary_crc)
        self._pos += len(so)
        if not groups:
            summary_start = 0
            summary_offset_start = 0
        # the footer's CRC covers the summary and the footer up to the CRC itself
        foot = R.record_bytes(
            M.Footer(
                summary_start=summary_start,
                summary_offset_start=summary_offset_start,
                summary_crc=0,
            )
        )[:-4]
        summary_crc = zlib.crc32(foot, summary_crc)
        self._f.write(foot + summary_crc.to_bytes(4, "little") + R.MAGIC)
        self._f.flush()
        self.finished = True

    def close(self) -> None:
        """Close the file; a finished one is renamed from ``NAME.partial`` to ``NAME``."""
        if self._f.closed:
            return
        self._f.close()
        if self.finished:
            os.replace(self.partial_path, self.path)
