"""The fault table of issue 6: every injected fault on the twin, with and without the supervisor.

One scenario per fault (:data:`SCENARIOS`): a closed-loop run on the twin
(re-tuned ESO-SMC gains, ``config/controllers_retuned.yaml``; linear: sine
20 mm / 0.25 Hz, rotary: 800 rpm), the fault injected at ``start_s`` for
``duration_s``, logged to a bag. Per row (:class:`FaultRow`):

- detection delay [cycles] = k_detect − k0: k0 the fault's first sample,
  k_detect the sample stamped on the first supervisor transition at level
  ERROR for an axis the fault acts on at or after k0 (a WARN, i.e. the
  non-latching soft limit, if there is no ERROR);
- time to safe state [cycles] = k_safe − k_detect: k_safe the first tick
  ≥ k_detect at which every affected valve is written 5 V (the runner's
  ``applied`` output: what the DAQ holds from that tick);
- max overtravel: max |x_true| beyond the soft limit (stroke/2 − margin) after
  k0 [mm], with the peak |x| (the end stop is at 75 mm); max overspeed: max
  |ω_true| above ``max_speed_rpm`` after k0 [rpm], with the peak speed;
- bag complete: read back by :func:`pneu_msgs_py.bag.reader.read_run` *and*
  by ``mcap_ros2.reader``: one message per sample on every sensor topic, every
  supervisor transition on ``/diagnostics``, the ``pneu.fault_intervals``
  metadata record, and ``pneu analyze`` marks the injected interval;
- the same scenario without the supervisor (``safety=False``): the peaks then.

``python -m pneu_control.experiment.fault_table [OUT_DIR]`` prints the markdown table.
"""

from __future__ import annotations

import math
import sys
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "SCENARIOS",
    "FaultRow",
    "Scenario",
    "bag_complete",
    "run_all",
    "run_scenario",
    "to_markdown",
]

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)


@dataclass(frozen=True)
class Scenario:
    """One fault table row's set-up: the fault (as ``pneu run --fault`` takes it), the axes, the
    duration."""

    fault: str  # NAME[:k=v,...] as pneu run --fault takes it
    axes: tuple[str, ...]
    duration_s: float = 3.0


_F = "start_s=1.0,duration_s=1.0"
SCENARIOS: tuple[Scenario, ...] = (
    Scenario(f"sensor_dropout:sensor=x,{_F}", ("linear",)),
    Scenario(f"stuck_sensor:sensor=x,{_F}", ("linear",)),
    Scenario(f"stuck_sensor:sensor=p_c1,{_F}", ("linear",)),
    Scenario(f"noise_burst:sensor=x,sigma_v=3.0,{_F}", ("linear",)),
    Scenario(f"broken_wire:sensor=x,{_F}", ("linear",)),
    Scenario(f"broken_wire:sensor=p_m1,{_F}", ("rotary",)),
    Scenario(f"encoder_missed:fraction=1.0,{_F}", ("rotary",)),
    Scenario("encoder_missed:fraction=1.0,start_s=0.5,duration_s=1.0", ("rotary",)),
    Scenario(f"encoder_missed:fraction=0.5,{_F}", ("rotary",)),
    Scenario(f"valve_stuck:axis=linear,volts=10,{_F}", ("linear",)),
    Scenario(f"valve_stuck:axis=rotary,volts=10,{_F}", ("rotary",)),
    Scenario(f"supply_drop:axis=both,factor=0.5,{_F}", ("linear", "rotary")),
    Scenario(f"added_mass:mass_kg=2.0,{_F}", ("linear",)),
    Scenario(f"controller_silent:axis=both,{_F}", ("linear", "rotary")),
    Scenario(f"controller_nan:axis=both,{_F}", ("linear", "rotary")),
)


@dataclass
class FaultRow:
    """One row of the fault table: which rule caught the fault, how fast, how far the axis went, the
    end state."""

    fault: str
    axes: str  # axes the fault acts on
    rule: str  # the latching (ERROR) rule that caught it ('' if none)
    detection_cycles: int | None  # k_detect − k0 of the first ERROR; None: no ERROR
    safe_cycles: int | None  # k_safe − k_detect
    warn_rule: str  # an earlier non-latching WARN (soft limit), '' if none
    warn_cycles: int | None
    overtravel_mm: float | None  # beyond the soft limit (linear rows)
    peak_x_mm: float | None
    overspeed_rpm: float | None  # above max_speed_rpm (rotary rows)
    peak_rpm: float | None
    bag_complete: bool
    end_state: str  # "SAFE (latched)" | "controlled, within limits" | "NOT SAFE"
    peak_x_mm_unprotected: float | None = None
    peak_rpm_unprotected: float | None = None
    note: str = ""
    result: Any = field(default=None, repr=False, compare=False)  # the protected RunResult
    bag: Path | None = None

    def to_dict(self) -> dict[str, Any]:
        """The row as plain data (the bag as a string; the RunResult left out)."""
        d = asdict(self)
        d.pop("result")
        d["bag"] = str(self.bag) if self.bag else None
        return d


