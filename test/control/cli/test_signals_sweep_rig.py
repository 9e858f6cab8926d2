"""Interruption of ``pneu sweep`` and ``pneu rig --backend sim``: real processes, real signals.

A sweep interrupted while its runs execute on local worker processes stops at
once, leaves no worker behind and writes nothing (exit 128 + N). A rig run
interrupted in its loop leaves the valves safe and finishes run.mcap and
loop.json marked interrupted (``pneu.end``), read back by two independent
readers; one interrupted during start-up leaves nothing or a finished run.
"""

from __future__ import annotations

import importlib.util
import json
import signal
import struct
import time
from pathlib import Path

import pytest
from mcap_ros2.reader import read_ros2_messages
from pneu_msgs_py.bag.reader import read_run

_spec = importlib.util.spec_from_file_location("_proc", Path(__file__).with_name("_proc.py"))
P = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(P)

pytestmark = pytest.mark.timeout(300)

# 200 runs of 600 s simulated on 2 workers: minutes of work, interrupted after the first second
# (a sweep that waited for its queued runs would not end within the test's time)
SWEEP = ["sweep", "--samples", "200", "--reference", "sine:amplitude=10,frequency_hz=1",
         "--duration", "600", "--controller", "pid", "--gains", "retuned", "--executor", "local",
         "--workers", "2", "--no-plots"]  # fmt: skip
RIG = ["rig", "--backend", "sim:seed=1", "--axis", "linear", "--controller", "pid",
       "--duration", "60"]  # fmt: skip


def _workers(pid: int) -> list[int]:
    return [c for c in P.children(pid) if "spawn_main" in _cmdline(c)]


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


@pytest.mark.parametrize(
    ("sig", "group"),
    [(signal.SIGINT, False), (signal.SIGTERM, False), (signal.SIGINT, True)],
    ids=["SIGINT", "SIGTERM", "SIGINT-to-the-process-group"],
)
def test_sweep_interrupted_stops_its_workers_and_writes_nothing(tmp_path, sig, group):
    """``group``: Ctrl-C in a terminal, the signal reaches the workers too (they leave it to
    the driver: no traceback from them)."""
    import os

    out = tmp_path / "sw"
    proc = P.start(*SWEEP, "--out", str(out), new_session=group)
    assert P.wait_for(lambda: len(_workers(proc.pid)) == 2, timeout=120)
    workers = _workers(proc.pid)
    everything = P.children(proc.pid)  # the workers and multiprocessing's resource tracker
    # the workers are running their first runs: each has run its initializer (SIGINT
    # ignored), loaded the compiled loop (llvmlite mapped), and computed for a CPU second since
    assert P.wait_for(
        lambda: all(P.ignores(w, signal.SIGINT) and P.maps(w, "llvmlite") for w in workers)
    )
    cpu0 = {w: P.cpu_s(w) for w in workers}
    assert P.wait_for(lambda: all(P.cpu_s(w) >= cpu0[w] + 1.0 for w in workers))
    assert proc.poll() is None
    if group:
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    rc, _, err = P.finish(proc, timeout=120)
    assert rc == 128 + sig, err
    assert "Traceback" not in err and f"interrupted by {sig.name}" in err
    assert not any(P.alive(w) for w in workers), "a worker was left running"
    assert P.wait_for(lambda: not any(P.alive(c) for c in everything), timeout=10)
    assert not out.exists() or not any(out.iterdir())  # nothing written, not even a partial


def _card_tick(card: Path) -> int:
    """The simulated card's clock tick, read from its file as another process sees it
    (0 before the card is powered up); opening it as a CardRegister could power it up."""
    try:
        data = card.read_bytes()
    except OSError:
        return 0
    if len(data) != 64 or data[:8] != b"PNEUCARD":
        return 0
    return struct.unpack_from("<Q", data, 48)[0]


def _rig(out: Path, card: Path) -> list[str]:
    """``pneu rig`` on the simulated card whose state file is ``card``, into ``out``."""
    return [
        *(a if a != "sim:seed=1" else f"sim:seed=1,card={card}" for a in RIG),
        "--out",
        str(out),
    ]


