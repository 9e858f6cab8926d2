#!/usr/bin/env python3
"""The long identification study: every plant of pneu_control.sysid.study, one by one.

    .venv/bin/python tools/sysid_study.py [--level full|quick] [--seed S] [--out out/sysid_study]
                                          [--only NAME] [--tables-only]

For each plant (perturbed in the model's family, or STRUCTURAL: a form the twin cannot take):
excitation bags (seed S for identify, S + 1 held out), identify, validate; per value the error
against the truth and its stated tolerance and whether the 95 % interval covers the truth; per
signal the held-out fit. Writes <out>/<plant>/study.json, <out>/study.md (one section per plant),
<out>/summary.md (one row per plant), <out>/coverage.md (per value, over the plants) and
<out>/calibration_tables.md (the tables of docs/calibration.md).
--tables-only rebuilds the tables from the study.json files already in <out>. Same arguments,
same tables (the twin and the fit are deterministic). The CI-fast version is test/control/sysid.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path

from pneu_control.sysid.study import PERTURBATIONS, STRUCTURAL, TOLERANCE, study_plant
from pneu_sim.physics.plant_file import load_plant

_SIG = ("x", "p_c1", "p_c2", "p_m1", "omega")


def _slug(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")


def _retolerate(result: dict) -> dict:
    """``result`` scored against the tolerances of the code as it is now (a study.json keeps
    the ones it ran with)."""
    for p in result["parameters"]:
        if p["name"] not in TOLERANCE and not p["name"].startswith("noise σ"):
            continue  # a curve's row: its own tolerance
        kind, tol = TOLERANCE["noise.x" if p["name"] == "noise σ x" else "noise.p" if p["name"].startswith("noise σ") else p["name"]]  # fmt: skip
        d = p["identified"] - p["truth"]
        p["error"] = d / p["truth"] if kind == "rel" else d
        p["tolerance"], p["within"] = [kind, tol], abs(p["error"]) <= tol
    return result


def _covered(rows: list[dict]) -> str:
    """'covered / with an interval' of ``rows``."""
    return (
        f"{sum(p['covered'] is True for p in rows)} / {sum(p['covered'] is not None for p in rows)}"
    )


def _summary(results: list[dict]) -> str:
    """One row per plant: kind, taken values within tolerance, covered by their interval, the
    held-out fit per signal, the warnings, the identify time."""
    lines = [
        "| plant | kind | taken values within tolerance | 95 % intervals covering the truth | "
        "held-out fit % x / p_c1 / p_c2 / p_m1 / ω | mismatch warning (held out) | "
        "unexplained segments | identify (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        rows = [p for p in r["parameters"] if p["taken"]]
        held = next(v for v in r["validation"] if v["held_out"])
        fits = " / ".join(f"{held['fit_percent'].get(k, float('nan')):.1f}" for k in _SIG)
        kind = "structural" if r["plant"] in STRUCTURAL else "in model"
        warn = ", ".join(sorted({w.split(" axis")[0].split("on the ")[-1] for w in held["structural_mismatch"]})) or "—"  # fmt: skip
        unexpl = sum(1 for n in r.get("notes", []) if "not explained" in n)
        lines.append(
            f"| {r['plant']} | {kind} | {sum(p['within'] for p in rows)} / {len(rows)} | "
            f"{_covered(rows)} | {fits} | {warn} | "
            f"{unexpl or '—'} | {r['times_s'].get('identify', 0):.0f} |"
        )
    return "\n".join(lines) + "\n"


def _coverage(results: list[dict]) -> str:
    """Per value: over the in-model and the structural plants, how often it was taken, within
    its tolerance, and covered by its 95 % interval; the totals last."""
    names: list[str] = []
    for r in results:
        names += [p["name"] for p in r["parameters"] if p["name"] not in names]
    lines = [
        "| value | in model: within tol. / covered / taken "
        "| structural: within tol. / covered / taken | worst error (plant) |",
        "|---|---|---|---|",
    ]
    tot = {k: [0, 0, 0, 0] for k in ("in", "st")}
    for n in names:
        cells = {}
        worst = (0.0, "")
        for k in ("in", "st"):
            rows = [
                p
                for r in results
                if (r["plant"] in STRUCTURAL) == (k == "st")
                for p in r["parameters"]
                if p["name"] == n and p["taken"]
            ]
            c = [sum(p["within"] for p in rows), sum(p["covered"] is True for p in rows)]
            c += [len(rows), sum(p["covered"] is not None for p in rows)]  # taken, with an interval
            tot[k] = [a + b for a, b in zip(tot[k], c)]
            cov = str(c[1]) if c[3] == c[2] else "—" if not c[3] else f"{c[1]} of {c[3]}"
            cells[k] = f"{c[0]} / {cov} / {c[2]}" if rows else "—"
        for r in results:
            for p in r["parameters"]:
                if p["name"] == n and p["taken"] and abs(p["error"]) / p["tolerance"][1] > worst[0]:
                    unit = "%" if p["tolerance"][0] == "rel" else ""
                    e = 100 * p["error"] if unit else p["error"]
                    worst = (abs(p["error"]) / p["tolerance"][1], f"{e:+.3g}{unit} ({r['plant']})")
        lines.append(f"| {n} | {cells['in']} | {cells['st']} | {worst[1] or '—'} |")
    for k, label in (("in", "in model"), ("st", "structural")):
        w, c, t, n = tot[k]
        if t:
            lines.append(
                f"| **all, {label}** | within {w} / {t} ({100 * w / t:.0f} %), "
                f"covered {c} / {n} ({100 * c / max(n, 1):.0f} %) | | |"
            )
    w = tot["in"][1] + tot["st"][1]
    t = tot["in"][3] + tot["st"][3]
    if t:
        lines.append(f"| **all plants: covered** | {w} / {t} ({100 * w / t:.0f} %) | | |")
    return "\n".join(lines) + "\n"


def _cell(p: dict) -> str:
    """An error as the calibration table shows it: relative in %, absolute in the unit; bold
    outside its tolerance; ✗ where the 95 % interval misses the truth; kept (n.i.) where
    identify kept the base."""
    if not p["taken"]:
        return "kept (n.i.)"
    e = f"{100 * p['error']:+.1f} %" if p["tolerance"][0] == "rel" else f"{p['error']:+.3f}"
    e = e if p["within"] else f"**{e}**"
    return e if p["covered"] is not False else e + " ✗"


def _calibration(results: list[dict]) -> str:
    """The tables docs/calibration.md quotes: errors per value and plant (✗: not covered), then
    per plant the perturbed values, the rest, the held-out fit and the times."""
    by = {r["plant"]: r for r in results}
    plants = [n for n in PERTURBATIONS if n in by]
    head = "| parameter (tolerance) | " + " | ".join(plants) + " |"
    lines = [head, "|---|" + "---|" * len(plants)]
    names: list[str] = []
    for r in results:
        names += [p["name"] for p in r["parameters"] if p["name"] not in names]
    for n in names:
        any_p = next(p for r in results for p in r["parameters"] if p["name"] == n)
        kind, tol = any_p["tolerance"]
        label = f"{n} (±{100 * tol:g} %)" if kind == "rel" else f"{n} (±{tol:g})"
        cells = []
        for plant in plants:
            p = next((p for p in by[plant]["parameters"] if p["name"] == n), None)
            cells.append("—" if p is None else _cell(p))
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "| plant | perturbed: truth → identified | other taken values within tolerance (worst) | "
        "held-out fit % x / p_c1 / p_c2 / p_m1 / ω | excite (1 bag) + identify, s |",
        "|---|---|---|---|---|",
    ]
    for plant in plants:
        r = by[plant]
        keys = {k.replace("du_table", "dead_band") for k in PERTURBATIONS[plant]}
        hit = [p for p in r["parameters"] if p["name"] in keys]
        if hit:
            cells = "; ".join(
                f"{p['name']} {p['truth']:.4g} → {p['identified']:.4g} ({_cell(p)})" for p in hit
            )
        else:
            cells = "not fitted: " + ", ".join(sorted(PERTURBATIONS[plant]))
        rest = [p for p in r["parameters"] if p not in hit and p["taken"]]
        worst = max(rest, key=lambda p: abs(p["error"]) / p["tolerance"][1], default=None)
        w = f" ({worst['name']} {_cell(worst)})" if worst else ""
        held = next(v for v in r["validation"] if v["held_out"])
        fits = " / ".join(f"{held['fit_percent'].get(k, float('nan')):.1f}" for k in _SIG)
        t = r["times_s"]
        lines.append(
            f"| {plant} | {cells} | {sum(p['within'] for p in rest)}/{len(rest)}{w} | {fits} | "
            f"{t.get('excite (2 bags)', 0) / 2:.0f} + {t.get('identify', 0):.0f} |"
        )
    return "\n".join(lines) + "\n"


def _write(out: Path, results: list[dict]) -> None:
    (out / "summary.md").write_text(_summary(results))
    (out / "coverage.md").write_text(_coverage(results))
    (out / "calibration_tables.md").write_text(_calibration(results))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--level", choices=("full", "quick"), default="full")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="out/sysid_study")
    ap.add_argument("--only", action="append", default=[], choices=list(PERTURBATIONS))
    ap.add_argument("--tables-only", action="store_true")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    names = args.only or list(PERTURBATIONS)
    results, parts = [], [f"# Identification study ({args.level} excitation, seed {args.seed})\n"]
    base = None if args.tables_only else load_plant()
    t_all = time.perf_counter()
    for name in names:
        path = out / _slug(name) / "study.json"
        if args.tables_only:
            if path.exists():
                results.append(_retolerate(json.loads(path.read_text())))
            continue
        print(f"== {name}", file=sys.stderr, flush=True)
        log = lambda m: print(m, file=sys.stderr, flush=True)  # noqa: E731
        res = study_plant(name, base, out / _slug(name), level=args.level, log=log, seed=args.seed)
        results.append(json.loads(path.read_text()))
        parts.append(res.markdown())
        (out / "study.md").write_text("\n".join(parts))
        _write(out, results)
        print(
            f"   {len(res.failures())} value(s) outside tolerance; {res.times_s}", file=sys.stderr
        )
    _write(out, results)
    print(
        f"wrote {out}/summary.md, coverage.md, calibration_tables.md in "
        f"{time.perf_counter() - t_all:.0f} s",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
