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
    st, c = v["stamp_ns"].tolist(), v["counts"].tolist()
    cols = [v[k].tolist() for k in ("p_c1", "p_c2", "p_m1", "x", "theta", "omega")]
    ul, ur = v["u_linear"].tolist(), v["u_rotary"].tolist()
    sl, sr = v["state_linear"].tolist(), v["state_rotary"].tolist()
    metadata = {"pneu.run": {"seed": str(seed), "config_yaml": "synthetic: true\n"}}
    with BagWriter(path, metadata=metadata, **writer_kw) as w:
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
    return v


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


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pneu_msgs_py.bench.bag")
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--dir", default=None, help="where to write the bag (default: temp dir)")
    ap.add_argument("--keep", action="store_true")
    ap.add_argument("--baseline-messages", type=int, default=300_000)
    a = ap.parse_args(argv)
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
