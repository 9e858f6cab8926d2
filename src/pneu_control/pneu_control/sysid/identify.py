"""From bags to a calibrated plant.yaml: noise from quiet segments, the output-error fits, the file.

Order: the sensor noise (first differences in the quiet segments: their
standard deviation within 5 robust σ of the median, /√2, blind to slow drifts), then the
cylinder and the motor at once, each on a thread of its own, their replays on one pool
(:mod:`pneu_sim.physics.workers`). They share one value: the polytropic index, which the
cylinder fixes and the motor sees only as n/V (its volumes are fixed), so the motor is fitted
at the base's index and its volumes are written at the cylinder's (the same twin), their
intervals widened by the index's. Each fitted
value goes into a copy of the base plant.yaml tree -- every other leaf and
every key of a leaf (unit, source, and any optional key such as a ``range``)
is kept -- with ``source: identified from <bags> (±x %)`` (95 % interval).
A parameter whose interval is wider than :data:`UNIDENTIFIABLE` of its value
keeps the base value and says so in its source: the data do not determine it --
unless its 95 % interval excludes the base value: then the data contradict the
base, and the fitted value is taken with its wide interval.
"""

from __future__ import annotations

import copy
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from pneu_sim.physics import workers
from threadpoolctl import threadpool_limits

from pneu_control.sysid import model
from pneu_control.sysid.fit import STAGES, AxisFit, FitOptions, fit_axis, in_polytropic_index
from pneu_control.sysid.record import Record

__all__ = [
    "Identification",
    "UNIDENTIFIABLE",
    "estimate_noise",
    "identify",
    "output_claims",
    "write_plant",
]

UNIDENTIFIABLE = 0.5  # 95 % half-width / value above which a value is not taken
_QUIET_SIGNALS = {"linear": ("x", "p_c1", "p_c2"), "rotary": ("p_m1",)}


@dataclass
class NoiseEstimate:
    """One sensor's noise σ from the quiet segments (SI) and the samples it rests on."""

    signal: str
    sigma: float  # SI (m or Pa)
    n: int

    @property
    def rel_ci95(self) -> float:
        """95 % half-width of σ, relative to σ."""
        return 1.96 / math.sqrt(max(self.n - 1, 1))  # σ of a σ estimate ≈ σ/√(2N), ×√2 for Δy


