"""Micro-benchmark of :meth:`AxisController.update` (not a test).

``us_per_update("eso_smc", "rotary")`` runs the controller against a cheap
second-order plant stand-in (so the states move like in a run) and returns
the mean wall time per ``update`` call in µs, plant excluded as far as
possible (the plant step is three float operations).
"""

from __future__ import annotations

import time

from pneu_msgs_py.contract.samples import SensorSample
from pneu_msgs_py.params.core import with_updates

from pneu_control.controller.axis import AxisController
from pneu_control.controller.params import load_controller_params

__all__ = ["us_per_update"]


def us_per_update(algorithm: str, axis: str, n: int = 20000, read_state: bool = False) -> float:
    """Mean µs per ``AxisController.update`` (and ``.state`` read if ``read_state``)."""
    params = with_updates(load_controller_params(axis), {"algorithm": algorithm})
    ctrl = AxisController(axis, params)
    T = params.sample_time_s
    samples = [SensorSample(k, k * 1_000_000, 2e5, 2e5, 2e5, 0.0, 0.0, 0.0, 0) for k in range(n)]
    y = v = 0.0
    b = 0.05 if axis == "linear" else 50.0  # SI per V per s (rough)
    linear = axis == "linear"
    update = ctrl.update
    t0 = time.perf_counter()
    for s in samples:
        if linear:
            s.x = y
        else:
            s.omega = y
        u = update(s)
        if read_state:
            ctrl.state  # noqa: B018
        v += T * b * (u - 5.0) - T * 20.0 * v
        y += T * v
    dt = time.perf_counter() - t0
    return dt / n * 1e6


if __name__ == "__main__":  # pragma: no cover
    for axis in ("linear", "rotary"):
        for alg in ("pid", "ladrc", "eso_smc"):
            print(
                f"{axis:7s} {alg:8s} {us_per_update(alg, axis):6.2f} µs/update"
                f"  (+state {us_per_update(alg, axis, read_state=True):6.2f})"
            )
