"""Fault injection for the twin: what breaks, when, and how the DAQ would see it.

A fault is a :class:`FaultSpec`: a name from :data:`FAULT_NAMES`, a start
time, a duration and the fault's own parameters (one frozen dataclass per
kind, validated by :mod:`pneu_msgs_py.params.core`). ``pneu run --fault`` takes
``NAME[:key=value,...]`` (:func:`parse_fault`), e.g.
``controller_silent:axis=linear,start_s=1,duration_s=0.5``.

Timing: a fault is active for the samples k with k0 <= k < k1, where
k0 = round(start_s / T) and k1 = k0 + max(1, round(duration_s / T)).

:class:`FaultInjector` applies the active faults once per cycle, at the
three places where the real thing happens:

- :meth:`~FaultInjector.sample` -- the sensors and the DAQ: sample k as read,
  and the raw AI volts (p_c1, p_c2, p_m1, laser) the driver's scaling would
  have turned into it (:class:`SensorScaling`); at k0 / k1 it also swaps the
  plant parameters (supply drop, added mass) for the coming step;
- :meth:`~FaultInjector.silent` / :meth:`~FaultInjector.command` -- the
  controller (a hung node publishes nothing; a broken one publishes NaN);
- :meth:`~FaultInjector.valves` -- the valve spool (stuck at a voltage,
  whatever is written).

Sensor faults are applied to the sample *after* the plant has produced it
(the sensors are modelled inside the numba kernel); the raw volts are derived
from the SI value with the twin's own sensor scaling, which is the inverse of
``config/rig.yaml``'s (Huba 511: 1e5 Pa/V from p_a; HG-C1200: 0.032 m/V about
2.5 V), and clipped to the channel's AI range as the DAQ would.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from pneu_msgs_py.contract.samples import AXES, SensorSample
from pneu_msgs_py.params.core import ParamError, from_dict, param, to_dict, validate
from pneu_msgs_py.params.spec import parse_spec

__all__ = [
    "FAULT_NAMES",
    "FAULT_PARAMS",
    "SENSOR_AXIS",
    "FaultInjector",
    "FaultSpec",
    "SensorScaling",
    "parse_fault",
    "parse_faults",
]

SENSORS = ("p_c1", "p_c2", "p_m1", "x", "encoder")
ANALOG = ("p_c1", "p_c2", "p_m1", "x")  # raw-volts order (p_c1, p_c2, p_m1, laser)
SENSOR_AXIS = {
    "p_c1": "linear",
    "p_c2": "linear",
    "x": "linear",
    "p_m1": "rotary",
    "encoder": "rotary",
}
AXIS_CHOICES = ("linear", "rotary", "both")
_TWO_PI = 2.0 * math.pi


# ------------------------------------------------------------------ parameters
@dataclass(frozen=True)
class SensorDropoutParams:
    """The sensor delivers no value: NaN (encoder: θ, ω NaN, the count held)."""

    sensor: str = param("x", choices=SENSORS, desc="which sensor drops out")


@dataclass(frozen=True)
class StuckSensorParams:
    """The reading freezes at its value at the fault's start (encoder: the count freezes)."""

    sensor: str = param("x", choices=SENSORS, desc="which sensor freezes")


@dataclass(frozen=True)
class NoiseBurstParams:
    """Gaussian noise added to the sensor's output voltage (EMI burst)."""

    sensor: str = param("x", choices=ANALOG, desc="which analog sensor")
    sigma_v: float = param(3.0, unit="V", lo=0.0, lo_open=True, hi=20.0, desc="noise (1 σ)")


@dataclass(frozen=True)
class BrokenWireParams:
    """The signal wire is cut: the AI reads ``volts`` (clipped to the channel's AI range).

    Default: the negative rail, what an open input pulled toward its negative
    bias reads. A cut wire that reads 0 V is plausible on a 0–10 V pressure
    sensor (0 V = atmospheric): ``volts=0`` shows that hole (the injected level
    is noise-free, so only the frozen-value rule can catch it).
    """

    sensor: str = param("x", choices=ANALOG, desc="which analog sensor")
    volts: float = param(-10.0, unit="V", lo=-10.5, hi=10.5, desc="what the open input reads")


@dataclass(frozen=True)
class EncoderMissedParams:
    """The counter misses this share of the encoder's edges (noise, a dirty disk)."""

    fraction: float = param(
        1.0,
        lo=0.0,
        lo_open=True,
        hi=1.0,
        desc="share of counts lost while active (1 = none counted)",
    )


@dataclass(frozen=True)
class ValveStuckParams:
    """The spool sticks: the valve acts as if ``volts`` were written, whatever is written."""

    axis: str = param("linear", choices=AXES, desc="which valve")
    volts: float = param(10.0, unit="V", lo=0.0, hi=10.0, desc="spool position, as a voltage")