@dataclass
class Identification:
    """What ``pneu identify`` found: the base and identified plants, the fits per axis, the noise,
    what was kept."""

    base: Any  # PlantParams
    plant: Any  # PlantParams, identified
    fits: dict[str, AxisFit]
    noise: dict[str, NoiseEstimate]
    bags: list[str]
    kept_base: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def rows(self) -> list[dict[str, Any]]:
        """One dict per fitted parameter: base, identified value, 95 % CI and whether it was
        taken."""
        out = []
        for fit in self.fits.values():
            for i, name in enumerate(fit.names):
                out.append(
                    {
                        "name": name,
                        "unit": fit.units[i],
                        "base": fit.base[i],
                        "value": fit.value[i],
                        "ci95": fit.ci95(i),
                        "rel_ci95": None if _absolute(name) else fit.rel_ci95(i),
                        "taken": name not in self.kept_base,
                    }
                )
        return out

    def to_dict(self) -> dict[str, Any]:
        """The identification as plain data (the ``.identify.json`` report)."""
        return {
            "bags": self.bags,
            "parameters": self.rows(),
            "correlated": {
                a: [list(p) for p in f.correlated_pairs()] for a, f in self.fits.items()
            },
            "offsets_pa": {a: f.offsets for a, f in self.fits.items()},
            "offsets_sigma_pa": {a: f.offsets_sigma for a, f in self.fits.items()},
            "noise": {k: {"sigma": v.sigma, "n": v.n} for k, v in self.noise.items()},
            "fit": {
                a: {
                    "cost_start": f.cost_start,
                    "cost": f.cost,
                    "nfev": f.nfev,
                    "wall_s": f.wall_s,
                    "residual_autocorrelation_time": f.inflation,
                    "n_residuals": f.n_residuals,
                    "status": f.status,
                    "correlation": f.corr.tolist(),
                    "names": f.names,
                    "q95": f.q95,
                    "sigma_fit": f.sigma_fit,
                    "replicate_rms_shift": f.replicate_shift,
                    "sigma_iid": f.sigma_iid,
                    "segments": f.n_clusters,
                    "unexplained": f.unexplained,
                }
                for a, f in self.fits.items()
            },
            "kept_base": self.kept_base,
            "notes": self.notes,
        }

    def report(self) -> str:
        """The identification as Markdown: one table row per parameter and noise estimate, then
        the correlated pairs and each bag's pressure sensor offsets."""
        lines = ["| parameter | base | identified | 95 % CI | taken |", "|---|---|---|---|---|"]
        for fit in self.fits.values():  # a valve's own curve: one row (its knots in the JSON)
            if fit.curve_support is not None:
                n = sum(1 for name in fit.names if model.is_handle(name))
                band = max(fit.ci95(i) for i, name in enumerate(fit.names) if model.is_handle(name))
                lines.append(
                    f"| {fit.curve_support.valve} curve | catalogue | own, {n} values "
                    f"({fit.curve_support.text()}) | ±{band:.3g} at most | yes |"
                )
        for r in self.rows():
            if model.is_handle(r["name"]):
                continue
            ci = (
                f"±{r['ci95']:.3g} {r['unit']}"
                if r["rel_ci95"] is None
                else f"±{100 * r['rel_ci95']:.2g} %"
            )
            lines.append(
                f"| {r['name']} | {r['base']:.4g} | {r['value']:.4g} {r['unit']} | {ci} | "
                f"{'yes' if r['taken'] else 'no (kept base)'} |"
            )
        for key, nz in self.noise.items():
            unit = "m" if key == "x" else "Pa"
            lines.append(
                f"| noise σ {key} | | {nz.sigma:.4g} {unit} | ±{100 * nz.rel_ci95:.2g} % | yes |"
            )
        for axis, f in self.fits.items():
            for a, b, rho in f.correlated_pairs():
                if model.is_handle(a) and model.is_handle(b):
                    continue  # neighbouring knots of one curve trade by construction
                lines.append(
                    f"\n{axis}: {a} and {b} correlated (ρ = {rho:+.3f}): not separately identifiable from these bags"
                )
            for rec, offs in f.offsets.items():
                s = ", ".join(f"{k} {v / 1e3:+.2f} kPa" for k, v in offs.items())
                lines.append(
                    f"\n{axis}: pressure sensor offsets in {rec}: {s} (not written: a property of the sensors)"
                )
        return "\n".join(lines) + "\n"


def estimate_noise(records: list[Record], axes: tuple[str, ...]) -> dict[str, NoiseEstimate]:
    """Sensor noise σ from the quiet segments (robust, from first differences)."""
    out: dict[str, NoiseEstimate] = {}
    for axis in axes:
        for name in _QUIET_SIGNALS[axis]:
            diffs = []
            for rec in records:
                if axis not in rec.commanded:
                    continue
                m = rec.quiet_mask(axis)
                y = rec.y[name]
                both = m[1:] & m[:-1] & np.isfinite(y[1:]) & np.isfinite(y[:-1])
                diffs.append(np.diff(y)[both])
            d = np.concatenate(diffs) if diffs else np.zeros(0)
            if len(d) < 50:
                continue
            # the standard deviation of the differences within 5 robust σ of their median: as
            # robust as the MAD against a step or a spike, but not quantised with the AI's
            # steps (the MAD of 16-bit pressure readings moves in 8 % steps of σ)
            med = float(np.median(d))
            mad = float(np.median(np.abs(d - med)))
            kept = d[np.abs(d - med) <= 5.0 * 1.4826 * mad] if mad > 0 else d
            out[name] = NoiseEstimate(name, float(np.std(kept)) / math.sqrt(2.0), len(kept))
    return out


