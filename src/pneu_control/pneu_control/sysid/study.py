"""Proof on known plants: perturbed twins, hidden from the identifier, identified and scored.

A study of one perturbed plant: run the excitation on it (seed s: the bag
``pneu identify`` sees; seed s + 1: a held-out bag with other pulse orders,
amplitudes, PRBS sequences, noise and sensor offsets), identify from the
first bag alone starting from the base plant, validate on both, and compare
every taken value with the truth against :data:`TOLERANCE` and its 95 %
interval (does it cover the truth?). :data:`STRUCTURAL` plants differ from
the twin in what it cannot fit (a valve curve's shape, the Stribeck width,
a sensor lag, the flow law's pressure ratio, the axis coupling, Table 1's
dead volumes): their shared values are still scored. The identifier
only ever gets the bags (written with ``hide_plant``); the truth is used
here, after the fact.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pneu_msgs_py.params.core import flatten, with_updates
from pneu_sim.physics.params import K_SEAL_ESTIMATE

from pneu_control.sysid import curve, model
from pneu_control.sysid.excite import excitation_spec, run_excitation
from pneu_control.sysid.identify import Identification, identify
from pneu_control.sysid.record import load_record
from pneu_control.sysid.validate import BagValidation, validate_record

__all__ = [
    "PERTURBATIONS",
    "STRUCTURAL",
    "TOLERANCE",
    "StudyResult",
    "perturbed_plant",
    "study_plant",
]


# name -> {dotted key: function(base value or base PlantParams group) -> true value}
PERTURBATIONS: dict[str, dict[str, Callable[[Any], Any]]] = {
    "J_m x1.6": {"rotary.J_m": lambda v: 1.6 * v},
    "leakage x2": {
        "valve_linear.leak_fraction": lambda v: 2.0 * v,
        "valve_rotary.leak_fraction": lambda v: 2.0 * v,
    },
    "flow curve shifted": {  # dead band +0.12 V, 15 % less flow
        "valve_linear.du_table": lambda t: model.shifted_table(t, 0.12),
        "valve_linear.Q_n": lambda v: 0.85 * v,
        "valve_rotary.du_table": lambda t: model.shifted_table(t, 0.12),
        "valve_rotary.Q_n": lambda v: 0.85 * v,
    },
    "breakaway x1.3": {"linear.breakaway_ratio": lambda v: 1.3 * v},
    "n = 1.05": {"ambient.n_poly": lambda v: 1.05},
    "n = 1.35": {"ambient.n_poly": lambda v: 1.35},
    "absolute supply": {  # the paper's 0.2 / 0.4 MPa read as absolute
        "supply.p_s_linear": lambda v: 0.2e6,
        "supply.p_s_rotary": lambda v: 0.4e6,
    },
    # several values at once, compensating (issue 21's plant B motor: J_m, M_c, V_m1)
    "motor J_m x1.5, M_c x0.6, V_m1 x1.6": {
        "rotary.J_m": lambda v: 1.5 * v,
        "rotary.M_c": lambda v: 0.6 * v,
        "rotary.V_m1": lambda v: 1.6 * v,
    },
    "cylinder A_f x1.3, c_v x0.75, leak x1.5": {
        "linear.A_f": lambda v: 1.3 * v,
        "linear.c_v": lambda v: 0.75 * v,
        "valve_linear.leak_fraction": lambda v: 1.5 * v,
    },
    # structural mismatch (STRUCTURAL): the twin's model cannot take these values
    "valve #1 curve of another shape": {  # more flow near the null: f^0.7 of the chart's
        "valve_linear.flow_table": lambda t: tuple(float(f) ** 0.7 for f in t),
    },
    "Stribeck dip 3x wider": {"linear.v_s": lambda v: 3.0 * v},
    "pressure sensor lag 5 ms": {"sensors.pressure.tau": lambda v: 0.005},
    "flow law b = 0.4 (pressure dependence of flow and leaks)": {
        "valve_linear.b": lambda v: 0.4,
        "valve_rotary.b": lambda v: 0.4,
    },
    "axis coupling on (seal torque)": {"coupling.k_seal": lambda v: K_SEAL_ESTIMATE},
    "dead volumes x1.3": {
        "linear.V_1d": lambda v: 1.3 * v,
        "linear.V_2d": lambda v: 1.3 * v,
    },
}
# plants the model's family does not contain (a fixed value or a form the fit cannot change)
STRUCTURAL = frozenset(list(PERTURBATIONS)[-6:])

# stated tolerance per identified parameter: ("rel", fraction) or ("abs", value in its unit)
TOLERANCE: dict[str, tuple[str, float]] = {
    "valve_linear.Q_n": ("rel", 0.05),
    "valve_linear.dead_band": ("abs", 0.03),
    "valve_linear.leak_fraction": ("rel", 0.15),
    "linear.A_f": ("rel", 0.15),
    "linear.c_v": ("rel", 0.10),
    "linear.breakaway_ratio": ("rel", 0.10),
    "ambient.n_poly": ("abs", 0.05),
    "supply.p_s_linear": ("rel", 0.03),
    "valve_rotary.Q_n": ("rel", 0.05),
    "valve_rotary.dead_band": ("abs", 0.03),
    "valve_rotary.leak_fraction": ("rel", 0.15),
    "rotary.J_m": ("rel", 0.10),
    "rotary.M_c": ("rel", 0.10),
    "rotary.M_v": ("rel", 0.10),
    "rotary.V_m1": ("rel", 0.15),
    "rotary.V_m2": ("rel", 0.50),
    "rotary.A_ex": ("rel", 0.20),
    "rotary.k_leak": ("rel", 0.20),
    # measured: the estimate scatters 1.7-2.0 % (1 σ) over noise seeds on one quick experiment
    # of an in-model motor (docs/calibration.md, the intervals); 3 % was 1.5 σ
    "supply.p_s_rotary": ("rel", 0.05),
    "noise.x": ("rel", 0.15),
    "noise.p": ("rel", 0.15),
}


def perturbed_plant(base, names: str | list[str]):
    """``base`` with the perturbations ``names`` (one or several of :data:`PERTURBATIONS`)."""
    names = [names] if isinstance(names, str) else list(names)
    flat = flatten(base)
    upd: dict[str, Any] = {}
    for name in names:
        for key, f in PERTURBATIONS[name].items():
            upd[key] = f(flat[key])
    return with_updates(base, upd)


def true_value(base, truth, name: str) -> float:
    """The hidden plant's value of fit parameter ``name`` (a dead band: its shift from ``base``)."""
    if name.endswith("." + model.DEAD_BAND):
        valve = name.split(".")[0]
        return getattr(truth, valve).du_table[1] - getattr(base, valve).du_table[1]
    return float(flatten(truth)[name])


