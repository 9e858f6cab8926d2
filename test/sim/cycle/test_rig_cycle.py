"""RigCycle (the sim node's bookkeeping) against a fake plant and fake controllers."""

from __future__ import annotations

import math

import pytest
from pneu_msgs_py.contract.samples import NEUTRAL_V, SensorSample
from pneu_msgs_py.params.core import ParamError, from_dict, validate
from pneu_sim.cycle.rig_cycle import RigCycle
from pneu_sim.nodes.sim_core import SimNodeParams, active_axes

T_NS = 1_000_000


class FakePlant:
    """x integrates u_linear, omega = u_rotary: the applied commands are readable."""

    T = 0.001

    def __init__(self):
        self.applied: list[tuple[float, float]] = []

    def _sample(self, k, x, omega):
        return SensorSample(k, k * T_NS, 2e5, 2e5, 1e5, x, 0.0, omega, 0)

    def reset(self, x0=0.0):
        self.k, self.x = 0, x0
        self.applied.clear()
        return self._sample(0, self.x, 0.0)

    def step(self, u_l, u_r):
        self.applied.append((u_l, u_r))
        self.k += 1
        self.x += u_l
        return self._sample(self.k, self.x, u_r)


def fake_controller(s: SensorSample) -> float:
    return 1.0 + 0.01 * s.k  # u_k depends on k: the delay is visible


def test_lockstep_applies_u_k_minus_1_like_the_runner():
    plant = FakePlant()
    core = RigCycle(plant, axes=("linear",))
    s = core.reset()
    ref_plant = FakePlant()
    rs = ref_plant.reset()
    u_hold = NEUTRAL_V
    for _ in range(50):
        # ROS side: the controller answers the published sample
        assert not core.complete and core.waiting_for == ("linear",)
        assert core.offer("linear", s.stamp_ns, fake_controller(s)) == "accepted"
        assert core.complete
        s = core.advance()
        # runner side (pneu_control.experiment.runner.run): u_k = update(s_k); s_{k+1} = step(u_{k-1})
        u = fake_controller(rs)
        rs = ref_plant.step(u_hold, NEUTRAL_V)
        u_hold = u
        assert s == rs
    assert plant.applied == ref_plant.applied
    assert plant.applied[0] == (NEUTRAL_V, NEUTRAL_V)  # before the first answer
    assert plant.applied[1] == (1.0, NEUTRAL_V)  # u_0 drives the step 1 -> 2
    assert core.timeouts == {"linear": 0} and core.steps == 50


def test_lockstep_rejects_answers_to_other_samples():
    core = RigCycle(FakePlant(), axes=("linear", "rotary"))
    s = core.reset()
    assert core.offer("linear", s.stamp_ns - T_NS, 3.0) == "stale"
    assert core.offer("linear", s.stamp_ns + T_NS, 3.0) == "stale"
    assert core.offer("linear", s.stamp_ns, 3.0) == "accepted"
    assert not core.complete and core.waiting_for == ("rotary",)
    assert core.offer("rotary", s.stamp_ns, 6.0) == "accepted"
    assert core.complete
    assert core.stale == {"linear": 2, "rotary": 0}


def test_inactive_axis_holds_neutral_and_is_ignored():
    plant = FakePlant()
    core = RigCycle(plant, axes=("rotary",))
    s = core.reset()
    assert core.offer("linear", s.stamp_ns, 9.0) == "inactive"
    core.offer("rotary", s.stamp_ns, 7.0)
    core.advance()
    s = core.sample
    core.offer("rotary", s.stamp_ns, 7.5)
    core.advance()
    assert plant.applied == [(NEUTRAL_V, NEUTRAL_V), (NEUTRAL_V, 7.0)]


def test_timeout_is_counted_and_previous_command_held():
    plant = FakePlant()
    core = RigCycle(plant, axes=("linear", "rotary"))
    s = core.reset()
    core.offer("linear", s.stamp_ns, 2.0)
    core.offer("rotary", s.stamp_ns, 8.0)
    s = core.advance()
    core.offer("linear", s.stamp_ns, 3.0)  # rotary never answers sample 1
    s = core.advance()  # the node's timeout fired
    assert core.timeouts == {"linear": 0, "rotary": 1}
    core.offer("linear", s.stamp_ns, 4.0)
    core.offer("rotary", s.stamp_ns, 9.0)
    core.advance()
    # step 2->3 runs under the answers to sample 1: linear 3.0, rotary still 8.0
    assert plant.applied == [(5.0, 5.0), (2.0, 8.0), (3.0, 8.0)]
    assert core.counters()["timeouts.rotary"] == 1