def excited_axes(records: list[Record]) -> tuple[str, ...]:
    """The axes some of ``records`` excite (a design, or a valve command that varies)."""
    return tuple(a for a in ("linear", "rotary") if _excited(records, a))


def _excited(records: list[Record], axis: str) -> list[Record]:
    out = []
    for r in records:
        if axis in r.designs or (axis in r.commanded and np.ptp(r.u[axis][r.valid[axis]]) > 0.05):
            out.append(r)
    return out


def identify(
    records: list[Record],
    base,
    *,
    axes: tuple[str, ...] | None = None,
    options: FitOptions | None = None,
    log: Callable[[str], None] = print,
    progress: Callable[[int, int], None] | None = None,
    replicate: bool = True,
) -> Identification:
    """Identify ``base`` (PlantParams) from ``records``; see the module docstring.

    ``progress(done, total)``: fit stages begun of at most ``STAGES`` per axis. ``replicate``:
    widen the intervals by a parametric-bootstrap draw (:mod:`pneu_control.sysid.replicate`)."""
    options = options or FitOptions()
    axes = axes or excited_axes(records)
    if not axes:
        raise ValueError("no axis is excited in these bags (no design, no varying valve command)")
    notes = [n for r in records for n in (f"{r.name}: {x}" for x in r.notes)]
    noise = estimate_noise(records, axes)
    kept: list[str] = []
    order = tuple(a for a in ("linear", "rotary") if a in axes)
    recs = {axis: _excited(records, axis) for axis in order}
    done = dict.fromkeys(order, 0)

    def counted(axis: str) -> Callable[[], None]:
        def stage() -> None:
            done[axis] += 1
            if progress is not None:
                progress(sum(done.values()), STAGES * len(order))

        return stage

    def fitted(axis: str) -> AxisFit:
        log(f"{axis}: fitting {len(model.AXIS_PARAMS[axis])} parameters to {len(recs[axis])} bag(s)")  # fmt: skip
        fit = fit_axis(axis, base, recs[axis], options, log=log, stage=counted(axis))
        done[axis] = STAGES
        if progress is not None:
            progress(sum(done.values()), STAGES * len(order))
        log(f"{axis}: cost {fit.cost_start:.4g} -> {fit.cost:.4g} in {fit.nfev} steps, {fit.wall_s:.0f} s")  # fmt: skip
        return fit

    # the replay's workers run every core (pneu_sim.physics.workers): BLAS threads beside
    # them only wait for cores, and OpenBLAS's spin after every call (docs/calibration.md)
    with threadpool_limits(1, "blas"):
        # both axes at once: they share no fitted value (the motor sees the cylinder's n
        # only as n/V, so its fit runs at the base's n and is written in the cylinder's)
        fits = dict(zip(order, workers.concurrently([lambda a=a: fitted(a) for a in order])))
        if "linear" in fits and "rotary" in fits:
            n = _taken(base, fits["linear"], []).ambient.n_poly
            fits["rotary"] = in_polytropic_index(fits["rotary"], n)
        if replicate:
            fits = _replicated(base, fits, recs, noise, options, log)
    if "linear" in fits and "rotary" in fits and "ambient.n_poly" in fits["linear"].names:
        lin = fits["linear"]  # the motor's volumes are known as far as the cylinder's n is
        i = lin.names.index("ambient.n_poly")
        n = fits["rotary"].plant.ambient.n_poly
        if n == lin.value[i]:  # taken (else the base's n: its own tolerance, not the fit's)
            fits["rotary"] = in_polytropic_index(fits["rotary"], n, lin.sigma[i] / n)
    plant = base
    for fit in fits.values():
        plant = _taken(plant, fit, kept)
        notes.extend(fit.unexplained)
    if "rotary" in axes and "linear" not in axes:
        notes.append(
            "ambient.n_poly not fitted: on the motor it only appears as n/V (fixed volumes); "
            "the cylinder's moving piston separates it"
        )
    plant = _with_noise(plant, noise)
    return Identification(
        base=base,
        plant=plant,
        fits=fits,
        noise=noise,
        bags=[r.path for r in records],
        kept_base=kept,
        notes=notes,
    )


