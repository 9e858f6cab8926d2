"""MCAP records (spec v0, https://mcap.dev/spec) as bytes, and the inverse parsers.

Only what pneu writes and reads: Header, Footer, Schema, Channel, Message,
Chunk, Message Index, Chunk Index, Metadata, Metadata Index, Statistics,
Summary Offset, Data End. All integers little endian; ``string`` = uint32
length + UTF-8; ``map<K,V>`` = uint32 byte length + entries.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping

import numpy as np

__all__ = ["MAGIC", "Op", "record"]

MAGIC = b"\x89MCAP0\r\n"


class Op:
    HEADER = 0x01
    FOOTER = 0x02
    SCHEMA = 0x03
    CHANNEL = 0x04
    MESSAGE = 0x05
    CHUNK = 0x06
    MESSAGE_INDEX = 0x07
    CHUNK_INDEX = 0x08
    ATTACHMENT = 0x09
    ATTACHMENT_INDEX = 0x0A
    STATISTICS = 0x0B
    METADATA = 0x0C
    METADATA_INDEX = 0x0D
    SUMMARY_OFFSET = 0x0E
    DATA_END = 0x0F


_U8 = struct.Struct("<B")
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_REC = struct.Struct("<BQ")

#: Message record header: opcode, length, channel_id, sequence, log_time, publish_time.
MESSAGE_HEADER = struct.Struct("<BQHIQQ")
MESSAGE_HEADER_SIZE = MESSAGE_HEADER.size  # 31
MESSAGE_RECORD_DTYPE = np.dtype(
    {
        "names": ["op", "length", "channel_id", "sequence", "log_time", "publish_time"],
        "formats": ["u1", "<u8", "<u2", "<u4", "<u8", "<u8"],
        "offsets": [0, 1, 9, 11, 15, 23],
        "itemsize": 31,
    }
)


def record(op: int, body: bytes) -> bytes:
    return _REC.pack(op, len(body)) + body


def s(text: str) -> bytes:
    raw = text.encode("utf-8")
    return _U32.pack(len(raw)) + raw


def b32(data: bytes) -> bytes:
    return _U32.pack(len(data)) + data


def str_map(m: Mapping[str, str]) -> bytes:
    body = b"".join(s(k) + s(v) for k, v in m.items())
    return _U32.pack(len(body)) + body


def header(profile: str, library: str) -> bytes:
    return record(Op.HEADER, s(profile) + s(library))


def schema(schema_id: int, name: str, encoding: str, data: bytes) -> bytes:
    return record(Op.SCHEMA, _U16.pack(schema_id) + s(name) + s(encoding) + b32(data))


def channel(
    channel_id: int, schema_id: int, topic: str, encoding: str, metadata: Mapping[str, str]
) -> bytes:
    return record(
        Op.CHANNEL,
        _U16.pack(channel_id) + _U16.pack(schema_id) + s(topic) + s(encoding) + str_map(metadata),
    )


def message(channel_id: int, sequence: int, log_time: int, publish_time: int, data: bytes) -> bytes:
    return MESSAGE_HEADER.pack(
        Op.MESSAGE, 22 + len(data), channel_id, sequence, log_time, publish_time
    ) + bytes(data)


def chunk(
    start: int, end: int, uncompressed_size: int, crc: int, compression: str, data: bytes
) -> bytes:
    body = struct.pack("<QQQI", start, end, uncompressed_size, crc) + s(compression)
    return _REC.pack(Op.CHUNK, len(body) + 8 + len(data)) + body + _U64.pack(len(data)) + data


def message_index(channel_id: int, times: np.ndarray, offsets: np.ndarray) -> bytes:
    arr = np.empty(len(times), dtype=[("t", "<u8"), ("o", "<u8")])
    arr["t"] = times
    arr["o"] = offsets
    body = _U16.pack(channel_id) + _U32.pack(arr.nbytes) + arr.tobytes()
    return record(Op.MESSAGE_INDEX, body)


def chunk_index(
    start: int,
    end: int,
    chunk_start_offset: int,
    chunk_length: int,
    message_index_offsets: Mapping[int, int],
    message_index_length: int,
    compression: str,
    compressed_size: int,
    uncompressed_size: int,
) -> bytes:
    mio = b"".join(_U16.pack(k) + _U64.pack(v) for k, v in message_index_offsets.items())
    body = (
        struct.pack("<QQQQ", start, end, chunk_start_offset, chunk_length)
        + _U32.pack(len(mio))
        + mio
        + _U64.pack(message_index_length)
        + s(compression)
        + struct.pack("<QQ", compressed_size, uncompressed_size)
    )
    return record(Op.CHUNK_INDEX, body)


def metadata(name: str, data: Mapping[str, str]) -> bytes:
    return record(Op.METADATA, s(name) + str_map(data))


def metadata_index(offset: int, length: int, name: str) -> bytes:
    return record(Op.METADATA_INDEX, struct.pack("<QQ", offset, length) + s(name))


def statistics(
    message_count: int,
    schema_count: int,
    channel_count: int,
    metadata_count: int,
    chunk_count: int,
    start: int,
    end: int,
    channel_message_counts: Mapping[int, int],
) -> bytes:
    cmc = b"".join(_U16.pack(k) + _U64.pack(v) for k, v in channel_message_counts.items())
    body = struct.pack(
        "<QHIIIIQQ",
        message_count,
        schema_count,
        channel_count,
        0,
        metadata_count,
        chunk_count,
        start,
        end,
    ) + b32(cmc)
    return record(Op.STATISTICS, body)


def summary_offset(group_opcode: int, group_start: int, group_length: int) -> bytes:
    return record(Op.SUMMARY_OFFSET, struct.pack("<BQQ", group_opcode, group_start, group_length))


def data_end(crc: int) -> bytes:
    return record(Op.DATA_END, _U32.pack(crc))


FOOTER_SIZE = 1 + 8 + 8 + 8 + 4  # opcode, length, summary_start, summary_offset_start, crc


def footer_prefix(summary_start: int, summary_offset_start: int) -> bytes:
    """Footer record up to (not including) summary_crc; the CRC covers these bytes too."""
    return _REC.pack(Op.FOOTER, 20) + struct.pack("<QQ", summary_start, summary_offset_start)


# -- parsing --------------------------------------------------------------------


class Cursor:
    """Sequential little-endian reads from a bytes-like object; IndexError past the end."""

    __slots__ = ("buf", "end", "pos")

    def __init__(self, buf: bytes | memoryview, pos: int = 0, end: int | None = None) -> None:
        self.buf = buf
        self.pos = pos
        self.end = len(buf) if end is None else end

    def _need(self, n: int) -> int:
        p = self.pos
        if p + n > self.end:
            raise IndexError("record field past end")
        self.pos = p + n
        return p

    def u8(self) -> int:
        return self.buf[self._need(1)]

    def u16(self) -> int:
        return _U16.unpack_from(self.buf, self._need(2))[0]

    def u32(self) -> int:
        return _U32.unpack_from(self.buf, self._need(4))[0]

    def u64(self) -> int:
        return _U64.unpack_from(self.buf, self._need(8))[0]

    def raw(self, n: int) -> bytes:
        p = self._need(n)
        return bytes(self.buf[p : p + n])

    def string(self) -> str:
        return self.raw(self.u32()).decode("utf-8")

    def bytes32(self) -> bytes:
        return self.raw(self.u32())

    def str_map(self) -> dict[str, str]:
        n = self.u32()
        stop = self.pos + n
        out = {}
        while self.pos < stop:
            k = self.string()
            out[k] = self.string()
        return out

    def u16_u64_map(self) -> dict[int, int]:
        n = self.u32()
        stop = self.pos + n
        out = {}
        while self.pos < stop:
            k = self.u16()
            out[k] = self.u64()
        return out