def test_realtime_takes_newest_answer_and_counts_missed_periods():
    plant = FakePlant()
    core = RigCycle(plant, axes=("linear",), mode="realtime")
    s0 = core.reset()
    s1 = core.advance()  # no answer in the first period
    assert core.missed == {"linear": 1}
    assert core.offer("linear", s0.stamp_ns, 2.0) == "accepted"  # late answer to s0
    assert core.offer("linear", s1.stamp_ns, 3.0) == "accepted"  # newer one wins
    assert core.offer("linear", s0.stamp_ns, 2.5) == "stale"  # older than accepted
    core.advance()
    core.advance()
    assert plant.applied == [(5.0, 5.0), (5.0, 5.0), (3.0, 5.0)]
    assert core.stale == {"linear": 1} and core.missed == {"linear": 2}


def test_answer_from_the_future_and_non_finite_refused():
    core = RigCycle(FakePlant(), axes=("linear",), mode="realtime")
    s = core.reset()
    assert core.offer("linear", s.stamp_ns + T_NS, 3.0) == "stale"
    assert core.offer("linear", s.stamp_ns, float("nan")) == "invalid"
    core.advance()
    assert core.held["linear"] == NEUTRAL_V  # nothing valid was written


def test_without_supervisor_a_non_finite_answer_keeps_the_previous_command():
    plant = FakePlant()
    core = RigCycle(plant, axes=("linear",))
    s = core.reset()
    core.offer("linear", s.stamp_ns, 7.0)
    s = core.advance()
    assert core.offer("linear", s.stamp_ns, float("inf")) == "invalid"
    assert core.complete  # it did answer: nothing to wait for
    core.advance()
    core.advance()  # no answer at all: a timeout
    assert [u for u, _ in plant.applied] == [5.0, 7.0, 7.0]
    assert core.timeouts == {"linear": 1}


class RecordingSupervisor:
    """The SafetySupervisor interface: passes the last command through unless e-stopped."""

    def __init__(self):
        self.commands, self.samples, self.now = [], [], []
        self.last = {"linear": NEUTRAL_V, "rotary": NEUTRAL_V}
        self.estopped = False

    def command(self, axis, u, stamp_ns):
        self.commands.append((axis, u, stamp_ns))
        self.last[axis] = u

    def check_sample(self, s, volts=None):
        self.samples.append(s.k)

    def outputs(self, now_ns):
        self.now.append(now_ns)
        if self.estopped:
            return NEUTRAL_V, NEUTRAL_V
        return self.last["linear"], self.last["rotary"]


def test_supervisor_in_the_runners_order():
    """Cycle k: check s_k, output for tick k (u_{k-1} after the rules), answers u_k, step."""
    plant = FakePlant()
    sup = RecordingSupervisor()
    core = RigCycle(plant, axes=("linear",), supervisor=sup)
    s = core.reset()
    assert (sup.samples, sup.now) == ([0], [0])
    core.offer("linear", s.stamp_ns, 2.0)
    s = core.advance()
    sup.estopped = True
    core.offer("linear", s.stamp_ns, 3.0)
    core.advance()
    core.advance()
    assert sup.commands == [("linear", 2.0, 0), ("linear", 3.0, T_NS)]
    assert sup.samples == [0, 1, 2, 3]
    assert sup.now == [0, T_NS, 2 * T_NS, 3 * T_NS]
    assert plant.applied == [(5.0, 5.0), (2.0, 5.0), (5.0, 5.0)]


def test_supervisor_gets_every_answer_as_is():
    sup = RecordingSupervisor()
    core = RigCycle(FakePlant(), axes=("linear",), supervisor=sup)
    s = core.reset()
    assert core.offer("linear", s.stamp_ns, 11.0) == "accepted"
    s = core.advance()
    assert core.offer("linear", s.stamp_ns, float("nan")) == "accepted"  # it refuses and trips
    assert sup.commands[0][1] == 11.0 and math.isnan(sup.commands[1][1])


def test_bad_mode_and_axes_refused():
    with pytest.raises(ParamError, match="mode"):
        RigCycle(FakePlant(), mode="fast")
    with pytest.raises(ParamError, match="axes"):
        RigCycle(FakePlant(), axes=("vertical",))
    with pytest.raises(RuntimeError):
        RigCycle(FakePlant()).advance()
    assert active_axes("both") == ("linear", "rotary")
    assert active_axes("none") == ()
    with pytest.raises(ParamError, match="axes"):
        active_axes("all")


def test_sim_node_params_validate():
    p = validate(SimNodeParams())
    assert p.mode == "lockstep" and p.lockstep.timeout_s > 0
    p = from_dict(SimNodeParams, {"mode": "realtime", "lockstep": {"timeout_s": 0.5}}, strict=False)
    assert p.lockstep.timeout_s == 0.5
    with pytest.raises(ParamError, match="mode"):
        from_dict(SimNodeParams, {"mode": "turbo"}, strict=False)


