"""MCAP writer for pneu runs (ROS 2 profile, CDR), without rclpy.

Hot path: ``write_sample``, ``write_command`` and ``write_controller_state``
only append a tuple to a list. When the buffered messages reach
``chunk_size`` bytes, the chunk is built in bulk: every fixed-layout topic is
CDR-encoded with numpy into a byte template (:mod:`.cdr`), the message
records are interleaved in log-time order, compressed, and written with their
message indexes, then the file is flushed to the OS -- so a hard kill loses at
most the chunk being buffered. ``close()`` (or leaving the ``with`` block)
writes the summary: schemas, channels, statistics, chunk indexes, metadata
indexes, summary offsets, footer.

File layout (what ``ros2 bag info/play``, Foxglove, PlotJuggler, mcap_ros2
and rosbags expect): profile ``ros2``; one schema per type, encoding
``ros2msg`` with the full Jazzy definition; channels with message encoding
``cdr`` and metadata ``offered_qos_profiles`` in rosbag2's YAML; log time =
publish time = the sample stamp (or the given log time for commands);
metadata records for the run configuration.
"""

from __future__ import annotations

import math
import os
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pneu_msgs_py import __version__
from pneu_msgs_py.bag import mcap_records as R
from pneu_msgs_py.bag.cdr import (
    FixedLayout,
    clock_layout,
    fluid_pressure_layout,
    joint_state_layout,
)
from pneu_msgs_py.bag.errors import BagWriteError
from pneu_msgs_py.bag.schemas import (
    MESSAGE_ENCODING,
    MSG_DEFINITIONS,
    PROFILE,
    SCHEMA_ENCODING,
    TYPE_HASHES,
)
from pneu_msgs_py.contract.convert import DiagStatus, _typestore, diagnostics_to_typestore
from pneu_msgs_py.contract.qos import MODES, QosProfile, offered_qos_yaml
from pneu_msgs_py.contract.samples import AXES, SensorSample
from pneu_msgs_py.contract.topics import (
    CLOCK_TOPIC,
    CONTROLLER_STATE_TOPIC,
    DEFAULT_STATE_FIELDS,
    DIAGNOSTICS_TOPIC,
    JOINT_STATE_TOPIC,
    PRESSURE_TOPICS,
    ROTARY_COUNTS_JOINT,
    VALVE_COMMAND_TOPIC,
    qos_for,
    valve_joint,
)

__all__ = ["BagWriter", "DiagStatus", "COMPRESSIONS"]

COMPRESSIONS = ("zstd", "lz4", "none")
_LIBRARY = f"pneu_msgs_py {__version__}"
_HDR = R.MESSAGE_HEADER_SIZE


@dataclass
class _Channel:
    id: int
    topic: str
    ros_type: str
    schema_id: int
    qos: QosProfile
    record: bytes = b""
    emitted: bool = False
    seq: int = 0
    count: int = 0


class _Batch:
    """Messages of one channel for one chunk: record rows (fixed) or record bytes (variable)."""

    __slots__ = ("channel", "log_times", "records", "rows")

    def __init__(self, channel, log_times, rows=None, records=None) -> None:
        self.channel = channel
        self.log_times = log_times  # int64 (n,)
        self.rows = rows  # (n, 31 + payload) uint8, or None
        self.records = records  # list[bytes], or None


