"""The sim's realtime loop (ROS-free): a late machine skips ticks, never the run's end."""

from __future__ import annotations

from pneu_sim.cycle.rig_cycle import RigCycle
from pneu_sim.nodes.sim_core import SimLoop
from pneu_sim.physics.plant import Plant
from pneu_sim.physics.plant_file import load_plant


class _LatePacer:
    """A pacer on a machine that starts every tick ``late`` ticks after it was due."""

    def __init__(self, late: int) -> None:
        from pneu_driver.loop.pacer import Timing

        self.late, self.skipped, self.lateness = late, 0, Timing()

    def start(self) -> None:
        pass

    def wait(self, k: int) -> int:
        started = k + (self.late if k else 0)
        self.skipped += started - k
        return started


def test_skipped_ticks_never_step_past_the_last_sample():
    for late, n_end in ((3, 50), (7, 50), (49, 50), (120, 50)):
        cycle = RigCycle(Plant(load_plant(None), seed=0), axes=())
        published = []
        loop = SimLoop(cycle, on_sample=lambda s, out=published: out.append(s.k), n_end=n_end)
        loop.pacer = _LatePacer(late)
        loop.run()
        assert loop.error is None
        assert published[-1] == n_end - 1  # the last sample, not one past it
        assert cycle.sample.k == n_end - 1 and cycle.steps == n_end - 1
