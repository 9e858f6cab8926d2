"""Chunk contents: fixed-size message records built in bulk, interleaved in log-time order.

A :class:`Batch` holds the messages of one channel for one chunk, either as
a ``(n, 31 + payload)`` byte array of fixed-size records (built by
:func:`records` from a bulk-CDR payload, :mod:`.cdr`) or as a list of record
bytes (variable-size messages). :func:`interleave` lays all batches out in
(log time, batch order) order and returns each message's offset in the chunk,
which the message indexes need.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pneu_msgs_py.bag import mcap_records as R
from pneu_msgs_py.bag.cdr import FixedLayout
from pneu_msgs_py.contract.qos import QosProfile

__all__ = ["Batch", "Channel", "interleave", "merge_same_channel", "records"]

_HDR = R.MESSAGE_HEADER_SIZE
# a chunk's records laid out and each batch's message offsets in it (by id of the batch)
Laid = tuple[bytes | np.ndarray, dict[int, np.ndarray]]


@dataclass
class Channel:
    id: int
    topic: str
    ros_type: str
    schema_id: int
    qos: QosProfile
    record: bytes = b""
    emitted: bool = False
    seq: int = 0
    count: int = 0


class Batch:
    """Messages of one channel for one chunk: record rows (fixed) or record bytes (variable)."""

    __slots__ = ("channel", "log_times", "records", "rows")

    def __init__(self, channel, log_times, rows=None, records=None) -> None:
        self.channel = channel
        self.log_times = log_times  # int64 (n,)
        self.rows = rows  # (n, 31 + payload) uint8, or None
        self.records = records  # list[bytes], or None


def records(
    ch: Channel, layout: FixedLayout, log_times: np.ndarray, pub_times: np.ndarray, payload
) -> np.ndarray:
    """Fixed-size message records ``(n, 31 + size)`` for one channel."""
    n = len(log_times)
    size = layout.size
    dt = np.dtype(
        {
            "names": [*R.MESSAGE_RECORD_DTYPE.names, "data"],
            "formats": [
                *(R.MESSAGE_RECORD_DTYPE.fields[k][0] for k in R.MESSAGE_RECORD_DTYPE.names),
                ("u1", (size,)),
            ],
            "offsets": [
                *(R.MESSAGE_RECORD_DTYPE.fields[k][1] for k in R.MESSAGE_RECORD_DTYPE.names),
                _HDR,
            ],
            "itemsize": _HDR + size,
        }
    )
    rec = np.empty(n, dtype=dt)
    rec["op"] = R.Op.MESSAGE
    rec["length"] = 22 + size
    rec["channel_id"] = ch.id
    rec["sequence"] = np.arange(ch.seq, ch.seq + n, dtype=np.uint64) & 0xFFFFFFFF
    rec["log_time"] = log_times
    rec["publish_time"] = pub_times
    rec["data"] = payload
    ch.seq += n
    ch.count += n
    return rec.view(np.uint8).reshape(n, _HDR + size)


def merge_same_channel(batches: list[Batch]) -> Batch:
    """Several fixed-size batches of one channel -> one variable batch in time order."""
    ch = batches[0].channel
    lts = np.concatenate([b.log_times for b in batches])
    recs = [row.tobytes() for b in batches for row in b.rows]
    order = np.argsort(lts, kind="stable")
    return Batch(ch, lts[order], records=[recs[i] for i in order])


def interleave(batches: list[Batch]) -> Laid:
    """Records of all batches in (log time, batch order) order; offsets per batch."""
    fixed = [b for b in batches if b.rows is not None]
    var = [b for b in batches if b.rows is None]
    if _in_rounds(fixed):
        return _rounds(fixed, var)
    return _by_time(batches, fixed)


def _in_rounds(fixed: list[Batch]) -> bool:
    """Whether the fast path applies: every fixed batch has the same, ordered log times (one
    message per channel per cycle)."""
    return bool(
        fixed
        and all(
            len(b.log_times) == len(fixed[0].log_times)
            and (b is fixed[0] or np.array_equal(b.log_times, fixed[0].log_times))
            for b in fixed
        )
        and np.all(np.diff(fixed[0].log_times) >= 0)
    )


def _rounds(fixed: list[Batch], var: list[Batch]) -> Laid:
    """Fast path: one round per log time (the fixed batches' records side by side, in batch
    order), each variable record inserted after the last round with time <= its time."""
    offsets: dict[int, np.ndarray] = {}
    t = fixed[0].log_times
    n = len(t)
    widths = [b.rows.shape[1] for b in fixed]
    cols = np.concatenate([[0], np.cumsum(widths)])
    block = np.concatenate([b.rows for b in fixed], axis=1)  # (n, round bytes)
    rb = int(cols[-1])
    if not var:
        base = np.arange(n, dtype=np.int64) * rb
        for b, c in zip(fixed, cols[:-1]):
            offsets[id(b)] = base + c
        return block.reshape(-1), offsets
    vt, vrecs, vowner = _time_ordered(var)
    ins = np.searchsorted(t, vt, side="right")  # round index the record precedes
    vsizes = np.array([len(r) for r in vrecs], dtype=np.int64)
    # bytes of variable records inserted before round i
    shift = np.cumsum(np.bincount(ins, weights=vsizes, minlength=n + 1)).astype(np.int64)[:n]
    base = np.arange(n, dtype=np.int64) * rb + shift
    for b, c in zip(fixed, cols[:-1]):
        offsets[id(b)] = base + c
    data, var_off = _splice(block.reshape(-1), rb, vrecs, ins, vowner, var)
    for b in var:
        offsets[id(b)] = np.array(var_off[id(b)], dtype=np.int64)
        # var batch times must follow the record order for the message index
        b.log_times = np.sort(b.log_times, kind="stable")
    return data, offsets


def _time_ordered(var: list[Batch]) -> tuple[np.ndarray, list[bytes], list[Batch]]:
    """The variable batches' records in stable log-time order: (times, records, their batches)."""
    vt = np.concatenate([b.log_times for b in var])
    vrecs = [r for b in var for r in b.records]
    vowner = [b for b in var for _ in b.records]
    order = np.argsort(vt, kind="stable")
    return vt[order], [vrecs[i] for i in order], [vowner[i] for i in order]


