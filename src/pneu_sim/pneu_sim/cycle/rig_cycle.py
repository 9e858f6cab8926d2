"""The control cycle of DESIGN §3 on the twin, written once.

Every path that closes a loop around the twin steps this class: the
in-process runner (``pneu_control.experiment.runner``), the sim node (ROS,
lockstep or realtime), and whatever joins them later (identification,
sweeps). Per cycle k (k = sample index, T = 1 ms)::

    s_k = sample()                  the plant's sample at tick k, injected sensor faults applied;
                                    the supervisor checks it (with the AI volts the sensors
                                    put out) and gives the tick-k output = u_{k-1} after its rules
    command(axis, u_k)              each active controller's answer to s_k (injected command
                                    faults applied) goes to the supervisor -- or, without one,
                                    is held if finite, as a DAQ holds its last value
    advance()                       the plant steps k -> k+1 under the tick-k output (through a
                                    stuck valve if one is injected); s_{k+1} begins

so u_k is written at tick k+1 and held until k+2: a one-sample transport
delay. Inactive axes hold the neutral 5 V. The supervisor's transitions are
drained by the caller (``supervisor.events()``) once per cycle, after the
commands.

Two modes for callers that get their answers over a network (the sim node):

``lockstep``
    :meth:`offer` accepts only an answer to the current sample; the node
    advances when :attr:`complete` (every active axis answered) or when its
    wall-clock timeout fires -- then the missing axes keep their previous
    command and the miss is counted in :attr:`timeouts`. Deterministic: the
    same config and seed give the in-process runner's numbers.
``realtime``
    The node advances on a 1 kHz wall-clock tick; the newest answer received
    since the last tick is written (what a DAQ would do), answers older than
    the newest accepted are dropped (:attr:`stale`), a period without a
    fresh answer is counted in :attr:`missed`.
"""

from __future__ import annotations

import math
from typing import Any

from pneu_msgs_py.contract.samples import AXES, NEUTRAL_V, SensorSample
from pneu_msgs_py.params.core import ParamError

__all__ = ["MODES", "RigCycle"]

MODES = ("lockstep", "realtime")


