#!/usr/bin/env python3
"""The long identification study: every perturbed plant of pneu_control.sysid.study, one by one.

    .venv/bin/python tools/sysid_study.py [--level full|quick] [--out out/sysid_study] [--only NAME]

For each plant: excitation bags (seed 0 for identify, seed 1 held out), identify, validate, the
recovered parameters against the truth and their stated tolerances. Writes <out>/<plant>/study.json
and <out>/study.md (the tables docs/calibration.md quotes). The CI-fast version is test/control/sysid.
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from pathlib import Path

from pneu_control.sysid.study import PERTURBATIONS, study_plant
from pneu_sim.physics.plant_file import load_plant


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--level", choices=("full", "quick"), default="full")
    ap.add_argument("--out", default="out/sysid_study")
    ap.add_argument("--only", action="append", default=[], choices=list(PERTURBATIONS))
    args = ap.parse_args()
    base = load_plant()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    parts = [f"# Identification study ({args.level} excitation)\n"]
    summary = [
        "| plant | perturbed parameters: truth -> identified | other identified values within tolerance | "
        "held-out fit % (x, p_c1, p_c2, p_m1, ω) | excite + identify (s) |",
        "|---|---|---|---|---|",
    ]
    t_all = time.perf_counter()
    for name in args.only or list(PERTURBATIONS):
        slug = re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")
        print(f"== {name}", file=sys.stderr, flush=True)
        res = study_plant(
            name,
            base,
            out / slug,
            level=args.level,
            log=lambda m: print(m, file=sys.stderr, flush=True),
        )
        parts.append(res.markdown())
        (out / "study.md").write_text("\n".join(parts))
        bad = res.failures()
        keys = set(PERTURBATIONS[name])
        hit = [
            r for r in res.rows if r.name in keys or r.name.replace("dead_band", "du_table") in keys
        ]
        cells = "; ".join(
            f"{r.name} {r.truth:.4g} -> {r.value:.4g} ({100 * r.error:+.1f} %)"
            if r.tol[0] == "rel"
            else f"{r.name} {r.truth:+.3g} -> {r.value:+.3g}"
            for r in hit
        )
        others = [r for r in res.rows if r not in hit and r.taken]
        ok = sum(r.ok for r in others)
        held = next(v for v in res.validations if v.held_out)
        fits = ", ".join(
            f"{held.fits.get(k, float('nan')):.1f}" for k in ("x", "p_c1", "p_c2", "p_m1", "omega")
        )
        t = res.times_s.get("excite (2 bags)", 0) / 2 + res.times_s.get("identify", 0)
        summary.append(f"| {name} | {cells} | {ok} / {len(others)} | {fits} | {t:.0f} |")
        (out / "summary.md").write_text("\n".join(summary) + "\n")
        print(
            f"   {len(bad)} parameter(s) outside tolerance; {res.times_s}",
            file=sys.stderr,
            flush=True,
        )
    print(f"wrote {out}/study.md in {time.perf_counter() - t_all:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