def _records(
    ch: _Channel, layout: FixedLayout, log_times: np.ndarray, pub_times: np.ndarray, payload
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


class BagWriter:
    """Write one pneu run to an MCAP file (ROS 2 profile).

    Parameters
    ----------
    path : output ``.mcap`` file (parent directory must exist; overwritten)
    metadata : ``{record name: {key: value}}`` written as MCAP metadata at start
    chunk_size : uncompressed bytes per chunk (also the most a hard kill loses)
    compression : ``zstd`` | ``lz4`` | ``none``
    controller_state_fields : names of the controller-state values, in order
    qos : ``lockstep`` | ``realtime`` -- which publisher QoS the channels record
    pressure_variance : FluidPressure.variance [Pa^2] (sensor noise variance, or 0)

    All times are int nanoseconds. The writer installs no signal handler: the
    runner calls :meth:`close` (also on SIGINT/SIGTERM).
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        metadata: Mapping[str, Mapping[str, str]] | None = None,
        chunk_size: int = 1 << 20,
        compression: str = "zstd",
        controller_state_fields: tuple[str, ...] = DEFAULT_STATE_FIELDS,
        qos: str = "lockstep",
        pressure_variance: float = 0.0,
    ) -> None:
        self.path = Path(path)
        if compression not in COMPRESSIONS:
            raise BagWriteError(
                self.path, f"compression {compression!r} refused; allowed: {COMPRESSIONS}"
            )
        if qos not in MODES:
            raise BagWriteError(self.path, f"qos {qos!r} refused; allowed: {MODES}")
        if chunk_size < 1024:
            raise BagWriteError(self.path, f"chunk_size {chunk_size} refused; allowed: >= 1024")
        if len(set(controller_state_fields)) != len(controller_state_fields) or not all(
            isinstance(f, str) and f for f in controller_state_fields
        ):
            raise BagWriteError(
                self.path, f"controller_state_fields {controller_state_fields!r}: need unique names"
            )
        if not math.isfinite(pressure_variance) or pressure_variance < 0:
            raise BagWriteError(
                self.path, f"pressure_variance {pressure_variance!r} refused; allowed: >= 0"
            )
        self.chunk_size = int(chunk_size)
        self._hard_limit = 2 * self.chunk_size  # flush point for writers without samples
        self.compression = compression
        self.qos_mode = qos
        self.state_fields = tuple(controller_state_fields)
        self.pressure_variance = float(pressure_variance)
        if compression == "zstd":
            import zstandard

            self._compress = zstandard.ZstdCompressor(level=1).compress
        elif compression == "lz4":
            import lz4.frame

            self._compress = lz4.frame.compress
        else:
            self._compress = None
        self._comp_name = "" if compression == "none" else compression

        try:
            self._f = open(self.path, "wb")
        except OSError as e:
            raise BagWriteError(self.path, f"cannot open for writing: {e.strerror}") from None
        self._pos = 0
        self._crc = 0
        self._closed = False
        self._schemas: dict[str, tuple[int, bytes]] = {}
        self._channels: dict[str, _Channel] = {}
        self._chunk_indexes: list[bytes] = []
        self._metadata_indexes: list[bytes] = []
        self._n_metadata = 0
        self._t_start: int | None = None
        self._t_end: int | None = None

        # buffers (hot path)
        self._samples: list[tuple] = []
        self._commands: dict[str, list[tuple[int, float, int]]] = {a: [] for a in AXES}
        # controller states: stamps, algorithms and the values flattened (no tuple per call)
        self._states: dict[str, tuple[list[int], list[str], list[float]]] = {
            a: ([], [], []) for a in AXES
        }
        self._n_fields = len(self.state_fields)
        self._clock: list[int] = []
        self._var: list[tuple[str, str, int, int, bytes]] = []  # topic, type, log, pub, data
        self._pending = 0

        # fixed layouts and their record sizes
        self._fp_layouts = {t: fluid_pressure_layout(fr) for t, (_, fr) in PRESSURE_TOPICS.items()}
        self._js_linear = joint_state_layout(["linear"], position=True)
        self._js_rotary = joint_state_layout(
            ["rotary", ROTARY_COUNTS_JOINT], position=True, velocity=True
        )
        self._cmd_layouts = {
            a: joint_state_layout([valve_joint(a)], position=False, effort=True) for a in AXES
        }
        self._state_layouts: dict[tuple[str, str], FixedLayout] = {}
        self._clock_layout = clock_layout()
        self._sample_bytes = sum(_HDR + L.size for L in self._fp_layouts.values()) + (
            2 * _HDR + self._js_linear.size + self._js_rotary.size
        )
        self._cmd_bytes = {a: _HDR + L.size for a, L in self._cmd_layouts.items()}
        self._state_bytes = _HDR + joint_state_layout(self.state_fields).size + 8

        self._write(R.MAGIC + R.header(PROFILE, _LIBRARY))
        for name, data in (metadata or {}).items():
            self.add_metadata(name, data)

    # -- context manager -----------------------------------------------------
    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    # -- low level -------------------------------------------------------------
    def _write(self, data: bytes) -> None:
        self._f.write(data)
        self._crc = zlib.crc32(data, self._crc)
        self._pos += len(data)

    def _check_open(self) -> None:
        if self._closed:
            raise BagWriteError(self.path, "writer is closed")

    def _channel(self, topic: str, ros_type: str) -> _Channel:
        ch = self._channels.get(topic)
        if ch is not None:
            if ch.ros_type != ros_type:
                raise BagWriteError(
                    self.path, f"topic {topic} already has type {ch.ros_type}, not {ros_type}"
                )
            return ch
        if ros_type not in self._schemas:
            sid = len(self._schemas) + 1
            text = MSG_DEFINITIONS.get(ros_type)
            if text is None:
                text = ""  # foreign type via write_serialized: definition unknown here
            self._schemas[ros_type] = (
                sid,
                R.schema(sid, ros_type, SCHEMA_ENCODING, text.encode("utf-8")),
            )
        sid = self._schemas[ros_type][0]
        cid = len(self._channels) + 1
        qos = qos_for(topic, self.qos_mode)
        ch = _Channel(cid, topic, ros_type, sid, qos)
        # the two channel metadata keys rosbag2 (Jazzy) writes
        meta = {
            "offered_qos_profiles": offered_qos_yaml([qos]),
            "topic_type_hash": TYPE_HASHES.get(ros_type, ""),
        }
        ch.record = R.channel(cid, sid, topic, MESSAGE_ENCODING, meta)
        self._channels[topic] = ch
        return ch

    def _add_pending(self, nbytes: int) -> None:
        self._pending += nbytes
        # with samples flowing, chunks are cut in write_sample (at cycle starts)
        if self._pending >= (self._hard_limit if self._samples else self.chunk_size):
            self.flush()

    # -- public write API ------------------------------------------------------
    def write_sample(self, s: SensorSample) -> None:
        """3 FluidPressure + 2 JointState at ``s.stamp_ns`` (log = publish = stamp)."""
        if self._closed:
            self._check_open()
        # A sample starts a cycle: cut chunks here, so that a chunk never ends between a
        # sample and the commands answering it (keeps the file in log-time order).
        if self._pending >= self.chunk_size:
            self.flush()
        self._samples.append(
            (s.stamp_ns, s.p_c1, s.p_c2, s.p_m1, s.x, s.theta, s.omega, float(s.counts))
        )
        self._pending += self._sample_bytes

    def write_command(
        self, axis: str, stamp_ns: int, u: float, log_time_ns: int | None = None
    ) -> None:
        """Valve command ``u`` [V] answering the sample stamped ``stamp_ns``.

        ``log_time_ns`` (default: ``stamp_ns``) is the record's log and publish time.
        """
        if self._closed:
            self._check_open()
        try:
            buf = self._commands[axis]
        except KeyError:
            raise ValueError(f"axis: {axis!r} refused; allowed: {AXES}") from None
        buf.append((stamp_ns, u, stamp_ns if log_time_ns is None else log_time_ns))
        self._pending += self._cmd_bytes[axis]
        if self._pending >= self._hard_limit:
            self.flush()

    def write_controller_state(
        self, axis: str, stamp_ns: int, values: Sequence[float], algorithm: str
    ) -> None:
        """One controller-state message: ``values`` in ``controller_state_fields`` order."""
        if self._closed:
            self._check_open()
        try:
            stamps, algos, flat = self._states[axis]
        except KeyError:
            raise ValueError(f"axis: {axis!r} refused; allowed: {AXES}") from None
        if len(values) != self._n_fields:
            raise ValueError(
                f"controller state: {len(values)} values for {self._n_fields} fields "
                f"{self.state_fields}"
            )
        flat.extend(values)  # copies the references: later changes to ``values`` do not leak
        stamps.append(stamp_ns)
        algos.append(algorithm)
        self._pending += self._state_bytes + len(algorithm)
        if self._pending >= self._hard_limit:
            self.flush()

    def write_cycle(
        self, s: SensorSample, answers: Sequence[tuple[str, float, Sequence[float], str]]
    ) -> None:
        """One control cycle in one call: the sample, then per answering axis its valve
        command and controller state, all stamped ``s.stamp_ns`` (log = publish = stamp).

        ``answers``: ``(axis, u, state values, algorithm)`` per axis that answered the
        sample. Same records and order as :meth:`write_sample` followed by
        :meth:`write_command` and :meth:`write_controller_state` per axis; cheaper
        (the in-process runner's hot path).
        """
        if self._closed:
            self._check_open()
        if self._pending >= self.chunk_size:
            self.flush()
        stamp = s.stamp_ns
        self._samples.append(
            (stamp, s.p_c1, s.p_c2, s.p_m1, s.x, s.theta, s.omega, float(s.counts))
        )
        pending = self._sample_bytes
        n_fields = self._n_fields
        for axis, u, values, algorithm in answers:
            try:
                cmds = self._commands[axis]
                stamps, algos, flat = self._states[axis]
            except KeyError:
                raise ValueError(f"axis: {axis!r} refused; allowed: {AXES}") from None
            if len(values) != n_fields:
                raise ValueError(
                    f"controller state: {len(values)} values for {n_fields} fields "
                    f"{self.state_fields}"
                )
            cmds.append((stamp, u, stamp))
            flat.extend(values)
            stamps.append(stamp)
            algos.append(algorithm)
            pending += self._cmd_bytes[axis] + self._state_bytes + len(algorithm)
        self._pending += pending

    def write_clock(self, stamp_ns: int) -> None:
        """``/clock`` (lockstep simulation only)."""
        self._check_open()
        self._clock.append(stamp_ns)
        self._add_pending(_HDR + self._clock_layout.size)

    def write_diagnostics(self, stamp_ns: int, statuses: Sequence[DiagStatus]) -> None:
        """``/diagnostics`` (low rate; encoded with the rosbags Jazzy typestore)."""
        self._check_open()
        ts = _typestore()
        msg = diagnostics_to_typestore(stamp_ns, statuses)
        data = bytes(ts.serialize_cdr(msg, "diagnostic_msgs/msg/DiagnosticArray"))
        self.write_serialized(
            DIAGNOSTICS_TOPIC, "diagnostic_msgs/msg/DiagnosticArray", data, stamp_ns, stamp_ns
        )

    def write_serialized(
        self, topic: str, ros_type: str, data: bytes, log_time_ns: int, publish_time_ns: int
    ) -> None:
        """An already-CDR-encoded message (e.g. from rclpy's ``serialize_message``)."""
        self._check_open()
        if len(data) < 4:
            raise BagWriteError(self.path, f"{topic}: {len(data)}-byte payload is not CDR")
        if log_time_ns < 0 or publish_time_ns < 0:
            raise BagWriteError(
                self.path, f"{topic}: negative time ({log_time_ns}, {publish_time_ns}) ns"
            )
        self._channel(topic, ros_type)  # type check now, not at flush
        self._var.append((topic, ros_type, int(log_time_ns), int(publish_time_ns), bytes(data)))
        self._add_pending(_HDR + len(data))

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """An MCAP metadata record (all keys and values str), written immediately."""
        self._check_open()
        if not isinstance(name, str) or not name:
            raise BagWriteError(self.path, f"metadata name {name!r}: need a non-empty str")
        for k, v in data.items():
            if not isinstance(k, str) or not isinstance(v, str):
                raise BagWriteError(
                    self.path, f"metadata {name}[{k!r}]: keys and values must be str, got {v!r}"
                )
        rec = R.metadata(name, dict(data))
        self._metadata_indexes.append(R.metadata_index(self._pos, len(rec), name))
        self._n_metadata += 1
        self._write(rec)
        self._f.flush()

    # -- chunk building --------------------------------------------------------
    def _collect(self) -> list[_Batch]:
        batches: list[_Batch] = []
        if self._samples:
            buf = self._samples
            self._samples = []
            a = np.array(buf, dtype=np.float64)  # column 0 (stamp) is re-read exactly below
            t = np.fromiter((r[0] for r in buf), np.int64, len(buf))
            for j, (topic, L) in enumerate(self._fp_layouts.items()):
                ch = self._channel(topic, L.ros_type)
                vals = np.empty((len(t), 2))
                vals[:, 0] = a[:, 1 + j]
                vals[:, 1] = self.pressure_variance
                batches.append(_Batch(ch, t, _records(ch, L, t, t, L.encode_many(t, vals))))
            ch = self._channel(JOINT_STATE_TOPIC["linear"], self._js_linear.ros_type)
            pay = self._js_linear.encode_many(t, a[:, 4:5])
            batches.append(_Batch(ch, t, _records(ch, self._js_linear, t, t, pay)))
            ch = self._channel(JOINT_STATE_TOPIC["rotary"], self._js_rotary.ros_type)
            vals = np.empty((len(t), 4))
            vals[:, 0] = a[:, 5]  # theta
            vals[:, 1] = a[:, 7]  # counts
            vals[:, 2] = a[:, 6]  # omega
            vals[:, 3] = np.nan
            pay = self._js_rotary.encode_many(t, vals)
            batches.append(_Batch(ch, t, _records(ch, self._js_rotary, t, t, pay)))
        for axis in AXES:
            buf = self._commands[axis]
            if buf:
                self._commands[axis] = []
                L = self._cmd_layouts[axis]
                st = np.fromiter((r[0] for r in buf), np.int64, len(buf))
                u = np.fromiter((r[1] for r in buf), np.float64, len(buf))
                lt = np.fromiter((r[2] for r in buf), np.int64, len(buf))
                ch = self._channel(VALVE_COMMAND_TOPIC[axis], L.ros_type)
                pay = L.encode_many(st, u[:, None])
                batches.append(_Batch(ch, lt, _records(ch, L, lt, lt, pay)))
        for axis in AXES:
            buf = self._states[axis]
            if buf[0]:
                self._states[axis] = ([], [], [])
                batches.extend(self._state_batches(axis, *buf))
        if self._clock:
            t = np.array(self._clock, dtype=np.int64)
            self._clock = []
            ch = self._channel(CLOCK_TOPIC, self._clock_layout.ros_type)
            pay = self._clock_layout.encode_many(t)
            batches.append(_Batch(ch, t, _records(ch, self._clock_layout, t, t, pay)))
        if self._var:
            by_topic: dict[str, list] = {}
            for item in self._var:
                by_topic.setdefault(item[0], []).append(item)
            self._var = []
            for topic, items in by_topic.items():
                ch = self._channel(topic, items[0][1])
                recs = []
                for _, _, lt, pt, data in items:
                    recs.append(R.message(ch.id, ch.seq & 0xFFFFFFFF, lt, pt, data))
                    ch.seq += 1
                ch.count += len(items)
                lts = np.array([it[2] for it in items], dtype=np.int64)
                batches.append(_Batch(ch, lts, records=recs))
        return batches

    def _state_batches(
        self, axis: str, stamps: list[int], algos: list[str], flat: list[float]
    ) -> list[_Batch]:
        topic = CONTROLLER_STATE_TOPIC[axis]
        n = len(stamps)
        groups: dict[str, list[int]] = {}
        if algos.count(algos[0]) == n:
            groups[algos[0]] = list(range(n))
        else:
            for i, a in enumerate(algos):
                groups.setdefault(a, []).append(i)
        st = np.array(stamps, dtype=np.int64)
        vals = np.array(flat, dtype=np.float64).reshape(n, self._n_fields)
        out = []
        for algo, idx in groups.items():
            L = self._state_layouts.get((axis, algo))
            if L is None:
                L = joint_state_layout(self.state_fields, position=True, frame_id=algo)
                self._state_layouts[(axis, algo)] = L
            ch = self._channel(topic, L.ros_type)
            if len(idx) == n:
                s, v = st, vals
            else:
                ii = np.asarray(idx)
                s, v = st[ii], vals[ii]
            out.append(_Batch(ch, s, _records(ch, L, s, s, L.encode_many(s, v))))
        if len(out) > 1:  # one channel, several layouts: merge so the channel's times stay sorted
            out = [_merge_same_channel(out)]
        return out

    def flush(self) -> None:
        """Write the buffered messages as one chunk (no-op if nothing is buffered)."""
        self._check_open()
        self._pending = 0
        batches = self._collect()
        if not batches:
            return
        for b in batches:
            if len(b.log_times) and int(b.log_times.min()) < 0:
                raise BagWriteError(
                    self.path, f"{b.channel.topic}: negative time {int(b.log_times.min())} ns"
                )
        data, offsets = _interleave(batches)
        # schema / channel records of channels first used in this chunk
        head = []
        for b in batches:
            ch = b.channel
            if not ch.emitted:
                sid, srec = self._schemas[ch.ros_type]
                if srec:
                    head.append(srec)
                    self._schemas[ch.ros_type] = (sid, b"")  # emitted
                head.append(ch.record)
                ch.emitted = True
        if head:
            self._write(b"".join(head))
        t_min = int(min(b.log_times.min() for b in batches))
        t_max = int(max(b.log_times.max() for b in batches))
        self._t_start = t_min if self._t_start is None else min(self._t_start, t_min)
        self._t_end = t_max if self._t_end is None else max(self._t_end, t_max)
        raw = memoryview(data)
        crc = zlib.crc32(raw)
        comp = self._compress(raw) if self._compress else bytes(raw)
        chunk_start = self._pos
        crec = R.chunk(t_min, t_max, len(raw), crc, self._comp_name, comp)
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
            R.chunk_index(
                t_min,
                t_max,
                chunk_start,
                len(crec),
                mi_offsets,
                self._pos - mi_start,
                self._comp_name,
                len(comp),
                len(raw),
            )
        )

    def close(self) -> None:
        """Write the last chunk and the summary; idempotent."""
        if self._closed:
            return
        try:
            self.flush()
            self._finish()
        finally:
            self._closed = True
            self._f.close()

    def _finish(self) -> None:
        # channels that never got a message still need their records for the summary
        for ch in self._channels.values():
            if not ch.emitted:
                sid, srec = self._schemas[ch.ros_type]
                if srec:
                    self._write(srec)
                    self._schemas[ch.ros_type] = (sid, b"")
                self._write(ch.record)
                ch.emitted = True
        rec = R.metadata("rosbag2", {"serialized_metadata": self._rosbag2_metadata()})
        self._metadata_indexes.append(R.metadata_index(self._pos, len(rec), "rosbag2"))
        self._n_metadata += 1
        self._write(rec)
        self._write(R.data_end(self._crc))
        summary_start = self._pos
        summary_crc = 0
        groups: list[tuple[int, int, int]] = []

        def group(op: int, recs: list[bytes]) -> None:
            nonlocal summary_crc
            if not recs:
                return
            blob = b"".join(recs)
            groups.append((op, self._pos, len(blob)))
            self._f.write(blob)
            summary_crc = zlib.crc32(blob, summary_crc)
            self._pos += len(blob)

        schema_recs = []
        for ros_type, (sid, _) in sorted(self._schemas.items(), key=lambda kv: kv[1][0]):
            text = MSG_DEFINITIONS.get(ros_type, "")
            schema_recs.append(R.schema(sid, ros_type, SCHEMA_ENCODING, text.encode("utf-8")))
        group(R.Op.SCHEMA, schema_recs)
        group(R.Op.CHANNEL, [ch.record for ch in self._channels.values()])
        n_msgs = sum(ch.count for ch in self._channels.values())
        group(
            R.Op.STATISTICS,
            [
                R.statistics(
                    n_msgs,
                    len(self._schemas),
                    len(self._channels),
                    self._n_metadata,
                    len(self._chunk_indexes),
                    self._t_start or 0,
                    self._t_end or 0,
                    {ch.id: ch.count for ch in self._channels.values()},
                )
            ],
        )
        group(R.Op.CHUNK_INDEX, self._chunk_indexes)
        group(R.Op.METADATA_INDEX, self._metadata_indexes)
        summary_offset_start = self._pos
        so = b"".join(R.summary_offset(op, start, length) for op, start, length in groups)
        self._f.write(so)
        summary_crc = zlib.crc32(so, summary_crc)
        self._pos += len(so)
        if not groups:
            summary_start = 0
            summary_offset_start = 0
        foot = R.footer_prefix(summary_start, summary_offset_start)
        summary_crc = zlib.crc32(foot, summary_crc)
        self._f.write(foot + summary_crc.to_bytes(4, "little") + R.MAGIC)
        self._f.flush()

    def _rosbag2_metadata(self) -> str:
        """rosbag2's BagMetadata (version 9) as the ``rosbag2`` metadata record holds it.

        ``ros2 bag info/play`` on the loose file read the version from it (so the
        string-coded QoS profiles are decoded as version 9) and take counts,
        times and topics from the summary statistics.
        """
        import yaml

        start = self._t_start or 0
        duration = (self._t_end or 0) - start
        count = sum(ch.count for ch in self._channels.values())
        info = {
            "version": 9,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": count,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": ch.topic,
                        "type": ch.ros_type,
                        "serialization_format": MESSAGE_ENCODING,
                        "offered_qos_profiles": [ch.qos.to_dict()],
                        "type_description_hash": TYPE_HASHES.get(ch.ros_type, ""),
                    },
                    "message_count": ch.count,
                }
                for ch in self._channels.values()
            ],
            # chunk compression belongs to the storage; rosbag2's own (file/message) is off
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.path.name],
            "files": [
                {
                    "path": self.path.name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration},
                    "message_count": count,
                }
            ],
            "custom_data": {"writer": _LIBRARY},
            "ros_distro": "jazzy",
        }
        return yaml.safe_dump(info, sort_keys=False, default_flow_style=False)


