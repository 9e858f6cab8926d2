"""pneu task end to end on the twin: outcomes against the recorded physics, files read back
independently, a bad program refused before anything is written."""

from __future__ import annotations

import json
import math
from pathlib import Path

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


# ------------------------------------------------------------------ holding a load: grip_and_twist
TASKS = sorted((Path(__file__).resolve().parents[3] / "config" / "tasks").glob("*.yaml"))
GRIP = "config/tasks/grip_and_twist.yaml"


def rod_force(ts, p) -> np.ndarray:
    """The measured pneumatic force on the rod (N): Eq. 1, p_c1 A_c1 − p_c2 A_c2 − p_a A_r."""
    lin, p_a = p.linear, p.ambient.p_a
    return ts["sample.p_c1"] * lin.A_c1 - ts["sample.p_c2"] * lin.A_c2 - p_a * (lin.A_c1 - lin.A_c2)


def sensor_force_error(p) -> float:
    """The largest error of that force from the pressure sensors' offsets (±accuracy · FS)."""
    fs = p.sensors.pressure
    return fs.accuracy_fs * fs.fs * (p.linear.A_c1 + p.linear.A_c2)


def breakaway(p) -> float:
    """The seals' largest force at rest (N): A_f × breakaway_ratio (the sliding level, Eq. 2)."""
    return p.linear.A_f * p.linear.breakaway_ratio


@pytest.mark.slow
def test_grip_and_twist_holds_the_rod_against_the_pull_while_it_twists(tmp_path):
    """The shipped task: the rod reaches 30 mm, the stem pulls it with 60 N, the rotary turns
    two turns. While the rotary turns, the rod stays within the twist's tolerance of 30 mm,
    and the chamber pressures carry the pull: their force on the piston is the load's,
    within the seals' breakaway and the pressure sensors' offsets."""
    from pneu_control.task.session import prepare

    out = tmp_path / "task"
    assert main(["task", GRIP, "--out", str(out)]) == 0
    rep = json.loads((out / "task_report.json").read_text())
    assert rep["outcome"] == "completed" and rep["reached"] == rep["segments_total"] == 4
    prepared = prepare(GRIP)
    plant, (_reach, grip, twist, _retract) = prepared.spec.plant, prepared.program.segments
    pull = grip.load["F_ext"]
    assert pull < 0.0  # a pull toward the cylinder (x decreasing)
    ts = np.load(out / "timeseries.npz")
    t, x, th = ts["t"], ts["sample.x"], ts["sample.theta"]
    seg = rep["segments"][twist.index]
    tol_mm, tol_deg = twist.until["tol_mm"], twist.until["tol_deg"]
    # while the rotary turns: from the first sample tol_deg past the twist's start to its end
    inside = (t >= seg["t_start_s"]) & (t <= seg["t_end_s"])
    turned = inside & (np.abs(np.degrees(th - twist.theta_start)) > tol_deg)
    assert np.degrees(th[turned][-1] - twist.theta_start) == pytest.approx(720.0, abs=tol_deg)
    assert turned.sum() > 1000  # it turned for over a second (two turns at 120 rpm)
    assert np.max(np.abs(x[turned] - twist.x_end)) * 1e3 <= tol_mm
    # the piston at rest on average: the pneumatic force balances the pull (Eq. 1)
    force = rod_force(ts, plant)[turned]
    bound = breakaway(plant) + sensor_force_error(plant)
    assert abs(force.mean() + pull) <= bound, (force.mean(), pull, bound)
    assert -pull > 4.0 * bound  # a load the check can tell from none, or from its sign's wrong


@pytest.mark.slow
@pytest.mark.parametrize("task", TASKS, ids=[f.stem for f in TASKS])
def test_every_shipped_task_completes_on_the_twin(tmp_path, task):
    from pneu_control.task.session import execute_task, prepare

    assert len(TASKS) >= 4
    prepared = prepare(task)
    _, result, rep = execute_task(prepared, tmp_path / "out")
    assert rep["outcome"] == "completed", rep["reason"]
    assert all(s["status"] == "reached" for s in rep["segments"])
    assert not [e for e in result.safety_events if e.level == "ERROR"]
    for seg, r in zip(prepared.program.segments, rep["segments"], strict=True):
        if seg.until["kind"] == "settled":  # what ended it: both joints inside its tolerance
            assert abs(r["error_mm"]) <= seg.until["tol_mm"]
            assert abs(r["error_deg"]) <= seg.until["tol_deg"]


