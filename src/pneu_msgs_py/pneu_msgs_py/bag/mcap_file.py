"""Low-level MCAP file access for the reader: summary, chunks, message offsets.

Reads one chunk at a time (bounded memory). With a summary, chunks are found
through the chunk indexes; without one (a file cut short by a hard kill, or a
writer that wrote no summary), the data section is scanned record by record
and everything up to the last complete chunk is returned.

Damage is contained: a summary whose CRC does not match is not trusted (the
data section is scanned instead); a chunk that cannot be read (CRC mismatch,
bad compressed data, impossible sizes) is skipped and reported as a
:class:`Chunk` with ``problem`` set and the number of messages its index
counted (``lost``, None when unknown); a record with an impossible length
stops the scan until the next intact chunk (found by its CRC).
"""

from __future__ import annotations

import mmap
import os
import stat
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from mcap import records as M

from pneu_msgs_py.bag import mcap_records as R
from pneu_msgs_py.bag.errors import BagError, NotMcapError, NotRos2Error, TruncatedBagError

__all__ = ["McapFile", "Chunk", "CorruptBagError"]

_REC = struct.Struct("<BQ")


class CorruptBagError(BagError):
    """A record inside the file is malformed (bad CRC, impossible length)."""


@dataclass
class Chunk:
    """One decompressed chunk: record bytes and, per channel, message offsets in it."""

    data: bytes
    offsets: dict[int, np.ndarray] | None  # None: no message index, walk the records
    loose: bool = False  # messages outside chunks (unchunked file), gathered as a chunk
    where: int = 0  # byte offset of the chunk record in the file
    problem: str = ""  # non-empty: the chunk could not be read (data is empty)
    lost: dict[int, int] | None = None  # damaged chunk: messages per channel its index counted


@dataclass
class _ChunkRef:
    offset: int
    length: int
    mi_length: int
    mi_offsets: dict[int, int] = field(default_factory=dict)


_MAX_CHUNK = 1 << 31  # larger uncompressed chunks are damage, not data