def _rig_checks(out: Path, sig: int, err: str) -> dict:
    """run.mcap and loop.json finished, marked interrupted, read by two independent readers."""
    from rosbags.highlevel import AnyReader

    assert sorted(p.name for p in out.iterdir()) == ["loop.json", "run.mcap"]  # no lock, no partial
    doc = json.loads((out / "loop.json").read_text())
    end = doc["end"]
    assert end["status"] == "interrupted" and end["interrupted"] is True
    assert end["signal"] == signal.Signals(sig).name and end["interrupted_utc"].endswith("Z")
    assert 0 < end["samples"] < end["planned_samples"] == 60_000
    data = read_run(out / "run.mcap")
    meta = data.metadata["pneu.end"]
    assert meta["interrupted"] == "true" and meta["signal"] == signal.Signals(sig).name
    assert int(meta["samples"]) == end["samples"]
    n = len(data["/pneu/linear/joint_state"])  # one per cycle that had a sample
    assert 0 < n <= end["samples"] and len(data["/pneu/linear/valve_command"]) == n
    n_mcap = sum(1 for _ in read_ros2_messages(str(out / "run.mcap")))
    with AnyReader([out / "run.mcap"]) as reader:
        n_rosbags = sum(1 for _ in reader.messages())
    assert n_mcap == n_rosbags == data.message_count
    assert "Traceback" not in err
    return doc


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP],
                         ids=lambda s: s.name)  # fmt: skip
def test_rig_interrupted_in_the_loop_finishes_its_files(tmp_path, sig):
    out = tmp_path / "rig"
    card = tmp_path / "card"
    proc = P.start(*_rig(out, card))
    assert P.wait_for(lambda: _card_tick(card) >= 200, timeout=120)  # the loop is running
    proc.send_signal(sig)
    rc, stdout, err = P.finish(proc)
    assert rc == 128 + sig, err
    doc = _rig_checks(out, sig, err)
    assert "interrupted by" in err and "valves are safe" in err
    # a cycle whose read was late has no sample: cycles = samples + late reads (busy machine)
    assert f"samples {doc['end']['samples']}" in stdout
    codes = dict(c.split(":") for c in doc["loop"]["daq_late_codes"].split())
    late_reads = sum(int(v) for c, v in codes.items() if c != "-209801")  # -209801: a late write
    assert int(doc["loop"]["cycles"]) == doc["end"]["samples"] + late_reads
    from pneu_sim.daq_sim.card import read_card_state

    st = read_card_state(card)  # the driver's finally: both valves at the safe 5 V
    assert (st.ao0_v, st.ao1_v, st.do_level) == (5.0, 5.0, False)


def test_rig_second_signal_while_finishing_changes_nothing(tmp_path):
    out = tmp_path / "rig"
    card = tmp_path / "card"
    proc = P.start(*_rig(out, card))
    assert P.wait_for(lambda: _card_tick(card) >= 1000, timeout=120)  # a second of the loop
    proc.send_signal(signal.SIGTERM)
    while proc.poll() is None:  # keep signalling while it writes the bag
        proc.send_signal(signal.SIGINT)
        time.sleep(0.002)
    rc, _, err = P.finish(proc)
    assert rc in (130, 143), err  # the kernel may deliver the pending SIGINT first
    _rig_checks(out, rc - 128, err)


def test_rig_interrupted_during_start_up_leaves_nothing_or_a_finished_run(tmp_path):
    out = tmp_path / "rig"
    proc = P.start(*RIG, "--out", str(out))
    assert P.wait_for(lambda: P.handlers_installed(proc.pid), timeout=60)
    proc.send_signal(signal.SIGINT)  # imports, config files, the claim: not yet in the loop
    rc, _, err = P.finish(proc)
    assert rc == 130, err
    assert "Traceback" not in err
    if out.exists() and any(out.iterdir()):
        _rig_checks(out, signal.SIGINT, err)
