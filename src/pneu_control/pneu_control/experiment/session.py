"""Build a :class:`RunSpec` from user-level options and execute it with logging.

Shared by ``pneu run``, ``pneu paper`` and the benchmarks so that every entry
point resolves config files, overrides and steady-state windows the same way.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pneu_msgs_py.lifecycle import signals
from pneu_msgs_py.lifecycle.duration import check_duration
from pneu_msgs_py.lifecycle.outputs import OutputDir
from pneu_msgs_py.live.sink import Tee
from pneu_msgs_py.params.core import ParamError, to_dict, unknown_key
from pneu_msgs_py.params.spec import parse_spec, parse_value
from pneu_msgs_py.params.yaml_file import from_option

from pneu_control.analysis.metrics import WindowSpec
from pneu_control.controller.params import load_controller_params
from pneu_control.experiment.runner import RunResult, RunSpec, run

__all__ = [
    "RUN_ARTEFACTS",
    "RunOptions",
    "build_spec",
    "check_seed",
    "execute",
    "parse_reference",
    "parse_sets",
    "run_dir",
    "window_for",
]

RUN_ARTEFACTS = ("run.mcap", "metrics.json", "timeseries.npz")
SEED_MAX = 2**32 - 1


def check_seed(seed: object, field: str = "--seed") -> int:
    """A seed is an integer in [0, 2^32 - 1] (numpy's SeedSequence takes it whole)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= SEED_MAX:
        raise ParamError(field, seed, f"an integer in [0, {SEED_MAX}]")
    return seed


def parse_sets(
    items: Iterable[str], axes: tuple[str, ...], taken: Mapping[str, str] | None = None
) -> dict[str, dict[str, Any]]:
    """``["eso_smc.epsilon=900", "rotary.pid.kp=0.3"]`` -> per-axis dotted overrides.

    Each key once per axis (``eso_smc.epsilon`` and ``linear.eso_smc.epsilon`` are the same
    key), and none that another option sets (``taken``: key -> that option, e.g.
    ``algorithm`` -> ``--controller``): the last would silently win.
    """
    out: dict[str, dict[str, Any]] = {axis: {} for axis in axes}
    first: dict[tuple[str, str], str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ParamError("--set", item, "KEY=VALUE, e.g. eso_smc.epsilon=900")
        head, _, rest = key.partition(".")
        targets = axes
        if head in ("linear", "rotary"):
            if head not in axes:
                raise ParamError(
                    f"--set {key}", value, f"a key of an active axis ({', '.join(axes)})"
                )
            targets, key = (head,), rest
        for axis in targets:
            if (taken or {}).get(key):
                raise ParamError(
                    f"--set {item.partition('=')[0]}",
                    value,
                    f"a key no other option sets ({taken[key]} sets {key})",
                )
            if (axis, key) in first:
                raise ParamError(
                    f"--set {item.partition('=')[0]}",
                    value,
                    f"each key once per axis (already --set {first[axis, key]} for {axis})",
                )
            first[axis, key] = item
            out[axis][key] = parse_value(value)
    return out


def parse_reference(text: str | None) -> dict[str, Any]:
    """``sine:amplitude=20,frequency_hz=0.25`` -> dotted ``reference.*`` overrides."""
    if not text:
        return {}
    kind, values = parse_spec(text, "--reference")
    check_reference_keys(kind, values, f"--reference {kind}")
    return {"reference.kind": kind, **{f"reference.{k}": v for k, v in values.items()}}


def check_reference_keys(kind: str, keys: Iterable[str], field: str) -> None:
    """Refuse an unknown reference kind, and a key the kind does not read (it would be
    silently ignored: ``constant:value=5,amplitude=3``)."""
    from pneu_control.controller.params import REFERENCE_KEYS

    if kind not in REFERENCE_KEYS:
        raise ParamError("--reference", kind, "a kind: one of " + ", ".join(REFERENCE_KEYS))
    for key in keys:
        if key not in REFERENCE_KEYS[kind]:
            raise ParamError(
                f"{field}",
                key,
                unknown_key(key, REFERENCE_KEYS[kind]).replace(
                    "no such parameter", f"a key of a {kind} reference"
                ),
            )


def rotary_average_s(speed_rpm: float) -> float:
    """Speed-metric averaging window: one revolution at the reference (pneu_control.analysis.metrics)."""
    return 60.0 / abs(speed_rpm) if speed_rpm else 0.0


def window_for(axis: str, reference: Any, window_start_s: float | None = None) -> WindowSpec:
    """DESIGN §7 default steady-state window for a reference kind."""
    if window_start_s is not None:
        return WindowSpec(kind="fixed", t_start_s=window_start_s)
    kind = reference.kind
    if kind == "sine":
        return WindowSpec(kind="sine", frequency_hz=reference.frequency_hz)
    if kind == "constant" and axis == "rotary":
        return WindowSpec(kind="speed", average_s=rotary_average_s(reference.value))
    if kind == "smooth_step":
        return WindowSpec(kind="positioning", t_start_s=reference.duration_s + 1.0)
    return WindowSpec(kind="fixed", t_start_s=1.0)


@dataclass(frozen=True)
class RunOptions:
    """The user-level options of one run, as ``pneu run`` takes them: :func:`build_spec`
    checks them and turns them into a :class:`RunSpec`.

    One definition for every entry point (``pneu run``/``rig``, the paper table,
    sweeps, tuning, benchmarks): a caller fills the fields it has and
    :func:`dataclasses.replace` varies them per run.
    """

    axes: tuple[str, ...]
    controller: str | None = None  # algorithm on every axis (None: each axis's from the file)
    reference: str | dict[str, Any] | None = None  # "KIND:k=v,..." or dotted reference.* values
    sets: Iterable[str] = ()  # --set KEY=VALUE overrides (see parse_sets)
    duration_s: float = 20.0
    seed: int = 0
    plant_file: str | Path | None = None  # None: config/plant.yaml
    controllers_file: str | Path | None = None  # None: config/controllers.yaml
    window_start_s: float | None = None  # None: the reference kind's window (window_for)
    faults: Iterable[Any] = ()  # NAME[:k=v,...] strings, dicts or FaultSpec
    name: str = "run"
    plant: Any | None = None  # PlantParams, used instead of plant_file
    safety: bool | Any = True  # True: the supervisor of safety_file; False: none; or SafetyParams
    safety_file: str | Path | None = None  # None: config/safety.yaml
    include_faults: bool = False  # metrics over the fault intervals too


def build_spec(options: RunOptions | None = None, /, **fields: Any) -> RunSpec:
    """A validated :class:`RunSpec` from :class:`RunOptions` (nothing half-applied).

    ``build_spec(options)``, ``build_spec(axes=..., ...)`` (the fields of
    :class:`RunOptions`) or ``build_spec(options, seed=3)`` (``options`` with
    those fields replaced).

    Everything is checked here, before anything is written: every file and
    option, the references against the stroke and speed limits and the faults
    against the run (:mod:`pneu_control.experiment.checks`).
    """
    from pneu_sim.faults.injection import parse_faults
    from pneu_sim.physics.plant_file import load_plant

    from pneu_control.experiment.checks import check_faults, check_references

    o = RunOptions(**fields) if options is None else dataclasses.replace(options, **fields)
    duration_s = _check_options(o)
    with from_option("--plant" if o.plant_file else None):
        plant_params = o.plant if o.plant is not None else load_plant(o.plant_file)
    controllers, windows = _controllers(o)
    fault_specs = parse_faults(o.faults)
    safety_params = _safety_params(o)
    if safety_params is not None:
        from pneu_driver.safety import check_plumbing

        with from_option("--safety" if o.safety_file else None):
            check_plumbing(
                safety_params, plant_params.rotary.plumbing, "the twin's rotary.plumbing"
            )
    check_faults(fault_specs, o.axes, duration_s)
    spec = RunSpec(
        axes=o.axes,
        controllers=controllers,
        plant=plant_params,
        duration_s=duration_s,
        seed=o.seed,
        windows=windows,
        name=o.name,
        faults=fault_specs,
        safety=safety_params,
        include_faults=o.include_faults,
    )
    check_references(spec, "--reference" if o.reference else None)
    return spec


def _check_options(o: RunOptions) -> float:
    """The checked duration; refuses a bad controller, seed or window start."""
    from pneu_control.controller.params import ALGORITHMS

    duration_s = check_duration(o.duration_s, "--duration")
    if o.controller is not None and o.controller not in ALGORITHMS:
        raise ParamError("--controller", o.controller, "one of " + ", ".join(ALGORITHMS))
    check_seed(o.seed)
    if o.safety is False and o.safety_file is not None:  # no supervisor would read it
        raise ParamError("--safety", str(o.safety_file), "not with --no-safety (one or the other)")
    w = o.window_start_s
    if w is not None and not (isinstance(w, (int, float)) and 0.0 <= w < duration_s):
        raise ParamError("--window-start", w, f"[0, {duration_s:g}) s: inside the run")
    return duration_s


def _controllers(o: RunOptions) -> tuple[dict[str, Any], dict[str, WindowSpec]]:
    """Each axis's controller parameters (file, then reference, algorithm and --set) and window."""
    ref = o.reference if isinstance(o.reference, dict) else parse_reference(o.reference)
    by = "--reference" if isinstance(o.reference, str) else "the experiment's reference"
    taken = dict.fromkeys(ref, by) | ({"algorithm": "--controller"} if o.controller else {})
    per_axis = parse_sets(o.sets, o.axes, taken)
    controllers: dict[str, Any] = {}
    windows: dict[str, WindowSpec] = {}
    for axis in o.axes:
        overrides: dict[str, Any] = dict(ref)
        if o.controller:
            overrides["algorithm"] = o.controller
        overrides.update(per_axis[axis])
        with from_option("--controllers" if o.controllers_file else None):
            load_controller_params(axis, o.controllers_file)  # the file's errors, located in it
        try:
            params = load_controller_params(axis, o.controllers_file, overrides)
        except ParamError as err:  # an override's: named with its axis
            raise ParamError(f"{axis}.{err.key}", err.value, err.allowed) from None
        kind = params.reference.kind  # a --set reference.KEY the kind reads, too
        sets = [k.partition(".")[2] for k in per_axis[axis] if k.startswith("reference.")]
        check_reference_keys(kind, [k for k in sets if k != "kind"], f"--set reference ({kind})")
        controllers[axis] = params
        windows[axis] = window_for(axis, params.reference, o.window_start_s)
    return controllers, windows


def _safety_params(o: RunOptions) -> Any:
    """The supervisor's parameters of the run (None: no supervisor)."""
    if o.safety is True:
        from pneu_driver.safety import load_safety_params

        with from_option("--safety" if o.safety_file else None):
            return load_safety_params(o.safety_file)
    if o.safety is False or o.safety is None:
        return None
    return o.safety


def config_echo(spec: RunSpec) -> dict[str, Any]:
    """The full config of a run, as plain data (metrics.json, bag metadata)."""
    from pneu_msgs_py import __version__

    return {
        "name": spec.name,
        "axes": list(spec.axes),
        "duration_s": spec.duration_s,
        "seed": spec.seed,
        "x0": spec.x0,
        "controllers": {
            axis: p.to_dict() if hasattr(p, "to_dict") else to_dict(p)
            for axis, p in spec.controllers.items()
        },
        "windows": {axis: w.to_dict() for axis, w in spec.windows.items()},
        "plant": to_dict(spec.plant),
        "faults": [f.to_dict() for f in spec.faults],
        "safety": None if spec.safety is None else to_dict(spec.safety),
        "version": __version__,
    }


def _progress_printer(total_s: float, label: str):
    start = time.monotonic()
    last = [start]

    def report(t_sim: float) -> None:
        now = time.monotonic()
        if now - last[0] >= 1.0 and now - start >= 2.0:
            last[0] = now
            print(f"  {label}: {t_sim:5.1f} / {total_s:.1f} s simulated", file=sys.stderr)

    return report


def run_dir(
    out_dir: str | Path,
    *,
    overwrite: bool = False,
    inputs: Iterable[str | Path | None] = (),
    bag_name: str = "run.mcap",
) -> OutputDir:
    """The claim on a run directory (:mod:`pneu_msgs_py.lifecycle.outputs`); ``.check()`` it early."""
    return OutputDir(
        out_dir, (bag_name, "metrics.json", "timeseries.npz"), overwrite=overwrite, inputs=inputs
    )


def end_record(result: RunResult) -> dict[str, Any]:
    """How the run ended: ``completed`` or ``interrupted`` (by which signal, when, how far)."""
    n = len(result.t)
    sig = signals.pending()
    return {
        "status": "interrupted" if result.interrupted else "completed",
        "interrupted": result.interrupted,
        "signal": signals.signal_name(sig) if (result.interrupted and sig) else "",
        "interrupted_utc": signals.pending_since() if result.interrupted else "",
        "last_sample_s": float(result.t[-1]) if n else 0.0,
        "samples": n,
        "planned_samples": int(round(result.spec.duration_s / result.spec.plant.sim.T)),
    }


def execute(
    spec: RunSpec,
    out_dir: str | Path | OutputDir,
    *,
    bag: bool = True,
    progress: bool = False,
    bag_name: str = "run.mcap",
    overwrite: bool = False,
    live: Any | None = None,
    echo_overrides: dict[str, Any] | None = None,
    hook: Any | None = None,
) -> RunResult:
    """Run ``spec``; write ``metrics.json``, ``timeseries.npz`` and (``bag``) the MCAP bag.

    The run directory is claimed first (:func:`run_dir`: refused if it holds
    files, unless ``overwrite``; locked). Files are written under ``.partial``
    names and renamed when complete. SIGINT, SIGTERM and SIGHUP stop the loop
    at the next cycle; the bag and the metrics of what ran are then finished
    with ``interrupted: true`` (``pneu.end`` metadata, metrics.json). A signal
    before the first sample leaves nothing behind and raises
    :class:`~pneu_msgs_py.lifecycle.signals.Interrupted`.

    ``live``: a :class:`pneu_msgs_py.live.server.LiveServer` that gets every cycle
    too (after the bag); the caller closes it. ``echo_overrides`` replace entries of
    the recorded config (e.g. a blind identification study hides the twin's parameters).
    ``hook``: the runner's per-cycle hook (:func:`pneu_control.experiment.runner.run`).
    """
    claim = (
        out_dir
        if isinstance(out_dir, OutputDir)
        else run_dir(out_dir, overwrite=overwrite, bag_name=bag_name)
    )
    echo = {**config_echo(spec), **(echo_overrides or {})}
    report = _progress_printer(spec.duration_s, spec.name) if progress else None
    with signals.deferred(), claim:
        writer = None
        try:
            signals.raise_if_pending()
            if bag:
                from pneu_control.experiment.bag_log import open_run_bag

                writer = open_run_bag(claim.final(bag_name), spec, echo)
            sink = writer if live is None else (live if writer is None else Tee(writer, live))
            result = run(spec, bag=sink, progress=report, hook=hook)
            if result.interrupted and len(result.t) == 0:
                raise signals.Interrupted(signals.pending() or 2)
        except BaseException as err:
            if writer is not None:
                _abandon(writer, err)
            claim.discard()
            raise
        result.end = end_record(result)
        if writer is not None:
            from pneu_control.experiment.bag_log import (
                END_METADATA,
                INTERVALS_METADATA,
                end_metadata,
                intervals_metadata,
            )

            writer.add_metadata(
                INTERVALS_METADATA,
                intervals_metadata(result.fault_intervals, result.safety_counters),
            )
            writer.add_metadata(END_METADATA, end_metadata(result.end))
            writer.close()
        result.save(claim.path, config_echo=echo)
    for iv in result.fault_intervals:
        if iv.kind == "safe":
            until = "the end" if iv.end_s == float("inf") else f"{iv.end_s:.3f} s"
            print(
                f"  {spec.name}: safety: {iv.axis} valve held safe from {iv.start_s:.3f} s to "
                f"{until} ({iv.cause})",
                file=sys.stderr,
            )
    return result


def _abandon(writer: Any, err: BaseException) -> None:
    """A run that raised: an interruption before the first sample leaves no bag; a failure
    leaves a complete bag that says it failed (``pneu.end`` status ``failed``)."""
    if isinstance(err, KeyboardInterrupt):
        writer.discard()
        return
    from pneu_control.experiment.bag_log import END_METADATA, end_metadata

    try:
        writer.add_metadata(
            END_METADATA,
            end_metadata({"status": "failed", "error": f"{type(err).__name__}: {err}"}),
        )
        writer.close()
    except Exception:
        writer.discard()


def metrics_from_bag(path: str | Path, axis: str):
    """The metrics of ``axis`` computed from the bag alone (the analysis path)."""
    from pneu_control.analysis.run_analysis import analyze

    return analyze(path).metrics[axis]
