"""MCAP records (spec v0, https://mcap.dev/spec) where pneu needs thousands at once.

Every record is written as the ``mcap`` library's record object
(``mcap.records``, serialized by :func:`record_bytes`), except what the bulk
paths need and the library does one Python object at a time (about 6 µs per
message record through ``mcap.Writer``, see :mod:`pneu_msgs_py.bag`): the
message record header as a struct and a numpy dtype (fixed-size records built
by the thousand) and message indexes from numpy arrays. Records are read by the
library's parsers too, made bounds-checked by :func:`parse` (the tolerant
reader must know a record is damaged). All integers little endian.
"""

from __future__ import annotations

import io
import struct
from typing import TypeVar

import numpy as np
from mcap.data_stream import ReadDataStream, RecordBuilder
from mcap.exceptions import EndOfFile
from mcap.opcode import Opcode as Op
from mcap.records import McapRecord
from mcap.writer import MCAP0_MAGIC as MAGIC

__all__ = ["MAGIC", "Op", "record_bytes", "message_index", "parse"]

_Rec = TypeVar("_Rec", bound=McapRecord)

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
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


class _Body(ReadDataStream):
    """A record body for ``mcap.records.X.read``, bounds-checked: damage raises IndexError.

    The library's stream returns a short read as it is (a cut string, a short
    schema); the tolerant reader needs to know the record is damaged.
    """

    def __init__(self, body: bytes | memoryview) -> None:
        super().__init__(io.BytesIO(body))

    def read(self, length: int) -> bytes:
        try:
            data = super().read(length)
        except EndOfFile:
            raise IndexError("record field past end") from None
        if len(data) < length:
            raise IndexError("record field past end")
        return data


def parse(record_type: type[_Rec], body: bytes | memoryview) -> _Rec:
    """The record of ``record_type`` (``mcap.records``) in ``body`` (after opcode and length).

    Raises IndexError (a field past the end), UnicodeDecodeError or struct.error
    on a damaged body.
    """
    return record_type.read(_Body(body))
