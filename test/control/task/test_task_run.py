"""pneu task end to end on the twin: outcomes against the recorded physics, files read back
independently, a bad program refused before anything is written."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from mcap_ros2.reader import read_ros2_messages
from pneu_control.cli.main import main
from pneu_msgs_py.params.core import ParamError

COUPLING = "config/tasks/coupling_insert_lock.yaml"


@pytest.mark.slow
def test_coupling_task_reaches_every_segment_as_the_physics_shows(tmp_path):
    out = tmp_path / "task"
    assert main(["task", COUPLING, "--out", str(out)]) == 0
    rep = json.loads((out / "task_report.json").read_text())
    assert rep["outcome"] == "completed" and rep["reached"] == rep["segments_total"] == 3
    ts = np.load(out / "timeseries.npz")
    t, x, th = ts["t"], ts["sample.x"], ts["sample.theta"]
    insert, lock, _hold = rep["segments"]
    # the report's errors are the targets minus what the sensors recorded at the segment's end
    k = int(np.searchsorted(t, insert["t_end_s"] - 1e-9))
    assert insert["error_mm"] == pytest.approx((0.040 - x[k]) * 1e3, abs=1e-9)
    assert abs(insert["error_mm"]) <= 0.5  # the segment's settled tolerance
    k = int(np.searchsorted(t, lock["t_end_s"] - 1e-9))
    assert lock["error_deg"] == pytest.approx(90.0 - math.degrees(th[k]), abs=1e-9)
    assert abs(lock["error_deg"]) <= 1.0
    # the rod stayed inserted while it was locked: the coupling's point
    m = (t >= lock["t_start_s"]) & (t <= lock["t_end_s"])
    assert np.max(np.abs(x[m] - 0.040)) < 1.5e-3
    assert (out / "task.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    n = sum(
        1
        for m in read_ros2_messages(str(out / "run.mcap"))
        if m.channel.topic == "/pneu/rotary/joint_state"
    )
    assert n == len(t)


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ("segments:\n  - move: {to_mm: 90.0, speed_mm_s: 10.0}\n", "segments[0].move"),
        ("segments:\n  - rotate: {by_deg: -30.0, speed_rpm: 30.0}\n", "segments[0].rotate.by_deg"),
        (
            "plumbing: bidirectional\nsegments:\n  - spin: {speed_rpm: 4000.0, duration_s: 1.0}\n",
            "segments[0].spin.speed_rpm",
        ),
    ],
)
def test_bad_programs_write_nothing(tmp_path, capsys, body, field):
    f = tmp_path / "bad.yaml"
    f.write_text(body)
    out = tmp_path / "out"
    assert main(["task", str(f), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and field in err[0], err
    assert not out.exists()
    with pytest.raises(ParamError):
        from pneu_control.task.session import prepare

        prepare(f)


def test_a_tasks_limits_are_the_supervisors_angle_limits_during_the_run(tmp_path):
    """The tool's range a task names is enforced by the supervisor while it runs (not only
    checked before): its soft limits angle_margin_deg inside, and a move inside them runs
    without a hold or a trip."""
    from pneu_control.task.session import execute_task, prepare

    f = tmp_path / "tool.yaml"
    f.write_text(
        "plumbing: bidirectional\nlimits: {angle_min_deg: -120, angle_max_deg: 120}\n"
        "segments:\n  - rotate: {by_deg: 60, speed_rpm: 30}\n    until: {settled: {tol_deg: 1.0, for_s: 0.05}}\n"
    )
    prepared = prepare(f)
    sp = prepared.spec.safety
    assert (sp.angle_limits, sp.angle_min_deg, sp.angle_max_deg) == (True, -120.0, 120.0)
    _, result, rep = execute_task(prepared, tmp_path / "out")
    assert rep["outcome"] == "completed"
    assert not [e for e in result.safety_events if e.rule in ("soft_limit", "angle_limit")]
    assert np.max(np.degrees(result.samples["theta"])) < 90.0  # inside the soft limit
