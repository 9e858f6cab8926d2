"""``ros2 run pneu_control bench_ros``: the ROS graph in real time, measured from its bag.

Launches ``ros2 launch pneu_sim sim.launch.py mode:=realtime`` (both axes,
supervisor on, ``ros2 bag record`` on) for ``--duration`` seconds in the
chosen deployment and executor, samples each process's CPU time from
``/proc`` while it runs, then reads the bag and reports:

- ``ticks``: samples the sim's loop stepped; ``missed.<axis>``: ticks without
  a fresh command from that axis' controller when the sim applied the
  commands (a skipped tick -- the loop itself too late -- counts as missed);
- ``turnaround.<axis>`` p50 / p99 / max: from a sample being ready in the loop to the
  loop taking the command that answers it, measured by the loop itself (the sim's
  end-of-run counters, every tick): in the separate-process deployment the way there
  and back over DDS, hosted the controller's computation;
- ``bag_turnaround.<axis>``: from a sample's publication to the publication of the
  command answering it, from the bag's ``publish_time`` (the publishers' source
  timestamps; hosted both are published after the loop took the command: a monitoring
  figure there);
- ``dropped_batches``: hosted, ticks whose messages the publishing thread dropped rather
  than delay the loop (:mod:`pneu_msgs_py.nodes.handoff`);
- ``late_ticks.<axis>``, ``held_ticks.<axis>``, ``ramped_ticks.<axis>``: the supervisor's
  count of ticks with a late command and of those written held or ramped (its
  ``late_policy``, DESIGN §14);
- ``safety_trips.<axis>`` and ``first_trip_s.<axis>``: the supervisor's ERROR transitions
  (e.g. its command watchdog): a trip holds the valve at 5 V until acknowledged, so
  a run with one is not a run at 1 kHz whatever the missed count says;
- ``cpu.<process>``: CPU time / wall time while the run was in its steady part.

Needs ROS 2 and this workspace sourced. Prints a table, or JSON with ``--json``.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["main", "measure"]

_CLK = os.sysconf("SC_CLK_TCK")


def _proc_table() -> dict[int, tuple[int, str, int]]:
    """pid -> (ppid, name, utime + stime in clock ticks) of every process."""
    out = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
            cmd = (d / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        rest = stat[stat.rindex(")") + 2 :].split()
        ppid, ticks = int(rest[1]), int(rest[11]) + int(rest[12])
        words = [c.decode(errors="replace") for c in cmd if c]
        name = _name(words)
        out[int(d.name)] = (ppid, name, ticks)
    return out


def _name(words: list[str]) -> str:
    """A readable process name: the node executable, or ``recorder`` for ros2 bag record."""
    if "bag" in words and "record" in words:
        return "recorder"
    for w in words:
        base = os.path.basename(w)
        if base in (
            "sim_node", "linear_controller", "rotary_controller", "logger",
            "controller_manager", "driver_node",
        ):  # fmt: skip
            return base
    return os.path.basename(words[0]) if words else "?"


def _descendants(root: int, table: dict[int, tuple[int, str, int]]) -> list[int]:
    kids: dict[int, list[int]] = {}
    for pid, (ppid, _, _) in table.items():
        kids.setdefault(ppid, []).append(pid)
    out, todo = [], [root]
    while todo:
        p = todo.pop()
        for c in kids.get(p, []):
            out.append(c)
            todo.append(c)
    return out


def _cpu(root: int) -> dict[str, int]:
    table = _proc_table()
    acc: dict[str, int] = {}
    for pid in _descendants(root, table):
        _, name, ticks = table[pid]
        if name in ("ros2", "python3", "bash", "sh", "?"):
            continue
        acc[name] = acc.get(name, 0) + ticks
    return acc


def _turnaround_us(data, axis: str) -> np.ndarray:
    sample_topic = "/pneu/pressure/cylinder_1"  # the first of the five a sample is published on
    s = data[sample_topic]
    c = data[f"/pneu/{axis}/valve_command"]
    pub = dict(zip(s.stamp_ns.tolist(), s.publish_time_ns.tolist()))
    # the answer to a sample is the first command with its stamp (at shutdown a controller
    # sends 5 V stamped with the last sample again: not an answer)
    first: dict[int, int] = {}
    for st, cp in zip(c.stamp_ns.tolist(), c.publish_time_ns.tolist()):
        if st in pub and (st not in first or cp < first[st]):
            first[st] = cp
    ta = [cp - pub[st] for st, cp in first.items()]
    return np.asarray(ta, dtype=np.int64) * 1e-3


def _safety_trips(data, axis: str) -> tuple[int, float | None]:
    """(ERROR transitions of ``axis``'s supervisor rules, the first one's time in s from the
    first sample or None): a trip latches the valve at 5 V until acknowledged."""
    t0 = int(data["/pneu/linear/joint_state"].stamp_ns[0])
    name = f"pneu_sim: safety {axis} "  # "... <rule>"; the 1 Hz axis summary has no rule
    trips = []
    for stamp, statuses in zip(
        data["/diagnostics"].stamp_ns.tolist(), data["/diagnostics"].objects
    ):
        trips += [stamp for st in statuses if st.level >= 2 and st.name.startswith(name)]
    first = (min(trips) - t0) * 1e-9 if trips else None
    return len(trips), first


def _sim_counters(data) -> dict[str, str]:
    """The sim's last ``pneu_sim: lockstep`` diagnostics values (its loop counters)."""
    last: dict[str, str] = {}
    for statuses in data["/diagnostics"].objects:
        for st in statuses:
            if st.name == "pneu_sim: lockstep":
                last = st.values
    return last