def _splice(
    flat: np.ndarray,
    rb: int,
    vrecs: list[bytes],
    ins: np.ndarray,
    vowner: list[Batch],
    var: list[Batch],
) -> tuple[bytes, dict[int, list[int]]]:
    """The rounds ``flat`` (``rb`` bytes each) with record ``vrecs[j]`` inserted before round
    ``ins[j]``; each record's offset listed under its batch ``vowner[j]`` (one of ``var``)."""
    parts: list[Any] = []
    prev = 0
    var_off: dict[int, list[int]] = {id(b): [] for b in var}
    pos = 0
    for r, i, owner in zip(vrecs, ins, vowner):
        seg = flat[prev * rb : i * rb]
        parts.append(seg)
        pos += seg.nbytes
        var_off[id(owner)].append(pos)
        parts.append(r)
        pos += len(r)
        prev = i
    parts.append(flat[prev * rb :])
    return b"".join(p.tobytes() if isinstance(p, np.ndarray) else p for p in parts), var_off


def _by_time(batches: list[Batch], fixed: list[Batch]) -> Laid:
    """General path: stable sort of every message by log time."""
    lts = np.concatenate([b.log_times for b in batches])
    sizes = np.concatenate(
        [
            np.full(len(b.log_times), b.rows.shape[1], dtype=np.int64)
            if b.rows is not None
            else np.array([len(r) for r in b.records], dtype=np.int64)
            for b in batches
        ]
    )
    order = np.argsort(lts, kind="stable")
    start = np.empty_like(sizes)
    start[order] = np.concatenate([[0], np.cumsum(sizes[order])[:-1]])
    spans = []  # each batch's records' offsets, in batch order
    k = 0
    for b in batches:
        spans.append(start[k : k + len(b.log_times)])
        k += len(b.log_times)
    out: Any
    if not fixed:  # only variable records (the ROS logger): one join, no per-record copy
        recs = [r for b in batches for r in b.records]
        out = b"".join([recs[i] for i in order.tolist()])
    else:
        out = _placed(batches, spans, int(sizes.sum()))
    offsets = {id(b): pos for b, pos in zip(batches, spans)}
    _index_in_time_order(batches, offsets)
    return out, offsets


def _placed(batches: list[Batch], spans: list[np.ndarray], size: int) -> np.ndarray:
    """One buffer of ``size`` bytes with every batch's records copied to their offsets ``spans``."""
    out = np.empty(size, dtype=np.uint8)
    for b, pos in zip(batches, spans):
        if b.rows is not None:
            w = b.rows.shape[1]
            out[pos[:, None] + np.arange(w)] = b.rows
        else:
            for p, r in zip(pos, b.records):
                out[p : p + len(r)] = np.frombuffer(r, dtype=np.uint8)
    return out


def _index_in_time_order(batches: list[Batch], offsets: dict[int, np.ndarray]) -> None:
    """Message index entries must be in log-time order per channel: each batch's times and
    offsets sorted (stable) where they are not."""
    for b in batches:
        o = np.argsort(b.log_times, kind="stable")
        if not np.all(o == np.arange(len(o))):
            b.log_times = b.log_times[o]
            offsets[id(b)] = offsets[id(b)][o]