def _spec(sc: Scenario, safety: bool, controllers_file: str | Path | None):
    from pneu_msgs_py.params.paths import config_file

    from pneu_control.experiment.session import build_spec

    sets = []
    if "linear" in sc.axes:
        sets += [
            "linear.reference.kind=sine",
            "linear.reference.amplitude=20",
            "linear.reference.frequency_hz=0.25",
        ]
    if "rotary" in sc.axes:
        sets += ["rotary.reference.kind=constant", "rotary.reference.value=800"]
    return build_spec(
        axes=sc.axes,
        controller="eso_smc",
        sets=sets,
        duration_s=sc.duration_s,
        controllers_file=controllers_file or config_file("controllers_retuned.yaml"),
        faults=[sc.fault],
        name=sc.fault.partition(":")[0],
        safety=safety,
    )


def bag_complete(path: str | Path, result: Any) -> tuple[bool, str]:
    """Is the bag of ``result`` complete, by our reader and by ``mcap_ros2``? (ok, why not)."""
    from mcap_ros2.reader import read_ros2_messages
    from pneu_msgs_py.bag.reader import read_run
    from pneu_msgs_py.contract.topics import DIAGNOSTICS_TOPIC, JOINT_STATE_TOPIC, PRESSURE_TOPICS

    from pneu_control.analysis.run_analysis import analyze
    from pneu_control.experiment.bag_log import INTERVALS_METADATA

    n = len(result.t)
    data = read_run(path)
    if data.warnings:
        return False, "reader warnings: " + "; ".join(data.warnings)
    sensor_topics = list(PRESSURE_TOPICS) + list(JOINT_STATE_TOPIC.values())
    for topic in sensor_topics:
        if len(data[topic]) != n:
            return False, f"{topic}: {len(data[topic])} messages for {n} samples"
    n_events = len(result.safety_events)
    diag = data.topics.get(DIAGNOSTICS_TOPIC)
    n_diag = 0 if diag is None else sum(len(o) for o in diag.objects)
    if n_diag != n_events:
        return False, f"/diagnostics: {n_diag} statuses for {n_events} supervisor transitions"
    if INTERVALS_METADATA not in data.metadata:
        return False, f"metadata {INTERVALS_METADATA} missing"
    counts: dict[str, int] = {}
    for msg in read_ros2_messages(str(path)):
        counts[msg.channel.topic] = counts.get(msg.channel.topic, 0) + 1
    for topic in sensor_topics:
        if counts.get(topic, 0) != n:
            return False, f"mcap_ros2: {topic} {counts.get(topic, 0)} messages for {n}"
    if counts.get(DIAGNOSTICS_TOPIC, 0) != (0 if diag is None else len(diag)):
        return False, "mcap_ros2: /diagnostics count differs"
    marked = analyze(path).faults
    if result.spec.faults and not any(iv.kind == "injected" for iv in marked):
        return False, "pneu analyze did not mark the injected fault"
    return True, ""


def _peaks(result: Any, k0: int, safety: Any) -> tuple[float, float, float, float]:
    tr = result.truth
    x = np.abs(tr["x"][k0:]) if len(tr) else np.abs(result.samples["x"][k0:])
    w = np.abs(tr["omega"][k0:]) if len(tr) else np.abs(result.samples["omega"][k0:])
    peak_x = float(np.max(x)) * 1e3 if x.size else math.nan
    peak_rpm = float(np.max(w)) * RPM_PER_RAD_S if w.size else math.nan
    soft = (safety.stroke_m / 2 - safety.stroke_margin_m) * 1e3
    return max(0.0, peak_x - soft), peak_x, max(0.0, peak_rpm - safety.max_speed_rpm), peak_rpm


