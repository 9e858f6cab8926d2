"""Low-level MCAP file access for the reader: summary, chunks, message offsets.

Reads one chunk at a time (bounded memory). With a summary, chunks are found
through the chunk indexes; without one (a file cut short by a hard kill, or a
writer that wrote no summary), the data section is scanned record by record
and everything up to the last complete chunk is returned.
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from pneu_msgs_py.bag import mcap_records as R
from pneu_msgs_py.bag.errors import BagError, NotMcapError, NotRos2Error, TruncatedBagError

__all__ = ["McapFile", "SchemaInfo", "ChannelInfo", "Chunk", "CorruptBagError"]

_REC = struct.Struct("<BQ")
_CHUNK_HEAD = struct.Struct("<QQQI")


class CorruptBagError(BagError):
    """A record inside the file is malformed (bad CRC, impossible length)."""


@dataclass
class SchemaInfo:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass
class ChannelInfo:
    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]


@dataclass
class Chunk:
    """One decompressed chunk: record bytes and, per channel, message offsets in it."""

    data: bytes
    offsets: dict[int, np.ndarray] | None  # None: no message index, walk the records
    loose: bool = False  # messages outside chunks (unchunked file), gathered as a chunk


@dataclass
class _ChunkRef:
    offset: int
    length: int
    mi_length: int
    mi_offsets: dict[int, int] = field(default_factory=dict)


def _decompress(path: str, compression: str, data: bytes, size: int) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(data)
    raise CorruptBagError(path, f"chunk compression {compression!r} not supported")


def walk_offsets(data: bytes) -> dict[int, np.ndarray]:
    """Message offsets per channel by walking the records of a chunk (slow path)."""
    out: dict[int, list[int]] = {}
    pos = 0
    n = len(data)
    while pos + 9 <= n:
        op, length = _REC.unpack_from(data, pos)
        if op == R.Op.MESSAGE:
            cid = struct.unpack_from("<H", data, pos + 9)[0]
            out.setdefault(cid, []).append(pos)
        pos += 9 + length
    return {k: np.array(v, dtype=np.int64) for k, v in out.items()}


class McapFile:
    """An open MCAP file of the ROS 2 profile.

    Raises NotMcapError, NotRos2Error or TruncatedBagError (nothing readable)
    on open. ``truncated`` tells whether the file ended early; ``warnings``
    says what was skipped.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = str(path)
        try:
            self._f = open(self.path, "rb")
        except OSError as e:
            raise NotMcapError(self.path, f"cannot open: {e.strerror}") from None
        self.size = os.fstat(self._f.fileno()).st_size
        self.schemas: dict[int, SchemaInfo] = {}
        self.channels: dict[int, ChannelInfo] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.message_counts: dict[int, int] | None = None
        self.truncated = False
        self.warnings: list[str] = []
        self._chunks: list[_ChunkRef] | None = None
        try:
            self._open()
        except BaseException:
            self._f.close()
            raise

    def close(self) -> None:
        self._f.close()

    def __enter__(self) -> McapFile:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- opening -----------------------------------------------------------------
    def _read_at(self, offset: int, n: int) -> bytes:
        self._f.seek(offset)
        return self._f.read(n)

    def _open(self) -> None:
        head = self._read_at(0, 8)
        if head != R.MAGIC:
            if len(head) < 8 and R.MAGIC.startswith(head) and head:
                raise TruncatedBagError(self.path, f"file ends after {len(head)} bytes")
            if not head:
                raise NotMcapError(self.path, "empty file, not MCAP")
            raise NotMcapError(self.path, "not an MCAP file (no MCAP magic at the start)")
        rec = self._read_at(8, 9)
        if len(rec) < 9:
            raise TruncatedBagError(self.path, "file ends inside the MCAP header")
        op, length = _REC.unpack(rec)
        if op != R.Op.HEADER or length > 1 << 20:
            raise NotMcapError(self.path, "MCAP file without a header record")
        body = self._read_at(17, length)
        if len(body) < length:
            raise TruncatedBagError(self.path, "file ends inside the MCAP header")
        c = R.Cursor(body)
        try:
            self.profile = c.string()
            self.library = c.string()
        except IndexError:
            raise NotMcapError(self.path, "malformed MCAP header record") from None
        if self.profile != "ros2":
            raise NotRos2Error(
                self.path, f"MCAP profile is {self.profile!r}, not 'ros2' (not a ROS 2 bag)"
            )
        self._data_start = 17 + length
        if not self._read_summary():
            self._scan_for_summary()

    def _read_summary(self) -> bool:
        if self.size < self._data_start + R.FOOTER_SIZE + 8:
            self.truncated = True
            return False
        tail = self._read_at(self.size - R.FOOTER_SIZE - 8, R.FOOTER_SIZE + 8)
        if tail[-8:] != R.MAGIC or tail[0] != R.Op.FOOTER:
            self.truncated = True
            return False
        summary_start, _so_start = struct.unpack_from("<QQ", tail, 9)
        if summary_start == 0:
            return False  # valid file without summary: scan it
        end = self.size - R.FOOTER_SIZE - 8
        if not self._data_start <= summary_start <= end:
            raise CorruptBagError(self.path, "footer points outside the file")
        blob = self._read_at(summary_start, end - summary_start)
        chunks: list[_ChunkRef] = []
        meta_refs: list[tuple[int, int]] = []
        pos = 0
        try:
            while pos + 9 <= len(blob):
                op, length = _REC.unpack_from(blob, pos)
                c = R.Cursor(blob, pos + 9, pos + 9 + length)
                if op == R.Op.SCHEMA:
                    self._add_schema(c)
                elif op == R.Op.CHANNEL:
                    self._add_channel(c)
                elif op == R.Op.STATISTICS:
                    c.u64(), c.u16(), c.u32(), c.u32(), c.u32(), c.u32(), c.u64(), c.u64()
                    self.message_counts = c.u16_u64_map()
                elif op == R.Op.CHUNK_INDEX:
                    c.u64(), c.u64()
                    off, clen = c.u64(), c.u64()
                    mio = c.u16_u64_map()
                    mil = c.u64()
                    chunks.append(_ChunkRef(off, clen, mil, mio))
                elif op == R.Op.METADATA_INDEX:
                    off, mlen = c.u64(), c.u64()
                    meta_refs.append((off, mlen))
                pos += 9 + length
        except IndexError:
            raise CorruptBagError(self.path, "malformed summary section") from None
        if not chunks and self.message_counts and sum(self.message_counts.values()):
            return False  # messages but no chunk index (unchunked file): scan
        self._chunks = sorted(chunks, key=lambda r: r.offset)
        for off, mlen in meta_refs:
            raw = self._read_at(off, mlen)
            if len(raw) == mlen and raw[0] == R.Op.METADATA:
                c = R.Cursor(raw, 9)
                name = c.string()
                self.metadata.setdefault(name, {}).update(c.str_map())
        return True

    def _add_schema(self, c: R.Cursor) -> None:
        sid = c.u16()
        self.schemas[sid] = SchemaInfo(sid, c.string(), c.string(), c.bytes32())

    def _add_channel(self, c: R.Cursor) -> None:
        cid = c.u16()
        sch = c.u16()
        self.channels[cid] = ChannelInfo(cid, sch, c.string(), c.string(), c.str_map())

    def _scan_for_summary(self) -> None:
        """No usable summary: the chunk list is built while scanning in iter_chunks."""
        self._chunks = None

    # -- chunks --------------------------------------------------------------------
    def iter_chunks(self) -> Iterator[Chunk]:
        """Decompressed chunks in file order (sets ``truncated``/``warnings`` when scanning)."""
        if self._chunks is not None:
            for ref in self._chunks:
                yield self._load_indexed(ref)
        else:
            yield from self._scan()

    def _load_indexed(self, ref: _ChunkRef) -> Chunk:
        raw = self._read_at(ref.offset, ref.length + ref.mi_length)
        if len(raw) < ref.length:
            raise TruncatedBagError(self.path, f"chunk at byte {ref.offset} is cut short")
        data = self._chunk_data(raw, ref.offset)
        offsets: dict[int, np.ndarray] | None = {}
        for cid, mio in ref.mi_offsets.items():
            p = mio - ref.offset
            offsets[cid] = self._parse_message_index(raw, p)[1]
        if not ref.mi_offsets:
            offsets = None
        return Chunk(data, offsets)

    def _chunk_data(self, raw: bytes, where: int) -> bytes:
        op, length = _REC.unpack_from(raw, 0)
        if op != R.Op.CHUNK:
            raise CorruptBagError(self.path, f"no chunk record at byte {where}")
        c = R.Cursor(raw, 9, 9 + length)
        try:
            _s, _e, usize, crc = _CHUNK_HEAD.unpack_from(raw, c._need(_CHUNK_HEAD.size))
            comp = c.string()
            n = c.u64()
            start = c._need(n)
        except IndexError:
            raise CorruptBagError(self.path, f"malformed chunk at byte {where}") from None
        data = _decompress(self.path, comp, raw[start : start + n], usize)
        if len(data) != usize:
            raise CorruptBagError(self.path, f"chunk at byte {where}: size mismatch")
        if crc and zlib.crc32(data) != crc:
            raise CorruptBagError(self.path, f"chunk at byte {where}: CRC mismatch")
        return data

    @staticmethod
    def _parse_message_index(raw: bytes, p: int) -> tuple[int, np.ndarray]:
        op, _length = _REC.unpack_from(raw, p)
        if op != R.Op.MESSAGE_INDEX:
            raise IndexError("not a message index")
        cid, nbytes = struct.unpack_from("<HI", raw, p + 9)
        arr = np.frombuffer(raw, dtype="<u8", count=nbytes // 8, offset=p + 15).reshape(-1, 2)
        return cid, arr[:, 1].astype(np.int64)

    def _scan(self) -> Iterator[Chunk]:
        f = self._f
        pos = self._data_start
        f.seek(pos)
        pending: Chunk | None = None
        loose: list[bytes] = []
        n_chunks = 0
        ended = False
        while True:
            head = f.read(9)
            if len(head) < 9:
                break
            op, length = _REC.unpack(head)
            if length > self.size:
                self.warnings.append(f"impossible record length at byte {pos}")
                break
            body = f.read(length)
            if len(body) < length:
                break
            if op != R.Op.MESSAGE_INDEX and pending is not None:
                yield pending
                pending = None
            if op == R.Op.CHUNK:
                try:
                    data = self._chunk_data(head + body, pos)
                except CorruptBagError as e:
                    self.warnings.append(e.problem)
                    break
                pending = Chunk(data, None)
                n_chunks += 1
            elif op == R.Op.MESSAGE_INDEX and pending is not None:
                _, offs = self._parse_message_index(head + body, 0)
                cid = struct.unpack_from("<H", body, 0)[0]
                if pending.offsets is None:
                    pending.offsets = {}
                pending.offsets[cid] = offs
            elif op == R.Op.SCHEMA:
                self._add_schema(R.Cursor(body))
            elif op == R.Op.CHANNEL:
                self._add_channel(R.Cursor(body))
            elif op == R.Op.MESSAGE:
                loose.append(head + body)
            elif op == R.Op.METADATA:
                c = R.Cursor(body)
                name = c.string()
                self.metadata.setdefault(name, {}).update(c.str_map())
            elif op == R.Op.DATA_END:
                ended = True
                break
            pos += 9 + length
        if pending is not None:
            # its message indexes may be cut: walk the records instead
            if self.truncated and not ended:
                pending.offsets = None
            yield pending
        if loose:
            yield Chunk(b"".join(loose), None, loose=True)
        if not ended:
            self.truncated = True
        if self.truncated:
            self.warnings.append(
                f"file is truncated; read the {n_chunks} complete chunk(s)"
                + (" and loose messages" if loose else "")
            )
