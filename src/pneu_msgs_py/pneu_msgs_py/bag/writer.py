"""MCAP writer for pneu runs (ROS 2 profile, CDR), without rclpy: the per-topic API.

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
from collections.abc import Mapping, Sequence
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
from pneu_msgs_py.bag.chunks import Batch, merge_same_channel, records
from pneu_msgs_py.bag.container import COMPRESSIONS, McapContainer
from pneu_msgs_py.bag.errors import BagWriteError
from pneu_msgs_py.bag.rosbag2_meta import rosbag2_metadata
from pneu_msgs_py.contract.convert import DiagStatus, diagnostics_to_typestore, jazzy_typestore
from pneu_msgs_py.contract.qos import MODES
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
    valve_joint,
)

__all__ = ["BagWriter", "DiagStatus", "COMPRESSIONS"]

LIBRARY = f"pneu_msgs_py {__version__}"
_HDR = R.MESSAGE_HEADER_SIZE


class BagWriter:
    """Write one pneu run to an MCAP file (ROS 2 profile).

    Parameters
    ----------
    path : output ``.mcap`` file (parent directory must exist), written as
        ``path.partial`` and renamed to ``path`` when closed (replacing it)
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
        self._mcap = McapContainer(self.path, LIBRARY, compression, qos)
        self._closed = False

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
    def _check_open(self) -> None:
        if self._closed:
            raise BagWriteError(self.path, "writer is closed")

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
        ts = jazzy_typestore()
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
        self._mcap.channel(topic, ros_type)  # type check now, not at flush
        self._var.append((topic, ros_type, int(log_time_ns), int(publish_time_ns), bytes(data)))
        self._add_pending(_HDR + len(data))

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """An MCAP metadata record (all keys and values str), written immediately."""
        self._check_open()
        self._mcap.add_metadata(name, data)

    # -- chunk building --------------------------------------------------------
    def _collect(self) -> list[Batch]:
        batches: list[Batch] = []
        if self._samples:
            buf = self._samples
            self._samples = []
            a = np.array(buf, dtype=np.float64)  # column 0 (stamp) is re-read exactly below
            t = np.fromiter((r[0] for r in buf), np.int64, len(buf))
            for j, (topic, L) in enumerate(self._fp_layouts.items()):
                ch = self._mcap.channel(topic, L.ros_type)
                vals = np.empty((len(t), 2))
                vals[:, 0] = a[:, 1 + j]
                vals[:, 1] = self.pressure_variance
                batches.append(Batch(ch, t, records(ch, L, t, t, L.encode_many(t, vals))))
            ch = self._mcap.channel(JOINT_STATE_TOPIC["linear"], self._js_linear.ros_type)
            pay = self._js_linear.encode_many(t, a[:, 4:5])
            batches.append(Batch(ch, t, records(ch, self._js_linear, t, t, pay)))
            ch = self._mcap.channel(JOINT_STATE_TOPIC["rotary"], self._js_rotary.ros_type)
            vals = np.empty((len(t), 4))
            vals[:, 0] = a[:, 5]  # theta
            vals[:, 1] = a[:, 7]  # counts
            vals[:, 2] = a[:, 6]  # omega
            vals[:, 3] = np.nan
            pay = self._js_rotary.encode_many(t, vals)
            batches.append(Batch(ch, t, records(ch, self._js_rotary, t, t, pay)))
        for axis in AXES:
            buf = self._commands[axis]
            if buf:
                self._commands[axis] = []
                L = self._cmd_layouts[axis]
                st = np.fromiter((r[0] for r in buf), np.int64, len(buf))
                u = np.fromiter((r[1] for r in buf), np.float64, len(buf))
                lt = np.fromiter((r[2] for r in buf), np.int64, len(buf))
                ch = self._mcap.channel(VALVE_COMMAND_TOPIC[axis], L.ros_type)
                pay = L.encode_many(st, u[:, None])
                batches.append(Batch(ch, lt, records(ch, L, lt, lt, pay)))
        for axis in AXES:
            buf = self._states[axis]
            if buf[0]:
                self._states[axis] = ([], [], [])
                batches.extend(self._state_batches(axis, *buf))
        if self._clock:
            t = np.array(self._clock, dtype=np.int64)
            self._clock = []
            ch = self._mcap.channel(CLOCK_TOPIC, self._clock_layout.ros_type)
            pay = self._clock_layout.encode_many(t)
            batches.append(Batch(ch, t, records(ch, self._clock_layout, t, t, pay)))
        if self._var:
            by_topic: dict[str, list] = {}
            for item in self._var:
                by_topic.setdefault(item[0], []).append(item)
            self._var = []
            pack, op = R.MESSAGE_HEADER.pack, R.Op.MESSAGE
            for topic, items in by_topic.items():
                ch = self._mcap.channel(topic, items[0][1])
                cid, seq = ch.id, ch.seq
                recs = [
                    pack(op, 22 + len(data), cid, (seq + i) & 0xFFFFFFFF, lt, pt) + data
                    for i, (_, _, lt, pt, data) in enumerate(items)
                ]
                ch.seq += len(items)
                ch.count += len(items)
                lts = np.array([it[2] for it in items], dtype=np.int64)
                batches.append(Batch(ch, lts, records=recs))
        return batches

    def _state_batches(
        self, axis: str, stamps: list[int], algos: list[str], flat: list[float]
    ) -> list[Batch]:
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
            ch = self._mcap.channel(topic, L.ros_type)
            if len(idx) == n:
                s, v = st, vals
            else:
                ii = np.asarray(idx)
                s, v = st[ii], vals[ii]
            out.append(Batch(ch, s, records(ch, L, s, s, L.encode_many(s, v))))
        if len(out) > 1:  # one channel, several layouts: merge so the channel's times stay sorted
            out = [merge_same_channel(out)]
        return out

    def flush(self) -> None:
        """Write the buffered messages as one chunk (no-op if nothing is buffered)."""
        self._check_open()
        self._pending = 0
        batches = self._collect()
        if batches:
            self._mcap.write_chunk(batches)

    def discard(self) -> None:
        """Close without finishing and remove the partial file (nothing worth keeping)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._mcap.close()
        except OSError:  # a full disk fails the last flush: the partial goes all the same
            pass
        finally:
            self._mcap.partial_path.unlink(missing_ok=True)

    def close(self) -> None:
        """Write the last chunk and the summary, rename ``.partial`` to the bag; idempotent."""
        if self._closed:
            return
        try:
            self.flush()
            m = self._mcap
            channels = list(m.channels.values())
            m.finish(rosbag2_metadata(channels, self.path.name, m.t_start, m.t_end, LIBRARY))
        finally:
            self._closed = True
            self._mcap.close()