@dataclass
class Row:
    """One parameter of the study: truth, base, identified value with its 95 % CI, and the tolerance
    it is scored against."""

    name: str
    truth: float
    base: float
    value: float
    ci95: float
    taken: bool
    tol: tuple[str, float]

    @property
    def error(self) -> float:
        """Relative error (rel tolerance) or absolute error (abs tolerance)."""
        d = self.value - self.truth
        return d / self.truth if self.tol[0] == "rel" else d

    @property
    def ok(self) -> bool:
        """Is the error inside the tolerance?"""
        return abs(self.error) <= self.tol[1]

    @property
    def covered(self) -> bool | None:
        """Does the 95 % interval contain the truth? (None: a value without an interval)"""
        if math.isnan(self.ci95):
            return None
        return abs(self.value - self.truth) <= self.ci95

    def to_dict(self) -> dict[str, Any]:
        """The row as plain data."""
        return {
            "name": self.name,
            "truth": self.truth,
            "base": self.base,
            "identified": self.value,
            "ci95": self.ci95,
            "taken": self.taken,
            "error": self.error,
            "tolerance": list(self.tol),
            "within": self.ok,
            "covered": self.covered,
        }


@dataclass
class StudyResult:
    """One perturbed plant of the study: the parameter rows, the validations of its bags, the
    identification."""

    plant: str
    rows: list[Row]
    validations: list[BagValidation]
    ident: Identification
    times_s: dict[str, float] = field(default_factory=dict)
    identified_plant: Any = None
    true_plant: Any = None

    def failures(self) -> list[Row]:
        """Rows taken into the identified plant whose error is outside the tolerance."""
        return [r for r in self.rows if r.taken and not r.ok]

    def to_dict(self) -> dict[str, Any]:
        """The result as plain data."""
        return {
            "plant": self.plant,
            "parameters": [r.to_dict() for r in self.rows],
            "validation": [v.to_dict() for v in self.validations],
            "correlated": {a: f.correlated_pairs() for a, f in self.ident.fits.items()},
            "notes": list(self.ident.notes),
            "structural": self.plant in STRUCTURAL,
            "times_s": self.times_s,
        }

    def markdown(self) -> str:
        """The result as a Markdown section: one table row per parameter."""
        lines = [
            f"#### {self.plant}",
            "",
            "| parameter | truth | base | identified | 95 % CI | error | tolerance | within | covered |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in self.rows:
            err = f"{100 * r.error:+.1f} %" if r.tol[0] == "rel" else f"{r.error:+.3g}"
            tol = f"±{100 * r.tol[1]:.0f} %" if r.tol[0] == "rel" else f"±{r.tol[1]:g}"
            ok = ("yes" if r.ok else "**no**") if r.taken else "not identifiable (base kept)"
            cov = {True: "yes", False: "**no**", None: "—"}[r.covered]
            lines.append(
                f"| {r.name} | {r.truth:.4g} | {r.base:.4g} | {r.value:.4g} | ±{r.ci95:.2g} | "
                f"{err} | {tol} | {ok} | {cov} |"
            )
        lines += [
            "",
            "| bag | held out | " + " | ".join(_SIG) + " |",
            "|---|---|" + "---|" * len(_SIG),
        ]
        for v in self.validations:
            cells = [f"{v.fits[s]:.1f}" if s in v.fits else "—" for s in _SIG]
            lines.append(
                f"| {Path(v.bag).parent.name} | {'yes' if v.held_out else 'no'} | "
                + " | ".join(cells)
                + " |"
            )
        t = ", ".join(f"{k} {v:.0f} s" for k, v in self.times_s.items())
        lines += [""] + [f"- {n}" for n in self.ident.notes]
        lines += [f"- {w}" for v in self.validations for w in v.warnings if v.held_out]
        lines += ["", f"wall times: {t}", ""]
        return "\n".join(lines)


_SIG = ("x", "p_c1", "p_c2", "p_m1", "omega")


def compare(ident: Identification, base, truth) -> list[Row]:
    """One :class:`Row` per fitted parameter of ``ident``, against the hidden plant ``truth``."""
    rows = []
    for fit in ident.fits.values():
        if fit.curve_support is not None:  # the valve's own curve, against the true one
            rows.extend(curve_rows(ident.plant, truth, fit.curve_support))
        for i, name in enumerate(fit.names):
            if curve.is_handle(name):
                continue
            rows.append(
                Row(
                    name,
                    true_value(base, truth, name),
                    fit.base[i],
                    fit.value[i],
                    fit.ci95(i),
                    name not in ident.kept_base,
                    TOLERANCE[name],
                )
            )
    s_t, s_b = truth.sensors, base.sensors
    for key, nz in ident.noise.items():
        if key == "x":
            t, b = s_t.laser.sigma_m, s_b.laser.sigma_m
        else:
            k = s_t.pressure.fs / s_t.pressure.v_fs
            t, b = s_t.pressure.sigma_v * k, s_b.pressure.sigma_v * k
        tol = TOLERANCE["noise.x" if key == "x" else "noise.p"]
        rows.append(Row(f"noise σ {key}", t, b, nz.sigma, nz.rel_ci95 * nz.sigma, True, tol))
    return rows


CURVE_TOLERANCE = 0.05  # of full flow, at every voltage (issue 21)


def curve_rows(plant, truth, sup) -> list[Row]:
    """The identified valve curve's worst error (fraction of full flow) over the voltages its
    knots were fitted on, judged by its tolerance without an interval (the knots' bands are
    per knot, not a band of the worst error: not counted in the coverage); and beyond them,
    where the data do not reach and the catalogue's shape is kept: not taken (not
    identifiable from the excitation), shown for what it is."""
    rng = sup.fitted_range()
    inside = curve.max_error(plant, truth, sup.valve, sup.ports, within=rng)
    beyond = curve.max_error(plant, truth, sup.valve, sup.ports, within=rng, outside=True)
    tol = ("abs", CURVE_TOLERANCE)
    return [
        Row(f"{sup.valve}.curve worst Δf where fitted", 0.0, 0.0, inside, math.nan, True, tol),
        Row(f"{sup.valve}.curve worst Δf beyond the data", 0.0, 0.0, beyond, math.nan, False, tol),
    ]


def study_plant(
    names: str | list[str],
    base,
    out_dir: str | Path,
    *,
    level: str = "quick",
    axes: tuple[str, ...] = ("linear", "rotary"),
    log: Callable[[str], None] = print,
    seed: int = 0,
) -> StudyResult:
    """Excite the perturbed twin (seeds ``seed`` and ``seed`` + 1), identify from the first,
    validate on both."""
    label = names if isinstance(names, str) else " + ".join(names)
    truth = perturbed_plant(base, names)
    out = Path(out_dir)
    times: dict[str, float] = {}
    bags = []
    t0 = time.perf_counter()
    for sd in (seed, seed + 1):
        d = out / f"excite_seed{sd}"
        spec = excitation_spec(axes, truth, seed=sd, level=level)
        run_excitation(spec, d, progress=False, hide_plant=True)
        bags.append(d / "run.mcap")
    times["excite (2 bags)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    recs = [load_record(b) for b in bags]
    ident = identify([recs[0]], base, axes=axes, log=log)
    times["identify"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    vals = [
        validate_record(recs[1], ident.plant, held_out=True),
        validate_record(recs[0], ident.plant, held_out=False),
    ]
    times["validate"] = time.perf_counter() - t0
    res = StudyResult(label, compare(ident, base, truth), vals, ident, times, ident.plant, truth)
    (out / "study.json").write_text(json.dumps(res.to_dict(), indent=2, default=float) + "\n")
    return res
