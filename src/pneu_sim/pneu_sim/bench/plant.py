"""Speed of the twin: ``plant_rtf`` = simulated seconds per wall second.

Both axes, sensors on, one :meth:`Plant.step` call per 1 ms sample (the path every
caller uses), valve excitation on both axes, one process (one core).
"""

from __future__ import annotations

import math
import time

__all__ = ["plant_rtf"]


def plant_rtf(duration_s: float = 20.0, seed: int = 0) -> float:
    """Simulated seconds per wall-clock second over ``duration_s`` (JIT warmed first)."""
    from pneu_sim.physics.plant import Plant
    from pneu_sim.physics.plant_file import load_plant

    if not (duration_s > 0.0):
        raise ValueError(f"duration_s: {duration_s!r} refused; allowed: > 0 s")
    plant = Plant(load_plant(), seed=seed)
    n = round(duration_s / plant.T)
    # excitation: 0.25 Hz sine on the linear valve, 1 Hz sine around 6 V on the rotary one
    u_l = [5.0 + 1.5 * math.sin(2 * math.pi * 0.25 * i * plant.T) for i in range(n)]
    u_r = [6.0 + 1.0 * math.sin(2 * math.pi * 1.0 * i * plant.T) for i in range(n)]
    plant.reset()
    for i in range(200):  # warm the JIT and the caches
        plant.step(u_l[i], u_r[i])
    plant.reset()
    step = plant.step
    t0 = time.perf_counter()
    for a, b in zip(u_l, u_r):
        step(a, b)
    wall = time.perf_counter() - t0
    return duration_s / wall


if __name__ == "__main__":
    print(f"plant_rtf = {plant_rtf():.0f}")