@dataclass(frozen=True)
class SupplyDropParams:
    """The supply falls to ``factor`` of its gauge pressure (compressor, regulator)."""

    axis: str = param("both", choices=AXIS_CHOICES, desc="which valve's supply")
    factor: float = param(
        0.5, lo=0.0, lo_open=True, hi=1.0, hi_open=True, desc="gauge supply left (share)"
    )


@dataclass(frozen=True)
class AddedMassParams:
    """A load of ``mass_kg`` is added to the piston's moving mass M (Eq. 1)."""

    mass_kg: float = param(2.0, unit="kg", lo=0.0, lo_open=True, hi=100.0, desc="added load")


@dataclass(frozen=True)
class ControllerFaultParams:
    """Which controller fails (``both`` = every active one)."""

    axis: str = param("both", choices=AXIS_CHOICES, desc="which controller")


FAULT_PARAMS: dict[str, type] = {
    "sensor_dropout": SensorDropoutParams,
    "stuck_sensor": StuckSensorParams,
    "noise_burst": NoiseBurstParams,
    "broken_wire": BrokenWireParams,
    "encoder_missed": EncoderMissedParams,
    "valve_stuck": ValveStuckParams,
    "supply_drop": SupplyDropParams,
    "added_mass": AddedMassParams,
    "controller_silent": ControllerFaultParams,  # the node hangs: no command, no state
    "controller_nan": ControllerFaultParams,  # the node publishes NaN commands
}
FAULT_NAMES = tuple(FAULT_PARAMS)
_SENSOR_FAULTS = ("sensor_dropout", "stuck_sensor", "noise_burst", "broken_wire", "encoder_missed")


@dataclass(frozen=True)
class FaultSpec:
    """One injected fault: ``name`` (:data:`FAULT_NAMES`), when, and its parameters."""

    name: str
    start_s: float = 1.0
    duration_s: float = 1.0
    params: Any = None

    def __post_init__(self) -> None:
        if self.name not in FAULT_PARAMS:
            raise ParamError("fault", self.name, "one of " + ", ".join(FAULT_NAMES))
        for key, lo_open in (("start_s", False), ("duration_s", True)):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ParamError(f"{self.name}.{key}", v, "a finite number of seconds")
            if v < 0.0 or (lo_open and v == 0.0):
                raise ParamError(f"{self.name}.{key}", v, "(0, inf) s" if lo_open else "[0, inf) s")
            object.__setattr__(self, key, float(v))
        cls = FAULT_PARAMS[self.name]
        if self.params is None:
            object.__setattr__(self, "params", cls())
        elif not isinstance(self.params, cls):
            raise ParamError(f"{self.name}.params", self.params, f"a {cls.__name__}")
        try:
            validate(self.params)
        except ParamError as err:
            raise ParamError(f"{self.name}.{err.key}", err.value, err.allowed) from None

    @property
    def end_s(self) -> float:
        return self.start_s + self.duration_s

    def axes(self, active: tuple[str, ...] = AXES) -> tuple[str, ...]:
        """The axes this fault acts on (restricted to ``active`` for controller faults)."""
        p = self.params
        if self.name in ("sensor_dropout", "stuck_sensor", "noise_burst", "broken_wire"):
            return (SENSOR_AXIS[p.sensor],)
        if self.name == "encoder_missed":
            return ("rotary",)
        if self.name == "added_mass":
            return ("linear",)
        if self.name == "valve_stuck":
            return (p.axis,)
        chosen = AXES if p.axis == "both" else (p.axis,)
        if self.name.startswith("controller_"):
            return tuple(a for a in chosen if a in active)
        return chosen

    @property
    def label(self) -> str:
        """``NAME:k=v,...`` (the parameters only), as :func:`parse_fault` reads it back."""
        kv = ",".join(f"{k}={v}" for k, v in to_dict(self.params).items())
        return f"{self.name}:{kv}" if kv else self.name

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "start_s": self.start_s,
            "duration_s": self.duration_s,
            "params": to_dict(self.params),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FaultSpec:
        name = d.get("name")
        if name not in FAULT_PARAMS:
            raise ParamError("fault", name, "one of " + ", ".join(FAULT_NAMES))
        params = from_dict(
            FAULT_PARAMS[name], d.get("params") or {}, strict=False, prefix=f"{name}."
        )
        return cls(name, d.get("start_s", 1.0), d.get("duration_s", 1.0), params)