_BUSY = "while True: pass"
# memory and I/O pressure: 256 MiB touched page by page, 32 MiB written and fsynced, again
_PRESSURE = """
import os, tempfile
fd, path = tempfile.mkstemp(prefix="pneu_bench_io_")
block = os.urandom(1 << 20)
try:
    while True:
        buf = bytearray(256 << 20)
        for i in range(0, len(buf), 4096):
            buf[i] = 1
        del buf
        os.lseek(fd, 0, 0)
        for _ in range(32):
            os.write(fd, block)
        os.fsync(fd)
finally:
    os.unlink(path)
"""


def _start_load(n: int, io: int = 0) -> list[subprocess.Popen]:
    """``n`` busy processes and ``io`` memory/IO-pressure processes at normal priority,
    beside the graph."""
    busy = [subprocess.Popen([sys.executable, "-c", _BUSY]) for _ in range(n)]
    return busy + [subprocess.Popen([sys.executable, "-c", _PRESSURE]) for _ in range(io)]


def measure(
    duration_s: float,
    deployment: str,
    executor: str,
    out: Path,
    keystore: str = "",
    load: int = 0,
    io_load: int = 0,
) -> dict:
    """Launch (secured by ``keystore``, beside ``load`` busy and ``io_load`` memory/IO
    processes), sample CPU, read the bag; returns the figures (see the module docstring)."""
    from pneu_msgs_py.bag.reader import read_run

    cmd = ["ros2", "launch", "--noninteractive", "pneu_sim", "sim.launch.py", "mode:=realtime"]
    cmd += ["axes:=both", f"duration:={duration_s:g}", f"deployment:={deployment}"]
    cmd += [f"out:={out}"] + ([f"executor:={executor}"] if executor else [])
    cmd += [f"keystore:={keystore}"] if keystore else []
    log = open(out.parent / f"{out.name}.log", "w")
    busy = _start_load(load, io_load)
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        # the steady part: from when the sim is publishing until just before the end
        deadline = time.monotonic() + 120.0
        started = None
        while time.monotonic() < deadline and proc.poll() is None:
            if (out / "bag" / "metadata.yaml").exists() or _sim_running(out):
                started = time.monotonic()
                break
            time.sleep(0.5)
        if started is None:
            raise RuntimeError(f"the sim did not start; see {log.name}")
        time.sleep(min(3.0, duration_s / 4))
        t0, c0 = time.monotonic(), _cpu(proc.pid)
        time.sleep(max(duration_s - 6.0, duration_s / 2))
        t1, c1 = time.monotonic(), _cpu(proc.pid)
        proc.wait(timeout=duration_s + 120)
    except BaseException:
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=60)
        raise
    finally:
        log.close()
        for b in busy:
            b.kill()
            b.wait()
    data = read_run(out / "bag")
    sim = _sim_counters(data)
    res: dict = {
        "deployment": deployment,
        "executor": executor or "default",
        "duration_s": duration_s,
        "ticks": int(sim.get("steps", "0")) + 1,
        "skipped_ticks": int(sim.get("skipped_ticks", "0")),
        "recorded_samples": len(data["/pneu/linear/joint_state"]),
        "load_average": os.getloadavg()[0],
        "busy_processes": load,
        "io_processes": io_load,
        "secured": bool(keystore),
        "dropped_batches": int(sim.get("dropped_batches", "0")),
        "realtime": sim.get("realtime", ""),
    }
    for axis in ("linear", "rotary"):
        missed = int(sim.get(f"missed.{axis}", "0"))
        res[f"missed.{axis}"] = missed
        res[f"missed_pct.{axis}"] = 100.0 * missed / max(res["ticks"], 1)
        for name in ("late_ticks", "held_ticks", "ramped_ticks"):
            res[f"{name}.{axis}"] = int(sim.get(f"{axis}.{name}", "0"))
        for q in ("p50", "p99", "max"):
            v = sim.get(f"turnaround.{axis}_{q}_us")
            res[f"turnaround_{q}_us.{axis}"] = float(v) if v not in (None, "") else None
        ta = _turnaround_us(data, axis)
        for q in (50, 99):
            v = float(np.percentile(ta, q)) if ta.size else None
            res[f"bag_turnaround_p{q}_us.{axis}"] = v
        res[f"bag_turnaround_max_us.{axis}"] = float(ta.max()) if ta.size else None
        res[f"safety_trips.{axis}"], res[f"first_trip_s.{axis}"] = _safety_trips(data, axis)
    for name in sorted(set(c0) | set(c1)):
        res[f"cpu_pct.{name}"] = 100.0 * (c1.get(name, 0) - c0.get(name, 0)) / _CLK / (t1 - t0)
    return res