def _grip_with(tmp_path, load: dict[str, float]) -> Path:
    """grip_and_twist with the stem's load replaced by ``load`` (removed again on retract)."""
    import yaml

    doc = yaml.safe_load(Path(GRIP).read_text())
    doc["segments"][1]["load"] = load
    doc["segments"][3]["load"] = {k: 0.0 for k in load}
    f = tmp_path / f"grip_{'_'.join(f'{k}{v:g}' for k, v in load.items())}.yaml"
    f.write_text(yaml.safe_dump(doc, sort_keys=False))
    return f


def _run(f, out):
    from pneu_control.task.session import execute_task, prepare

    prepared = prepare(f)
    _, result, rep = execute_task(prepared, out)
    return prepared, result, rep


@pytest.mark.slow
def test_a_pull_the_cylinder_can_hold_is_held_and_one_beyond_it_is_not(tmp_path):
    """The physical limit: a pull displaces the rod; to bring it back and hold it the valve
    puts chamber 1 at supply and chamber 2 at atmosphere, A_c1 (p_s − p_a) (Eq. 1), less the
    seals' sliding force A_f. Pulls inside it (20 N, 90 % of it, a spring pulling 100 N at
    30 mm) are held: the task completes, and the pneumatic force grows by the load's growth
    (same seed, same sensor offsets; within the seals' breakaway twice). A pull beyond what
    the pressures can give at all (20 % over A_c1 (p_s − p_a) + the breakaway) drags the rod
    out to the stroke's soft limit: the supervisor takes the axis safe and the task reports
    the segment running then aborted, the twist not reached (the task checker does not
    refuse loads)."""
    from pneu_sim.physics.plant_file import load_plant

    p = load_plant()
    lin = p.linear
    push = lin.A_c1 * (p.supply.p_s_linear - p.ambient.p_a)  # chamber 1 at p_s, 2 at p_a
    limit = push - lin.A_f
    k = 100.0 / 0.030  # N/m: 100 N at 30 mm with x_0 = 0 (a spring pulling the rod in)
    held = {"small": {"F_ext": -20.0}, "near": {"F_ext": -0.9 * limit}, "spring": {"k_spring": k}}
    forces = {}  # name: (the pneumatic force held, the load's force at the target)
    for name, load in held.items():
        prepared, result, rep = _run(_grip_with(tmp_path, load), tmp_path / name)
        assert rep["outcome"] == "completed", (name, rep["reason"])
        twist, seg = rep["segments"][2], prepared.program.segments[2]
        assert abs(twist["error_mm"]) <= seg.until["tol_mm"]
        t = result.t
        rest = (t >= twist["t_end_s"] - 0.5) & (t <= twist["t_end_s"])  # held, turning
        ts = {f"sample.{c}": result.samples[c] for c in ("p_c1", "p_c2")}
        load_force = load.get("F_ext", 0.0) - load.get("k_spring", 0.0) * seg.x_end
        forces[name] = (rod_force(ts, p)[rest].mean(), load_force)
    (f0, l0) = forces["small"]
    for name in ("near", "spring"):  # the force grows by the load's growth
        f1, l1 = forces[name]
        assert f1 - f0 == pytest.approx(-(l1 - l0), abs=2.0 * breakaway(p)), (name, forces)
    beyond = -1.2 * (push + breakaway(p))
    _prepared, result, rep = _run(_grip_with(tmp_path, {"F_ext": beyond}), tmp_path / "beyond")
    assert rep["outcome"] == "aborted" and "safety" in rep["reason"]
    # aborted while it gripped or twisted (the 0.2 s grip may end before the rod is out there)
    status = [s["status"] for s in rep["segments"]][1:]
    assert status in (
        ["aborted", "not started", "not started"],
        ["reached", "aborted", "not started"],
    )
    trips = [e for e in result.safety_events if e.level == "ERROR"]
    assert ("linear", "stroke_limit") in [(e.axis, e.rule) for e in trips]
    assert np.min(result.samples["x"]) < -p.linear.L / 2 + 0.015  # pulled out to the limit