def parse_fault(text: str) -> FaultSpec:
    """``NAME[:key=value,...]`` -> :class:`FaultSpec`; keys ``start_s``, ``duration_s`` and the fault's own.

    Raises :class:`ParamError` naming the field, the value and what is allowed.
    """
    name, kv = parse_spec(text, "--fault")
    if name not in FAULT_PARAMS:
        raise ParamError("--fault", name, "one of " + ", ".join(FAULT_NAMES))
    timing = {k: kv.pop(k) for k in ("start_s", "duration_s") if k in kv}
    params = from_dict(FAULT_PARAMS[name], kv, strict=False, prefix=f"{name}.")
    return FaultSpec(name, params=params, **timing)


def parse_faults(items: Any) -> tuple[FaultSpec, ...]:
    """Strings, dicts or :class:`FaultSpec` objects -> a tuple of specs (all validated first)."""
    out = []
    for it in items or ():
        if isinstance(it, FaultSpec):
            out.append(it)
        elif isinstance(it, dict):
            out.append(FaultSpec.from_dict(it))
        else:
            out.append(parse_fault(str(it)))
    return tuple(out)


# --------------------------------------------------------------------- scaling
class SensorScaling:
    """SI ↔ raw AI volts of the twin's analog sensors (the inverse of the driver's scaling).

    Huba 511: v = (p − p_a)·v_fs/fs (gauge sensor, 0–10 bar ↔ 0–10 V);
    HG-C1200: v = x·v_fs/range + v_fs/2 (span centred on x = 0).
    """

    def __init__(self, plant_params: Any):
        s = plant_params.sensors
        self.p_a = plant_params.ambient.p_a
        self.v_per_pa = s.pressure.v_fs / s.pressure.fs
        self.v_per_m = s.laser.v_fs / s.laser.range_m
        self.v_mid = 0.5 * s.laser.v_fs
        d = s.daq
        self.ai_range = {
            "p_c1": d.ai_range_pressure,
            "p_c2": d.ai_range_pressure,
            "p_m1": d.ai_range_pressure,
            "x": d.ai_range_laser,
        }
        self.cpr = 4 * s.encoder.ppr

    def volts(self, s: SensorSample) -> tuple[float, float, float, float]:
        """Raw volts (p_c1, p_c2, p_m1, laser) of sample ``s``."""
        k, pa = self.v_per_pa, self.p_a
        return (
            (s.p_c1 - pa) * k,
            (s.p_c2 - pa) * k,
            (s.p_m1 - pa) * k,
            s.x * self.v_per_m + self.v_mid,
        )

    def to_si(self, sensor: str, v: float) -> float:
        if sensor == "x":
            return (v - self.v_mid) / self.v_per_m
        return self.p_a + v / self.v_per_pa

    def to_volts(self, sensor: str, value: float) -> float:
        if sensor == "x":
            return value * self.v_per_m + self.v_mid
        return (value - self.p_a) * self.v_per_pa

    def clip(self, sensor: str, v: float) -> float:
        """What the DAQ reads of ``v`` (AI range; NaN stays NaN)."""
        r = self.ai_range[sensor]
        return min(max(v, -r), r) if math.isfinite(v) else v