def _sim_running(out: Path) -> bool:
    return (out / "bag").is_dir()


def main(argv: list[str] | None = None) -> int:
    """``bench_ros``: launch the graph, measure it, print the figures; the exit code."""
    p = argparse.ArgumentParser(
        prog="ros2 run pneu_control bench_ros", description=__doc__.split("\n")[0]
    )
    p.add_argument("--duration", type=float, default=60.0, help="seconds of real time (10..3600)")
    p.add_argument("--deployment", choices=("nodes", "hosted"), default="nodes")
    p.add_argument("--executor", choices=("", "events", "single", "auto"), default="")
    p.add_argument("--out", help="directory for the bag and the launch log (default: a temp dir)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--keystore", default="", help="run the graph secured (SROS2, a `pneu security` keystore)"
    )
    p.add_argument(
        "--load",
        type=int,
        default=0,
        help="busy processes at normal priority beside the graph (0..16)",
    )
    p.add_argument(
        "--io-load",
        type=int,
        default=0,
        help="memory/IO-pressure processes beside the graph (256 MiB touched, 32 MiB written "
        "and fsynced, over and over; 0..8)",
    )
    args = p.parse_args(argv)
    if not 0 <= args.io_load <= 8:
        p.error(f"--io-load: {args.io_load} refused; allowed: 0..8 processes")
    if not 0 <= args.load <= 16:
        p.error(f"--load: {args.load} refused; allowed: 0..16 busy processes")
    if not 10.0 <= args.duration <= 3600.0:
        p.error(f"--duration: {args.duration:g} refused; allowed: [10, 3600] s")
    base = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="pneu_bench_ros_"))
    base.mkdir(parents=True, exist_ok=True)
    tag = ("_secured" if args.keystore else "") + (f"_load{args.load}" if args.load else "")
    tag += f"_io{args.io_load}" if args.io_load else ""
    out = base / f"{args.deployment}_{args.executor or 'default'}{tag}"
    if out.exists():
        p.error(f"--out: {out} exists; allowed: a directory without a previous bench run")
    res = measure(
        args.duration, args.deployment, args.executor, out, args.keystore, args.load, args.io_load
    )
    if args.json:
        print(json.dumps(res, indent=1))
    else:
        for k, v in res.items():
            print(f"{k:32s} {v:.4g}" if isinstance(v, float) else f"{k:32s} {v}")
        print(f"bag: {out / 'bag'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