def run_scenario(
    sc: Scenario,
    out_dir: str | Path,
    controllers_file: str | Path | None = None,
    compare: bool = True,
) -> FaultRow:
    """Run one scenario (and, with ``compare``, the same without the supervisor); measure the row."""
    from pneu_control.experiment.session import execute

    out = Path(out_dir)
    spec = _spec(sc, True, controllers_file)
    f = spec.faults[0]
    result = execute(spec, out / "protected", bag=True)
    bare = None
    if compare:
        bare = execute(_spec(sc, False, controllers_file), out / "unprotected", bag=False)
    T = spec.plant.sim.T
    k0 = int(round(f.start_s / T))
    t0_ns = round(k0 * T * 1e9)
    affected = tuple(a for a in f.axes(spec.axes) if a in spec.axes)

    def first(level: str) -> Any:
        for e in result.safety_events:
            if e.level == level and e.stamp_ns >= t0_ns and e.axis in (*affected, "all"):
                return e
        return None

    det, warn = first("ERROR"), first("WARN")
    if warn is not None and det is not None and warn.stamp_ns >= det.stamp_ns:
        warn = None
    k_det = None if det is None else int(round(det.stamp_ns * 1e-9 / T))
    k_safe = None
    if k_det is not None:
        safe = np.ones(len(result.t) - k_det, dtype=bool)
        for axis in affected:
            safe &= result.applied[axis][k_det:] == 5.0
        idx = np.flatnonzero(safe)
        k_safe = None if idx.size == 0 else k_det + int(idx[0])
    safety = spec.safety
    ot, px, osp, prpm = _peaks(result, k0, safety)
    px_b = prpm_b = None
    if bare is not None:
        _, px_b, _, prpm_b = _peaks(bare, k0, safety)
    bag = out / "protected" / "run.mcap"
    ok, why = bag_complete(bag, result)
    latched = all(
        any(
            iv.kind == "safe" and iv.axis == a and math.isinf(iv.end_s)
            for iv in result.fault_intervals
        )
        and result.applied[a][-1] == 5.0
        for a in affected
    )
    within = ot == 0.0 and osp == 0.0
    end_state = (
        "SAFE (latched)" if latched else ("controlled, within limits" if within else "NOT SAFE")
    )
    lin, rot = "linear" in affected, "rotary" in affected
    return FaultRow(
        fault=f.label + f" @ {f.start_s:g} s for {f.duration_s:g} s",
        axes=",".join(affected),
        rule="" if det is None else det.rule,
        detection_cycles=None if k_det is None else k_det - k0,
        safe_cycles=None if k_safe is None else k_safe - k_det,
        warn_rule="" if warn is None else warn.rule,
        warn_cycles=None if warn is None else int(round(warn.stamp_ns * 1e-9 / T)) - k0,
        overtravel_mm=ot if lin else None,
        peak_x_mm=px if lin else None,
        overspeed_rpm=osp if rot else None,
        peak_rpm=prpm if rot else None,
        bag_complete=ok,
        end_state=end_state,
        peak_x_mm_unprotected=px_b if lin else None,
        peak_rpm_unprotected=prpm_b if rot else None,
        note=why,
        result=result,
        bag=bag,
    )


def run_all(
    out_dir: str | Path | None = None,
    scenarios: tuple[Scenario, ...] = SCENARIOS,
    controllers_file: str | Path | None = None,
) -> list[FaultRow]:
    """Every scenario, with and without the supervisor, each into its own directory under
    ``out_dir`` (a temporary one if None)."""
    out = Path(out_dir) if out_dir else Path(tempfile.mkdtemp(prefix="pneu-faults-"))
    return [
        run_scenario(sc, out / f"{i:02d}_{sc.fault.partition(':')[0]}", controllers_file)
        for i, sc in enumerate(scenarios)
    ]


def _num(v: float | None, fmt: str = "{:.1f}") -> str:
    return "—" if v is None else fmt.format(v)


def to_markdown(rows: list[FaultRow]) -> str:
    """The closing-note table (one row per scenario)."""
    head = (
        "| fault | axes | detected by | detection delay (cycles) | time to safe state (cycles) "
        "| max overtravel / overspeed | without supervisor | bag complete | end state |\n"
        "|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for r in rows:
        parts, bare = [], []
        if r.peak_x_mm is not None:
            parts.append(
                f"{r.overtravel_mm:.1f} mm past soft limit (peak \\|x\\| {r.peak_x_mm:.1f} mm)"
            )
            if r.peak_x_mm_unprotected is not None:
                bare.append(f"peak \\|x\\| {r.peak_x_mm_unprotected:.1f} mm")
        if r.peak_rpm is not None:
            parts.append(f"{r.overspeed_rpm:.0f} rpm over limit (peak {r.peak_rpm:.0f} rpm)")
            if r.peak_rpm_unprotected is not None:
                bare.append(f"peak {r.peak_rpm_unprotected:.0f} rpm")
        caught = r.rule or "not detected"
        delay = _num(r.detection_cycles, "{}")
        if r.warn_rule:
            caught = f"{r.warn_rule} (WARN), then {caught}"
            delay = f"{r.warn_cycles} (WARN), {delay}"
        bag = "yes" if r.bag_complete else "no: " + r.note
        lines.append(
            f"| {r.fault} | {r.axes} | {caught} | {delay} | {_num(r.safe_cycles, '{}')} | "
            f"{'; '.join(parts)} | {'; '.join(bare) or '—'} | {bag} | {r.end_state} |"
        )
    return head + "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Print the fault table of every scenario (argument: the output directory); the exit code."""
    argv = sys.argv[1:] if argv is None else argv
    rows = run_all(argv[0] if argv else None)
    print(to_markdown(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