def _merge_same_channel(batches: list[_Batch]) -> _Batch:
    """Several fixed-size batches of one channel -> one variable batch in time order."""
    ch = batches[0].channel
    lts = np.concatenate([b.log_times for b in batches])
    recs = [row.tobytes() for b in batches for row in b.rows]
    order = np.argsort(lts, kind="stable")
    return _Batch(ch, lts[order], records=[recs[i] for i in order])


def _interleave(batches: list[_Batch]) -> tuple[bytes | np.ndarray, dict[int, np.ndarray]]:
    """Records of all batches in (log time, batch order) order; offsets per batch."""
    fixed = [b for b in batches if b.rows is not None]
    var = [b for b in batches if b.rows is None]
    offsets: dict[int, np.ndarray] = {}
    # fast path: every fixed batch has the same log times (one message per channel per cycle)
    if (
        fixed
        and all(
            len(b.log_times) == len(fixed[0].log_times)
            and (b is fixed[0] or np.array_equal(b.log_times, fixed[0].log_times))
            for b in fixed
        )
        and np.all(np.diff(fixed[0].log_times) >= 0)
    ):
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
        # a few variable records: insert each after the last round with time <= its time
        vt = np.concatenate([b.log_times for b in var])
        vrecs = [r for b in var for r in b.records]
        vowner = [b for b in var for _ in b.records]
        order = np.argsort(vt, kind="stable")
        vt = vt[order]
        vrecs = [vrecs[i] for i in order]
        vowner = [vowner[i] for i in order]
        ins = np.searchsorted(t, vt, side="right")  # round index the record precedes
        vsizes = np.array([len(r) for r in vrecs], dtype=np.int64)
        # bytes of variable records inserted before round i
        shift = np.cumsum(np.bincount(ins, weights=vsizes, minlength=n + 1)).astype(np.int64)[:n]
        base = np.arange(n, dtype=np.int64) * rb + shift
        for b, c in zip(fixed, cols[:-1]):
            offsets[id(b)] = base + c
        flat = block.reshape(-1)
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
        for b in var:
            offsets[id(b)] = np.array(var_off[id(b)], dtype=np.int64)
            # var batch times must follow the record order for the message index
            b.log_times = np.sort(b.log_times, kind="stable")
        return b"".join(p.tobytes() if isinstance(p, np.ndarray) else p for p in parts), offsets
    # general path: stable sort of every message by log time
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
    out = np.empty(int(sizes.sum()), dtype=np.uint8)
    k = 0
    for b in batches:
        n = len(b.log_times)
        pos = start[k : k + n]
        k += n
        if b.rows is not None:
            w = b.rows.shape[1]
            out[pos[:, None] + np.arange(w)] = b.rows
            offsets[id(b)] = pos
        else:
            for p, r in zip(pos, b.records):
                out[p : p + len(r)] = np.frombuffer(r, dtype=np.uint8)
            offsets[id(b)] = pos
    # message index entries must be in log-time order per channel
    for b in batches:
        o = np.argsort(b.log_times, kind="stable")
        if not np.all(o == np.arange(len(o))):
            b.log_times = b.log_times[o]
            offsets[id(b)] = offsets[id(b)][o]
    return out, offsets
