"""Columns that grow chunk by chunk while a bag is read (preallocated; constant while possible).

:class:`Collector` gathers one topic's decoded pieces (:mod:`.decode`) into
columns -- a column holding one value throughout takes no memory until the
value changes -- and builds its :class:`~pneu_msgs_py.bag.run_data.TopicArrays`.
"""

from __future__ import annotations

import numpy as np

from pneu_msgs_py.bag.decode import Piece
from pneu_msgs_py.bag.run_data import TopicArrays
from pneu_msgs_py.contract.qos import QosProfile

__all__ = ["Collector", "aliases"]


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
            if not self.has_const:  # no value at all
                return np.empty(0, dtype=self.dtype)
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


class Collector:
    """One topic's columns, filled chunk by chunk (preallocated from the file's statistics)."""

    def __init__(
        self,
        topic: str,
        ros_type: str,
        qos: list[QosProfile],
        capacity: int,
        master: Collector | None = None,
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
        aliases(self.ros_type, self.names, fields)
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


def aliases(ros_type: str, names: list[str], fields: dict[str, np.ndarray]) -> None:
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
