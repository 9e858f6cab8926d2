"""One figure per experiment with the sweep's bands.

Top: the tracking error |e(t)| (max per bin, the metric's averaging) over the
plant samples, median line and 5–95 % band, per controller and gain set (the
paper's gains dashed). Bottom: e_max per controller and gain set, median dot,
5–95 % bar, the paper's figure as a red star; a band edge without a number
(runs the supervisor stopped) is drawn at the top edge marked "trip", a median
without one as a cross there; the trips are counted in the label.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pneu_control.analysis.plots import pyplot
from pneu_control.experiment.catalog import Experiment

__all__ = ["plot_bands"]


def _quantiles(block: np.ndarray) -> np.ndarray:
    """(3, bins) 5/50/95 % over the samples, NaN where no sample has a value."""
    out = np.full((3, block.shape[1]), np.nan)
    ok = np.isfinite(block).any(axis=0)
    if ok.any():
        out[:, ok] = np.nanquantile(block[:, ok], (0.05, 0.5, 0.95), axis=0)
    return out


def plot_bands(
    exp: Experiment,
    rows: Sequence[dict],
    envelopes: np.ndarray,
    dt_s: float,
    summaries: Sequence,
    path: str | Path,
) -> Path:
    """``rows`` (table order, aligned with ``envelopes``) of one sweep; draws ``exp``'s."""
    plt = pyplot()
    fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(9.0, 7.0))
    groups = [g for g in summaries if g.experiment == exp.id]
    n = len({r["sample"] for r in rows if r["experiment"] == exp.id})
    floor = []
    for i, g in enumerate(groups):
        idx = [
            k
            for k, r in enumerate(rows)
            if (r["experiment"], r["controller"], r["gains"])
            == (g.experiment, g.controller, g.gains)
        ]
        q = _quantiles(envelopes[idx])
        t = (np.arange(q.shape[1]) + 0.5) * dt_s
        style = "--" if g.gains == "paper" else "-"
        colour = f"C{i % 10}"
        label = f"{g.controller} ({g.gains})"
        ax0.plot(t, q[1], style, color=colour, lw=1.0, label=label)
        positive = q[1][np.isfinite(q[1]) & (q[1] > 0)]
        if positive.size:
            floor.append(float(positive.min()))
        ax0.fill_between(t, q[0], q[2], color=colour, alpha=0.15, lw=0)
        lo, med, hi = g.e_max.q05, g.e_max.median, g.e_max.q95
        top = _finite_top(groups)
        yv = [min(v, top) for v in (lo, med, hi)]
        ax1.errorbar(
            [i],
            [yv[1]],
            yerr=[[yv[1] - yv[0]], [yv[2] - yv[1]]],
            fmt="x" if math.isinf(med) else "o",
            color=colour,
            capsize=4,
        )
        if math.isinf(hi):  # the band reaches runs without a number: say so at the top
            ax1.annotate("trip", (i, top), fontsize=7, ha="center", va="bottom", color=colour)
        if g.paper_e_max is not None:
            ax1.plot([i], [g.paper_e_max], "r*", ms=10, label="paper" if i == 0 else None)
    ax0.set_yscale("log")
    if floor:  # a quantised error can be 0 in a bin: keep the axis on the medians' decades
        ax0.set_ylim(bottom=10.0 ** (math.floor(math.log10(min(floor))) - 1))
    ax0.set_xlabel("t (s)")
    ax0.set_ylabel(f"|e| ({exp.unit}), max per {dt_s * 1e3:.0f} ms")
    ax0.legend(fontsize=7, ncol=2, loc="upper right")
    ax0.set_title(f"{exp.title}: {n} plant samples, median and 5–95 % band", fontsize=10)
    ax1.set_yscale("log")
    ax1.set_xticks(range(len(groups)))
    ax1.set_xticklabels(
        [f"{g.controller}\n{g.gains}\ntrips {g.trips}/{g.n}" for g in groups], fontsize=7
    )
    ax1.set_ylabel(f"e_max ({exp.unit})")
    _, labels = ax1.get_legend_handles_labels()
    if labels:
        ax1.legend(fontsize=7)
    fig.tight_layout()
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, format="png")
    plt.close(fig)
    return out


def _finite_top(groups) -> float:
    vals = [
        v
        for g in groups
        for v in (g.e_max.q05, g.e_max.median, g.e_max.q95, g.paper_e_max or math.nan)
        if v is not None and math.isfinite(v)
    ]
    return 2.0 * max(vals) if vals else 1.0