def test_injected_faults_act_where_the_runner_applies_them():
    from pneu_sim.faults.injection import parse_faults
    from pneu_sim.physics.plant import Plant
    from pneu_sim.physics.plant_file import load_plant

    faults = parse_faults(
        [
            "sensor_dropout:sensor=x,start_s=0.002,duration_s=0.002",
            "controller_silent:axis=linear,start_s=0.005,duration_s=0.001",
            "controller_nan:axis=linear,start_s=0.007,duration_s=0.001",
            "valve_stuck:axis=linear,volts=7.5,start_s=0.009,duration_s=0.001",
        ]
    )
    plant = Plant(load_plant(), seed=1)
    core = RigCycle(plant, axes=("linear",), faults=faults, seed=1)
    s = core.reset()
    seen = []
    for _ in range(12):
        seen.append(s.x)
        status = core.offer("linear", s.stamp_ns, 6.0)
        if s.k == 5:
            assert status == "silent" and core.complete  # a muted controller is not waited for
        elif s.k == 7:
            assert status == "invalid" and core.complete  # NaN: the DAQ holds 6 V
        else:
            assert status == "accepted"
        s = core.advance()
    assert math.isnan(seen[2]) and math.isnan(seen[3]) and not math.isnan(seen[4])
    assert core.counters()["silenced.linear"] == 1 and core.timeouts == {"linear": 0}
    # the AO holds 6 V (16-bit DAC); the stuck spool acted only during k = 9
    assert plant.state.u_linear == pytest.approx(6.0, abs=1e-3)


def test_a_supervisor_for_another_plumbing_than_the_twins_is_refused():
    """The stall rule reads from the supervisor which valve directions drive the motor."""
    from pneu_driver.safety import SafetyParams, SafetySupervisor
    from pneu_msgs_py.params.core import with_updates
    from pneu_sim.physics.plant import Plant
    from pneu_sim.physics.plant_file import load_plant

    plant = Plant(with_updates(load_plant(), {"rotary.plumbing": "bidirectional"}))
    with pytest.raises(
        ParamError,
        match=r"^rotary_plumbing: 'paper' refused; allowed: 'bidirectional', the twin's",
    ):
        RigCycle(plant, supervisor=SafetySupervisor(SafetyParams()))
    RigCycle(plant, supervisor=SafetySupervisor(SafetyParams(rotary_plumbing="bidirectional")))


class QuietPlant(FakePlant):
    """Plausible samples for a SafetySupervisor (at rest, live sensor noise); records the
    applied commands."""

    def _sample(self, k, x, omega):
        w = 10.0 * (k % 3)
        return SensorSample(
            k, k * T_NS, 2.5e5 + w, 2.4e5 - w, 1.8e5 + w, 1e-6 * (k % 2), 0.0, 0.0, 0
        )


@pytest.mark.parametrize("mode", ["lockstep", "realtime"])
def test_the_sim_writes_the_late_policy_and_counts_it(mode):
    """A controller that misses k ticks in a row: the twin integrates its last command for
    late_hold_ms (hold), then 5 V, and the next answer at once, not latched; the
    supervisor's counts are the sim's counters (its /diagnostics status values)."""
    from pneu_driver.safety import SafetyParams, SafetySupervisor

    p = SafetyParams()
    hold = round(p.late_hold_ms)
    k = hold + 5
    plant = QuietPlant()
    sup = SafetySupervisor(p, sample_time_s=plant.T)
    core = RigCycle(plant, axes=("linear",), mode=mode, supervisor=sup)
    s = core.reset()
    for _ in range(3):
        core.offer("linear", s.stamp_ns, 7.0)
        s = core.advance()
    for _ in range(k):  # no answer (lockstep: the node's timeout fires each time)
        s = core.advance()
    core.offer("linear", s.stamp_ns, 3.0)
    core.advance()
    core.advance()
    applied = [u for u, _ in plant.applied]
    # step j runs under the tick-j output: the answer to sample j-1, late by m periods at
    # j = 3 + m (the last answer is to sample 2)
    assert applied[:4] == [5.0, 7.0, 7.0, 7.0]
    assert applied[4 : 4 + hold] == [7.0] * hold  # late by 1..hold ms: held
    assert applied[4 + hold : 4 + k] == [5.0] * (k - hold)  # beyond the hold: closed
    assert applied[4 + k] == 3.0  # the answer to the newest sample: written at once
    assert not [e for e in sup.events() if e.level == "ERROR"]
    c = core.counters()
    # the k ticks, and the last one (the last advance's sample got no answer either)
    late = (c["linear.late_ticks"], c["linear.held_ticks"], c["linear.ramped_ticks"])
    assert late == (k + 1, hold + 1, 0)
    assert c["rotary.late_ticks"] == 0 and c["future_commands"] == 0  # the driver's keys too
    assert c[("timeouts" if mode == "lockstep" else "missed") + ".linear"] == k + 1
