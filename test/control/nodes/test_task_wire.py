"""Tasks and trajectories on the wire, without ROS: the controller core's JointTrajectory input,
the task runner core, the sim's task gate, and a task through the lockstep loopback equal to
``pneu task`` in process."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pneu_control.controller.params import load_controller_params
from pneu_control.controller.trajectory import (
    JointTrajectory,
    TrajectoryPoint,
    from_stamped,
    joint_reference,
    to_stamped,
)
from pneu_control.experiment.runner import run
from pneu_control.nodes.controller_core import ControllerShellCore
from pneu_control.nodes.loopback import run_loopback
from pneu_control.task.runner import TaskDriver
from pneu_control.task.session import prepare
from pneu_msgs_py.contract.convert import (
    DiagStatus,
    joint_trajectory_from_msg,
    joint_trajectory_to_typestore,
    typestore_messages,
)
from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.contract.task_progress import TaskProgress
from pneu_msgs_py.params.core import ParamError
from pneu_msgs_py.params.paths import config_file

T_NS = 1_000_000


def _sample(k: int, x: float = 0.0, theta: float = 0.0, base_ns: int = 0) -> SensorSample:
    return SensorSample(k, base_ns + k * T_NS, 4e5, 4e5, 1.0e5, x, theta, 0.0, 0)


def _move(dx: float, d: float, joints=("linear", "rotary")) -> JointTrajectory:
    pts = (
        TrajectoryPoint((0.0,) * len(joints), time_from_start=0.0),
        TrajectoryPoint((dx,) * len(joints), time_from_start=d),
    )
    return JointTrajectory(joints, pts)


# --- the message's time base --------------------------------------------------------------


def test_stamped_round_trip_is_exact_through_cdr():
    traj = from_stamped(*to_stamped(_move(0.03, 0.37), 0), 0)  # on the ns grid
    base = 1_733_000_000_123_456_789  # a wall-clock base: the stamps are large
    msg = joint_trajectory_to_typestore(*to_stamped(traj, base))
    ts = typestore_messages()
    back = joint_trajectory_from_msg(
        ts.deserialize_cdr(
            ts.serialize_cdr(msg, "trajectory_msgs/msg/JointTrajectory"),
            "trajectory_msgs/msg/JointTrajectory",
        )
    )
    again = from_stamped(*back, base)
    assert again == traj
    assert back[0] == base  # header.stamp = the trajectory's start on the samples' clock


def test_from_stamped_refuses_a_start_before_the_time_base_and_negative_times():
    with pytest.raises(ParamError, match="header.stamp"):
        from_stamped(5, ("linear",), [((0.0,), (), (), 0), ((0.01,), (), (), 10)], 6)
    with pytest.raises(ParamError, match=r"points\[1\].time_from_start"):
        from_stamped(5, ("linear",), [((0.0,), (), (), 0), ((0.01,), (), (), -10)], 0)


# --- the controller core ---------------------------------------------------------------------


def _core(axis: str, **over) -> ControllerShellCore:
    base = {"reference.kind": "constant", "reference.value": 0.0}
    if axis == "rotary":
        base.update({"rotary_control": "angle", "algorithm": "pid"})
    base.update(over)
    return ControllerShellCore(axis, load_controller_params(axis, None, base))


def test_the_controller_follows_its_joint_of_a_trajectory_from_its_start_on():
    core = _core("linear")
    for k in range(5):
        core.update(_sample(k))
    traj = _move(0.02, 0.1)
    stamp, names, pts = to_stamped(traj, 8 * T_NS)  # starts at sample 8
    assert core.on_trajectory(stamp, names, pts)
    ref = joint_reference(from_stamped(stamp, names, pts, 0), "linear")
    for k in range(5, 120):
        core.update(_sample(k))
        got = core.controller.state_values()[1]  # reference (m)
        want = 0.0 if k < 8 else ref(k * T_NS * 1e-9)[0]  # the old reference until its start
        assert got == want, k
    assert core.n_trajectories == 1 and core.n_trajectories_late == 0


def test_stamp_zero_starts_at_the_next_sample_and_a_late_one_is_joined_midway():
    core = _core("linear")
    core.update(_sample(0))
    _stamp, names, pts = to_stamped(_move(0.02, 0.1), 0)
    core.on_trajectory(0, names, pts)  # header.stamp 0: joint_trajectory_controller's "now"
    core.update(_sample(1))
    assert core.controller.state_values()[1] == 0.0  # its first point, at rest
    core.update(_sample(51))
    mid = core.controller.state_values()[1]
    assert 0.0 < mid < 0.02
    core.on_trajectory(20 * T_NS, names, pts)  # started 31 samples ago
    core.update(_sample(52))
    assert core.n_trajectories_late == 1


def test_a_joint_not_named_is_ignored_and_bad_ones_are_refused_in_one_line():
    lin, rot_speed = (
        _core("linear"),
        ControllerShellCore("rotary", load_controller_params("rotary")),
    )
    stamp, names, pts = to_stamped(_move(1.0, 0.2, ("rotary",)), 0)
    assert lin.on_trajectory(stamp, names, pts) is False  # not its joint
    with pytest.raises(ParamError, match="rotary_control: angle") as ei:
        rot_speed.on_trajectory(stamp, names, pts)
    assert "\n" not in str(ei.value)
    with pytest.raises(ParamError, match="at rest"):  # a moving last point
        lin.on_trajectory(0, ("linear",), [((0.0,), (), (), 0), ((0.01,), (1.0,), (), 10**8)])
    assert lin.n_trajectories_refused == 1 and rot_speed.n_trajectories_refused == 1
    status = lin.diagnostics("n")[0]
    assert status.level == 1 and status.values["trajectories_refused"] == "1"


def test_retuning_keeps_the_trajectory_and_a_new_reference_ends_it():
    from pneu_msgs_py.params.core import with_updates

    core = _core("linear", algorithm="pid")
    core.update(_sample(0))
    stamp, names, pts = to_stamped(_move(0.02, 0.5), T_NS)
    core.on_trajectory(stamp, names, pts)
    for k in range(1, 200):
        core.update(_sample(k))
    r_before = core.controller.state_values()[1]
    core.set_params(with_updates(core.params, {"pid.kp": core.params.pid.kp * 1.1}))
    core.update(_sample(200))
    r_after = core.controller.state_values()[1]
    assert 0.0 < r_before < r_after < 0.02  # still the trajectory
    core.set_params(with_updates(core.params, {"reference.value": 5.0}))  # mm
    core.update(_sample(201))
    assert core.controller.state_values()[1] == pytest.approx(0.005)


# --- progress, gate ----------------------------------------------------------------------------


def test_task_progress_round_trips_exactly_and_refuses_other_statuses():
    p = TaskProgress(7, "t", "start", 2, "2 rotate", "running", "", {"T_c": 0.1 + 0.2})
    back = TaskProgress.from_status(7, p.to_status())
    assert back == p and back.loads["T_c"] == 0.1 + 0.2  # repr: exact
    with pytest.raises(ValueError, match="not 'task: <name>'"):
        TaskProgress.from_status(7, DiagStatus(0, "pneu_sim: lockstep"))
    with pytest.raises(ValueError, match="event"):
        TaskProgress.from_status(7, DiagStatus(0, "task: t", values={"index": "1"}))


# --- the whole task through the loopback -----------------------------------------------------


def _in_process(task: str):
    prep = prepare(task)
    p = prep.spec.plant
    d = TaskDriver(prep.program, A_c1=p.linear.A_c1, A_c2=p.linear.A_c2, p_a=p.ambient.p_a)
    return d, run(prep.spec, hook=d)


@pytest.mark.parametrize("name", ["coupling_insert_lock", "grip_and_twist"])
def test_a_task_over_the_wire_equals_pneu_task_bit_for_bit(name):
    task = config_file(f"tasks/{name}.yaml")
    d, r1 = _in_process(task)
    prep = prepare(task)
    r2 = run_loopback(prep.spec, task=prep)
    core = r2.task
    assert core.driver.outcome == d.outcome
    assert [(r.status, r.t_start_s, r.t_end_s) for r in core.driver.results] == [
        (r.status, r.t_start_s, r.t_end_s) for r in d.results
    ]
    assert len(r2.t) == len(r1.t)
    for k in ("x", "theta", "p_c1", "p_c2", "p_m1"):
        assert np.array_equal(r1.samples[k], r2.samples[k]), k
    for axis in ("linear", "rotary"):
        for k in ("reference", "u"):
            assert np.array_equal(r1.axes[axis][k], r2.axes[axis][k]), (axis, k)
    started = sum(math.isfinite(r.t_start_s) for r in d.results)
    assert core.n_trajectories == started  # one trajectory per segment started


def test_abort_over_the_wire_takes_both_valves_safe_and_ends_after_the_safe_tail():
    from pneu_control.task.runner import SAFE_TAIL_S

    prep = prepare(config_file("tasks/coupling_insert_lock.yaml"))
    calls = {"n": 0}
    from pneu_control.nodes import task_core

    original = task_core.TaskShellCore.step

    def step(self, s):  # a user's ~/abort at 0.5 s
        calls["n"] += 1
        if calls["n"] == 500:
            assert self.abort("service ~/abort")[0]
        return original(self, s)

    task_core.TaskShellCore.step = step
    try:
        r = run_loopback(prep.spec, task=prep)
    finally:
        task_core.TaskShellCore.step = original
    d = r.task.driver
    assert d.outcome == "aborted" and d.reason == "service ~/abort"
    assert r.t[-1] == pytest.approx(0.499 + SAFE_TAIL_S, abs=2e-3)
    after = r.t > 0.5
    assert np.all(r.applied["linear"][: len(r.t)][after] == 5.0)
    assert np.all(r.applied["rotary"][: len(r.t)][after] == 5.0)
    assert any("task aborted: service ~/abort" in e.message for e in r.safety_events)
