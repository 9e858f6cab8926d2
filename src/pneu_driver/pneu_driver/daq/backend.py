"""The DAQ backend protocol and the simulated backend (any plant as a DAQ).

A backend reads one :class:`~pneu_driver.daq.scaling.RawSample` per tick and
writes the two valve voltages. :class:`~pneu_driver.daq.nidaqmx_backend.NidaqmxBackend`
is the real rig; :class:`SimBackend` wraps any object with
``step(u_lin, u_rot) -> SensorSample`` (the twin's ``pneu_sim.physics.plant.Plant``)
so the loop core runs, and is benchmarked, without hardware. Duck typing: no
import of pneu_sim here.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from pneu_msgs_py.contract.samples import SensorSample

from pneu_driver.daq.rig import RigParams
from pneu_driver.daq.scaling import RawSample, Scaler, ao_volts

__all__ = ["DaqBackend", "SteppablePlant", "SimBackend"]


@runtime_checkable
class DaqBackend(Protocol):
    """What :class:`~pneu_driver.loop.driver_loop.DriverLoop` drives.

    ``hardware_paced``: True when :meth:`read` blocks until the next sample
    clock (HW-timed single point); False when the loop paces itself.
    ``open`` leaves the valves safe (5 V) before anything is enabled;
    ``close`` leaves them safe whatever state the device is in.
    ``heartbeat(level)`` sets the heartbeat DO line (the loop toggles it once
    per cycle; a backend without the line ignores it). A hardware-paced
    backend raises :class:`~pneu_driver.daq.errors.LateCycleError` from
    ``read``/``write`` when sample clocks were missed.
    """

    hardware_paced: bool
    #: the device this backend drives, held by one driver at a time (None: nothing shared)
    device_id: str | None

    def open(self) -> None: ...

    def read(self) -> RawSample: ...

    def write(self, u_linear: float, u_rotary: float) -> None: ...

    def heartbeat(self, level: bool) -> None: ...

    def close(self) -> None: ...


class SteppablePlant(Protocol):
    def step(self, u_lin: float, u_rot: float) -> SensorSample: ...


class SimBackend:
    """A plant seen through the DAQ: SI samples are turned back into volts and counts.

    Timing as on the rig: a value written is emitted at the next tick, so
    :meth:`read` at tick k+1 advances the plant over [k, k+1] under the output
    that was current at tick k (DESIGN §3; the in-process runner does the same).
    """

    hardware_paced = False
    device_id = None  # a plant in this process: nothing to share

    def __init__(self, plant: SteppablePlant, rig: RigParams):
        if not callable(getattr(plant, "step", None)):
            raise TypeError(f"plant: {type(plant).__name__} has no step(u_lin, u_rot) method")
        self.plant = plant
        self.rig = rig
        self._scaler = Scaler(rig)
        safe = rig.ao.safe_v
        self._u_current = (safe, safe)  # written, emitted at the next tick
        self._u_held = (safe, safe)  # what the plant sees during the current period
        self.is_open = False
        self.reads = 0
        self.writes = 0
        self.heartbeat_level = False
        self.heartbeat_edges = 0

    @property
    def last_written(self) -> tuple[float, float]:
        return self._u_current

    def open(self) -> None:
        safe = self.rig.ao.safe_v
        self._u_current = self._u_held = (safe, safe)
        self.is_open = True

    def read(self) -> RawSample:
        s = self.plant.step(*self._u_held)
        self._u_held = self._u_current
        self.reads += 1
        return self._scaler.raw(s)

    def write(self, u_linear: float, u_rotary: float) -> None:
        ao = self.rig.ao
        self._u_current = (ao_volts(u_linear, ao), ao_volts(u_rotary, ao))
        self.writes += 1

    def heartbeat(self, level: bool) -> None:
        level = bool(level)
        self.heartbeat_edges += level != self.heartbeat_level
        self.heartbeat_level = level

    def close(self) -> None:
        safe = self.rig.ao.safe_v
        self._u_current = (safe, safe)
        self.is_open = False
