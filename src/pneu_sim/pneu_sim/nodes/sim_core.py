"""The sim node's core without ROS: its parameters, messages, faults and diagnostics.

The cycle itself is :class:`pneu_sim.cycle.rig_cycle.RigCycle` (the one the
in-process runner steps); the node publishes each sample with
:func:`fill_sample_messages`, offers the controllers' answers to the cycle
and advances it (lockstep: when every active axis answered; realtime: on a
1 kHz wall-clock tick).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from pneu_msgs_py.contract.convert import fill_fluid_pressure, fill_joint_state, sample_to_values
from pneu_msgs_py.contract.samples import AXES, SensorSample
from pneu_msgs_py.contract.topics import PRESSURE_TOPICS
from pneu_msgs_py.params.core import ParamError, param

__all__ = [
    "MODES",
    "SimNodeParams",
    "active_axes",
    "fill_sample_messages",
    "load_faults",
    "safety_statuses",
]

from pneu_sim.cycle.rig_cycle import MODES

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