def _with_noise(plant, noise: dict[str, NoiseEstimate]):
    """``plant`` with the sensor noise σ measured in the quiet segments."""
    from pneu_msgs_py.params.core import with_updates

    upd = {}
    s = plant.sensors
    if "x" in noise:
        upd["sensors.laser.sigma_m"] = noise["x"].sigma
    pn = [noise[k].sigma for k in ("p_c1", "p_c2", "p_m1") if k in noise]
    if pn:
        upd["sensors.pressure.sigma_v"] = float(np.mean(pn)) * s.pressure.v_fs / s.pressure.fs
    return with_updates(plant, upd)


def _taken(plant, fit: AxisFit, kept: list[str], every: bool = False):
    """``plant`` with the values of ``fit`` whose 1.96 σ is within :data:`UNIDENTIFIABLE` (of
    the value; of the width for a linear parameter) or whose 95 % interval excludes the base
    value, the names of the others appended to ``kept``; with ``every``, every fitted value.
    A valve's own curve is taken whole."""
    from pneu_control.sysid.curve import with_curve_of

    params = list(fit.fit_params)
    take = []
    for i, p in enumerate(params):
        if model.is_handle(p.name):  # a curve knot: the curve is taken whole, below
            continue
        # judged on the estimated scatter (1.96 σ), not on the interval's t quantile, which
        # also carries how few bootstrap draws that estimate rests on
        half = 1.96 * fit.sigma[i]
        v = fit.value[i]
        rel = half / p.width if p.transform == "lin" else (half / abs(v) if v else math.inf)
        # a value 8 σ from its base is imprecise, not undetermined (a trial of the study's
        # breakaway plant: 1.94 ± 0.23 at 95 % against a base of 1.5, truth 1.95, base kept)
        contradicted = abs(v - fit.base[i]) > fit.ci95(i)
        if not every and (not math.isfinite(rel) or rel > UNIDENTIFIABLE) and not contradicted:
            kept.append(p.name)
        else:
            take.append(i)
    plant = model.apply(plant, [params[i] for i in take], [fit.value[i] for i in take])
    if fit.curve_support is not None:  # the valve's own curve, as fitted (its band reported)
        plant = with_curve_of(plant, fit.plant, fit.curve_support.valve)
    return plant


def _replicated(base, fits: dict[str, AxisFit], recs, noise, options, log) -> dict[str, AxisFit]:
    """``fits`` with their parametric-bootstrap draw (:mod:`pneu_control.sysid.replicate`):
    the bags' designs run once more on the identified twin (every fitted value, the
    measured noise), each axis fitted again from its values; an axis without a design in
    its bags keeps its fit's intervals (and a line says so)."""
    from pneu_control.sysid.fit import refit, with_replicate
    from pneu_control.sysid.replicate import REPLICATES, replicate_records

    t0 = time.perf_counter()
    twin = base
    for fit in fits.values():
        twin = _taken(twin, fit, [], every=True)
    twin = _with_noise(twin, noise)
    records = list({id(r): r for rs in recs.values() for r in rs}.values())
    starts, fitted_base = {}, base  # the motor's fit is written in the cylinder's values
    for axis, fit in fits.items():
        starts[axis] = fitted_base
        fitted_base = _taken(fitted_base, fit, [])
    jobs = []  # (axis, draw): each draw's fits start while the next draw is excited
    with workers.Group() as group:
        for k in range(REPLICATES):
            reps = replicate_records(records, tuple(fits), twin, k)
            for axis in fits:
                mine = [r for r in reps if axis in r.designs]
                if mine:
                    jobs.append((axis, k))
                    group.start([lambda a=axis, m=mine: refit(a, starts[a], m, fits[a], options)])
        again = group.results()
    out = {}
    for axis, fit in fits.items():
        mine_again = [d for (a, _k), d in zip(jobs, again) if a == axis]
        if len(mine_again) < REPLICATES:
            log(f"  {axis}: no design in the bags: intervals from the fit alone (no replicate)")
            out[axis] = fit
            continue
        log(f"  {axis}: fitted again on each: " + ", ".join(f"{d.nfev} steps" for d in mine_again))
        out[axis] = with_replicate(fit, mine_again)
    log(
        f"  replicate on the identified twin ({REPLICATES} excitations, {len(jobs)} fits again, "
        f"each draw's fits beside the next draw's excitation): {time.perf_counter() - t0:.0f} s"
    )
    return out


