"""The sim node's core without ROS: its parameters, messages, faults and diagnostics.

The cycle itself is :class:`pneu_sim.cycle.rig_cycle.RigCycle` (the one the
in-process runner steps); the node publishes each sample as raw CDR
(:class:`pneu_msgs_py.contract.wire.SensorWire`), offers the controllers'
answers to the cycle and advances it -- lockstep: when every active axis
answered; realtime: on a 1 kHz wall-clock tick of :class:`SimLoop`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from pneu_msgs_py.contract.samples import AXES
from pneu_msgs_py.params.core import ParamError, param

__all__ = [
    "MODES",
    "SimNodeParams",
    "active_axes",
    "load_faults",
    "safety_statuses",
    "SimLoop",
    "RealtimeParams",
    "StartupParams",
    "TaskGate",
    "TaskParams",
]

from pneu_sim.cycle.rig_cycle import MODES

AXES_CHOICES = ("linear", "rotary", "both", "none")


def load_faults(text: str = "", path: str = "") -> tuple[Any, ...]:
    """Fault specs from ``NAME[:k=v,...]`` items separated by ``;`` and/or a YAML file.

    The file holds a list of ``{name, start_s, duration_s, params}`` mappings
    (or a mapping with that list under ``faults``). Everything is validated
    (:func:`pneu_sim.faults.injection.parse_faults`) before anything runs.
    """
    from pneu_sim.faults.injection import parse_faults

    items: list[Any] = [t for t in (p.strip() for p in text.split(";")) if t]
    if path:
        from pneu_msgs_py.params.yaml_file import load_yaml

        data = load_yaml(path) or []
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


@dataclass(frozen=True)
class RealtimeParams:
    spin_us: float = param(
        200.0,
        unit="µs",
        desc="the loop sleeps until this long before each tick, then spins on the clock",
        lo=0.0,
        hi=1000.0,
        read_only=True,
    )
    rt_priority: int = param(
        50,
        desc="SCHED_FIFO priority of the loop thread, the node's other threads one below (0 = "
        "normal scheduling; needs CAP_SYS_NICE or an rtprio limit, else one warning line and "
        "normal scheduling)",
        lo=0,
        hi=99,
        read_only=True,
    )
    switch_interval_us: float = param(
        500.0,
        unit="µs",
        desc="Python's GIL switch interval while the loop runs (sys.setswitchinterval; the "
        "default 5000 µs lets another thread hold the GIL for 5 ticks; 0 = leave it)",
        lo=0.0,
        hi=5000.0,
        read_only=True,
    )


@dataclass(frozen=True)
class StartupParams:
    wait_for_logger: bool = param(
        False,
        desc="before sample 0: wait until the logger node listens on /parameter_events, so "
        "that it has every node's parameters for the run's metadata",
        read_only=True,
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
    timeout_s: float = param(
        30.0,
        unit="s",
        desc="start anyway (with a warning) after waiting this long for subscribers",
        lo=0.0,
        hi=3600.0,
        read_only=True,
    )


@dataclass(frozen=True)
class TaskParams:
    wait: bool = param(
        False,
        desc="lockstep: also wait for the task runner's progress for every sample before "
        "advancing (its segments, loads and e-stop then act at the samples they do in process)",
        read_only=True,
    )
    ends_run: bool = param(
        False,
        desc="the run ends when the task runner's task ends (its 'end' progress)",
        read_only=True,
    )


class TaskGate:
    """The sim's side of a task runner (``/pneu/task/progress``, ROS-free).

    Each progress event is carried out on the cycle: a segment's ``load.*`` values on
    the twin (from the next step, as the in-process runner sets them), ``aborted`` as
    the supervisor's e-stop with the in-process wording. ``wait``: the current sample
    is not :attr:`complete` until the task has answered it (or ended); ``ended``: the
    task's ``end`` was seen.
    """

    def __init__(self, cycle: Any, params: TaskParams | None = None) -> None:
        self.cycle = cycle
        self.p = params or TaskParams()
        self.acked = -1
        self.ended = False
        self.events = 0
        self.refused = 0  # progress statuses that were not a task's

    def on_progress(self, stamp_ns: int, statuses: Any) -> list[str]:
        """One progress message (its statuses); returns a line per status refused."""
        from pneu_msgs_py.contract.task_progress import TaskProgress

        bad = []
        for st in statuses:
            try:
                ev = TaskProgress.from_status(stamp_ns, st)
            except ValueError as err:
                self.refused += 1
                bad.append(str(err))
                continue
            self.events += 1
            if ev.event == "start" and ev.loads and hasattr(self.cycle.plant, "set_load"):
                self.cycle.plant.set_load(**ev.loads)
            elif ev.event == "aborted" and self.cycle.supervisor is not None:
                self.cycle.supervisor.estop(f"task aborted: {ev.reason}")
            elif ev.event == "end":
                self.ended = True
        s = self.cycle.sample
        if s is not None and stamp_ns == s.stamp_ns:
            self.acked = stamp_ns
        return bad

    @property
    def complete(self) -> bool:
        """The current sample needs nothing more from the task."""
        s = self.cycle.sample
        return not self.p.wait or self.ended or (s is not None and self.acked == s.stamp_ns)


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
    realtime: RealtimeParams = param(RealtimeParams)
    startup: StartupParams = param(StartupParams)
    task: TaskParams = param(TaskParams)


class SimLoop:
    """The sim's realtime loop, without ROS: :class:`RigCycle` paced at 1/T in its own thread.

    Per tick k (due at t0 + k·T, :class:`pneu_driver.loop.pacer.Pacer`): the
    supervisor's transitions of cycle k−1 go to ``on_events``; the cycle
    advances (the plant steps under u_{k−1}, the newest answers are held) to
    sample k; ``on_sample(s)`` publishes it -- and in the one-process
    deployment computes and offers the answers at once. Answers arrive from
    any thread through :meth:`offer` (a lock guards the cycle); the time from
    a sample being ready to its answer is recorded per axis (``turnaround``).
    A tick started a whole period late steps the plant over the missed ticks
    without publishing them (the controllers miss those, counted). Ends after
    ``n_end`` samples (0: when stopped).
    """

    def __init__(
        self,
        cycle: Any,
        *,
        on_sample: Any,
        on_events: Any = None,
        n_end: int = 0,
        params: RealtimeParams | None = None,
    ) -> None:
        import threading

        from pneu_driver.loop.pacer import Pacer, Timing

        self.cycle = cycle
        self.p = params or RealtimeParams()
        self.on_sample = on_sample
        self.on_events = on_events
        self.n_end = int(n_end)
        self.pacer = Pacer(round(cycle.period_s * 1e9), spin_us=self.p.spin_us)
        self.turnaround = {axis: Timing() for axis in cycle.axes}
        self.lock = threading.Lock()
        self.stop_event = threading.Event()
        self.finished = threading.Event()
        self.error: BaseException | None = None
        self.notes: list[str] = []
        self._stamp = -1
        self._ready_ns = 0

    def offer(self, axis: str, stamp_ns: int, u: float) -> str:
        """A controller's answer (any thread); see :meth:`RigCycle.offer`."""
        import time

        now = time.perf_counter_ns()
        with self.lock:
            status = self.cycle.offer(axis, stamp_ns, u)
            if status == "accepted" and stamp_ns == self._stamp:
                self.turnaround[axis].add(now - self._ready_ns)
        return status

    def run(self) -> None:
        """The loop (call in its own thread; :meth:`start` does)."""
        import sys
        import time

        from pneu_msgs_py.lifecycle.realtime import enable_realtime

        old_switch = sys.getswitchinterval()
        if self.p.switch_interval_us > 0:
            sys.setswitchinterval(self.p.switch_interval_us * 1e-6)
        self.notes, restore = enable_realtime(self.p.rt_priority)
        cycle, pacer, clock = self.cycle, self.pacer, time.perf_counter_ns
        try:
            pacer.start()
            k = 0
            while not self.stop_event.is_set():
                started = pacer.wait(k)
                if self.n_end:  # catching up never steps past the last sample
                    started = min(started, self.n_end - 1)
                with self.lock:
                    events = []
                    if k == 0:
                        s = cycle.reset()
                    else:
                        for _ in range(started - k):  # ticks missed entirely: no sample out
                            events += self._drain()
                            cycle.advance()
                        events += self._drain()
                        s = cycle.advance()
                    self._stamp = s.stamp_ns
                    self._ready_ns = clock()
                if events and self.on_events is not None:
                    self.on_events(events, s.stamp_ns)
                self.on_sample(s)
                k = started + 1
                if self.n_end and s.k + 1 >= self.n_end:
                    break
            with self.lock:
                events = self._drain()
            if events and self.on_events is not None:
                self.on_events(events, cycle.sample.stamp_ns)
        except BaseException as err:  # reported by the node
            self.error = err
        finally:
            with self.lock:
                cycle.safe_outputs()
            restore()
            sys.setswitchinterval(old_switch)
            self.finished.set()

    def _drain(self) -> list[Any]:
        sup = self.cycle.supervisor
        return sup.events() if sup is not None else []

    def start(self) -> Any:
        import threading

        th = threading.Thread(target=self.run, name="pneu_sim_loop", daemon=True)
        th.start()
        return th

    def stats(self, last: int | None = None) -> dict[str, str]:
        """Timing and counters for ``/diagnostics`` (percentiles over the ``last`` ticks) and the
        end-of-run report (``last`` None: the whole ring)."""
        out = {k: str(v) for k, v in self.cycle.counters().items()}
        out.update(self.pacer.lateness.summary("lateness", last))
        out["skipped_ticks"] = str(self.pacer.skipped)
        for axis, t in self.turnaround.items():
            out.update(t.summary(f"turnaround.{axis}", last))
        out["realtime"] = "; ".join(self.notes) or "normal scheduling"
        return out