def _decompress(path: str, compression: str, data: bytes, size: int) -> bytes:
    if compression == "":
        return data
    if size > _MAX_CHUNK:
        raise CorruptBagError(path, f"chunk claims {size} uncompressed bytes")
    try:
        if compression == "zstd":
            import zstandard

            return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
        if compression == "lz4":
            import lz4.frame

            return lz4.frame.decompress(data)
    except MemoryError:
        raise CorruptBagError(path, "chunk does not decompress (out of memory)") from None
    except Exception as err:  # zstd.ZstdError, lz4's RuntimeError: damaged compressed bytes
        raise CorruptBagError(
            path, f"chunk does not decompress ({type(err).__name__}: {err})"
        ) from None
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
        try:  # non-blocking open: a pipe without a writer is refused below, never waited on
            fd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
        except OSError as e:
            raise NotMcapError(self.path, f"cannot open: {e.strerror}") from None
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            os.close(fd)
            raise NotMcapError(
                self.path, "not a regular file (a directory, device, pipe or socket)"
            )
        os.set_blocking(fd, True)
        self._f = os.fdopen(fd, "rb")
        self.size = st.st_size
        from pneu_msgs_py.params.inputs import note_input

        note_input(self.path, st)  # no output of the command may replace it
        self.schemas: dict[int, M.Schema] = {}
        self.channels: dict[int, M.Channel] = {}
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
        # a file that ends with the MCAP magic is a bag whose first bytes are damaged: read on
        tail_ok = self.size >= 16 and self._read_at(self.size - 8, 8) == R.MAGIC
        if head != R.MAGIC:
            if len(head) < 8 and R.MAGIC.startswith(head) and head:
                raise TruncatedBagError(self.path, f"file ends after {len(head)} bytes")
            if not head:
                raise NotMcapError(self.path, "empty file, not MCAP")
            if not tail_ok:
                raise NotMcapError(self.path, "not an MCAP file (no MCAP magic at the start)")
            self.warnings.append("MCAP magic at the start damaged (the file ends as MCAP)")
        rec = self._read_at(8, 9)
        if len(rec) < 9:
            raise TruncatedBagError(self.path, "file ends inside the MCAP header")
        op, length = _REC.unpack(rec)
        try:
            if op != R.Op.HEADER or length > 1 << 20:
                raise NotMcapError(self.path, "MCAP file without a header record")
            body = self._read_at(17, length)
            if len(body) < length:
                raise TruncatedBagError(self.path, "file ends inside the MCAP header")
            try:
                header = R.parse(M.Header, body)
                self.profile, self.library = header.profile, header.library
            except (IndexError, UnicodeDecodeError):
                raise NotMcapError(self.path, "malformed MCAP header record") from None
        except NotMcapError as err:
            if not tail_ok:
                raise
            self.warnings.append(f"MCAP header damaged ({err.problem}): read on as ROS 2")
            self.profile, self.library = "ros2", ""
            length = length if op == R.Op.HEADER and length <= 1 << 20 else -9
        if self.profile != "ros2":
            near = len(self.profile) == 4 and sum(a != b for a, b in zip(self.profile, "ros2")) <= 2
            if tail_ok and (near or not (self.profile.isprintable() and self.profile.isascii())):
                self.warnings.append(f"MCAP profile {self.profile!r} damaged: read on as ROS 2")
            else:
                raise NotRos2Error(
                    self.path, f"MCAP profile is {self.profile!r}, not 'ros2' (not a ROS 2 bag)"
                )
        self._data_start = 17 + length
        try:
            ok = self._read_summary()
        except (CorruptBagError, IndexError, struct.error, UnicodeDecodeError, ValueError) as err:
            why = err.problem if isinstance(err, CorruptBagError) else "malformed"
            self.warnings.append(f"summary section unreadable ({why}): scanned the data section")
            self.schemas.clear()
            self.channels.clear()
            self.metadata.clear()
            self.message_counts = None
            ok = False
        if not ok:
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
        want_crc = struct.unpack_from("<I", tail, R.FOOTER_SIZE - 4)[0]
        if want_crc and zlib.crc32(tail[: R.FOOTER_SIZE - 4], zlib.crc32(blob)) != want_crc:
            raise CorruptBagError(self.path, "summary CRC mismatch")
        chunks: list[_ChunkRef] = []
        meta_refs: list[tuple[int, int]] = []
        pos = 0
        try:
            while pos + 9 <= len(blob):
                op, length = _REC.unpack_from(blob, pos)
                body = blob[pos + 9 : pos + 9 + length]
                if op in (R.Op.SCHEMA, R.Op.CHANNEL):
                    self._add_definition(op, body)
                elif op == R.Op.STATISTICS:
                    self.message_counts = R.parse(M.Statistics, body).channel_message_counts
                elif op == R.Op.CHUNK_INDEX:
                    ci = R.parse(M.ChunkIndex, body)
                    chunks.append(
                        _ChunkRef(
                            ci.chunk_start_offset,
                            ci.chunk_length,
                            ci.message_index_length,
                            ci.message_index_offsets,
                        )
                    )
                elif op == R.Op.METADATA_INDEX:
                    mi = R.parse(M.MetadataIndex, body)
                    meta_refs.append((mi.offset, mi.length))
                pos += 9 + length
        except IndexError:
            raise CorruptBagError(self.path, "malformed summary section") from None
        if not chunks and self.message_counts and sum(self.message_counts.values()):
            return False  # messages but no chunk index (unchunked file): scan
        self._chunks = sorted(chunks, key=lambda r: r.offset)
        for off, mlen in meta_refs:
            raw = self._read_at(off, mlen)
            try:
                if len(raw) == mlen and raw[0] == R.Op.METADATA:
                    self._add_metadata(raw[9:])
                else:
                    raise IndexError
            except (IndexError, struct.error, UnicodeDecodeError):
                self.warnings.append(f"metadata record at byte {off} unreadable: skipped")
        return True

    def _add_definition(self, op: int, body: bytes) -> None:
        """A Schema or Channel record's body (IndexError, UnicodeDecodeError: damaged)."""
        if op == R.Op.SCHEMA:
            sch = R.parse(M.Schema, body)
            self.schemas[sch.id] = sch
        else:
            ch = R.parse(M.Channel, body)
            self.channels[ch.id] = ch

    def _add_metadata(self, body: bytes) -> None:
        md = R.parse(M.Metadata, body)
        self.metadata.setdefault(md.name, {}).update(md.metadata)

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
        """The chunk at ``ref``, or a damaged :class:`Chunk` saying why and what was lost."""
        if ref.length > self.size or ref.mi_length > self.size:
            return Chunk(b"", {}, where=ref.offset, problem="impossible size in its index")
        raw = self._read_at(ref.offset, ref.length + ref.mi_length)
        if len(raw) < ref.length:
            raise TruncatedBagError(self.path, f"chunk at byte {ref.offset} is cut short")
        offsets: dict[int, np.ndarray] | None = {}
        bad_index = False
        for cid, mio in ref.mi_offsets.items():
            try:
                offsets[cid] = self._parse_message_index(raw, mio - ref.offset)[1]
            except (IndexError, ValueError, struct.error):
                bad_index = True
        if not ref.mi_offsets:
            offsets = None
        try:
            data = self._chunk_data(raw, ref.offset)
        except CorruptBagError as err:
            lost = None if bad_index or offsets is None else {c: len(o) for c, o in offsets.items()}
            return Chunk(b"", {}, where=ref.offset, problem=err.problem, lost=lost)
        if bad_index:
            offsets = None  # the data is intact (CRC): walk its records instead
        return Chunk(data, offsets, where=ref.offset)

    def _chunk_data(self, raw: bytes, where: int) -> bytes:
        if len(raw) < 9:
            raise CorruptBagError(self.path, f"chunk at byte {where} is cut short")
        op, length = _REC.unpack_from(raw, 0)
        if op != R.Op.CHUNK:
            raise CorruptBagError(self.path, f"no chunk record at byte {where}")
        try:
            ch = R.parse(M.Chunk, raw[9 : 9 + length])
        except (IndexError, UnicodeDecodeError, struct.error):
            raise CorruptBagError(self.path, f"malformed chunk at byte {where}") from None
        usize, crc = ch.uncompressed_size, ch.uncompressed_crc
        try:
            data = _decompress(self.path, ch.compression, ch.data, usize)
        except CorruptBagError as err:
            raise CorruptBagError(self.path, f"chunk at byte {where}: {err.problem}") from None
        if len(data) != usize:
            raise CorruptBagError(self.path, f"chunk at byte {where}: size mismatch")
        if crc and zlib.crc32(data) != crc:
            raise CorruptBagError(self.path, f"chunk at byte {where}: CRC mismatch")
        return data

    @staticmethod
    def _parse_message_index(raw: bytes, p: int) -> tuple[int, np.ndarray]:
        op, length = _REC.unpack_from(raw, p)
        if op != R.Op.MESSAGE_INDEX:
            raise IndexError("not a message index")
        cid, nbytes = struct.unpack_from("<HI", raw, p + 9)
        if nbytes % 16 or nbytes + 6 != length or p + 15 + nbytes > len(raw):
            raise IndexError("malformed message index")
        arr = np.frombuffer(raw, dtype="<u8", count=nbytes // 8, offset=p + 15).reshape(-1, 2)
        return cid, arr[:, 1].astype(np.int64)

    def definitions_in(self, data: bytes) -> None:
        """Schema and channel records written inside a chunk (some writers do)."""
        pos, n = 0, len(data)
        while pos + 9 <= n:
            op, length = _REC.unpack_from(data, pos)
            if op in (R.Op.SCHEMA, R.Op.CHANNEL):
                try:
                    self._add_definition(op, data[pos + 9 : pos + 9 + length])
                except (IndexError, UnicodeDecodeError, struct.error):
                    pass
            pos += 9 + length

    def _resync(self, pos: int) -> int | None:
        """The byte offset of the next intact chunk record after ``pos`` (its CRC checks), or None."""
        with mmap.mmap(self._f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
            at = pos + 1
            for _ in range(100_000):
                at = mm.find(bytes([R.Op.CHUNK]), at)
                if at < 0 or at + 9 > self.size:
                    return None
                length = _REC.unpack_from(mm, at)[1]
                if 9 + length <= self.size - at:
                    try:
                        self._chunk_data(mm[at : at + 9 + length], at)
                        return at
                    except CorruptBagError:
                        pass
                at += 1
        return None

    def _scan(self) -> Iterator[Chunk]:
        """Chunks in file order from a walk over every record (no usable summary)."""
        f = self._f
        pos = self._data_start
        f.seek(pos)
        pending: Chunk | None = None  # the last chunk, until the message indexes after it end
        loose: list[bytes] = []
        n_chunks = 0
        ended = False
        while True:
            head = f.read(9)
            if len(head) < 9:
                break
            op, length = _REC.unpack(head)
            if length > self.size - pos - 9 or not 0x01 <= op <= 0x10:
                if pending is not None:
                    # its message indexes end here, some perhaps not read (a file cut inside
                    # them: a SIGKILLed ros2 bag record): walk its records instead
                    if not pending.problem:
                        pending.offsets = None
                    yield pending
                    pending = None
                nxt, ended = self._skip_unreadable(pos, op, length)
                if nxt is None:
                    break
                pos = nxt
                f.seek(pos)
                continue
            body = f.read(length)
            if len(body) < length:
                break
            if op != R.Op.MESSAGE_INDEX and pending is not None:
                yield pending
                pending = None
            if op == R.Op.DATA_END:
                ended = True
                break
            pending = self._take(op, head, body, pos, pending, loose)
            if op == R.Op.CHUNK and pending is not None and not pending.problem:
                n_chunks += 1
            pos += 9 + length
        yield from self._scan_end(pending, loose, ended, n_chunks)

    def _skip_unreadable(self, pos: int, op: int, length: int) -> tuple[int | None, bool]:
        """Past a record at ``pos`` with an impossible opcode or length: (where the next intact
        chunk starts, or None; whether the data ended cleanly). A warning says what was skipped;
        a record cut by the end of the file is (None, False): a truncation, said at the end."""
        nxt = self._resync(pos)
        if nxt is None and 0x01 <= op <= 0x10 and length <= self.size:
            return None, False  # a record cut by the end of the file: truncated
        self.warnings.append(
            f"unreadable bytes from byte {pos} "
            + (f"to {nxt}: skipped to the next intact chunk" if nxt else "to the end")
            + " (messages there lost, count unknown)"
        )
        if nxt is None:
            return None, True  # nothing more to read: not a truncation
        return nxt, False

    def _take(
        self, op: int, head: bytes, body: bytes, pos: int, pending: Chunk | None, loose: list[bytes]
    ) -> Chunk | None:
        """One whole record at ``pos`` met while scanning; returns the pending chunk (a chunk
        record starts a new one). Loose message records are gathered in ``loose``."""
        try:
            if op == R.Op.CHUNK:
                try:
                    return Chunk(self._chunk_data(head + body, pos), None, where=pos)
                except CorruptBagError as e:
                    return Chunk(b"", {}, where=pos, problem=e.problem, lost={})
            elif op == R.Op.MESSAGE_INDEX and pending is not None:
                self._index_into(pending, head + body)
            elif op in (R.Op.SCHEMA, R.Op.CHANNEL):
                self._add_definition(op, body)
            elif op == R.Op.MESSAGE:
                loose.append(head + body)
            elif op == R.Op.METADATA:
                self._add_metadata(body)
        except (IndexError, ValueError, struct.error, UnicodeDecodeError):
            if op == R.Op.MESSAGE_INDEX and pending is not None and not pending.problem:
                pending.offsets = None  # walk the (CRC-checked) records instead
            else:
                self.warnings.append(f"unreadable record (opcode {op}) at byte {pos}: skipped")
        return pending

    def _index_into(self, pending: Chunk, raw: bytes) -> None:
        """A message index record after ``pending``: its channel's offsets, or (a damaged
        chunk) the count of messages lost on that channel."""
        cid, offs = self._parse_message_index(raw, 0)
        if pending.problem:
            pending.lost[cid] = pending.lost.get(cid, 0) + len(offs)
        else:
            if pending.offsets is None:
                pending.offsets = {}
            pending.offsets[cid] = offs

    def _scan_end(
        self, pending: Chunk | None, loose: list[bytes], ended: bool, n_chunks: int
    ) -> Iterator[Chunk]:
        """The end of a scan: the last chunk, the loose messages as one chunk, and
        ``truncated`` with its warning when no data end record closed the walk."""
        if pending is not None:
            # its message indexes may be cut: walk the records instead
            if not ended and not pending.problem:
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
                + " (messages of the chunk being written when it was cut are lost)"
            )
