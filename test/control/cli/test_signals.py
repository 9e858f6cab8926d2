"""Interruption at any moment: real ``pneu run`` processes, real signals, independent readers.

Moments: start-up (pneu's handlers installed, imports and config still loading),
the control loop (the bag is being written), finalisation (a second signal
while the first one's files are being finished), and a hard kill (SIGKILL:
``pneu recover``). Every bag left behind is read back by ``mcap_ros2`` and
``rosbags``; metrics.json says ``interrupted: true`` with the time, and so
does the bag's ``pneu.end`` record.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import json
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from mcap_ros2.reader import read_ros2_messages
from pneu_control.cli.main import main
from pneu_msgs_py.bag.reader import read_run

_spec = importlib.util.spec_from_file_location("_proc", Path(__file__).with_name("_proc.py"))
P = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(P)

SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP]
RUN = ["run", "--axis", "linear", "--controller", "pid", "--duration", "60"]


def loop_running(out: Path) -> bool:
    """The control loop has written its first chunk into the (partial) bag."""
    partial = out / "run.mcap.partial"
    return partial.exists() and partial.stat().st_size > 100_000


def count_independently(bag: Path) -> int:
    """Messages as two independent readers see them (they must agree)."""
    from rosbags.highlevel import AnyReader

    n_mcap = sum(1 for _ in read_ros2_messages(str(bag)))
    with AnyReader([bag]) as reader:
        n_rosbags = sum(1 for _ in reader.messages())
    assert n_mcap == n_rosbags
    return n_mcap


def check_interrupted_run(out: Path, sig: int, err: str) -> dict:
    """The run directory holds finished artefacts only, marked interrupted, readable by all."""
    names = sorted(p.name for p in out.iterdir())
    assert names == ["metrics.json", "run.mcap", "timeseries.npz"], names  # no lock, no partial
    doc = json.loads((out / "metrics.json").read_text())
    assert doc["interrupted"] is True
    end = doc["end"]
    assert end["status"] == "interrupted" and end["signal"] == signal.Signals(sig).name
    assert end["interrupted_utc"].endswith("Z") and 0 < end["samples"] < end["planned_samples"]
    n = end["samples"]
    ts = np.load(out / "timeseries.npz")
    assert len(ts["t"]) == n and len(ts["linear.u"]) == n and len(ts["sample.x"]) == n
    data = read_run(out / "run.mcap")
    assert data.metadata["pneu.end"]["interrupted"] == "true"
    assert data.metadata["pneu.end"]["signal"] == signal.Signals(sig).name
    for topic in ("/pneu/linear/joint_state", "/pneu/pressure/cylinder_1"):
        assert len(data[topic]) == n, topic  # every cycle that ran, none missing
    assert len(data["/pneu/linear/controller_state"]) == n
    total = count_independently(out / "run.mcap")
    assert total == data.message_count
    assert "Traceback" not in err and "interrupted" in err
    return doc


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_signal_during_the_loop_finishes_everything_marked_interrupted(tmp_path, sig):
    out = tmp_path / "run"
    proc = P.start(*RUN, "--out", str(out))
    assert P.wait_for(lambda: loop_running(out))
    proc.send_signal(sig)
    rc, _, err = P.finish(proc)
    assert rc == 128 + sig, err
    doc = check_interrupted_run(out, sig, err)
    assert f"interrupted by {signal.Signals(sig).name}" in err
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["analyze", str(out / "run.mcap")]) == 0
    assert f"run interrupted by {signal.Signals(sig).name} at" in buf.getvalue()
    assert doc["end"]["last_sample_s"] > 0


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_signal_during_start_up_leaves_nothing_or_a_finished_run(tmp_path, sig):
    out = tmp_path / "run"
    proc = P.start(*RUN, "--out", str(out))
    assert P.wait_for(lambda: P.handlers_installed(proc.pid), timeout=60)
    proc.send_signal(sig)  # imports, parser, config files, claims: not yet in the loop
    rc, _, err = P.finish(proc)
    assert rc == 128 + sig, err
    assert "Traceback" not in err and len(err.strip().splitlines()) >= 1
    if out.exists() and any(out.iterdir()):  # it had reached the loop: then a finished run
        check_interrupted_run(out, sig, err)
    else:
        assert not out.exists() or not any(out.iterdir())


def test_second_signal_during_finalisation_changes_nothing(tmp_path):
    out = tmp_path / "run"
    proc = P.start(*RUN, "--out", str(out))
    assert P.wait_for(lambda: loop_running(out))
    proc.send_signal(signal.SIGTERM)
    # keep signalling while it finishes its files (every 2 ms until it has exited)
    while proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        time.sleep(0.002)
    rc, _, err = P.finish(proc)
    # the kernel delivers pending signals lowest number first: SIGINT may be the one recorded
    assert rc in (130, 143), err
    check_interrupted_run(out, rc - 128, err)


def test_signals_throughout_a_run_never_lose_data(tmp_path):
    """A signal at a random moment of the loop of each of several runs: every outcome is a
    complete run marked interrupted. The moment is a random size the bag must have reached
    (well below the whole run's), so the signal always lands while the run is in progress."""
    rng = np.random.default_rng(7)
    for i, sig in enumerate(SIGNALS):
        out = tmp_path / f"run{i}"
        partial = out / "run.mcap.partial"
        size = int(rng.uniform(0.2e6, 5e6))  # bytes; the 60 s run's bag is about 13 MB
        proc = P.start(*RUN, "--out", str(out))
        assert P.wait_for(lambda: partial.exists() and partial.stat().st_size >= size)  # noqa: B023
        assert proc.poll() is None, "the run ended before the signal"
        proc.send_signal(sig)
        rc, _, err = P.finish(proc)
        assert rc == 128 + sig, err
        doc = check_interrupted_run(out, sig, err)
        assert doc["end"]["last_sample_s"] > 0


def test_hard_kill_leaves_a_partial_bag_that_recover_makes_whole(tmp_path):
    out = tmp_path / "run"
    proc = P.start(*RUN, "--out", str(out))
    partial = out / "run.mcap.partial"
    assert P.wait_for(lambda: partial.exists() and partial.stat().st_size > 300_000)
    proc.send_signal(signal.SIGKILL)
    rc, _, _ = P.finish(proc)
    assert rc == -signal.SIGKILL
    assert not (out / "run.mcap").exists() and not (out / "metrics.json").exists()
    # pneu analyze says what happened and reads what was written
    assert main(["analyze", str(out / "run.mcap")]) == 2  # points at the partial file
    assert main(["analyze", str(partial)]) == 0
    fixed = tmp_path / "fixed.mcap"
    assert main(["recover", str(partial), "--out", str(fixed)]) == 0
    n = count_independently(fixed)
    data = read_run(fixed)
    assert n == data.message_count > 0
    rec = data.metadata["pneu.recovered"]
    assert rec["source_truncated"] == "true" and int(rec["messages"]) == n
    assert "pneu.run" in data.metadata  # the run's config came along
    js = data["/pneu/linear/joint_state"]
    assert np.all(np.diff(js.stamp_ns) == 1_000_000)  # no cycle missing up to the cut
