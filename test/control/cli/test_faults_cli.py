"""``pneu run --fault`` and ``pneu analyze`` on a faulty run (the acceptance command)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from mcap_ros2.reader import read_ros2_messages
from pneu_control.cli import main as cli
from pneu_msgs_py.bag.reader import read_run


def test_pneu_run_controller_silent_ends_safe_with_a_complete_bag(tmp_path):
    out = tmp_path / "silent"
    proc = subprocess.run(
        [sys.executable, "-m", "pneu_control.cli.main", "run", "--fault", "controller_silent",
         "--axis", "linear", "--duration", "3", "--out", str(out)],
        capture_output=True, text=True, env=dict(os.environ), timeout=300,
    )  # fmt: skip
    assert proc.returncode == 3, proc.stderr  # the supervisor took the axis safe
    assert "safety  linear  SAFE at the end" in proc.stdout
    data = read_run(out / "run.mcap")
    assert not data.warnings
    assert len(data["/pneu/linear/joint_state"]) == 3000
    n = sum(
        1
        for m in read_ros2_messages(str(out / "run.mcap"))
        if m.channel.topic == "/pneu/linear/joint_state"
    )
    assert n == 3000
    diag = [s for o in data["/diagnostics"].objects for s in o]
    assert any(s.name == "pneu_runner: safety linear watchdog" and s.level == 2 for s in diag)
    doc = json.loads(Path(out / "metrics.json").read_text())
    assert {iv["kind"] for iv in doc["fault_intervals"]} == {"injected", "safe"}


def test_pneu_analyze_prints_the_fault_intervals(tmp_path, capsys):
    out = tmp_path / "nan"
    rc = cli.main(["run", "--fault", "controller_nan:start_s=0.3,duration_s=0.1", "--axis", "linear",
                   "--duration", "0.6", "--window-start", "0.1", "--out", str(out)])  # fmt: skip
    assert rc == 3  # the NaN commands tripped output_sanity
    capsys.readouterr()
    assert cli.main(["analyze", str(out / "run.mcap")]) == 0
    text = capsys.readouterr().out
    assert "fault injected: 0.300 s – 0.400 s" in text and "excluded from the metrics" in text
    assert "valve held safe: 0.300 s – end" in text
    assert "(200 samples)" in text  # 0.1 .. 0.3 s
    assert cli.main(["analyze", str(out / "run.mcap"), "--include-faults"]) == 0
    assert "(500 samples)" in capsys.readouterr().out


def test_bad_fault_is_one_clear_line(tmp_path, capsys):
    rc = cli.main(["run", "--fault", "valve_stuck:volts=12", "--out", str(tmp_path)])
    assert rc == 2
    err = capsys.readouterr().err
    assert "valve_stuck.volts: 12" in err and "[0, 10] V" in err and "Traceback" not in err