class RigCycle:
    """The twin, the injected faults and the supervisor, stepped one cycle at a time.

    ``plant`` is a :class:`pneu_sim.physics.plant.Plant` (``reset(x0=)``,
    ``step(u_l, u_r)``, ``T``, ``params``, ``state``); any object with that
    interface works. ``supervisor``: a
    :class:`pneu_driver.safety.supervisor.SafetySupervisor` (``check_sample``,
    ``outputs``, ``command``) or None. ``faults``:
    :class:`pneu_sim.faults.injection.FaultSpec` items (or their ``NAME:k=v``
    / dict forms). ``volts_of(sample)``: the raw AI volts the supervisor
    checks (default: the twin's own sensor scaling when there is a
    supervisor).
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
        safety = getattr(supervisor, "params", None)
        if safety is not None and hasattr(plant, "params"):
            from pneu_driver.safety import check_plumbing

            check_plumbing(safety, plant.params.rotary.plumbing, "the twin's rotary.plumbing")
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
        self._hold = [NEUTRAL_V, NEUTRAL_V]  # (linear, rotary) the DAQ holds during the step
        self._answer: dict[str, float] = {}  # valid answers to the current sample (u_k)
        self._answered: set[str] = set()  # axes that answered it (valid or not)
        self._answer_stamp = dict.fromkeys(self.axes, -1)  # newest accepted stamp per axis

    @property
    def period_s(self) -> float:
        return float(self.plant.T)

    @property
    def held(self) -> dict[str, float]:
        """The voltages the DAQ holds during the current step (u_{k-1}, after the supervisor)."""
        return {"linear": self._hold[0], "rotary": self._hold[1]}

    @property
    def held_pair(self) -> tuple[float, float]:
        """:attr:`held` as ``(linear, rotary)``."""
        return self._hold[0], self._hold[1]

    # -- the cycle ---------------------------------------------------------
    def reset(self) -> SensorSample:
        """Sample s_0 (faults applied); every axis back to the neutral 5 V, counters kept."""
        self._hold = [NEUTRAL_V, NEUTRAL_V]
        self._answer = {}
        self._answered = set()
        self._answer_stamp = dict.fromkeys(self.axes, -1)
        self.k = 0
        return self._begin(self.plant.reset(x0=self.x0))

    def _begin(self, s: SensorSample) -> SensorSample:
        """Cycle k starts: faults on the sample, supervisor check, tick-k output."""
        volts = None
        if self.injector is not None:
            s, volts = self.injector.sample(self.k, s)
        elif self._volts_of is not None:
            volts = self._volts_of(s)
        if self.supervisor is not None:
            self.supervisor.check_sample(s, volts)
            u_l, u_r = self.supervisor.outputs(s.stamp_ns)  # u_{k-1} after the rules, tick k
            self._hold = [u_l, u_r]
        self.sample = s
        return s

    def silent(self, axis: str) -> bool:
        """An injected ``controller_silent`` fault mutes ``axis`` at the current sample."""
        return self.injector is not None and self.injector.silent(self.k, axis)

    def command(self, axis: str, u_v: float) -> float:
        """``axis``'s answer u_k to the current sample; returns it as it goes to the DAQ.

        Injected command faults are applied first. With a supervisor the
        answer goes to it as is (NaN included: it refuses and trips);
        without one a non-finite answer is dropped and the previous command
        held, as a DAQ would.
        """
        u = float(u_v)
        if self.injector is not None:
            u = self.injector.command(self.k, axis, u)
        self._answered.add(axis)
        if self.supervisor is not None:
            self.supervisor.command(axis, u, self.sample.stamp_ns)
            self._answer[axis] = u
        elif u == u and -math.inf < u < math.inf:
            self._answer[axis] = u
        return u

    def advance(self) -> SensorSample:
        """Step the plant k -> k+1 under the held u_{k-1}; then hold the answers u_k.

        An axis without an answer keeps its previous command (the DAQ holds
        its last output; the supervisor's late-command policy decides what is
        written while it is late and its watchdog when it is gone, DESIGN §14)
        and is counted: ``timeouts`` in lockstep, ``missed`` in realtime.
        """
        if self.sample is None:
            raise RuntimeError("RigCycle.advance before reset()")
        if len(self._answered) < len(self.axes):
            for axis in self.waiting_for:
                if self.mode == "lockstep":
                    self.timeouts[axis] += 1
                else:
                    self.missed[axis] += 1
        u_l, u_r = self._hold
        if self.injector is not None:
            u_l, u_r = self.injector.valves(self.k, u_l, u_r)
        s = self.plant.step(u_l, u_r)
        self.steps += 1
        if self.supervisor is None:
            ans = self._answer
            if "linear" in ans:
                self._hold[0] = ans["linear"]
            if "rotary" in ans:
                self._hold[1] = ans["rotary"]
        self._answer = {}
        self._answered = set()
        self.k += 1
        return self._begin(s)

    # -- answers over a network (the sim node) -------------------------------
    def offer(self, axis: str, stamp_ns: int, u_v: float) -> str:
        """Take one controller answer; returns ``accepted``, ``stale``, ``silent``, ``inactive`` or ``invalid``.

        Lockstep accepts only ``stamp_ns`` == the current sample's stamp (a
        second answer to the same sample replaces the first); realtime takes
        the newest answer not older than one already accepted. Then as
        :meth:`command`.
        """
        if self.sample is None:
            raise RuntimeError("RigCycle.offer before reset()")
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
        self._answer_stamp[axis] = stamp_ns
        self.command(axis, u_v)
        if self.supervisor is None and axis not in self._answer:
            return "invalid"
        return "accepted"

    @property
    def complete(self) -> bool:
        """Every active axis has answered the current sample (or is muted by a fault)."""
        return not self.waiting_for

    @property
    def waiting_for(self) -> tuple[str, ...]:
        return tuple(a for a in self.axes if a not in self._answered and not self.silent(a))

    def safe_outputs(self) -> tuple[float, float]:
        """What a real rig would hold after a stop: the valve-safe 5 V on both axes."""
        self._hold = [NEUTRAL_V, NEUTRAL_V]
        self._answer = {}
        self._answered = set()
        return NEUTRAL_V, NEUTRAL_V

    def counters(self) -> dict[str, int]:
        """Flat counters for diagnostics: ``steps``, ``timeouts.linear``, ..., then the
        supervisor's (as the driver reports them: ``future_commands``, ``trips``, ...,
        ``linear.late_ticks``, ``linear.held_ticks``, ``linear.ramped_ticks``, ...)."""
        out = {"steps": self.steps}
        for name in ("timeouts", "stale", "missed", "silenced"):
            for axis, n in getattr(self, name).items():
                out[f"{name}.{axis}"] = n
        out.update(getattr(self.supervisor, "counters", None) or {})
        return out
