"""A controller under the supervisor's hold: it commands what the valve gets, and rejoins
bumplessly when released (issue 22: a controller killed and restarted mid-run).

Closed loop on the twin without ROS: the sim's cycle and supervisor (RigCycle), the linear
controller's shell core fed the statuses the sim node puts on ``/diagnostics`` (its
transitions, stamped with their sample, and the 1 Hz state) a few samples late, as a
realtime graph delivers them. The linear controller falls silent (SIGKILL) at 2 s, a fresh
one starts at 4 s -- its axis latched by the watchdog -- and the operator resets at R.
"""

from __future__ import annotations

import numpy as np
import pytest
from pneu_control.controller.axis import AxisController
from pneu_control.controller.params import load_controller_params
from pneu_control.nodes.controller_core import ControllerShellCore, supervisor_hold
from pneu_driver.safety import SafetySupervisor, load_safety_params
from pneu_msgs_py.contract.convert import DiagStatus
from pneu_msgs_py.params.paths import config_file
from pneu_sim.cycle.rig_cycle import RigCycle
from pneu_sim.nodes.sim_core import safety_statuses
from pneu_sim.physics.plant import Plant
from pneu_sim.physics.plant_file import load_plant

GAINS = config_file("controllers_retuned.yaml")  # the sim launch's default
KILL, RESTART, N = 2000, 4000, 7000
LATENCY = 3  # samples from the sim's publication to the controller's callback


def _periodic(sup: SafetySupervisor, node: str = "pneu_sim") -> list[DiagStatus]:
    """The 1 Hz safety statuses the sim node (and, named pneu_driver, the driver) publishes."""
    return [
        DiagStatus(2 if st.state == "SAFE" else 0, f"{node}: safety {axis}", st.state, node,
                   {"causes": ",".join(st.causes)})
        for axis, st in sup.status.items()
    ]  # fmt: skip


def _run(reset_at: int, feedback: bool):
    """The applied linear valve voltage per tick, and the restarted core."""
    plant = Plant(load_plant(None), seed=0)
    sup = SafetySupervisor(load_safety_params(None), sample_time_s=plant.T)
    cycle = RigCycle(plant, mode="lockstep", supervisor=sup)
    rotary = AxisController("rotary", load_controller_params("rotary", GAINS))
    linear = ControllerShellCore("linear", load_controller_params("linear", GAINS))
    inbox: list[tuple[int, list]] = []  # (due sample, statuses)
    applied, s = [], cycle.reset()
    for k in range(N):
        if k == RESTART:
            linear = ControllerShellCore("linear", load_controller_params("linear", GAINS))
        while feedback and inbox and inbox[0][0] <= k:
            linear.on_supervisor(inbox.pop(0)[1])
        if not KILL <= k < RESTART:
            cycle.offer("linear", s.stamp_ns, linear.update(s))
        cycle.offer("rotary", s.stamp_ns, rotary.update(s))
        if k == reset_at:
            assert sup.reset()[0]
        events = sup.events()
        if events:
            inbox.append((k + LATENCY, safety_statuses("pneu_sim", events)))
        if k % 1000 == 500:
            inbox.append((k + LATENCY, _periodic(sup)))
        s = cycle.advance()
        applied.append(cycle.held["linear"])
    return np.array(applied), linear


@pytest.mark.parametrize("reset_at", [4600, 6000])
def test_a_restarted_controller_rejoins_bumplessly_only_after_the_reset(reset_at):
    u, core = _run(reset_at, feedback=True)
    steps = np.abs(np.diff(u))
    normal = steps[100:KILL].max()  # the controller's own largest step per tick, running
    hold_ms = load_safety_params(None).late_hold_ms
    trip = KILL + 1 + np.argmax(u[KILL:] == 5.0)  # the late command's hold ends: 5 V
    assert trip - KILL <= hold_ms + 2  # late_hold_ms (+ the one-sample delay), then latched
    assert np.all(u[trip:reset_at] == 5.0)  # held until the operator's reset
    moved = reset_at + np.argmax(u[reset_at:] != 5.0)  # the controller's first own command
    assert moved <= reset_at + LATENCY + 2
    assert abs(u[moved] - 5.0) <= normal  # no jump at the rejoin
    assert steps[moved : moved + 200].max() <= 1.25 * normal
    assert core.controller.n_rejoins == 1 and core.held_by == ""


def test_without_the_supervisors_word_the_restarted_controller_jumps():
    """The same run with the controller deaf to ``/diagnostics``: wound up while held, it puts
    its saturated command on the valve at the reset (what the hold above prevents)."""
    u, _ = _run(4600, feedback=False)
    normal = np.abs(np.diff(u))[100:KILL].max()
    assert abs(u[4600] - 5.0) > 3 * normal


def test_supervisor_hold_reads_the_sim_and_driver_statuses():
    sup = SafetySupervisor(load_safety_params(None), sample_time_s=1e-3)
    assert supervisor_hold(_periodic(sup), "linear") == ""  # no command yet: nothing latched
    sup.estop("service ~/estop")
    events = safety_statuses("pneu_driver", sup.events())
    assert supervisor_hold(events, "linear") == supervisor_hold(events, "rotary") == "estop"
    assert supervisor_hold(_periodic(sup, "pneu_driver"), "rotary") == "estop"
    sup.reset()
    assert supervisor_hold(safety_statuses("pneu_sim", sup.events()), "linear") == ""
    other = [DiagStatus(2, "linear_controller: linear controller", "no samples"),
             DiagStatus(2, "pneu_sim: safety rotary watchdog", "rotary tripped")]  # fmt: skip
    assert supervisor_hold(other, "linear") is None  # nothing about the linear valve


def test_a_hold_outside_the_command_band_is_refused():
    c = AxisController("linear", load_controller_params("linear", GAINS))
    with pytest.raises(ValueError, match="hold"):
        c.hold(11.0)
