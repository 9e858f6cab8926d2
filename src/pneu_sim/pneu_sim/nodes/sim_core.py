"""The sim node's cycle bookkeeping, without ROS: which command drives which step.

DESIGN §3, the same cycle as the in-process runner (``pneu_control.experiment.runner``):
sample s_k is published; each active controller answers with u_k, stamped
with s_k's stamp; u_k is written at tick k+1 and held until k+2, so the
plant steps from k to k+1 under u_{k-1} (the neutral 5 V before the first
answer). Inactive axes hold the neutral 5 V.

Two modes:

``lockstep``
    :meth:`LockstepCore.offer` accepts only an answer to the current
    sample; the node advances when :attr:`complete` (every active axis
    answered) or when its wall-clock timeout fires -- then the missing axes
    keep their previous command and the miss is counted in :attr:`timeouts`.
    Deterministic: same config and seed -> the runner's numbers.
``realtime``
    The node advances on a 1 kHz wall-clock tick; the newest answer received
    since the last tick is written (what a DAQ would do), answers to older
    samples than the newest accepted are dropped (:attr:`stale`), a period
    without a fresh answer is counted in :attr:`missed`.

Per cycle k, in the runner's order (``pneu_control.experiment.runner.run``): sample
s_k, with injected faults (:class:`pneu_sim.faults.injection.FaultInjector`) -> the
``supervisor`` (:class:`pneu_driver.safety.supervisor.SafetySupervisor`:
``check_sample(sample, volts)``, ``outputs(now_ns)``, ``command(axis, u,
stamp_ns)``) checks it and gives the tick-k output (u_{k-1} after its
rules) -> the controllers' answers u_k go to it -> the plant steps k -> k+1
under the tick-k output (through a stuck valve if one is injected). Without
a supervisor the DAQ holds the last finite answer.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from pneu_msgs_py.contract.convert import fill_fluid_pressure, fill_joint_state, sample_to_values
from pneu_msgs_py.contract.samples import AXES, NEUTRAL_V, SensorSample
from pneu_msgs_py.contract.topics import PRESSURE_TOPICS
from pneu_msgs_py.params.core import ParamError, param

__all__ = [
    "MODES",
    "LockstepCore",
    "SimNodeParams",
    "active_axes",
    "fill_sample_messages",
    "load_faults",
    "safety_statuses",
]

MODES = ("lockstep", "realtime")
AXES_CHOICES = ("linear", "rotary", "both", "none")


def fill_sample_messages(
    msgs: Mapping[str, Any], s: SensorSample, variances: Mapping[str, float] | None = None
) -> None:
    """Fill the five sensor messages of sample ``s`` in place (``{topic: message}``).

    Pressures: FluidPressure (Pa abs, ``variance`` in Pa^2 per topic if given);
    joint states: JointState as :func:`pneu_msgs_py.contract.convert.sample_to_values`
    lays them out. All stamped with ``s.stamp_ns``.
    """
    for topic, (frame, names, pos, vel) in sample_to_values(s).items():
        m = msgs[topic]
        if topic in PRESSURE_TOPICS:
            var = variances.get(topic, 0.0) if variances else 0.0
            fill_fluid_pressure(m, s.stamp_ns, pos[0], frame, var)
        else:
            fill_joint_state(m, s.stamp_ns, names, pos, vel)


def load_faults(text: str = "", path: str = "") -> tuple[Any, ...]:
    """Fault specs from ``NAME[:k=v,...]`` items separated by ``;`` and/or a YAML file.

    The file holds a list of ``{name, start_s, duration_s, params}`` mappings
    (or a mapping with that list under ``faults``). Everything is validated
    (:func:`pneu_sim.faults.injection.parse_faults`) before anything runs.
    """
    from pneu_sim.faults.injection import parse_faults

    items: list[Any] = [t for t in (p.strip() for p in text.split(";")) if t]
    if path:
        import yaml

        with open(path, encoding="utf-8") as fh:
            data = yaml.safe_load(fh) or []
        if isinstance(data, Mapping):
            data = data.get("faults", [])
        if not isinstance(data, list):
            raise ParamError("faults_file", path, "a YAML list of faults (or faults: [...])")
        items.extend(data)
    return parse_faults(items)


def safety_statuses(node: str, events: Any) -> list[Any]:
    """Supervisor transitions as ``/diagnostics`` statuses, named ``<node>: safety <axis> <rule>``.

    The name is the one :mod:`pneu_control.analysis.fault_marks` parses (runner, sim
    node and driver alike), so ``pneu analyze`` finds the safe intervals.
    """
    from pneu_msgs_py.contract.convert import DiagStatus

    level = {"OK": 0, "WARN": 1, "ERROR": 2}
    return [
        DiagStatus(
            level[e.level], f"{node}: safety {e.axis} {e.rule}", e.message, "twin", dict(e.values)
        )
        for e in events
    ]


def active_axes(choice: str) -> tuple[str, ...]:
    """``"both"`` -> ``("linear", "rotary")``; ``"none"`` -> ``()`` (open loop)."""
    if choice not in AXES_CHOICES:
        raise ParamError("axes", choice, "one of " + ", ".join(AXES_CHOICES))
    if choice == "both":
        return AXES
    return () if choice == "none" else (choice,)


@dataclass(frozen=True)
class LockstepParams:
    timeout_s: float = param(
        2.0,
        unit="s",
        desc="wall-clock time to wait for every active controller's answer before advancing "
        "without it (counted as a timeout)",
        lo=0.0,
        lo_open=True,
        hi=60.0,
    )
    min_subscribers: int = param(
        1,
        desc="before sample 0: wait until every sensor topic has this many matched subscriptions "
        "(active controllers + logger) and every active axis' command topic has a publisher",
        lo=0,
        hi=64,
        read_only=True,
    )
    settle_s: float = param(
        1.0,
        unit="s",
        desc="once the subscribers are there, wait this long before sample 0 so that the other "
        "connections (controllers -> logger) are matched too",
        lo=0.0,
        hi=60.0,
        read_only=True,
    )
    startup_timeout_s: float = param(
        30.0,
        unit="s",
        desc="start anyway (with a warning) after waiting this long for subscribers",
        lo=0.0,
        hi=3600.0,
        read_only=True,
    )


@dataclass(frozen=True)
class SimNodeParams:
    """Parameters of ``pneu_sim sim_node`` (the plant itself comes from plant.yaml)."""

    mode: str = param(
        "lockstep",
        desc="lockstep: publish /clock and wait for every active controller; "
        "realtime: paced by the wall clock at 1/T",
        choices=MODES,
        read_only=True,
    )
    axes: str = param(
        "both",
        desc="axes with an active controller (the others hold 5 V)",
        choices=AXES_CHOICES,
        read_only=True,
    )
    duration_s: float = param(
        0.0,
        unit="s",
        desc="simulated time after which the node stops and exits (0 = run until stopped)",
        lo=0.0,
        hi=86400.0,
        read_only=True,
    )
    seed: int = param(0, desc="noise seed of the twin", lo=0, hi=2**31 - 1, read_only=True)
    x0: float = param(
        0.0, unit="m", desc="initial piston position", lo=-0.075, hi=0.075, read_only=True
    )
    plant_file: str = param(
        "", desc="plant YAML ('' = plant.yaml of the installed config)", read_only=True
    )
    safety: bool = param(
        True,
        desc="put the SafetySupervisor (safety_file) between the commands and the plant, as on "
        "the rig; transparent unless a rule trips",
        read_only=True,
    )
    safety_file: str = param(
        "", desc="safety YAML ('' = safety.yaml of the installed config)", read_only=True
    )
    faults: str = param(
        "",
        desc="injected faults, ';'-separated NAME[:key=value,...] as pneu run --fault takes them, "
        "e.g. 'sensor_dropout:sensor=x,start_s=2,duration_s=0.5'",
        read_only=True,
    )
    faults_file: str = param(
        "",
        desc="YAML list of faults ({name, start_s, duration_s, params}); added to 'faults'",
        read_only=True,
    )
    lockstep: LockstepParams = param(LockstepParams)


class LockstepCore:
    """Sample/command bookkeeping of one simulated rig (see module docstring).

    ``plant`` is a :class:`pneu_sim.physics.plant.Plant` (``reset(x0=)``, ``step(u_l, u_r)``,
    ``T``, ``params``); any object with that interface works (the tests use a
    fake). ``faults``: :class:`pneu_sim.faults.injection.FaultSpec` items (or their
    ``NAME:k=v`` / dict forms), injected as the runner injects them.
    ``volts_of(sample)``: the raw AI volts the supervisor checks (default: the
    twin's own sensor scaling when there is a supervisor).
    """

    def __init__(
        self,
        plant: Any,
        axes: tuple[str, ...] = AXES,
        mode: str = "lockstep",
        x0: float = 0.0,
        supervisor: Any | None = None,
        faults: Any = (),
        seed: int = 0,
        volts_of: Any | None = None,
    ) -> None:
        if mode not in MODES:
            raise ParamError("mode", mode, "one of " + ", ".join(MODES))
        for axis in axes:
            if axis not in AXES:
                raise ParamError("axes", axis, "one of " + ", ".join(AXES))
        self.plant = plant
        self.axes = tuple(axes)
        self.mode = mode
        self.x0 = x0
        self.supervisor = supervisor
        self.injector = None
        if faults:
            from pneu_sim.faults.injection import FaultInjector

            self.injector = FaultInjector(faults, plant, seed=seed, active_axes=self.axes)
        elif supervisor is not None and volts_of is None and hasattr(plant, "params"):
            from pneu_sim.faults.injection import SensorScaling

            volts_of = SensorScaling(plant.params).volts
        self._volts_of = volts_of
        self.sample: SensorSample | None = None
        self.k = 0
        self.steps = 0
        self.timeouts = dict.fromkeys(self.axes, 0)
        self.stale = dict.fromkeys(self.axes, 0)
        self.missed = dict.fromkeys(self.axes, 0)
        self.silenced = dict.fromkeys(self.axes, 0)
        self._hold = dict.fromkeys(AXES, NEUTRAL_V)  # what the DAQ holds during the coming step
        self._answer: dict[str, float] = {}  # valid answers to the current sample (u_k)
        self._answered: set[str] = set()  # axes that answered it (valid or not)
        self._answer_stamp = dict.fromkeys(self.axes, -1)  # newest accepted stamp per axis

    @property
    def period_s(self) -> float:
        return float(self.plant.T)

    @property
    def held(self) -> dict[str, float]:
        """The voltages the DAQ holds during the current step (u_{k-1}, after the supervisor)."""
        return dict(self._hold)

    def reset(self) -> SensorSample:
        """Sample s_0 (faults applied); every axis back to the neutral 5 V, counters kept."""
        self._hold = dict.fromkeys(AXES, NEUTRAL_V)
        self._answer = {}
        self._answered = set()
        self._answer_stamp = dict.fromkeys(self.axes, -1)
        self.k = 0
        return self._begin(self.plant.reset(x0=self.x0))

    def _begin(self, s: SensorSample) -> SensorSample:
        """Cycle k starts (runner order): faults on the sample, supervisor check, tick-k output."""
        volts = None
        if self.injector is not None:
            s, volts = self.injector.sample(self.k, s)
        elif self._volts_of is not None:
            volts = self._volts_of(s)
        if self.supervisor is not None:
            self.supervisor.check_sample(s, volts)
            u_l, u_r = self.supervisor.outputs(s.stamp_ns)  # u_{k-1} after the rules, tick k
            self._hold = {"linear": u_l, "rotary": u_r}
        self.sample = s
        return s

    def silent(self, axis: str) -> bool:
        """An injected ``controller_silent`` fault mutes ``axis`` at the current sample."""
        return self.injector is not None and self.injector.silent(self.k, axis)

    def offer(self, axis: str, stamp_ns: int, u_v: float) -> str:
        """Take one controller answer; returns ``accepted``, ``stale``, ``silent``, ``inactive`` or ``invalid``.

        Lockstep accepts only ``stamp_ns`` == the current sample's stamp (a
        second answer to the same sample replaces the first); realtime takes
        the newest answer not older than one already accepted. With a
        supervisor every accepted answer goes to it as is (NaN included: it
        refuses and trips); without one a non-finite answer is dropped and
        the previous command held, as a DAQ would.
        """
        if self.sample is None:
            raise RuntimeError("LockstepCore.offer before reset()")
        if axis not in self.axes:
            return "inactive"
        if self.mode == "lockstep":
            if stamp_ns != self.sample.stamp_ns:
                self.stale[axis] += 1
                return "stale"
        elif stamp_ns < self._answer_stamp[axis] or stamp_ns > self.sample.stamp_ns:
            self.stale[axis] += 1
            return "stale"
        if self.silent(axis):
            self.silenced[axis] += 1
            return "silent"
        u = float(u_v)
        if self.injector is not None:
            u = self.injector.command(self.k, axis, u)
        self._answer_stamp[axis] = stamp_ns
        self._answered.add(axis)
        if self.supervisor is not None:
            self.supervisor.command(axis, u, stamp_ns)
        elif not math.isfinite(u):
            return "invalid"
        self._answer[axis] = u
        return "accepted"

    @property
    def complete(self) -> bool:
        """Every active axis has answered the current sample (or is muted by a fault)."""
        return not self.waiting_for

    @property
    def waiting_for(self) -> tuple[str, ...]:
        return tuple(a for a in self.axes if a not in self._answered and not self.silent(a))

    def advance(self) -> SensorSample:
        """Step the plant k -> k+1 under the held u_{k-1}; then hold the answers u_k.

        An axis without an answer keeps its previous command (the DAQ holds
        its last output; the supervisor's watchdog decides when that is too
        old) and is counted: ``timeouts`` in lockstep, ``missed`` in realtime.
        """
        if self.sample is None:
            raise RuntimeError("LockstepCore.advance before reset()")
        for axis in self.waiting_for:
            if self.mode == "lockstep":
                self.timeouts[axis] += 1
            else:
                self.missed[axis] += 1
        u_l, u_r = self._hold["linear"], self._hold["rotary"]
        if self.injector is not None:
            u_l, u_r = self.injector.valves(self.k, u_l, u_r)
        s = self.plant.step(u_l, u_r)
        self.steps += 1
        if self.supervisor is None:
            self._hold.update(self._answer)
        self._answer = {}
        self._answered = set()
        self.k += 1
        return self._begin(s)

    def safe_outputs(self) -> tuple[float, float]:
        """What a real rig would hold after a stop: the valve-safe 5 V on both axes."""
        self._hold = dict.fromkeys(AXES, NEUTRAL_V)
        self._answer = {}
        self._answered = set()
        return NEUTRAL_V, NEUTRAL_V

    def counters(self) -> dict[str, int]:
        """Flat counters for diagnostics: ``steps``, ``timeouts.linear``, ..."""
        out = {"steps": self.steps}
        for name in ("timeouts", "stale", "missed", "silenced"):
            for axis, n in getattr(self, name).items():
                out[f"{name}.{axis}"] = n
        return out
