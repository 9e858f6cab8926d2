"""What a sweep says: bands, the paper's figures against them, ranking odds, sensitivities.

Per (experiment, controller, gain set), over the N plant samples:

- **band**: the median and the 5–95 % band of e_max and RMSE, as empirical
  quantiles (inverted CDF: each is one sample's value). A run the supervisor
  stopped, or whose steady window never opened, has no number: it counts as
  worse than any number (+inf), so a band edge reads "trip" when more than
  5 % (or 50 %, 95 %) of the samples failed;
- **paper in band**: does the paper's figure lie inside that 5–95 % band;
- **sensitivity**: Spearman's rank correlation ρ between each sampled factor
  (a discrete one by its label's index) and e_max; the three largest |ρ|.
  With N samples, |ρ| under 2/√(N−1) (twice its standard error when there is no
  dependence) is not told apart from 0 (marked "n.s.").
  A factor or result that does not vary has no ρ (scipy would warn and give nan).

Per experiment where the paper reports all three of its controllers, and per
gain set: the probability over plant samples that the paper's ranking holds,
ESO-SMC < LADRC < PID (e_max, and RMSE where the paper gives it), with a 95 %
Wilson interval; controllers compared on the same sample (same plant, same
noise seed).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from pneu_control.experiment.catalog import Experiment

__all__ = ["Band", "GroupSummary", "Ranking", "summarise", "render_summary"]

QUANTILES = (0.05, 0.5, 0.95)
RANKED = ("eso_smc", "ladrc", "pid")  # the paper's ranking, best first


@dataclass(frozen=True)
class Band:
    """The 5 %, 50 % and 95 % quantiles of a figure over the plant samples (a failed sample counts
    as +inf)."""

    q05: float
    median: float
    q95: float
    failed: int  # samples without a number (+inf here)

    def holds(self, x: float | None) -> bool | None:
        """Is ``x`` inside [q05, q95]? (None for no ``x``)"""
        return None if x is None else bool(self.q05 <= x <= self.q95)


@dataclass(frozen=True)
class GroupSummary:
    """One (experiment, controller, gains) group over the plant samples: bands, trips, the paper's
    figures against the bands, sensitivities."""

    experiment: str
    controller: str
    gains: str
    unit: str
    n: int
    trips: int
    e_max: Band
    rmse: Band
    paper_e_max: float | None
    paper_rmse: float | None
    paper_e_max_in_band: bool | None
    paper_rmse_in_band: bool | None
    in_stated_band: float | None  # fraction of samples inside the paper's stated band
    sensitivity: list[tuple[str, float]]  # (factor, Spearman ρ of e_max), top 3 by |ρ|

    def to_dict(self) -> dict[str, Any]:
        """The summary as plain data."""
        return asdict(self)


@dataclass(frozen=True)
class Ranking:
    """How often the paper's ranking (ESO-SMC < LADRC < PID) holds over the plant samples, with its
    95 % interval."""

    experiment: str
    gains: str
    metric: str
    n: int
    p_ranking: float  # P(ESO-SMC < LADRC < PID)
    ci95: tuple[float, float]
    p_eso_lt_ladrc: float
    p_ladrc_lt_pid: float

    def to_dict(self) -> dict[str, Any]:
        """The ranking as plain data."""
        return asdict(self)


def _finite_or_inf(values: Sequence[float]) -> np.ndarray:
    a = np.asarray(values, dtype=float)
    return np.where(np.isfinite(a), a, np.inf)


def band(values: Sequence[float]) -> Band:
    """The :class:`Band` of ``values`` (non-finite ones as +inf, counted as failed)."""
    a = _finite_or_inf(values)
    q = np.quantile(a, QUANTILES, method="inverted_cdf")
    return Band(float(q[0]), float(q[1]), float(q[2]), int(np.isinf(a).sum()))


def wilson(k: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """95 % Wilson score interval of a binomial proportion k/n."""
    if n == 0:
        return (math.nan, math.nan)
    p = k / n
    den = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return (max(0.0, centre - half), min(1.0, centre + half))


def spearman_top(
    columns: dict[str, np.ndarray], y: Sequence[float], top: int = 3
) -> list[tuple[str, float]]:
    """The ``top`` factors by |Spearman ρ| with ``y`` (non-finite y = +inf, ranked last)."""
    from scipy.stats import spearmanr

    yy = _finite_or_inf(y)
    if yy.size < 3 or np.all(yy == yy[0]):
        return []
    out = []
    for name, x in columns.items():
        if np.all(x == x[0]):
            continue
        rho = float(spearmanr(x, yy).statistic)
        if math.isfinite(rho):
            out.append((name, rho))
    out.sort(key=lambda kv: (-abs(kv[1]), kv[0]))
    return out[:top]


def summarise(
    rows: Sequence[dict[str, Any]],
    factors: Sequence[Any],
    experiments: Sequence[Experiment],
) -> tuple[list[GroupSummary], list[Ranking]]:
    """Bands, paper-in-band, sensitivities and ranking odds of a sweep table.

    ``rows``: table rows as dicts (:func:`pneu_control.sweep.table.read_table`,
    or the RunRows' fields); ``factors``: :class:`~pneu_control.sweep.sampling.Factor`.
    """
    exps = {e.id: e for e in experiments}
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["experiment"], r["controller"], r["gains"]), []).append(r)
    summaries = []
    for (exp_id, ctrl, gains), rs in groups.items():
        rs = sorted(rs, key=lambda r: r["sample"])
        exp = exps[exp_id]
        paper_e, paper_r = exp.paper.get(ctrl, (None, None))
        eb, rb = band([r["e_max"] for r in rs]), band([r["rmse"] for r in rs])
        cols = {f.name: np.array([f.code(r[f.name]) for r in rs]) for f in factors}
        stated = [r["in_band"] is True for r in rs] if exp.band is not None else None
        summaries.append(
            GroupSummary(
                experiment=exp_id,
                controller=ctrl,
                gains=gains,
                unit=rs[0]["unit"],
                n=len(rs),
                trips=sum(1 for r in rs if r["safety_trip"]),
                e_max=eb,
                rmse=rb,
                paper_e_max=paper_e,
                paper_rmse=paper_r,
                paper_e_max_in_band=eb.holds(paper_e),
                paper_rmse_in_band=rb.holds(paper_r),
                in_stated_band=None if stated is None else sum(stated) / len(stated),
                sensitivity=spearman_top(cols, [r["e_max"] for r in rs]),
            )
        )
    return summaries, _rankings(groups, exps)


def _rankings(groups, exps) -> list[Ranking]:
    out = []
    seen = []
    for exp_id, _, gains in groups:
        if (exp_id, gains) not in seen:
            seen.append((exp_id, gains))
    for exp_id, gains in seen:
        exp = exps[exp_id]
        if not all(c in exp.controllers for c in RANKED):
            continue
        per = {c: groups.get((exp_id, c, gains)) for c in RANKED}
        if any(v is None for v in per.values()):
            continue
        metrics = ["e_max"]
        if all(exp.paper.get(c, (None, None))[1] is not None for c in RANKED):
            metrics.append("rmse")
        for metric in metrics:
            by_sample = {
                c: {r["sample"]: r[metric] for r in per[c]} for c in RANKED
            }  # same samples for all
            samples = sorted(set.intersection(*(set(v) for v in by_sample.values())))
            eso, ladrc, pid = (_finite_or_inf([by_sample[c][s] for s in samples]) for c in RANKED)
            n = len(samples)
            k = int(np.sum((eso < ladrc) & (ladrc < pid)))
            out.append(
                Ranking(
                    experiment=exp_id,
                    gains=gains,
                    metric=metric,
                    n=n,
                    p_ranking=k / n if n else math.nan,
                    ci95=wilson(k, n),
                    p_eso_lt_ladrc=float(np.mean(eso < ladrc)) if n else math.nan,
                    p_ladrc_lt_pid=float(np.mean(ladrc < pid)) if n else math.nan,
                )
            )
    return out


def _q(x: float) -> str:
    return "trip" if math.isinf(x) else f"{x:.3g}"


def _band_text(b: Band) -> str:
    return f"{_q(b.median)} [{_q(b.q05)}–{_q(b.q95)}]"


def _yes(v: bool | None) -> str:
    return "—" if v is None else ("yes" if v else "no")


def render_summary(
    summaries: Sequence[GroupSummary],
    rankings: Sequence[Ranking],
    n_samples: int,
    nominal: dict[tuple[str, str, str], tuple[float, float]] | None = None,
) -> str:
    """Markdown: the band table (beside the nominal figures when given) and the ranking odds."""
    nominal = nominal or {}
    sig = 2.0 / math.sqrt(max(n_samples - 1, 1))
    lines = [
        f"Over {n_samples} plant samples (5–95 % band; 'trip' = the supervisor stopped the run "
        "or the steady window never opened, counted as worse than any number).",
        "",
        "| experiment | controller | gains | nominal e_max | e_max median [5–95 %] | paper e_max | "
        "paper in band | RMSE median [5–95 %] | paper RMSE | paper in band | trips | "
        "most sensitive to (Spearman ρ of e_max) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for g in summaries:
        nom = nominal.get((g.experiment, g.controller, g.gains))
        nom_text = "—" if nom is None else _q(nom[0] if math.isfinite(nom[0]) else math.inf)
        sens = ", ".join(
            f"{_md(name)} {rho:+.2f}" + ("" if abs(rho) > sig else " (n.s.)")
            for name, rho in g.sensitivity
        )
        stated = ""
        if g.in_stated_band is not None:
            stated = f" ({100 * g.in_stated_band:.0f} % in the paper's band)"
        lines.append(
            f"| {g.experiment} | {g.controller} | {g.gains} | {nom_text} | "
            f"{_band_text(g.e_max)} {g.unit}{stated} | {_opt(g.paper_e_max)} | "
            f"{_yes(g.paper_e_max_in_band)} | {_band_text(g.rmse)} {g.unit} | "
            f"{_opt(g.paper_rmse)} | {_yes(g.paper_rmse_in_band)} | {g.trips}/{g.n} | "
            f"{sens or '—'} |"
        )
    if rankings:
        lines += [
            "",
            "Probability over the plant samples that the paper's ranking holds "
            "(same plant and noise seed for the three controllers):",
            "",
            "| experiment | gains | metric | P(ESO-SMC < LADRC < PID) [95 % CI] | "
            "P(ESO-SMC < LADRC) | P(LADRC < PID) |",
            "|---|---|---|---|---|---|",
        ]
        for r in rankings:
            lines.append(
                f"| {r.experiment} | {r.gains} | {r.metric} | {r.p_ranking:.2f} "
                f"[{r.ci95[0]:.2f}–{r.ci95[1]:.2f}] | {r.p_eso_lt_ladrc:.2f} | "
                f"{r.p_ladrc_lt_pid:.2f} |"
            )
    return "\n".join(lines) + "\n"


def _md(text: str) -> str:
    """A factor name inside a Markdown table cell (``supply[gauge|absolute]``)."""
    return text.replace("|", "\\|")


def _opt(x: float | None) -> str:
    return "—" if x is None else f"{x:g}"