def _absolute(name: str) -> bool:
    """Is the interval of ``name`` reported in its unit (a dead band, a curve knot)?"""
    return name.endswith("." + model.DEAD_BAND) or model.is_handle(name)


def _core_leaves(tree: Any) -> Any:
    if isinstance(tree, dict):
        if "value" in tree and isinstance(tree.get("unit"), str):
            return {k: tree[k] for k in ("value", "unit", "source") if k in tree}
        return {k: _core_leaves(v) for k, v in tree.items()}
    return tree


def _set(tree: dict, dotted: str, value: Any, source: str, ci95: float | None = None) -> None:
    """Set a leaf's value and source. An uncertainty the base gave it (an optional ``range``
    or ``alternatives`` key, as ``pneu sweep`` reads them) is what identification just
    measured: a range becomes the 95 % interval, alternatives are resolved (dropped)."""
    node = tree
    for key in dotted.split("."):
        node = node[key]
    node["value"] = value
    node["source"] = source
    if "range" in node and ci95 is not None and isinstance(value, float):
        node["range"] = [value - ci95, value + ci95]
    node.pop("alternatives", None)


def output_claims(
    out: str | Path, *, overwrite: bool = False, inputs: Any = (), field: str = "--out"
) -> tuple[Any, Any]:
    """The claims on the identified plant.yaml and its report ``NAME.identify.json``
    (:class:`pneu_msgs_py.lifecycle.outputs.OutputFile`), both checked: new files (or
    ``overwrite``), neither one of ``inputs``."""
    from pneu_msgs_py.lifecycle.outputs import OutputFile

    out = Path(out)
    plant = OutputFile(
        out, overwrite=overwrite, inputs=inputs, field=field, suffixes=(".yaml", ".yml")
    )
    report = OutputFile(
        out.with_suffix(".identify.json"), overwrite=overwrite, inputs=inputs, field=field
    )
    return plant.check(), report.check()


def _identified_tree(ident: Identification, base_tree: dict, names: str) -> dict:
    """``base_tree`` with the identified leaves replaced (each saying how it was identified
    from ``names``) and the unidentifiable ones marked as kept."""
    from pneu_msgs_py.params.core import flatten

    tree = copy.deepcopy(base_tree)
    values = flatten(ident.plant)
    for fit in ident.fits.values():
        _set_own_curve(tree, fit, values, names)
        for i, name in enumerate(fit.names):
            if model.is_handle(name):
                continue
            if name.endswith("." + model.DEAD_BAND):
                leaf = name.split(".")[0] + ".du_table"
                if name in ident.kept_base:
                    continue
                _set(
                    tree,
                    leaf,
                    [float(v) for v in values[leaf]],
                    f"identified from {names}: the base breakpoints shifted by "
                    f"{fit.value[i]:+.3f} V (±{fit.ci95(i):.3f} V)",
                )
                continue
            if name in ident.kept_base:
                node = tree
                for key in name.split("."):
                    node = node[key]
                node["source"] = (
                    f"not identifiable from {names} (95 % CI ±{100 * fit.rel_ci95(i):.0f} %): "
                    f"base value kept ({node.get('source', '')})"
                )
                continue
            _set(
                tree,
                name,
                float(values[name]),
                f"identified from {names} (±{100 * fit.rel_ci95(i):.2g} %)",
                fit.ci95(i),
            )
    for key, leaf in (("x", "sensors.laser.sigma_m"), ("p", "sensors.pressure.sigma_v")):
        nz = [v for k, v in ident.noise.items() if (k == "x") == (key == "x")]
        if nz:
            rel = min(v.rel_ci95 for v in nz)
            _set(
                tree,
                leaf,
                float(values[leaf]),
                f"identified from the quiet segments of {names} (±{100 * rel:.2g} %)",
            )
    return tree


