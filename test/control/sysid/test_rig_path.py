"""The rig path with the simulated DAQ: the driver loop + SimBackend, the exciter answering.

What runs on the rig (the driver's 1 kHz loop, the supervisor, the DAQ's
volts and counts) with the twin behind the DAQ boundary and the exciter core
answering each sample as the exciter node would (on simulated time: a fake
clock paces the loop). The excitation drives the valves with its designed
commands one sample late, stays inside the limits, and the bag written from
it gives ``pneu identify`` the voltages that were on the valves.
"""

from __future__ import annotations

import numpy as np
from pneu_control.controller.axis import STATE_FIELDS
from pneu_control.experiment.bag_log import excite_metadata
from pneu_control.sysid.design import design_for
from pneu_control.sysid.exciter import Exciter
from pneu_control.sysid.record import load_record
from pneu_driver.daq.backend import SimBackend
from pneu_driver.daq.rig import RigParams
from pneu_driver.loop.driver_loop import DriverLoop
from pneu_driver.safety import SafetyParams, SafetySupervisor
from pneu_msgs_py.bag import BagWriter
from pneu_msgs_py.params.core import with_updates
from pneu_sim.physics.params import PlantParams
from pneu_sim.physics.plant import Plant

N = 6000  # the quiet segment, the first moves and pulses of both axes


class Clock:
    def __init__(self):
        self.t = 10**9

    def __call__(self):
        self.t += 1_000
        return self.t

    def sleep(self, s):
        self.t += round(s * 1e9)


class Recording:
    """The twin behind the DAQ, remembering what each step integrated over."""

    def __init__(self, plant):
        self.plant = plant
        self.u = []

    def step(self, u_lin, u_rot):
        self.u.append((u_lin, u_rot))
        return self.plant.step(u_lin, u_rot)


def test_exciter_through_the_driver_loop(tmp_path):
    rig = with_updates(RigParams(), {"loop.timing": "software"})
    plant = Plant(PlantParams(), seed=4)
    plant.reset()
    twin = Recording(plant)
    designs = {a: design_for(a, 4, "quick") for a in ("linear", "rotary")}
    ex = {a: Exciter(d) for a, d in designs.items()}
    clock = Clock()
    sup = SafetySupervisor(SafetyParams(), rig.period_s)
    bag_path = tmp_path / "rig.mcap"
    echo = {"controllers": {a: d.to_dict() for a, d in designs.items()}, "seed": 4}
    writer = BagWriter(bag_path, metadata=excite_metadata(echo), controller_state_fields=STATE_FIELDS, qos="realtime")  # fmt: skip
    events = []

    def answer(s):  # the exciter node's work per sample
        answers = []
        for a, e in ex.items():
            u = e.update(s)
            loop.put_command(a, u, s.stamp_ns)
            answers.append((a, u, e.state_values(), e.algorithm))
        writer.write_cycle(s, answers)

    loop = DriverLoop(SimBackend(twin, rig), rig, sup, on_sample=answer, on_events=events.extend, clock_ns=clock, sleep=clock.sleep)  # fmt: skip
    with writer:
        loop.run(N)
    assert [e for e in events if e.level != "OK"] == []
    rec = load_record(bag_path)
    # the backend's read at tick k steps the twin into sample k: twin.u[k + 1] is what it
    # integrated over period k (sample k -> k+1); what the bag says was on the valves then
    held = np.array(twin.u[1 : rec.n])
    for i, a in enumerate(("linear", "rotary")):
        assert np.allclose(rec.u[a][: len(held)], held[:, i], atol=2 * 20.0 / 2**16), a
        assert np.ptp(held[:, i]) > 0.3  # it excited
    assert set(rec.designs) == {"linear", "rotary"}
    assert np.nanmax(np.abs(rec.y["x"])) < 0.055
