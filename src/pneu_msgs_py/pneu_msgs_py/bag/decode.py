"""Bulk decoding of one channel's messages in one chunk into numpy arrays.

For each channel, message records are located through the chunk's message
index. Records of one length whose constant bytes (names, frame_id, string
and sequence lengths, padding) equal a known :class:`~.cdr.FixedLayout` are
decoded together through a structured-dtype view -- strided over the chunk
without copying where the records are evenly spaced (pneu's own files),
gathered with one fancy-index otherwise. Anything else (other layouts,
malformed payloads) takes the per-message path, which gives the same arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pneu_msgs_py.bag import mcap_records as R
from pneu_msgs_py.bag.cdr import CdrDecodeError, FixedLayout, layout_of, parse_fixed

__all__ = ["Piece", "ChannelDecoder", "FIXED_TYPES"]

FIXED_TYPES = (
    "sensor_msgs/msg/FluidPressure",
    "sensor_msgs/msg/JointState",
    "rosgraph_msgs/msg/Clock",
)
_HDR = R.MESSAGE_HEADER_SIZE
_NS = 1_000_000_000


@dataclass
class Piece:
    """Decoded messages: times, header stamps, float64 fields, frame ids."""

    log_time: np.ndarray
    publish_time: np.ndarray
    stamp: np.ndarray
    fields: dict[str, np.ndarray]
    frame_ids: list[str]  # one per message, or a single one for all
    names: tuple[str, ...] = ()
    objects: list | None = None  # variable-layout messages (diagnostics)
    order_key: np.ndarray | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.log_time)


def _segments(offs: np.ndarray) -> list[tuple[int, int, int]]:
    """Split offsets into runs of constant stride: (start index, stop index, stride)."""
    n = len(offs)
    if n == 1:
        return [(0, 1, 1)]
    d = np.diff(offs)
    if (d == d[0]).all():
        return [(0, n, int(d[0]))]
    # break wherever the spacing changes
    brk = np.flatnonzero(d[1:] != d[:-1]) + 1
    bounds = [0, *brk.tolist(), n]
    out = []
    i = 0
    while i < len(bounds) - 1:
        a, b = bounds[i], bounds[i + 1]
        if b - a == 1:  # a lone message: pair it with the next one's stride if possible
            out.append((a, b, 1))
        else:
            out.append((a, b, int(offs[a + 1] - offs[a])))
        i += 1
    return out


class ChannelDecoder:
    """Decodes one channel's messages, chunk after chunk, remembering layouts."""

    def __init__(self, ros_type: str) -> None:
        self.ros_type = ros_type
        self.layouts: dict[int, list[FixedLayout]] = {}  # payload size -> layouts seen
        self.fixed = ros_type in FIXED_TYPES

    # -- record access ----------------------------------------------------------------
    @staticmethod
    def _header_view(buf: np.ndarray, offs: np.ndarray) -> np.ndarray:
        """(n,) records with fields op, length, channel_id, sequence, log_time, publish_time."""
        segs = _segments(offs)
        if len(segs) <= max(4, len(offs) // 64):
            parts = []
            for a, b, stride in segs:
                parts.append(
                    np.ndarray(
                        shape=(b - a,),
                        dtype=R.MESSAGE_RECORD_DTYPE,
                        buffer=buf,
                        offset=int(offs[a]),
                        strides=(stride,),
                    )
                )
            return parts[0] if len(parts) == 1 else np.concatenate(parts)
        idx = offs[:, None] + np.arange(_HDR)
        return buf[idx].view(R.MESSAGE_RECORD_DTYPE)[:, 0]

    @staticmethod
    def _payload_rows(buf: np.ndarray, offs: np.ndarray, size: int) -> np.ndarray:
        """(n, size) uint8 payloads (a strided view when evenly spaced, else a copy)."""
        segs = _segments(offs)
        if len(segs) == 1:
            a, b, stride = segs[0]
            return np.lib.stride_tricks.as_strided(
                buf[int(offs[0]) + _HDR :], shape=(b - a, size), strides=(stride, 1)
            )
        if len(segs) <= max(4, len(offs) // 64):
            return np.concatenate(
                [
                    np.lib.stride_tricks.as_strided(
                        buf[int(offs[a]) + _HDR :], shape=(b - a, size), strides=(stride, 1)
                    )
                    for a, b, stride in segs
                ]
            )
        return buf[(offs + _HDR)[:, None] + np.arange(size)]

    # -- decoding -----------------------------------------------------------------------
    def decode(self, data: bytes, offs: np.ndarray, walk_ok: bool = True) -> list[Piece]:
        """Pieces for the records at ``offs`` in chunk ``data`` (record order kept)."""
        if len(offs) == 0:
            return []
        buf = np.frombuffer(data, dtype=np.uint8)
        if int(offs.max()) + _HDR > len(buf) or int(offs.min()) < 0:
            raise CdrDecodeError("message index points outside the chunk")
        hv = self._header_view(buf, offs)
        if not (hv["op"] == R.Op.MESSAGE).all():
            raise CdrDecodeError("message index points at a non-message record")
        sizes = hv["length"].astype(np.int64) - 22
        if int((offs + _HDR + sizes).max()) > len(buf) or int(sizes.min()) < 0:
            raise CdrDecodeError("message record runs past the chunk")
        log_t = hv["log_time"].astype(np.int64)
        pub_t = hv["publish_time"].astype(np.int64)
        if not self.fixed:
            return [self._objects(data, offs, sizes, log_t, pub_t)]
        uniq = np.unique(sizes)
        pieces: list[Piece] = []
        for size in uniq.tolist():
            sel = None if len(uniq) == 1 else np.flatnonzero(sizes == size)
            o = offs if sel is None else offs[sel]
            rows = self._payload_rows(buf, o, size)
            pieces.extend(
                self._decode_rows(
                    rows,
                    log_t if sel is None else log_t[sel],
                    pub_t if sel is None else pub_t[sel],
                    np.arange(len(offs)) if sel is None else sel,
                )
            )
        return pieces

    def _decode_rows(self, rows, log_t, pub_t, key) -> list[Piece]:
        size = rows.shape[1]
        remaining = np.ones(len(rows), dtype=bool)
        pieces = []
        cands = self.layouts.setdefault(size, [])
        tried_new = False
        while remaining.any():
            idx = np.flatnonzero(remaining)
            sub = rows[idx] if len(idx) != len(rows) else rows
            hit = None
            for L in cands:
                m = L.matches(sub)
                if m.any():
                    hit = (L, m)
                    break
            if hit is None:
                if tried_new and len(cands) > 8:
                    break  # too many layouts: the rest goes message by message
                first = bytes(sub[0])
                try:
                    parsed = parse_fixed(self.ros_type, first)
                    L = layout_of(self.ros_type, parsed)
                    ok = parsed["little_endian"] and L.size == size
                    ok = ok and L.encode(parsed["stamp_ns"], self._values(L, parsed)) == first
                except CdrDecodeError:
                    ok = False
                if not ok:
                    # slow path for this one message
                    pieces.append(self._slow(sub[:1], log_t[idx[:1]], pub_t[idx[:1]], key[idx[:1]]))
                    remaining[idx[0]] = False
                    continue
                cands.append(L)
                tried_new = True
                continue
            L, m = hit
            take = idx[m]
            part = sub[m] if not m.all() else sub
            stamps, vals = L.decode_many(part)
            pieces.append(
                Piece(
                    log_t[take],
                    pub_t[take],
                    stamps,
                    vals,
                    [L.frame_id],
                    L.names,
                    order_key=key[take],
                )
            )
            remaining[take] = False
        if remaining.any():
            idx = np.flatnonzero(remaining)
            pieces.append(self._slow(rows[idx], log_t[idx], pub_t[idx], key[idx]))
        return pieces

    @staticmethod
    def _values(L: FixedLayout, parsed: dict) -> list[float]:
        if L.ros_type == "sensor_msgs/msg/FluidPressure":
            return [parsed["fluid_pressure"], parsed["variance"]]
        if L.ros_type == "sensor_msgs/msg/JointState":
            return [*parsed["position"], *parsed["velocity"], *parsed["effort"]]
        return []

    def _slow(self, rows, log_t, pub_t, key) -> Piece:
        """Message by message (any layout); same output columns as the bulk path."""
        n = len(rows)
        stamps = np.empty(n, dtype=np.int64)
        frames: list[str] = []
        cols: dict[str, np.ndarray] = {}
        names_all: list[str] = []
        for i in range(n):
            try:
                p = parse_fixed(self.ros_type, bytes(rows[i]))
            except CdrDecodeError as e:
                raise CdrDecodeError(f"{self.ros_type} message: {e}") from None
            stamps[i] = p["stamp_ns"]
            frames.append(p["frame_id"])
            if self.ros_type == "sensor_msgs/msg/FluidPressure":
                for k in ("fluid_pressure", "variance"):
                    cols.setdefault(k, np.full(n, np.nan))[i] = p[k]
            elif self.ros_type == "sensor_msgs/msg/JointState":
                for j, nm in enumerate(p["name"]):
                    if nm not in names_all:
                        names_all.append(nm)
                    for k in ("position", "velocity", "effort"):
                        arr = p[k]
                        if j < len(arr):
                            cols.setdefault(f"{nm}.{k}", np.full(n, np.nan))[i] = arr[j]
        return Piece(log_t, pub_t, stamps, cols, frames, tuple(names_all), order_key=key)

    def _objects(self, data, offs, sizes, log_t, pub_t) -> Piece:
        """Variable-layout types: deserialize each message with the rosbags typestore."""
        from pneu_msgs_py.contract.convert import (
            diag_statuses_from_msg,
            jazzy_typestore,
            stamp_to_ns,
        )

        ts = jazzy_typestore()
        objs = []
        stamps = np.zeros(len(offs), dtype=np.int64)
        for i, (o, s) in enumerate(zip(offs.tolist(), sizes.tolist())):
            msg = ts.deserialize_cdr(data[o + _HDR : o + _HDR + s], self.ros_type)
            if self.ros_type == "diagnostic_msgs/msg/DiagnosticArray":
                objs.append(diag_statuses_from_msg(msg))
            else:
                objs.append(msg)
            hdr = getattr(msg, "header", None)
            if hdr is not None:
                stamps[i] = stamp_to_ns(hdr.stamp)
            else:
                stamps[i] = log_t[i]
        return Piece(log_t, pub_t, stamps, {}, [""], objects=objs, order_key=np.arange(len(offs)))