def _set_own_curve(tree: dict, fit: AxisFit, values: dict, names: str) -> None:
    """The valve's own curve of ``fit`` (if its last stage fitted one) into ``tree``, with its
    provenance: what the data informed, the knots' 95 % band; Q_n becomes its unit."""
    sup = fit.curve_support
    if sup is None:
        return
    valve = sup.valve
    band = max((fit.ci95(i) for i, n in enumerate(fit.names) if model.is_handle(n)), default=0.0)
    src = (
        f"identified from {names}: the valve's own curve, monotone per port, {sup.text()}; "
        f"knots ±{band:.3f} of full flow at most (95 %)"
    )
    for leaf in ("u_curve", "flow_4", "flow_2"):
        key = f"{valve}.{leaf}"
        _set(tree, key, [float(v) for v in values[key]], src)
    if sup.ports == ("4",):
        _set(
            tree,
            f"{valve}.flow_2",
            [float(v) for v in values[f"{valve}.flow_2"]],
            src + "; port 2 unused by the plumbing: written as port 4's image (-flow_4)",
        )
    _set(
        tree,
        f"{valve}.Q_n",
        float(values[f"{valve}.Q_n"]),
        f"identified from {names}: the unit of the identified curve (u_curve, flow_4, flow_2 "
        "are fractions of this nominal flow), the flow scale of the catalogue-shaped fit it "
        "started from",
    )
    node = tree[valve]["Q_n"]
    node.pop("range", None)  # the catalogue's tolerance band is not this unit's uncertainty


def write_plant(
    ident: Identification,
    base_tree: dict,
    out: str | Path | tuple[Any, Any],
    *,
    overwrite: bool = False,
) -> Path:
    """Write the identified plant.yaml and its report (claims of :func:`output_claims`, or a
    path: claimed here; never overwrites unless ``overwrite``). Both are written as
    ``NAME.partial``, the YAML read back strictly, and renamed when both are complete."""
    from pneu_msgs_py.params.yaml_file import load_yaml
    from pneu_sim.physics.plant_file import params_from_tree, plant_tree_yaml

    claims = out if isinstance(out, tuple) else output_claims(out, overwrite=overwrite)
    names = ", ".join(
        Path(b).name if Path(b).name != "run.mcap" else str(Path(b).parent.name + "/run.mcap")
        for b in ident.bags
    )
    tree = _identified_tree(ident, base_tree, names)
    header = [
        "# Plant of the linear-rotary pneumatic actuator twin (pneu_sim), identified by `pneu identify`",
        f"# from {names}. Each leaf: value, unit, source; identified leaves say so, with their",
        "# 95 % interval; everything else is the base file's. Pressures absolute, SI units.",
    ]
    text = plant_tree_yaml(tree, header)
    plant_claim, report_claim = claims
    with plant_claim, report_claim:
        try:
            plant_claim.partial.write_text(text, encoding="utf-8")
            # what was written loads strictly, or nothing is published (checked on the leaves'
            # value, unit and source: optional leaf keys, e.g. a range, are the base file's)
            params_from_tree(_core_leaves(load_yaml(plant_claim.partial)))
            report_claim.partial.write_text(
                json.dumps(ident.to_dict(), indent=2, sort_keys=True, default=float) + "\n",
                encoding="utf-8",
            )
        except BaseException:
            plant_claim.discard()
            report_claim.discard()
            raise
        report_claim.publish()
        return plant_claim.publish()
