"""Benchmarks of the bag writer and reader (not tests: run them by hand).

``python -m pneu_msgs_py.bench.bag [--minutes 10] [--dir /tmp]`` writes a
synthetic both-axes 1 kHz run with every topic and prints

- ``write_us_per_cycle``: µs to log one 1 kHz cycle (5 sensor messages,
  2 commands, 2 controller states) through :class:`BagWriter`, close included;
- ``analyze_msgs_per_s``: messages decoded (``read_run``, all topics) and
  analysed (per-topic statistics, the controller errors' RMSE) per second;
- ``baseline_msgs_per_s``: the same with rosbags' ``AnyReader`` +
  ``deserialize`` per message (on the first ``max_messages`` messages);
- the peak RSS of a child process that reads the file.

``python -m pneu_msgs_py.bench.bag --writers [--seconds 20]`` compares, on a
typical run (both axes, 1 kHz, every topic, 1 MiB zstd chunks), pneu's own
MCAP container against the ``mcap`` library: :func:`writer_comparison`
(BagWriter, the same bulk CDR through ``mcap.Writer``, and ``mcap_ros2``'s
Writer encoding each message) and :func:`reader_comparison` (``read_run``,
``mcap``'s reader with and without ``mcap_ros2`` decoding, rosbags).
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pneu_msgs_py.bag.writer import BagWriter
from pneu_msgs_py.contract.convert import DiagStatus
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.topics import DEFAULT_STATE_FIELDS

__all__ = [
    "synthetic_cycles",
    "write_synthetic_run",
    "write_us_per_cycle",
    "analyze",
    "analyze_msgs_per_s",
    "baseline_msgs_per_s",
    "peak_rss_mib",
    "analysis_figures",
    "writer_comparison",
    "reader_comparison",
    "serialized_comparison",
]

PERIOD_NS = 1_000_000


def synthetic_cycles(n: int, seed: int = 0, t0_ns: int = 0) -> dict[str, np.ndarray]:
    """Plausible per-cycle values (SI) for ``n`` 1 kHz cycles, seeded."""
    rng = np.random.Generator(np.random.PCG64(seed))
    t = np.arange(n, dtype=np.float64) * 1e-3
    counts = np.cumsum(rng.integers(0, 8, n)).astype(np.int64)
    k_f = len(DEFAULT_STATE_FIELDS)
    out = {
        "stamp_ns": t0_ns + np.arange(n, dtype=np.int64) * PERIOD_NS,
        "p_c1": 3e5 + 1e5 * np.sin(t) + rng.normal(0, 200, n),
        "p_c2": 3e5 - 1e5 * np.sin(t) + rng.normal(0, 200, n),
        "p_m1": 4e5 + rng.normal(0, 200, n),
        "x": 0.02 * np.sin(2 * math.pi * 0.25 * t) + rng.normal(0, 1e-5, n),
        "theta": counts * (2 * math.pi / 4000),
        "omega": np.r_[0, np.diff(counts)] * (2 * math.pi / 4000) / 1e-3,
        "counts": counts,
        "u_linear": 5 + rng.normal(0, 1, n),
        "u_rotary": 5 + rng.normal(0, 1, n),
        "state_linear": rng.normal(size=(n, k_f)),
        "state_rotary": rng.normal(size=(n, k_f)),
    }
    out["state_linear"][:, 5:8] = np.nan  # e.g. PID has no observer states
    return out


def write_synthetic_run(
    path: str | os.PathLike,
    n_cycles: int,
    *,
    seed: int = 0,
    t0_ns: int = 0,
    diag_every: int = 1000,
    clock: bool = False,
    switch_at: int | None = None,
    command_delay_ns: int = 0,
    **writer_kw,
) -> dict[str, np.ndarray]:
    """Write ``n_cycles`` of a both-axes run through :class:`BagWriter`; return the values.

    ``switch_at``: cycle from which the linear controller reports ``ladrc``
    instead of ``eso_smc`` (a live algorithm switch).
    """
    v = synthetic_cycles(n_cycles, seed, t0_ns)
    metadata = {"pneu.run": {"seed": str(seed), "config_yaml": "synthetic: true\n"}}
    with BagWriter(path, metadata=metadata, **writer_kw) as w:
        _write_cycles(w, v, diag_every, clock, switch_at, command_delay_ns)
    return v


def _write_cycles(
    w, v: dict[str, np.ndarray], diag_every=1000, clock=False, switch_at=None, command_delay_ns=0
) -> None:
    """The cycles of :func:`synthetic_cycles` ``v`` through the writer ``w`` (BagWriter API)."""
    n_cycles = len(v["stamp_ns"])
    st, c = v["stamp_ns"].tolist(), v["counts"].tolist()
    cols = [v[k].tolist() for k in ("p_c1", "p_c2", "p_m1", "x", "theta", "omega")]
    ul, ur = v["u_linear"].tolist(), v["u_rotary"].tolist()
    sl, sr = v["state_linear"].tolist(), v["state_rotary"].tolist()
    for k in range(n_cycles):
        t = st[k]
        if clock:
            w.write_clock(t)
        w.write_sample(
            SensorSample(
                k,
                t,
                cols[0][k],
                cols[1][k],
                cols[2][k],
                cols[3][k],
                cols[4][k],
                cols[5][k],
                c[k],
            )
        )
        w.write_command("linear", t, ul[k], t + command_delay_ns)
        w.write_command("rotary", t, ur[k], t + command_delay_ns)
        algo = "eso_smc" if switch_at is None or k < switch_at else "ladrc"
        w.write_controller_state("linear", t, sl[k], algo)
        w.write_controller_state("rotary", t, sr[k], "pid")
        if diag_every and k % diag_every == 0:
            w.write_diagnostics(
                t, [DiagStatus(0, "pneu/runner", "ok", "twin", {"late_cycles": str(k // 7)})]
            )


def write_us_per_cycle(n_cycles: int = 100_000, directory: str | None = None) -> float:
    """µs per 1 kHz cycle (9 messages) written through BagWriter, close() included."""
    v = synthetic_cycles(n_cycles, 1)
    samples = [
        SensorSample(
            k,
            int(v["stamp_ns"][k]),
            *(float(v[f][k]) for f in ("p_c1", "p_c2", "p_m1", "x", "theta", "omega")),
            int(v["counts"][k]),
        )
        for k in range(n_cycles)
    ]
    ul, ur = v["u_linear"].tolist(), v["u_rotary"].tolist()
    sl, sr = v["state_linear"].tolist(), v["state_rotary"].tolist()
    with tempfile.TemporaryDirectory(dir=directory) as d:
        t0 = time.perf_counter()
        with BagWriter(Path(d) / "bench.mcap") as w:
            for k, s in enumerate(samples):
                t = s.stamp_ns
                w.write_sample(s)
                w.write_command("linear", t, ul[k])
                w.write_command("rotary", t, ur[k])
                w.write_controller_state("linear", t, sl[k], "eso_smc")
                w.write_controller_state("rotary", t, sr[k], "pid")
        return (time.perf_counter() - t0) / n_cycles * 1e6


def analyze(path: str | os.PathLike, batch_chunks: int = 64) -> tuple[int, dict[str, float]]:
    """Decode every topic (streamed, bounded memory) and compute per-topic figures.

    Figures: mean of every field, RMSE and max |e| of controller-state
    ``error``, largest gap between header stamps. Returns (messages, figures).
    """
    from pneu_msgs_py.bag.reader import iter_run

    sums: dict[str, float] = {}
    counts: dict[str, int] = {}
    sq: dict[str, float] = {}
    emax: dict[str, float] = {}
    gap: dict[str, int] = {}
    last: dict[str, int] = {}
    n = 0
    for batch in iter_run(path, batch_chunks=batch_chunks):
        n += batch.message_count
        for name, ta in batch.topics.items():
            if not len(ta):
                continue
            for key, arr in ta.fields.items():
                if "." in key:
                    continue  # aliases hold the same arrays
                k = f"{name}:{key}"
                sums[k] = sums.get(k, 0.0) + float(np.sum(arr))
                counts[k] = counts.get(k, 0) + len(arr)
            if "error" in ta:
                e = ta["error"]
                sq[name] = sq.get(name, 0.0) + float(np.dot(e, e))
                emax[name] = max(emax.get(name, 0.0), float(np.max(np.abs(e))))
            st = ta.stamp_ns
            g = int(np.max(np.diff(st))) if len(st) > 1 else 0
            if name in last:
                g = max(g, int(st[0]) - last[name])
            last[name] = int(st[-1])
            gap[name] = max(gap.get(name, 0), g)
    figs = {f"{k}:mean": sums[k] / counts[k] for k in sums}
    for name in sq:
        figs[f"{name}:rmse"] = math.sqrt(sq[name] / counts[f"{name}:error"])
        figs[f"{name}:e_max"] = emax[name]
    figs.update({f"{name}:max_gap_ns": float(g) for name, g in gap.items()})
    return n, figs


def analyze_msgs_per_s(path: str | os.PathLike) -> float:
    """Messages decoded and analysed per second by pneu's reader (all topics)."""
    t0 = time.perf_counter()
    n, _ = analyze(path)
    return n / (time.perf_counter() - t0)


