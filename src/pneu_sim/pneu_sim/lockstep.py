"""The sim node's cycle bookkeeping, without ROS: which command drives which step.

DESIGN §3, the same cycle as the in-process runner (``pneu_control.runner``):
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

An optional ``supervisor`` (:class:`pneu_driver.safety.SafetySupervisor`:
``command(axis, u, stamp_ns)``, ``check_sample(sample)``,
``outputs(now_ns) -> (u_linear, u_rotary)``) sits between the answers and the
plant, as it does between the controllers and the DAQ in the driver: every
answer goes to it unclamped, every sample is checked, and what it outputs for
tick k+1 is what the plant holds. In normal operation it passes the answers
through unchanged (a one-period-old command is fresh), so the numbers stay
the runner's. Without a supervisor, answers are clamped to 0–10 V like a DAC.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from pneu_msgs_py.convert import fill_fluid_pressure, fill_joint_state, sample_to_values
from pneu_msgs_py.params import ParamError, param
from pneu_msgs_py.samples import AXES, NEUTRAL_V, U_MAX_V, U_MIN_V, SensorSample
from pneu_msgs_py.topics import PRESSURE_TOPICS

__all__ = ["MODES", "LockstepCore", "SimNodeParams", "active_axes", "fill_sample_messages"]

MODES = ("lockstep", "realtime")
AXES_CHOICES = ("linear", "rotary", "both", "none")


def fill_sample_messages(
    msgs: Mapping[str, Any], s: SensorSample, variances: Mapping[str, float] | None = None
) -> None:
    """Fill the five sensor messages of sample ``s`` in place (``{topic: message}``).

    Pressures: FluidPressure (Pa abs, ``variance`` in Pa^2 per topic if given);
    joint states: JointState as :func:`pneu_msgs_py.convert.sample_to_values`
    lays them out. All stamped with ``s.stamp_ns``.
    """
    for topic, (frame, names, pos, vel) in sample_to_values(s).items():
        m = msgs[topic]
        if topic in PRESSURE_TOPICS:
            var = variances.get(topic, 0.0) if variances else 0.0
            fill_fluid_pressure(m, s.stamp_ns, pos[0], frame, var)
        else:
            fill_joint_state(m, s.stamp_ns, names, pos, vel)


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
    lockstep: LockstepParams = param(LockstepParams)


@dataclass
class LockstepCore:
    """Sample/command bookkeeping of one simulated rig (see module docstring).

    ``plant`` is a :class:`pneu_sim.plant.Plant` (``reset(x0=)``, ``step(u_l, u_r)``,
    ``T``); any object with that interface works (the tests use a fake).
    """

    plant: Any
    axes: tuple[str, ...] = AXES
    mode: str = "lockstep"
    x0: float = 0.0
    supervisor: Any | None = None
    sample: SensorSample | None = field(default=None, init=False)
    timeouts: dict[str, int] = field(default_factory=dict, init=False)
    stale: dict[str, int] = field(default_factory=dict, init=False)
    missed: dict[str, int] = field(default_factory=dict, init=False)
    steps: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ParamError("mode", self.mode, "one of " + ", ".join(MODES))
        for axis in self.axes:
            if axis not in AXES:
                raise ParamError("axes", axis, "one of " + ", ".join(AXES))
        self.timeouts = dict.fromkeys(self.axes, 0)
        self.stale = dict.fromkeys(self.axes, 0)
        self.missed = dict.fromkeys(self.axes, 0)
        self._hold = dict.fromkeys(AXES, NEUTRAL_V)  # written at the last tick, held now
        self._answer: dict[str, float] = {}  # answers for the coming tick
        self._answer_stamp = dict.fromkeys(self.axes, -1)  # newest accepted stamp per axis

    @property
    def period_s(self) -> float:
        return float(self.plant.T)

    @property
    def held(self) -> dict[str, float]:
        """The voltages the DAQ holds during the current step (u_{k-1})."""
        return dict(self._hold)

    def reset(self) -> SensorSample:
        """Sample s_0; every axis back to the neutral 5 V, counters kept."""
        self._hold = dict.fromkeys(AXES, NEUTRAL_V)
        self._answer = {}
        self._answer_stamp = dict.fromkeys(self.axes, -1)
        self.sample = self.plant.reset(x0=self.x0)
        self._check(self.sample)
        return self.sample

    def safe_outputs(self) -> tuple[float, float]:
        """What a real rig would hold after a stop: the valve-safe 5 V on both axes."""
        self._hold = dict.fromkeys(AXES, NEUTRAL_V)
        self._answer = {}
        return NEUTRAL_V, NEUTRAL_V

    def offer(self, axis: str, stamp_ns: int, u_v: float) -> str:
        """Take one controller answer; returns ``accepted``, ``stale``, ``inactive`` or ``invalid``.

        Lockstep accepts only ``stamp_ns`` == the current sample's stamp (a
        second answer to the same sample replaces the first); realtime takes
        the newest answer not older than one already accepted.
        """
        if self.sample is None:
            raise RuntimeError("LockstepCore.offer before reset()")
        if axis not in self.axes:
            return "inactive"
        if not math.isfinite(u_v):
            self.stale[axis] += 1
            return "invalid"
        if self.mode == "lockstep":
            if stamp_ns != self.sample.stamp_ns:
                self.stale[axis] += 1
                return "stale"
        elif stamp_ns < self._answer_stamp[axis] or stamp_ns > self.sample.stamp_ns:
            self.stale[axis] += 1
            return "stale"
        self._answer_stamp[axis] = stamp_ns
        if self.supervisor is not None:
            self.supervisor.command(axis, float(u_v), stamp_ns)
            self._answer[axis] = float(u_v)
        else:
            self._answer[axis] = min(max(float(u_v), U_MIN_V), U_MAX_V)
        return "accepted"

    @property
    def complete(self) -> bool:
        """Every active axis has answered the current sample."""
        return all(axis in self._answer for axis in self.axes)

    @property
    def waiting_for(self) -> tuple[str, ...]:
        return tuple(axis for axis in self.axes if axis not in self._answer)

    def advance(self) -> SensorSample:
        """Step the plant k -> k+1 under the held u_{k-1}; then hold the answers u_k.

        An axis without an answer keeps its previous command (the DAQ holds
        its last output) and is counted: ``timeouts`` in lockstep, ``missed``
        in realtime.
        """
        if self.sample is None:
            raise RuntimeError("LockstepCore.advance before reset()")
        for axis in self.waiting_for:
            if self.mode == "lockstep":
                self.timeouts[axis] += 1
            else:
                self.missed[axis] += 1
        s = self.plant.step(self._hold["linear"], self._hold["rotary"])
        self.steps += 1
        self.sample = s
        self._check(s)
        if self.supervisor is not None:
            u_l, u_r = self.supervisor.outputs(s.stamp_ns)  # written at tick k+1
            self._hold = {"linear": u_l, "rotary": u_r}
        else:
            self._hold.update(self._answer)
        self._answer = {}
        return s

    def _check(self, s: SensorSample) -> None:
        if self.supervisor is not None:
            self.supervisor.check_sample(s)

    def counters(self) -> dict[str, int]:
        """Flat counters for diagnostics: ``steps``, ``timeouts.linear``, ..."""
        out = {"steps": self.steps}
        for name in ("timeouts", "stale", "missed"):
            for axis, n in getattr(self, name).items():
                out[f"{name}.{axis}"] = n
        return out