# -------------------------------------------------------------------- injector
class FaultInjector:
    """Applies ``faults`` to one run of ``plant`` (a :class:`pneu_sim.physics.plant.Plant`).

    Call per cycle k, in this order: :meth:`sample` (every cycle),
    :meth:`silent` / :meth:`command` per controller, :meth:`valves` before the
    plant steps. Deterministic: noise comes from ``seed``.
    """

    def __init__(self, faults: Any, plant: Any, seed: int = 0, active_axes: tuple[str, ...] = AXES):
        self.faults = parse_faults(faults)
        self.plant = plant
        self.active_axes = tuple(active_axes)
        self.scaling = SensorScaling(plant.params)
        T = plant.T
        self.windows = []
        for f in self.faults:
            k0 = int(round(f.start_s / T))
            self.windows.append((k0, k0 + max(1, int(round(f.duration_s / T)))))
        self._base_params = plant.params
        self._rng = [
            np.random.Generator(np.random.PCG64([int(seed), 6, i])) for i in range(len(self.faults))
        ]
        self._frozen: dict[int, float] = {}  # fault index -> frozen volts
        self._last_true: int | None = None  # encoder: true count of the last sample
        self._lost = 0.0  # counts lost so far
        self._prev_reported: int | None = None
        self._touched = False  # the last sample's encoder fields were rewritten
        self._plant_faults_on: set[int] = set()

    def _active(self, i: int, k: int) -> bool:
        k0, k1 = self.windows[i]
        return k0 <= k < k1

    def active(self, k: int) -> list[FaultSpec]:
        """The faults active at sample k."""
        return [f for i, f in enumerate(self.faults) if self._active(i, k)]

    def cycles(self, i: int) -> tuple[int, int]:
        """(k0, k1) of fault i: active for k0 <= k < k1."""
        return self.windows[i]

    # -- sensors and plant -------------------------------------------------------
    def sample(self, k: int, s: SensorSample) -> tuple[SensorSample, tuple[float, ...]]:
        """Sample k as the DAQ reads it (``s`` modified in place) and its raw AI volts.

        Encoder faults lose counts (a counter that misses edges, is stuck or has
        no signal does not catch up later): reported = true − lost, θ and ω are
        recomputed from the reported counts; a dropout also makes θ, ω NaN.
        """
        self._plant_edges(k)
        sc = self.scaling
        base = sc.volts(s)
        volts = list(base)
        true_counts = s.counts
        dc = 0 if self._last_true is None else true_counts - self._last_true
        self._last_true = true_counts
        lose = 0.0
        enc_nan = False
        for i, f in enumerate(self.faults):
            name = f.name
            if name not in _SENSOR_FAULTS:
                continue
            if not self._active(i, k):
                self._frozen.pop(i, None)
                continue
            p = f.params
            if name == "encoder_missed":
                lose = max(lose, p.fraction)
            elif p.sensor == "encoder":  # dropout or stuck: nothing counted
                lose = 1.0
                enc_nan = enc_nan or name == "sensor_dropout"
            else:
                j = ANALOG.index(p.sensor)
                if name == "sensor_dropout":
                    volts[j] = math.nan
                elif name == "stuck_sensor":
                    volts[j] = self._frozen.setdefault(i, volts[j])
                elif name == "noise_burst":
                    noise = p.sigma_v * float(self._rng[i].standard_normal())
                    volts[j] = sc.clip(p.sensor, volts[j] + noise)
                else:  # broken_wire
                    volts[j] = sc.clip(p.sensor, p.volts)
        for j, name in enumerate(ANALOG):
            if volts[j] != base[j]:  # also True for NaN
                setattr(s, name, sc.to_si(name, volts[j]))
        self._lost += lose * dc
        reported = true_counts - int(round(self._lost))
        prev = self._prev_reported
        self._prev_reported = reported
        if reported != true_counts or enc_nan or self._touched:
            self._touched = reported != true_counts
            s.counts = reported
            if enc_nan:
                s.theta = s.omega = math.nan
            else:
                s.theta = reported * _TWO_PI / sc.cpr
                s.omega = (
                    (reported - (reported if prev is None else prev))
                    * _TWO_PI
                    / (sc.cpr * self.plant.T)
                )
        return s, tuple(volts)

    def _plant_edges(self, k: int) -> None:
        """Swap the plant parameters when a plant fault starts or ends (effective for the step k -> k+1)."""
        changed = False
        for i, f in enumerate(self.faults):
            if f.name not in ("supply_drop", "added_mass"):
                continue
            on = self._active(i, k)
            if on != (i in self._plant_faults_on):
                changed = True
                (self._plant_faults_on.add if on else self._plant_faults_on.discard)(i)
        if changed:
            self.plant.set_params(self._faulty_params())

    def _faulty_params(self) -> Any:
        prm = self._base_params
        for i in sorted(self._plant_faults_on):
            f = self.faults[i]
            p = f.params
            if f.name == "added_mass":
                prm = replace(prm, linear=replace(prm.linear, M=prm.linear.M + p.mass_kg))
            else:
                p_a = prm.ambient.p_a
                upd = {}
                for axis, key in (("linear", "p_s_linear"), ("rotary", "p_s_rotary")):
                    if p.axis in (axis, "both"):
                        upd[key] = p_a + p.factor * (getattr(prm.supply, key) - p_a)
                prm = replace(prm, supply=replace(prm.supply, **upd))
        return prm

    # -- controllers and valves ------------------------------------------------------
    def silent(self, k: int, axis: str) -> bool:
        """The ``axis`` controller publishes nothing at sample k (hung node)."""
        for i, f in enumerate(self.faults):
            if f.name == "controller_silent" and self._active(i, k) and axis in f.axes(AXES):
                return True
        return False

    def command(self, k: int, axis: str, u: float) -> float:
        """The command the ``axis`` controller publishes at sample k."""
        for i, f in enumerate(self.faults):
            if f.name == "controller_nan" and self._active(i, k) and axis in f.axes(AXES):
                return math.nan
        return u

    def valves(self, k: int, u_linear: float, u_rotary: float) -> tuple[float, float]:
        """What the valves do during the step k -> k+1 given the written voltages."""
        for i, f in enumerate(self.faults):
            if f.name == "valve_stuck" and self._active(i, k):
                if f.params.axis == "linear":
                    u_linear = f.params.volts
                else:
                    u_rotary = f.params.volts
        return u_linear, u_rotary