def baseline_msgs_per_s(path: str | os.PathLike, max_messages: int = 300_000) -> float:
    """The same with rosbags' AnyReader + deserialize, one message at a time."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    n = 0
    acc: dict[str, list[float]] = {}
    t0 = time.perf_counter()
    with AnyReader([Path(path)], default_typestore=ts) as r:
        for conn, _t, raw in r.messages():
            msg = r.deserialize(raw, conn.msgtype)
            lst = acc.setdefault(conn.topic, [])
            if conn.msgtype == "sensor_msgs/msg/FluidPressure":
                lst.append(msg.fluid_pressure)
            elif conn.msgtype == "sensor_msgs/msg/JointState":
                arr = msg.position if len(msg.position) else msg.effort
                lst.append(float(arr[0]))
            n += 1
            if n >= max_messages:
                break
    for lst in acc.values():
        if lst:
            np.mean(lst)
    return n / (time.perf_counter() - t0)


def peak_rss_mib(path: str | os.PathLike, what: str = "analyze") -> float:
    """Peak RSS (MiB) of a fresh Python process running ``analyze`` or ``read_run`` on ``path``."""
    call = {
        "analyze": f"from pneu_msgs_py.bench.bag import analyze; analyze({str(path)!r})",
        "read_run": f"from pneu_msgs_py.bag.reader import read_run; read_run({str(path)!r})",
    }[what]
    # VmHWM (peak RSS of this process image); ru_maxrss would carry the parent's over exec
    code = (
        f"{call}\n"
        "import re, resource\n"
        "try:\n"
        "    txt = open('/proc/self/status').read()\n"
        "    print(int(re.search(r'VmHWM:\\s+(\\d+)', txt).group(1)))\n"
        "except OSError:\n"
        "    print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return int(out.stdout.strip().splitlines()[-1]) / 1024


def analysis_figures(
    minutes: float = 10.0, baseline_messages: int = 300_000, directory: str | None = None
) -> dict[str, float]:
    """All bag figures on a synthetic ``minutes``-long both-axes 1 kHz run (for ``pneu bench``).

    Keys: ``write_us_per_cycle``, ``analyze_msgs_per_s``, ``baseline_msgs_per_s``
    (rosbags, first ``baseline_messages`` messages), ``analyze_vs_baseline``,
    ``analyze_peak_rss_mib`` (streamed analysis, child process),
    ``read_run_peak_rss_mib`` (all topics at once), ``bag_mib``, ``bag_messages``.
    """
    out: dict[str, float] = {"write_us_per_cycle": write_us_per_cycle(directory=directory)}
    with tempfile.TemporaryDirectory(dir=directory) as d:
        path = Path(d) / "bench.mcap"
        write_synthetic_run(path, int(minutes * 60_000))
        out["bag_minutes"] = minutes
        out["bag_mib"] = path.stat().st_size / 2**20
        t0 = time.perf_counter()
        n, _ = analyze(path)
        out["analyze_msgs_per_s"] = n / (time.perf_counter() - t0)
        out["bag_messages"] = n
        out["baseline_msgs_per_s"] = baseline_msgs_per_s(path, baseline_messages)
        out["analyze_vs_baseline"] = out["analyze_msgs_per_s"] / out["baseline_msgs_per_s"]
        out["analyze_peak_rss_mib"] = peak_rss_mib(path, "analyze")
        out["read_run_peak_rss_mib"] = peak_rss_mib(path, "read_run")
    return out


# -- own MCAP container against the mcap library -------------------------------------


class _LibraryContainer:
    """:class:`~pneu_msgs_py.bag.container.McapContainer`'s interface on ``mcap.Writer``.

    The benchmark's alternative: :class:`BagWriter` keeps its buffers, bulk CDR
    and chunk cuts; each chunk's messages go through ``mcap.Writer.add_message``
    (the only way into the library's chunks) and ``flush()`` ends the chunk. The
    library writes header, schemas, channels, chunks, message and chunk indexes,
    statistics, metadata indexes, summary offsets and footer.
    """

    def __init__(self, path: Path, library: str, compression: str, qos_mode: str) -> None:
        from mcap.writer import CompressionType, Writer

        from pneu_msgs_py.bag.schemas import PROFILE

        self.path = path
        self.qos_mode = qos_mode
        self.partial_path = path.with_name(path.name + ".partial")
        self._f = open(self.partial_path, "xb")
        comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4}
        # chunks are cut by BagWriter (flush), never inside a cycle by the library
        self._w = Writer(
            self._f, chunk_size=1 << 62, compression=comp.get(compression, CompressionType.NONE)
        )
        self._w.start(PROFILE, library)
        self.channels: dict = {}
        self._schema_ids: dict[str, int] = {}
        self.t_start: int | None = None
        self.t_end: int | None = None

    def channel(self, topic: str, ros_type: str, **_kw):
        from pneu_msgs_py.bag.chunks import Channel
        from pneu_msgs_py.bag.schemas import (
            MESSAGE_ENCODING,
            MSG_DEFINITIONS,
            SCHEMA_ENCODING,
            TYPE_HASHES,
        )
        from pneu_msgs_py.contract.qos import offered_qos_yaml
        from pneu_msgs_py.contract.topics import qos_for

        ch = self.channels.get(topic)
        if ch is not None:
            return ch
        sid = self._schema_ids.get(ros_type)
        if sid is None:
            text = MSG_DEFINITIONS.get(ros_type, "").encode()
            sid = self._schema_ids[ros_type] = self._w.register_schema(
                ros_type, SCHEMA_ENCODING, text
            )
        qos = qos_for(topic, self.qos_mode)
        meta = {
            "offered_qos_profiles": offered_qos_yaml([qos]),
            "topic_type_hash": TYPE_HASHES.get(ros_type, ""),
        }
        cid = self._w.register_channel(topic, MESSAGE_ENCODING, sid, meta)
        ch = self.channels[topic] = Channel(cid, topic, ros_type, sid, qos)
        return ch

    def add_metadata(self, name: str, data) -> None:
        self._w.add_metadata(name, dict(data))

    def write_chunk(self, batches) -> None:
        from pneu_msgs_py.bag.chunks import interleave
        from pneu_msgs_py.bag.mcap_records import MESSAGE_HEADER_SIZE, MESSAGE_RECORD_DTYPE

        data, offsets = interleave(batches)
        buf = data.tobytes() if isinstance(data, np.ndarray) else data
        offs = np.sort(np.concatenate([offsets[id(b)] for b in batches]))
        raw = np.frombuffer(buf, dtype=np.uint8)
        hv = raw[offs[:, None] + np.arange(MESSAGE_HEADER_SIZE)].view(MESSAGE_RECORD_DTYPE)[:, 0]
        ends = (offs + 9 + hv["length"].astype(np.int64)).tolist()
        add = self._w.add_message
        for o, e, cid, seq, lt, pt in zip(
            (offs + MESSAGE_HEADER_SIZE).tolist(),
            ends,
            hv["channel_id"].tolist(),
            hv["sequence"].tolist(),
            hv["log_time"].tolist(),
            hv["publish_time"].tolist(),
        ):
            add(cid, lt, buf[o:e], pt, seq)
        self._w.flush()
        t0, t1 = int(hv["log_time"].min()), int(hv["log_time"].max())
        self.t_start = t0 if self.t_start is None else min(self.t_start, t0)
        self.t_end = t1 if self.t_end is None else max(self.t_end, t1)

    def finish(self, rosbag2_yaml: str) -> None:
        self._w.add_metadata("rosbag2", {"serialized_metadata": rosbag2_yaml})
        self._w.finish()
        self._finished = True

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()
            if getattr(self, "_finished", False):
                os.replace(self.partial_path, self.path)


def _library_bag_writer(path: Path, **kw) -> BagWriter:
    """A BagWriter whose container is ``mcap.Writer`` (:class:`_LibraryContainer`)."""
    from pneu_msgs_py.bag.writer import LIBRARY

    w = BagWriter(path, **kw)
    w._mcap.close()
    w._mcap.partial_path.unlink()
    w._mcap = _LibraryContainer(w.path, LIBRARY, w.compression, w.qos_mode)
    return w


def _level3_bag_writer(path: Path, **kw) -> BagWriter:
    """BagWriter with zstd level 3 (``mcap.Writer``'s ``zstandard.compress`` default), not 1."""
    import zstandard

    w = BagWriter(path, **kw)
    w._mcap._compress = zstandard.ZstdCompressor(level=3).compress
    return w


def _mcap_ros2_write(path: Path, v: dict[str, np.ndarray], chunk_size: int) -> None:
    """The same run through ``mcap_ros2.writer.Writer``: one dict encoded per message."""
    from mcap_ros2.writer import Writer

    from pneu_msgs_py.bag.schemas import MSG_DEFINITIONS
    from pneu_msgs_py.contract.topics import (
        CONTROLLER_STATE_TOPIC,
        DIAGNOSTICS_TOPIC,
        JOINT_STATE_TOPIC,
        PRESSURE_TOPICS,
        ROTARY_COUNTS_JOINT,
        VALVE_COMMAND_TOPIC,
        valve_joint,
    )

    n = len(v["stamp_ns"])
    st = v["stamp_ns"].tolist()
    cols = {k: v[k].tolist() for k in ("p_c1", "p_c2", "p_m1", "x", "theta", "omega")}
    counts = v["counts"].astype(float).tolist()
    u = {"linear": v["u_linear"].tolist(), "rotary": v["u_rotary"].tolist()}
    state = {"linear": v["state_linear"].tolist(), "rotary": v["state_rotary"].tolist()}
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=chunk_size)
        fp = w.register_msgdef(
            "sensor_msgs/msg/FluidPressure", MSG_DEFINITIONS["sensor_msgs/msg/FluidPressure"]
        )
        js = w.register_msgdef(
            "sensor_msgs/msg/JointState", MSG_DEFINITIONS["sensor_msgs/msg/JointState"]
        )
        da = w.register_msgdef(
            "diagnostic_msgs/msg/DiagnosticArray",
            MSG_DEFINITIONS["diagnostic_msgs/msg/DiagnosticArray"],
        )
        w.add_metadata("pneu.run", {"seed": "0", "config_yaml": "synthetic: true\n"})
        fields = list(DEFAULT_STATE_FIELDS)
        for k in range(n):
            t = st[k]
            stamp = {"sec": t // 1_000_000_000, "nanosec": t % 1_000_000_000}
            for topic, (col, frame) in PRESSURE_TOPICS.items():
                msg = {
                    "header": {"stamp": stamp, "frame_id": frame},
                    "fluid_pressure": cols[col][k],
                    "variance": 0.0,
                }
                w.write_message(topic, fp, msg, t, t)
            hdr = {"stamp": stamp, "frame_id": ""}
            lin = {"header": hdr, "name": ["linear"], "position": [cols["x"][k]]}
            lin.update(velocity=[], effort=[])
            w.write_message(JOINT_STATE_TOPIC["linear"], js, lin, t, t)
            rot = {
                "header": hdr,
                "name": ["rotary", ROTARY_COUNTS_JOINT],
                "position": [cols["theta"][k], counts[k]],
                "velocity": [cols["omega"][k], 0.0],
                "effort": [],
            }
            w.write_message(JOINT_STATE_TOPIC["rotary"], js, rot, t, t)
            for axis in ("linear", "rotary"):
                cmd = {"header": hdr, "name": [valve_joint(axis)], "position": []}
                cmd.update(velocity=[], effort=[u[axis][k]])
                w.write_message(VALVE_COMMAND_TOPIC[axis], js, cmd, t, t)
                algo = {"linear": "eso_smc", "rotary": "pid"}[axis]
                cs = {
                    "header": {"stamp": stamp, "frame_id": algo},
                    "name": fields,
                    "position": state[axis][k],
                    "velocity": [],
                    "effort": [],
                }
                w.write_message(CONTROLLER_STATE_TOPIC[axis], js, cs, t, t)
            if k % 1000 == 0:
                status = {
                    "level": 0,
                    "name": "pneu/runner",
                    "message": "ok",
                    "hardware_id": "twin",
                    "values": [{"key": "late_cycles", "value": str(k // 7)}],
                }
                w.write_message(DIAGNOSTICS_TOPIC, da, {"header": hdr, "status": [status]}, t, t)
        w.finish()


def _bag_numbers(path: Path) -> tuple[int, int]:
    """(messages, CDR payload bytes) of a bag, by the mcap library."""
    from mcap.reader import make_reader

    n = size = 0
    with open(path, "rb") as f:
        for _s, _c, m in make_reader(f).iter_messages(log_time_order=False):
            n += 1
            size += len(m.data)
    return n, size


def writer_comparison(
    seconds: float = 20.0,
    repeats: int = 3,
    chunk_size: int = 1 << 20,
    directory: str | None = None,
    mcap_ros2_seconds: float = 5.0,
) -> dict[str, dict[str, float]]:
    """Write a typical run (both axes, 1 kHz, ``seconds``, the 10 topics of a run) per writer.

    Writers: ``pneu`` (BagWriter: bulk CDR, own container, zstd level 1),
    ``pneu_zstd3`` (the same at zstd level 3, ``mcap.Writer``'s fixed level),
    ``mcap.Writer`` (BagWriter's bulk CDR and chunk cuts, the library's container,
    :class:`_LibraryContainer`), ``mcap_ros2`` (``mcap_ros2.writer.Writer``, one
    dict encoded per message; on ``mcap_ros2_seconds`` only, it is slow). All with
    ``chunk_size``-byte zstd chunks. Per writer, the best of ``repeats``:
    ``s`` (wall, close included), ``us_per_cycle``, ``msgs_per_s``, ``payload_mb_per_s``
    (CDR bytes, 1e6), ``file_mib``, and ``messages``.
    """
    n = int(seconds * 1000)
    v = synthetic_cycles(n, 0)
    meta = {"pneu.run": {"seed": "0", "config_yaml": "synthetic: true\n"}}
    out: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory(dir=directory) as d:
        makers = {
            "pneu": BagWriter,
            "pneu_zstd3": _level3_bag_writer,
            "mcap.Writer": _library_bag_writer,
        }
        for name, make in makers.items():
            path = Path(d) / f"{name}.mcap"
            best = math.inf
            for _ in range(repeats):
                path.unlink(missing_ok=True)
                t0 = time.perf_counter()
                with make(path, chunk_size=chunk_size) as w:
                    for rec, data in meta.items():
                        w.add_metadata(rec, data)
                    _write_cycles(w, v)
                best = min(best, time.perf_counter() - t0)
            out[name] = _figures(path, best, n)
        n2 = int(mcap_ros2_seconds * 1000)
        v2 = {k: a[:n2] for k, a in v.items()}
        path = Path(d) / "mcap_ros2.mcap"
        t0 = time.perf_counter()
        _mcap_ros2_write(path, v2, chunk_size)
        out["mcap_ros2"] = _figures(path, time.perf_counter() - t0, n2)
    return out


def serialized_comparison(
    seconds: float = 20.0, repeats: int = 3, chunk_size: int = 1 << 20, directory: str | None = None
) -> dict[str, dict[str, float]]:
    """The ROS logger's path: already-CDR messages one at a time, per writer (best of ``repeats``).

    The messages of a typical ``seconds``-long run (BagWriter bag, read back by
    ``mcap``) in log-time order, written by ``pneu`` (``BagWriter.write_serialized``)
    and by ``mcap.Writer`` (``register_schema``/``register_channel`` on first use,
    ``add_message``), ``chunk_size``-byte zstd chunks. Same figures as
    :func:`writer_comparison`.
    """
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    from pneu_msgs_py.bag.schemas import MESSAGE_ENCODING, MSG_DEFINITIONS, PROFILE
    from pneu_msgs_py.bag.schemas import SCHEMA_ENCODING as ENC

    n = int(seconds * 1000)
    out: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory(dir=directory) as d:
        src = Path(d) / "src.mcap"
        write_synthetic_run(src, n)
        with open(src, "rb") as f:
            msgs = [
                (c.topic, s.name, m.data, m.log_time, m.publish_time)
                for s, c, m in make_reader(f).iter_messages()
            ]

        def pneu(path: Path) -> None:
            with BagWriter(path, chunk_size=chunk_size) as w:
                for topic, ros_type, data, lt, pt in msgs:
                    w.write_serialized(topic, ros_type, data, lt, pt)

        def library(path: Path) -> None:
            with open(path, "wb") as f:
                w = Writer(f, chunk_size=chunk_size, compression=CompressionType.ZSTD)
                w.start(PROFILE, "bench")
                schemas: dict[str, int] = {}
                channels: dict[str, int] = {}
                seq: dict[int, int] = {}
                for topic, ros_type, data, lt, pt in msgs:
                    cid = channels.get(topic)
                    if cid is None:
                        sid = schemas.get(ros_type)
                        if sid is None:
                            text = MSG_DEFINITIONS[ros_type].encode()
                            sid = schemas[ros_type] = w.register_schema(ros_type, ENC, text)
                        cid = channels[topic] = w.register_channel(topic, MESSAGE_ENCODING, sid)
                    k = seq[cid] = seq.get(cid, -1) + 1
                    w.add_message(cid, lt, data, pt, k)
                w.finish()

        for name, write in {"pneu write_serialized": pneu, "mcap.Writer": library}.items():
            path = Path(d) / "out.mcap"
            best = math.inf
            for _ in range(repeats):
                path.unlink(missing_ok=True)
                t0 = time.perf_counter()
                write(path)
                best = min(best, time.perf_counter() - t0)
            out[name] = _figures(path, best, n)
    return out


def _figures(path: Path, wall: float, n_cycles: int) -> dict[str, float]:
    msgs, payload = _bag_numbers(path)
    return {
        "s": wall,
        "us_per_cycle": wall / n_cycles * 1e6,
        "msgs_per_s": msgs / wall,
        "payload_mb_per_s": payload / wall / 1e6,
        "file_mib": path.stat().st_size / 2**20,
        "messages": msgs,
    }


def reader_comparison(
    seconds: float = 20.0, repeats: int = 3, directory: str | None = None
) -> dict[str, dict[str, float]]:
    """Read a BagWriter bag of a typical ``seconds``-long run, per reader (best of ``repeats``).

    ``read_run`` (pneu: every topic into numpy arrays), ``mcap`` (``make_reader``
    ``iter_messages``: the records only, nothing decoded), ``mcap_ros2`` (the same
    with ``iter_decoded_messages``), ``rosbags`` (``AnyReader`` + ``deserialize``).
    Per reader ``s`` and ``msgs_per_s``.
    """
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from pneu_msgs_py.bag.reader import read_run

    def pneu(p: Path) -> int:
        return read_run(p).message_count

    def mcap_raw(p: Path) -> int:
        with open(p, "rb") as f:
            return sum(1 for _ in make_reader(f).iter_messages(log_time_order=False))

    def mcap_ros2(p: Path) -> int:
        with open(p, "rb") as f:
            r = make_reader(f, decoder_factories=[DecoderFactory()])
            return sum(1 for _ in r.iter_decoded_messages(log_time_order=False))

    def rosbags(p: Path) -> int:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        ts = get_typestore(Stores.ROS2_JAZZY)
        with AnyReader([p], default_typestore=ts) as r:
            return sum(1 for c, _t, raw in r.messages() if r.deserialize(raw, c.msgtype))

    out: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory(dir=directory) as d:
        path = Path(d) / "run.mcap"
        write_synthetic_run(path, int(seconds * 1000))
        for name, read in {
            "read_run": pneu,
            "mcap": mcap_raw,
            "mcap_ros2": mcap_ros2,
            "rosbags": rosbags,
        }.items():
            best, n = math.inf, 0
            for _ in range(repeats if name in ("read_run", "mcap") else 1):
                t0 = time.perf_counter()
                n = read(path)
                best = min(best, time.perf_counter() - t0)
            out[name] = {"s": best, "msgs_per_s": n / best, "messages": n}
    return out


def _print_table(title: str, rows: dict[str, dict[str, float]], keys: list[str]) -> None:
    print(title)
    print("| " + " | ".join(["", *keys]) + " |")
    print("|" + "---|" * (len(keys) + 1))
    for name, r in rows.items():
        cells = [f"{r[k]:,.2f}" if r[k] < 100 else f"{r[k]:,.0f}" for k in keys]
        print("| " + " | ".join([name, *cells]) + " |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pneu_msgs_py.bench.bag")
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--dir", default=None, help="where to write the bag (default: temp dir)")
    ap.add_argument("--keep", action="store_true")
    ap.add_argument("--baseline-messages", type=int, default=300_000)
    ap.add_argument(
        "--writers", action="store_true", help="own container against the mcap library instead"
    )
    ap.add_argument("--seconds", type=float, default=20.0, help="run length for --writers")
    a = ap.parse_args(argv)
    if a.writers:
        import platform

        print(
            f"{platform.python_implementation()} {platform.python_version()}, "
            f"{os.cpu_count()} CPUs, {platform.machine()}; {a.seconds:g} s both-axes run"
        )
        _print_table(
            "write (best of 3; mcap_ros2 once, on 5 s)",
            writer_comparison(a.seconds, directory=a.dir),
            ["s", "us_per_cycle", "msgs_per_s", "payload_mb_per_s", "file_mib"],
        )
        _print_table(
            "write, already-CDR messages one at a time (the ROS logger's path; best of 3)",
            serialized_comparison(a.seconds, directory=a.dir),
            ["s", "us_per_cycle", "msgs_per_s", "payload_mb_per_s", "file_mib"],
        )
        _print_table(
            "read", reader_comparison(a.seconds, directory=a.dir), ["s", "msgs_per_s", "messages"]
        )
        return 0
    print(f"write_us_per_cycle: {write_us_per_cycle():.2f}")
    d = a.dir or tempfile.mkdtemp()
    path = Path(d) / f"bench_{a.minutes:g}min.mcap"
    n = int(a.minutes * 60_000)
    t0 = time.perf_counter()
    write_synthetic_run(path, n)
    print(
        f"wrote {path} ({path.stat().st_size / 2**20:.0f} MiB, {n} cycles) in {time.perf_counter() - t0:.1f} s"
    )
    a_rate = analyze_msgs_per_s(path)
    print(f"analyze_msgs_per_s: {a_rate:,.0f}")
    b_rate = baseline_msgs_per_s(path, a.baseline_messages)
    print(f"baseline_msgs_per_s: {b_rate:,.0f} (first {a.baseline_messages} messages)")
    print(f"ratio: {a_rate / b_rate:.1f}x")
    print(f"peak_rss_mib (analyze, streamed): {peak_rss_mib(path):.0f}")
    print(f"peak_rss_mib (read_run, all topics at once): {peak_rss_mib(path, 'read_run'):.0f}")
    if not a.keep:
        path.unlink()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
