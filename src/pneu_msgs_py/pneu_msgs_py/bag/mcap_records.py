"""MCAP records (spec v0, https://mcap.dev/spec) where pneu needs thousands at once.

Every record is written as the ``mcap`` library's record object
(``mcap.records``, serialized by :func:`record_bytes`), except what the bulk
paths need and the library does one Python object at a time (about 6 µs per
message record through ``mcap.Writer``, see :mod:`pneu_msgs_py.bag`): the
message record header as a struct and a numpy dtype (fixed-size records built
by the thousand), message indexes from numpy arrays, and :class:`Cursor`, the
bounds-checked parser the tolerant reader needs. All integers little endian.
"""

from __future__ import annotations

import struct

import numpy as np
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode as Op
from mcap.records import McapRecord
from mcap.writer import MCAP0_MAGIC as MAGIC

__all__ = ["MAGIC", "Op", "record_bytes", "message_index", "Cursor"]

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


def record_bytes(rec: McapRecord) -> bytes:
    """One ``mcap.records`` record as bytes."""
    b = RecordBuilder()
    rec.write(b)
    return b.end()


def message_index(channel_id: int, times: np.ndarray, offsets: np.ndarray) -> bytes:
    """A Message Index record of one channel from its (log time, offset) arrays."""
    arr = np.empty(len(times), dtype=[("t", "<u8"), ("o", "<u8")])
    arr["t"] = times
    arr["o"] = offsets
    body = _U16.pack(channel_id) + _U32.pack(arr.nbytes) + arr.tobytes()
    return _REC.pack(Op.MESSAGE_INDEX, len(body)) + body


FOOTER_SIZE = 1 + 8 + 8 + 8 + 4  # opcode, length, summary_start, summary_offset_start, crc


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
