"""The twin wired as the DAQ: a simulated PCI-6221 behind the driver's backend interface.

:class:`TwinDaq` implements :class:`pneu_driver.daq.backend.DaqBackend` the way
:class:`pneu_driver.daq.nidaqmx_backend.NidaqmxBackend` does it on the rig, so
the driver's 1 kHz loop (:class:`pneu_driver.loop.driver_loop.DriverLoop`)
runs end to end without hardware -- scaling, safety, late-cycle counting,
heartbeat, bags:

- **volts in, volts and counts out.** The valve voltages drive the twin
  (:class:`pneu_sim.physics.plant.Plant`); the four AI channels carry the
  twin's sensor voltages through its own sensor model (``config/plant.yaml``,
  :class:`pneu_sim.faults.injection.SensorScaling`), clipped to the AI range;
  the counter carries the encoder count. The driver turns them back into SI
  with ``config/rig.yaml``'s calibration, as on the rig: a calibration that
  disagrees with the sensors shows up here as it would there.
- **the same clock.** A sample clock at ``loop.rate_hz`` on the monotonic
  clock: ``read`` blocks until the next tick (HW-timed single point); the twin
  steps once per tick whether or not the program keeps up. A value written
  after reading sample k is emitted at clock k+1 (the one-sample delay).
- **late cycles as DAQmx reports them** (``loop.report_missed_samples``, with
  no warm-up iterations, as the rig's backend sets it): a read that finds clocks gone by returns the
  newest sample and raises :class:`~pneu_driver.daq.errors.LateCycleError`
  with -209800 (-201027 for three or more), a write made after its clock
  -209801. ``stalls`` inject program stalls: the write at or after each
  ``(t_s, dur_s)`` first sleeps ``dur_s``.
- **outputs that outlive the process** (:class:`~pneu_sim.daq_sim.card.CardRegister`):
  the AO voltages and the heartbeat line are in a register, in a file if
  ``card`` names one. Killed, the process leaves them as they were -- the
  real card's behaviour -- and ``open`` writes 5 V first, as the rig's does.

Lives in pneu_sim because it needs the plant and the twin's sensor model;
pneu_driver finds it by name through the ``pneu_driver.backends`` entry point
(``backend: sim``) without importing pneu_sim (DESIGN §2).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from typing import Any

from pneu_driver.daq.errors import LateCycleError
from pneu_driver.daq.rig import RigParams
from pneu_driver.daq.scaling import RawSample, ao_volts
from pneu_msgs_py.lifecycle.duration import MAX_DURATION_S
from pneu_msgs_py.params.core import ParamError

from pneu_sim.daq_sim.card import CardRegister
from pneu_sim.faults.injection import SensorScaling

__all__ = ["TwinDaq", "make_backend", "OPTIONS", "WARMUP_ITERATIONS"]

# DAQmx_RealTime_NumOfWarmupIters as NidaqmxBackend sets it (NI's default is 100)
WARMUP_ITERATIONS = 0
_ANALOG = ("p_c1", "p_c2", "p_m1", "x")


class TwinDaq:
    """The simulated card around a stepped plant (``step(u_l, u_r) -> SensorSample``, ``params``, ``T``).

    ``clock_ns`` / ``sleep``: the monotonic clock and sleep (injectable: tests run
    on simulated time). ``stalls``: ``(t_s, dur_s)`` pairs in card time.
    """

    hardware_paced = True

    def __init__(
        self,
        rig: RigParams,
        plant: Any,
        *,
        card: CardRegister | None = None,
        stalls: Iterable[tuple[float, float]] = (),
        clock_ns: Callable[[], int] = time.perf_counter_ns,
        sleep: Callable[[float], None] = time.sleep,
        warmup: int = WARMUP_ITERATIONS,
    ):
        if abs(plant.T - rig.period_s) > 1e-12:
            raise ParamError("loop.rate_hz", rig.loop.rate_hz, f"1 / sim.T = {1.0 / plant.T:g} Hz")
        self.rig = rig
        self.plant = plant
        self.card = card if card is not None else CardRegister()
        # a card in a file outlives the process and may be driven from another: claim it
        self.device_id = f"card:{self.card.path.resolve()}" if self.card.path else None
        self._scaling = SensorScaling(plant.params)
        self._stalls = sorted((float(t), float(d)) for t, d in stalls)
        self._clock = clock_ns
        self._sleep = sleep
        self._warmup = int(warmup)
        self._report = rig.loop.report_missed_samples
        self._T = rig.period_ns
        self._spin = round(rig.loop.spin_us * 1e3)
        self._lo, self._hi = rig.ai.min_v, rig.ai.max_v
        safe = rig.ao.safe_v
        self._emitted = (safe, safe)  # what the DACs drive
        self._pending: tuple[float, float, int] | None = None  # written, not yet clocked
        self._sample = None
        self._t0 = 0
        self._tick = 0  # the plant's state is at this clock
        self._next = 1  # the clock the next read returns
        self.reads = 0
        self.is_open = False

    # -------------------------------------------------------------- lifecycle
    def open(self) -> None:
        """Valves safe at once (on demand), the clock starts; the twin is at its sample 0."""
        self.card.claim()
        self._emit(self.rig.ao.safe_v, self.rig.ao.safe_v)
        self.card.set_do(False)
        if self._sample is None:  # the first step compiles the kernel: not on the clock
            self.plant.step(*self._emitted)
            self._sample = self.plant.reset()  # the noise stream restarts from the seed
        self._t0 = self._clock()
        self._tick, self._next, self.reads = 0, 1, 0
        self._pending = None
        self.is_open = True

    def close(self) -> None:
        """The on-demand safe write; the clock stops (the twin is no longer stepped)."""
        self._emit(self.rig.ao.safe_v, self.rig.ao.safe_v)
        self._pending = None
        self.is_open = False

    # ------------------------------------------------------------------ cycle
    def read(self) -> RawSample:
        now = self._clock()
        due = self._t0 + self._next * self._T
        if now < due:
            self._wait_until(due)
            newest = self._next
        else:  # clocks went by: the newest sample; the ones between are lost
            newest = (now - self._t0) // self._T
        missed = newest - self._next
        self._advance(newest)
        self._next = newest + 1
        self.reads += 1
        if missed and self._report and self.reads > self._warmup:
            raise LateCycleError((-201027 if missed >= 3 else -209800,))
        return self._raw()

    def write(self, u_linear: float, u_rotary: float) -> None:
        ao = self.rig.ao
        now = self._clock()
        if self._stalls and now >= self._t0 + round(self._stalls[0][0] * 1e9):
            self._sleep(self._stalls.pop(0)[1])  # the program stalls before its write
            now = self._clock()
        self._pending = (ao_volts(u_linear, ao), ao_volts(u_rotary, ao), now)
        if now >= self._t0 + self._next * self._T:  # its clock (k+1) has gone by
            raise LateCycleError((-209801,))

    def heartbeat(self, level: bool) -> None:
        self.card.set_do(level)

    # --------------------------------------------------------------- internal
    def _advance(self, tick: int) -> None:
        """Step the twin clock by clock up to ``tick`` under what the DACs drive."""
        plant = self.plant
        for i in range(self._tick, tick):
            self._clock_out(i)
            self._sample = plant.step(*self._emitted)
        self._clock_out(tick)
        self._tick = tick
        self.card.set_tick(tick)

    def _clock_out(self, i: int) -> None:
        """Clock ``i``: a value written before it goes to the DACs."""
        p = self._pending
        if p is not None and p[2] < self._t0 + i * self._T:
            self._emit(p[0], p[1])
            self._pending = None

    def _emit(self, u_l: float, u_r: float) -> None:
        self._emitted = (u_l, u_r)
        self.card.set_ao(u_l, u_r)

    def _raw(self) -> RawSample:
        s = self._sample
        sc, lo, hi = self._scaling, self._lo, self._hi
        volts = sc.volts(s)
        clipped = []
        for name, v in zip(_ANALOG, volts, strict=True):
            v = sc.clip(name, v)  # the sensor's own output range
            clipped.append(min(max(v, lo), hi) if math.isfinite(v) else v)
        return RawSample((clipped[0], clipped[1], clipped[2], clipped[3]), int(s.counts))

    def _wait_until(self, deadline: int) -> None:
        clock = self._clock
        remaining = deadline - clock()
        if remaining > self._spin:
            self._sleep((remaining - self._spin) * 1e-9)
        while clock() < deadline:
            pass


# options of ``backend: sim[:key=value,...]``: name -> (type, default, description)
OPTIONS: dict[str, tuple[type, Any, str]] = {
    "seed": (int, 0, "the twin's noise seed"),
    "plant": (str, "", "plant.yaml ('' = the project's config/plant.yaml)"),
    "card": (str, "", "file holding the card's outputs across processes ('' = in memory)"),
    "stall_at_s": (float, -1.0, "inject one program stall at this card time (< 0: none)"),
    "stall_ms": (float, 3.0, "length of that stall"),
}
_TYPE_NAMES = {int: "an integer", float: "a number", str: "a string"}
SEED_MAX = 2**32 - 1  # numpy's SeedSequence takes it whole (as every pneu --seed)


def check_options(**options: Any) -> dict[str, Any]:
    """Every option of ``sim[:...]`` with its default, checked: an unknown, mistyped or
    out-of-range one is refused with one line naming it (nothing is opened)."""
    values: dict[str, Any] = {}
    for key, value in options.items():
        if key not in OPTIONS:
            raise ParamError(f"backend sim {key}", value, "one of " + ", ".join(OPTIONS))
        typ = OPTIONS[key][0]
        if typ is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if typ is str and not isinstance(value, str):
            value = str(value)
        if not isinstance(value, typ) or isinstance(value, bool):
            raise ParamError(f"backend sim {key}", value, _TYPE_NAMES[typ])
        values[key] = value
    opt = {k: values.get(k, d) for k, (_t, d, _s) in OPTIONS.items()}
    if not 0 <= opt["seed"] <= SEED_MAX:
        raise ParamError("backend sim seed", opt["seed"], f"an integer in [0, {SEED_MAX}]")
    cap = MAX_DURATION_S  # a stall after the longest run, or longer than it, never happens
    if not (opt["stall_at_s"] < 0.0 or opt["stall_at_s"] <= cap):
        raise ParamError(
            "backend sim stall_at_s", opt["stall_at_s"], f"< 0 (no stall) or [0, {cap:g}] s"
        )
    if not 0.0 < opt["stall_ms"] <= cap * 1e3:
        raise ParamError(
            "backend sim stall_ms", opt["stall_ms"], f"(0, {cap * 1e3:g}] ms (the duration cap)"
        )
    if opt["plant"]:  # read (strictly) now: refused before anything is opened
        from pneu_msgs_py.params.yaml_file import from_option

        from pneu_sim.physics.plant_file import load_plant

        with from_option("backend sim plant"):
            load_plant(opt["plant"])
    return opt


def make_backend(rig: RigParams, **options: Any) -> TwinDaq:
    """``backend: sim[:seed=0,plant=...,card=...,stall_at_s=...,stall_ms=...]`` (entry point;
    its options checked by :func:`check_options`, also before anything is opened)."""
    from pneu_sim.physics.plant import Plant
    from pneu_sim.physics.plant_file import load_plant

    opt = check_options(**options)
    plant = Plant(load_plant(opt["plant"] or None), seed=opt["seed"])
    stalls = [(opt["stall_at_s"], opt["stall_ms"] * 1e-3)] if opt["stall_at_s"] >= 0.0 else []
    card = CardRegister(opt["card"] or None)
    return TwinDaq(rig, plant, card=card, stalls=stalls)


make_backend.check_options = check_options  # pneu_driver.daq.backends.check_backend
